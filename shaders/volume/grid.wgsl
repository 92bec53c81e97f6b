// Voxel reads of the bricked grid (twin of hytrace_volume::BrickedGrid::voxel): indirection,
// brick table, atlas texel, decode `offset + t * scale`; and the two trilinear blends of the
// CPU (the lookup's weighted sum and the exact estimator's nested lerps), in its order of
// operations. No hardware filtering. Kernels composed with `nanovdb` also read grids stored
// as raw NanoVDB buffers (volume/nanovdb); kernels composed with `streamed` read a brick
// store through the brick pool's page table (volume/stream).
// #import volume/bindings
// #if nanovdb
// #import volume/nanovdb
// #endif
// #if streamed
// #import volume/stream
// #endif

// Code-unit value of texel `j` (4 * row + column) of a BC4 block at atlas word `w`
// (hytrace_volume bc4.rs: endpoints in bytes 0 and 1, 3-bit indices from bit 16).
fn bc4_texel(w: u32, j: u32) -> f32 {
    let lo = atlas_word(w);
    let hi = atlas_word(w + 1u);
    let b = 16u + 3u * j;
    var index: u32;
    if b + 3u <= 32u {
        index = (lo >> b) & 7u;
    } else if b >= 32u {
        index = (hi >> (b - 32u)) & 7u;
    } else {
        index = ((lo >> b) | (hi << (32u - b))) & 7u;
    }
    let r0 = lo & 255u;
    let r1 = (lo >> 8u) & 255u;
    let a = f32(r0);
    let c = f32(r1);
    if index == 0u {
        return a;
    }
    if index == 1u {
        return c;
    }
    if r0 > r1 {
        return (f32(8u - index) * a + f32(index - 1u) * c) / 7.0;
    }
    if index == 6u {
        return 0.0;
    }
    if index == 7u {
        return 255.0;
    }
    return (f32(6u - index) * a + f32(index - 1u) * c) / 5.0;
}

// The IEEE half in the low 16 bits of `h` as f32, exactly (in integer arithmetic: no
// float16 capability needed). The bricked format never stores infinities or NaNs.
fn half_to_f32(h: u32) -> f32 {
    let sign = (h & 0x8000u) << 16u;
    let e = (h >> 10u) & 31u;
    let m = h & 1023u;
    if e == 0u {
        // Zero or subnormal: m * 2^-24, exact in f32.
        return bitcast<f32>(sign | bitcast<u32>(f32(m) * (1.0 / 16777216.0)));
    }
    return bitcast<f32>(sign | ((e + 112u) << 23u) | (m << 13u));
}

// Code-unit value of voxel `i` (x + 8 y + 64 z) of atlas slot `slot` of the grid (its
// slots start at texture slot `atlas_base`), from the 3D texture: unorm codes read back
// exactly, BC4 as the device decodes it.
// #if atlas_texture
fn texture_texel(slot: u32, i: u32) -> f32 {
    let bricks = textureDimensions(atlas_texture) >> vec3<u32>(3u);
    let s = vparams.atlas_base + slot;
    let brick = vec3<u32>(s % bricks.x, (s / bricks.x) % bricks.y, s / (bricks.x * bricks.y));
    let texel = (brick << vec3<u32>(3u)) | vec3<u32>(i & 7u, (i >> 3u) & 7u, i >> 6u);
    let v = textureLoad(atlas_texture, texel, 0).r;
    switch vparams.format {
        case VOLUME_FORMAT_UNORM8: {
            return round(v * 255.0);
        }
        case VOLUME_FORMAT_UNORM16: {
            return round(v * 65535.0);
        }
        case VOLUME_FORMAT_BC4: {
            return v * 255.0;
        }
        default: {
            return v;
        }
    }
}
// #endif

// Code-unit value of voxel `i` (x + 8 y + 64 z) of atlas slot `slot` of the grid (its
// slots start at word `atlas_base`), decoded from the atlas' words or, in kernels composed
// with `atlas_texture`, read from the 3D texture.
fn atlas_texel(slot: u32, i: u32) -> f32 {
    // #if atlas_texture
    return texture_texel(slot, i);
    // #endif
    let w = vparams.atlas_base;
    switch vparams.format {
        case VOLUME_FORMAT_F32: {
            return bitcast<f32>(atlas_word(w + slot * 512u + i));
        }
        case VOLUME_FORMAT_F16: {
            return half_to_f32(atlas_word(w + slot * 256u + (i >> 1u)) >> (16u * (i & 1u)));
        }
        case VOLUME_FORMAT_UNORM16: {
            return f32((atlas_word(w + slot * 256u + (i >> 1u)) >> (16u * (i & 1u))) & 0xffffu);
        }
        case VOLUME_FORMAT_UNORM8: {
            return f32((atlas_word(w + slot * 128u + (i >> 2u)) >> (8u * (i & 3u))) & 0xffu);
        }
        default: {
            // BC4: per z slice four 4x4 blocks of two words, by block row then column.
            let x = i & 7u;
            let y = (i >> 3u) & 7u;
            let z = i >> 6u;
            let block = 4u * z + 2u * (y >> 2u) + (x >> 2u);
            return bc4_texel(w + slot * 64u + 2u * block, 4u * (y & 3u) + (x & 3u));
        }
    }
}

