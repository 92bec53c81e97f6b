// The media along a ray, as the renderer needs them: twin of
// crates/trace/src/render/media.rs (Media::emission_absorption, Media::collision and
// Media::transmittance), up to RENDER_MAX_MEDIA placements whose grids share the volume
// group's arrays. Scattering goes through the same volume/estimate module as the
// transmittance kernel.
// #import generated/trace_records
// #import csg/spans
// #import transform
// #import volume/rng
// #import render/bindings
// #if absorption
// #import volume/walk
// #import volume/grid
// #endif
// #if scattering
// #import volume/estimate
// #endif

// What the media do along one piece of a ray.
struct MediumStep {
    // Light they emit toward the piece's start and the fraction they let through.
    radiance: vec3<f32>,
    transmittance: f32,
    // A real collision on a path (scattering media): where, the grid value there, and in
    // which placed medium.
    collided: bool,
    t: f32,
    value: f32,
    medium: u32,
}

fn no_medium() -> MediumStep {
    return MediumStep(vec3<f32>(0.0), 1.0, false, 0.0, 0.0, 0u);
}

// #if media
// A world point (w = 1) or direction (w = 0) in the index space of placed medium `k`
// (translated as its grid's upload).
fn medium_space(k: u32, p: vec3<f32>, w: f32) -> vec3<f32> {
    let m = media[k].rows;
    return rows_apply(m[0], m[1], m[2], p, w);
}

fn medium_emission(k: u32) -> vec3<f32> {
    let e = media[k].emission;
    return vec3<f32>(e[0], e[1], e[2]);
}
// #endif

// #if absorption
// Emission-absorption of the media over [0, t1] of the world ray o + t d, path and shadow
// pieces alike: midpoint compositing over the union of the ray's parts inside each
// medium's range-mips box, in steps of `medium_step` voxels of the finest medium; at each
// step the media covering it add their extinctions sigma and sources j, the step adds
// T j / sigma (1 - exp(-sigma h)) and multiplies T by exp(-sigma h).
fn emission_absorption(o: vec3<f32>, d: vec3<f32>, t1: f32) -> MediumStep {
    var out = no_medium();
    // Per medium crossed: the ray in its index space and its span there.
    var origin: array<vec3<f32>, RENDER_MAX_MEDIA>;
    var dir: array<vec3<f32>, RENDER_MAX_MEDIA>;
    var span_from: array<f32, RENDER_MAX_MEDIA>;
    var span_to: array<f32, RENDER_MAX_MEDIA>;
    var crossed: array<u32, RENDER_MAX_MEDIA>;
    var count = 0u;
    var a = INF;
    var b = -INF;
    var h = INF;
    for (var k = 0u; k < rparams.media_count; k++) {
        use_volume(media[k].volume);
        let oi = medium_space(k, o, 1.0);
        let di = medium_space(k, d, 0.0);
        var w = walk_start(oi, di, 0.0, t1, true);
        let s0 = w.base;
        let s1 = walk_absolute(&w, w.t_end);
        if s0 < s1 {
            origin[count] = oi;
            dir[count] = di;
            span_from[count] = s0;
            span_to[count] = s1;
            crossed[count] = k;
            count += 1u;
            a = min(a, s0);
            b = max(b, s1);
            h = min(h, rparams.medium_step / length(di));
        }
    }
    if count == 0u {
        return out;
    }
    let n = max(ceil((b - a) / h), 1.0);
    let step = (b - a) / n;
    for (var i = 0u; i < u32(n); i++) {
        let t = a + (f32(i) + 0.5) * step;
        var sigma = 0.0;
        var source = vec3<f32>(0.0);
        for (var c = 0u; c < count; c++) {
            if t >= span_from[c] && t <= span_to[c] {
                let k = crossed[c];
                use_volume(media[k].volume);
                let p = origin[c] + t * dir[c];
                let cell = floor(p);
                let value = trilinear_sum(grid_fetch(vec3<i32>(cell), 8u), p - cell);
                let density = value * vparams.density_scale;
                sigma += density;
                source += density * value * medium_emission(k);
            }
        }
        if sigma > 0.0 {
            let step_t = exp(-sigma * step);
            out.radiance += out.transmittance * source / sigma * (1.0 - step_t);
            out.transmittance *= step_t;
        }
    }
    return out;
}
// #endif

// #if scattering
// The scattering media over [0, t1] of the world ray o + t d, each under the local
// majorants of its range mips, in placement order (twins of Media::collision and
// Media::transmittance): a path piece's first real collision by delta tracking on the
// path's stream (the earliest of the media's collisions); a shadow piece's transmittance
// by ratio tracking, each medium on a stream of its own keyed by one draw of the path's.
fn medium_tracked(o: vec3<f32>, d: vec3<f32>, t1: f32, shadow: bool, rng: ptr<function, VolumeRng>) -> MediumStep {
    var out = no_medium();
    var est = VOLUME_ESTIMATOR_DELTA;
    var key = 0u;
    if shadow {
        est = VOLUME_ESTIMATOR_RATIO;
        key = rng_u32(rng);
    }
    for (var k = 0u; k < rparams.media_count; k++) {
        use_volume(media[k].volume);
        var stream = *rng;
        if shadow {
            stream = rng_new(media[k].seed, key, 0u);
        }
        let e = estimate_sample(medium_space(k, o, 1.0), medium_space(k, d, 0.0), 0.0, t1, est, false, &stream, false);
        if shadow {
            out.transmittance *= e.weight;
        } else {
            *rng = stream;
            if e.collided && (!out.collided || e.t < out.t) {
                out.collided = true;
                out.t = e.t;
                out.value = e.value;
                out.medium = k;
            }
        }
    }
    return out;
}
// #endif
