// One sample of every transmittance estimator along a ray through the bricked grid, in
// f32: the twins of hytrace_volume's exact quadrature, midpoint march, delta, ratio and
// residual ratio tracking, and of IndexTransmittance::collision (delta tracking reports
// where it stopped). The transmittance kernel and the renderer both call it, once each.
//
// One loop over the segments of the walk and, inside each, one loop over lookups serves
// every estimator, so the walk, the cell walk and the voxel fetch each have one call site
// (drivers inline every call).
// #import generated/trace_records
// #import volume/bindings
// #import volume/rng
// #import volume/grid
// #import volume/walk

// 1 / sqrt(3): the 2-point Gauss-Legendre nodes sit at half * (1 -+ 1/sqrt(3)).
const INV_SQRT3: f32 = 0.5773502691896258;

// What one sample found along the ray.
struct Estimated {
    // Exact and march: the optical depth.
    tau: f32,
    // Trackers: the sample's transmittance (delta tracking: 0 after a real collision).
    weight: f32,
    // Delta tracking: the real collision's t and the grid value there.
    collided: bool,
    t: f32,
    value: f32,
    lookups: u32,
    nulls: u32,
    // VOLUME_STATUS_* bits of a ray the CPU would refuse.
    status: u32,
}

// Optical depth of a stretch of constant density: 0 for zero density, also over an
// infinite length; VOLUME_INF for a positive density over one.
fn constant_tau(density: f32, len: f32) -> f32 {
    if density == 0.0 {
        return 0.0;
    }
    if len >= VOLUME_INF * 0.5 {
        return VOLUME_INF;
    }
    return density * len;
}

// A free-flight distance under majorant mu > 0.
fn free_flight(rng: ptr<function, VolumeRng>, mu: f32) -> f32 {
    return -log(1.0 - rng_next(rng)) / mu;
}

