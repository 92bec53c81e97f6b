// A scene's media for photons: twins of photons/media.rs (PhotonMedia::collision, through
// cpu/media.rs' SceneMedia::collision, and `collide`). Each placed medium is tracked by
// the volume/estimate module's delta tracking on the photon's own stream, in placement
// order; the earliest real collision wins. Placements and grids are bound as the renderer
// binds them (crates/trace/src/gpu/photons.rs); a medium read as stored from a brick store
// is read through the brick pool (kernels composed with `streamed`, volume/stream).
// #import generated/trace_records
// #import transform
// #import volume/rng
// #import volume/estimate
// #import render/phase
// #import photons/bulk

// Every placed medium, in the CPU's instance order.
@group(2) @binding(12) var<storage, read> pmedia: array<RenderMedium>;

struct MediumHit {
    collided: bool,
    // Where along the step, and in which placement.
    t: f32,
    placement: u32,
}

// The first real collision with the media over [0, t1] of the ray o + t d.
fn media_collision(o: vec3<f32>, d: vec3<f32>, t1: f32, rng: ptr<function, VolumeRng>) -> MediumHit {
    var out = MediumHit(false, 0.0, 0u);
    for (var k = 0u; k < arrayLength(&pmedia); k++) {
        let m = pmedia[k];
        use_volume(m.volume);
        let oi = rows_apply(m.rows[0], m.rows[1], m.rows[2], o, 1.0);
        let di = rows_apply(m.rows[0], m.rows[1], m.rows[2], d, 0.0);
        let e = estimate_sample(oi, di, 0.0, t1, VOLUME_ESTIMATOR_DELTA, false, rng, false);
        if e.collided && (!out.collided || e.t < out.t) {
            out = MediumHit(true, e.t, k);
        }
    }
    return out;
}

// A collision in placement `k`'s medium: false when it absorbs the photon, else `dp` is
// its new direction (Henyey-Greenstein) and polarization (the old one projected, or a
// random one where the old one lies along the new direction).
fn medium_collide(k: u32, dp: ptr<function, DirPol>, rng: ptr<function, VolumeRng>) -> bool {
    let m = pmedia[k];
    if rng_next(rng) >= m.albedo {
        return false;
    }
    let u0 = rng_next(rng);
    let u1 = rng_next(rng);
    let dir = normalized(sample_henyey_greenstein((*dp).dir, m.g, vec2<f32>(u0, u1)));
    let projected = (*dp).pol - dir * v3_dot(dir, (*dp).pol);
    var pol = normalized(projected);
    if v3_length(projected) <= 1e-9 {
        let a = TAU * rng_next(rng);
        pol = normalized(rotate_uz(vec3<f32>(cos(a), sin(a), 0.0), dir));
    }
    *dp = DirPol(dir, pol);
    return true;
}
