// Counter-based random numbers, bit for bit those of hytrace_volume::Rng: draw n of stream
// (seed, ray, sample) is pcg4d(seed, ray, sample, n).x, uniforms its top 24 bits.

fn pcg4d(v_in: vec4<u32>) -> vec4<u32> {
    // u32 arithmetic wraps in WGSL, as the CPU's wrapping_mul / wrapping_add.
    var v = v_in * 1664525u + vec4<u32>(1013904223u);
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    v = v ^ (v >> vec4<u32>(16u));
    v.x += v.y * v.w;
    v.y += v.z * v.x;
    v.z += v.x * v.y;
    v.w += v.y * v.z;
    return v;
}

struct VolumeRng {
    key: vec3<u32>,
    counter: u32,
}

fn rng_new(seed: u32, stream: u32, sample: u32) -> VolumeRng {
    return VolumeRng(vec3<u32>(seed, stream, sample), 0u);
}

// The next 32 random bits.
fn rng_u32(r: ptr<function, VolumeRng>) -> u32 {
    let h = pcg4d(vec4<u32>((*r).key, (*r).counter));
    (*r).counter += 1u;
    return h.x;
}

// The next uniform in [0, 1), a multiple of 2^-24 (exact in f32).
fn rng_next(r: ptr<function, VolumeRng>) -> f32 {
    return f32(rng_u32(r) >> 8u) * (1.0 / 16777216.0);
}