// One sample of estimator `est` (VOLUME_ESTIMATOR_*) along the index-space ray o + t d over
// [tmin, tmax], walking one global segment over the box when `global`. A tracker stops at
// a zero weight unless `check_rest`, which walks on to flag negative ranges (the CPU
// refuses such a ray whatever the sample does).
fn estimate_sample(o: vec3<f32>, d: vec3<f32>, tmin: f32, tmax: f32, est: u32, global: bool, rng: ptr<function, VolumeRng>, check_rest: bool) -> Estimated {
    var out = Estimated(0.0, 1.0, false, 0.0, 0.0, 0u, 0u, 0u);
    let lookup = vparams.lookup_filter;
    let scale = vparams.density_scale;
    let tracking = est >= VOLUME_ESTIMATOR_DELTA;
    var walk = walk_start(o, d, tmin, tmax, global);
    var alive = true;
    loop {
        let s = walk_next(&walk);
        if !s.valid {
            break;
        }
        let low = s.lo * scale;
        let high = s.hi * scale;
        let seg_len = s.t1 - s.t0;
        if tracking {
            if low < 0.0 {
                out.status |= VOLUME_STATUS_NEGATIVE;
            }
            if !alive {
                if check_rest {
                    continue;
                }
                break;
            }
        }
        // Segments of known density: no lookups.
        let known = select(low == high, s.lo == s.hi, est == VOLUME_ESTIMATOR_EXACT);
        if select(known, s.outside, est == VOLUME_ESTIMATOR_MARCH) {
            if est == VOLUME_ESTIMATOR_DELTA {
                if low > 0.0 {
                    // A constant segment collides wherever the first flight lands.
                    let f = free_flight(rng, low);
                    if f < seg_len {
                        alive = false;
                        out.weight = 0.0;
                        out.collided = true;
                        out.t = s.t0 + f;
                        out.value = s.lo;
                    }
                }
            } else if tracking {
                out.weight *= exp(-constant_tau(low, seg_len));
            } else {
                out.tau += constant_tau(low, seg_len);
            }
            continue;
        }
        var cells: CellWalk;
        var steps = 0u;
        var h = 0.0;
        var control = 0.0;
        var mu = 0.0;
        var t = s.t0;
        if est == VOLUME_ESTIMATOR_EXACT {
            let offset = select(0.0, -0.5, lookup == VOLUME_FILTER_NEAREST);
            cells = cells_start(o + s.t0 * d, d, s.t0, s.t1, offset);
        } else if est == VOLUME_ESTIMATOR_MARCH {
            let n = max(ceil(seg_len / vparams.march_step), 1.0);
            // More than u32::MAX steps (the CPU's error); 2^32 is exact in f32.
            if n >= 4294967296.0 {
                out.status |= VOLUME_STATUS_MARCH_STEPS;
                break;
            }
            steps = u32(n);
            h = seg_len / n;
        } else {
            // Ratio tracking of density - control under majorant - control.
            control = select(0.0, low, est == VOLUME_ESTIMATOR_RESIDUAL);
            out.weight *= exp(-constant_tau(control, seg_len));
            mu = high - control;
        }
        var step_index = 0u;
        loop {
            var piece: CellPiece;
            var cell: vec3<i32>;
            var count = 1u;
            var p = vec3<f32>(0.0);
            if est == VOLUME_ESTIMATOR_EXACT {
                piece = cells_next(&cells);
                if !piece.valid {
                    break;
                }
                cell = piece.cell;
                count = select(8u, 1u, lookup == VOLUME_FILTER_NEAREST);
            } else {
                if est == VOLUME_ESTIMATOR_MARCH {
                    if step_index >= steps {
                        break;
                    }
                    p = o + (s.t0 + (f32(step_index) + 0.5) * h) * d;
                    step_index += 1u;
                } else {
                    t += free_flight(rng, mu);
                    if t >= s.t1 {
                        break;
                    }
                    p = o + t * d;
                }
                let base = floor(p);
                if lookup == VOLUME_FILTER_NEAREST {
                    cell = vec3<i32>(floor(p + 0.5));
                } else if lookup == VOLUME_FILTER_TRILINEAR {
                    cell = vec3<i32>(base);
                    count = 8u;
                } else {
                    // Per axis the upper neighbour when u < frac (three draws, x first).
                    let ux = rng_next(rng) < p.x - base.x;
                    let uy = rng_next(rng) < p.y - base.y;
                    let uz = rng_next(rng) < p.z - base.z;
                    cell = vec3<i32>(base) + vec3<i32>(select(0, 1, ux), select(0, 1, uy), select(0, 1, uz));
                }
            }
            let v = grid_fetch(cell, count);
            if est == VOLUME_ESTIMATOR_EXACT {
                let piece_length = piece.t1 - piece.t0;
                if lookup == VOLUME_FILTER_NEAREST {
                    out.tau += v[0] * scale * piece_length;
                    out.lookups += 1u;
                } else {
                    let half = 0.5 * piece_length;
                    let offset = half * INV_SQRT3;
                    var sum = 0.0;
                    for (var q = 0u; q < 2u; q++) {
                        let u = select(half + offset, half - offset, q == 0u);
                        sum += trilinear_lerp(v, piece.entry + u * d - vec3<f32>(piece.cell));
                    }
                    out.tau += sum * half * scale;
                    out.lookups += 2u;
                }
                continue;
            }
            let value = select(v[0], trilinear_sum(v, p - floor(p)), lookup == VOLUME_FILTER_TRILINEAR);
            let density = value * scale;
            out.lookups += 1u;
            if est == VOLUME_ESTIMATOR_MARCH {
                out.tau += h * density;
                continue;
            }
            if est == VOLUME_ESTIMATOR_DELTA {
                if rng_next(rng) * mu < density {
                    alive = false;
                    out.weight = 0.0;
                    out.collided = true;
                    out.t = t;
                    out.value = value;
                    break;
                }
            } else {
                out.weight *= 1.0 - (density - control) / mu;
            }
            out.nulls += 1u;
        }
        if out.weight == 0.0 {
            alive = false;
        }
    }
    return out;
}
