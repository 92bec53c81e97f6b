// The bricked grids and their range mips as the volume kernels read them (uploaded by
// crates/trace/src/gpu/transmittance.rs): group 0, bindings 0 to 4 (5 to 7 and 9 to 17 for split
// arrays, 8 for texels in a 3D texture). Several grids share the arrays (the renderer's
// media); each has its parameters, with its first entries in them.
// #import generated/trace_records

@group(0) @binding(0) var<storage, read> volume_params: array<VolumeParams>;
// The arrays below grow with the grids: each is read through its accessor and, above the
// device's binding limit, split over its binding and three more.
// (min, max) of every block of every mip level, level after level (VolumeParams.level_dims.w).
// #chunked ranges vec2<f32> 0 1 9 block_range
// Brick-table index of every brick of each grid's indirection box (x fastest), or
// VOLUME_NO_BRICK.
// #chunked indirection u32 0 2 12 indirection_entry
// #chunked bricks BrickEntry 0 3 15 brick_entry
// The atlas bytes as little-endian words (brick texels, or raw NanoVDB grids).
// #chunked atlas u32 0 4 5 atlas_word
// #if atlas_texture
// The grids' texels as one 3D texture instead (crates/trace/src/gpu/texels.rs): the 8^3
// texels of texture slot s at brick (s % bx, s / bx % by, s / (bx by)) of its bx x by x bz
// bricks, in the format's own texture format; each grid's slots follow those of the grids
// before it, from its `atlas_base`.
@group(0) @binding(8) var atlas_texture: texture_3d<f32>;
// #endif
// The parameters of the grid the walks and lookups read (`use_volume`), and their entry.
var<private> vparams: VolumeParams;
var<private> vparams_entry: u32 = 0xffffffffu;

// Makes entry `i` of the volume parameters the grid read. A private copy: reads of its
// fields are then plain loads on every driver, where indexed storage reads gather per
// lane on CPU drivers.
fn use_volume(i: u32) {
    if i != vparams_entry {
        vparams = volume_params[i];
        vparams_entry = i;
    }
}