// Voxel `c`: the background outside the stored bricks, `offset` for a constant brick; for
// a raw NanoVDB grid (only in kernels composed with `nanovdb`), its voxel `c` moved back by
// the host's translation.
fn grid_voxel(c: vec3<i32>) -> f32 {
    // #if nanovdb
    if vparams.format == VOLUME_FORMAT_NANOVDB {
        let shift = vparams.index_shift;
        return nanovdb_voxel(c + vec3<i32>(shift[0], shift[1], shift[2]));
    }
    // #endif
    let local = (c >> vec3<u32>(3u)) - vec3<i32>(vparams.brick_lo[0], vparams.brick_lo[1], vparams.brick_lo[2]);
    let dims = vec3<i32>(vec3<u32>(vparams.brick_dims[0], vparams.brick_dims[1], vparams.brick_dims[2]));
    if any(local < vec3<i32>(0)) || any(local >= dims) {
        return vparams.background;
    }
    let l = vec3<u32>(local);
    let d = vec3<u32>(dims);
    let page = (l.z * d.y + l.y) * d.x + l.x;
    let e = indirection_entry(vparams.indirection_base + page);
    if e == VOLUME_NO_BRICK {
        return vparams.background;
    }
    // #if streamed
    // A brick store's page table: `e` is the brick's pool slot, or it is absent (and holds
    // its record: its octant's mean stands in until it arrives).
    if (e & VOLUME_ABSENT_BRICK) != 0u {
        stream_request(page);
        return stream_coarse(e & ~VOLUME_ABSENT_BRICK, vec3<u32>(c & vec3<i32>(7)));
    }
    stream_touch(e);
    // #endif
    let entry = brick_entry(e);
    if entry.atlas_slot == VOLUME_NO_SLOT {
        return entry.offset;
    }
    let b = vec3<u32>(c & vec3<i32>(7));
    return entry.offset + atlas_texel(entry.atlas_slot, b.x | (b.y << 3u) | (b.z << 6u)) * entry.scale;
}

// Voxels `cell + (c & 1, c >> 1 & 1, c >> 2)` for c < count (1 or 8): the one read place
// (a loop, so grid_voxel is inlined once).
fn grid_fetch(cell: vec3<i32>, count: u32) -> array<f32, 8> {
    var v: array<f32, 8>;
    for (var c = 0u; c < count; c++) {
        v[c] = grid_voxel(cell + vec3<i32>(vec3<u32>(c & 1u, (c >> 1u) & 1u, c >> 2u)));
    }
    return v;
}

// `sum + w v` unless the weight `w` is zero.
fn corner_add(sum: f32, w: f32, v: f32) -> f32 {
    if w != 0.0 {
        return sum + w * v;
    }
    return sum;
}

// The trilinear lookup's blend (hytrace_volume::sample_trilinear): the sum over the corners
// (x the fastest) of the product of the per-axis weights (x, then y, then z), zero weights
// skipped. Straight-line code: lavapipe (llvmpipe) gives all the loops of an invocation
// 65535 iterations together (shaders/loop_budget.wgsl), so per-lookup arithmetic loops
// none.
fn trilinear_sum(v: array<f32, 8>, f: vec3<f32>) -> f32 {
    let x = vec2<f32>(1.0 - f.x, f.x);
    let y = vec2<f32>(1.0 - f.y, f.y);
    let z = vec2<f32>(1.0 - f.z, f.z);
    var sum = corner_add(0.0, x[0] * y[0] * z[0], v[0]);
    sum = corner_add(sum, x[1] * y[0] * z[0], v[1]);
    sum = corner_add(sum, x[0] * y[1] * z[0], v[2]);
    sum = corner_add(sum, x[1] * y[1] * z[0], v[3]);
    sum = corner_add(sum, x[0] * y[0] * z[1], v[4]);
    sum = corner_add(sum, x[1] * y[0] * z[1], v[5]);
    sum = corner_add(sum, x[0] * y[1] * z[1], v[6]);
    return corner_add(sum, x[1] * y[1] * z[1], v[7]);
}

fn lerp1(a: f32, b: f32, w: f32) -> f32 {
    return a + (b - a) * w;
}

// The exact estimator's blend (transmittance.rs `trilinear`): lerps along x, y, then z.
fn trilinear_lerp(v: array<f32, 8>, f: vec3<f32>) -> f32 {
    let x0 = lerp1(v[0], v[1], f.x);
    let x1 = lerp1(v[2], v[3], f.x);
    let x2 = lerp1(v[4], v[5], f.x);
    let x3 = lerp1(v[6], v[7], f.x);
    return lerp1(lerp1(x0, x1, f.y), lerp1(x2, x3, f.y), f.z);
}
