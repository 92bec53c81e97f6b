// Transmittance along rays through a bricked grid (hytrace volume transmittance --backend
// gpu), the twin of hytrace_volume::transmittance_batch in f32, compared ray by ray in
// crates/trace/tests/gpu_volume.rs. Rays come in the grid's index space, moved near the
// grid by the host (crates/trace/src/gpu/volume.rs), so only lengths of t matter here.
//
// One loop over the segments of the walk and, inside each, one loop over lookups serves
// every estimator, so the walk, the cell walk and the voxel fetch each have one call site
// (drivers inline every call). Trackers walk the segments again for every sample.
// #import trace_records
// #import volume/bindings
// #import volume/rng
// #import volume/grid
// #import volume/walk

@group(0) @binding(5) var<storage, read> rays: array<RayRecord>;
@group(0) @binding(6) var<storage, read_write> results: array<TransmittanceRecord>;

// 1 / sqrt(3): the 2-point Gauss-Legendre nodes sit at half * (1 -+ 1/sqrt(3)).
const INV_SQRT3: f32 = 0.5773502691896258;

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

@compute @workgroup_size(64)
fn transmittance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let i = gid.y * groups_.x * 64u + gid.x;
    if i >= vparams.ray_count {
        return;
    }
    let r = rays[i];
    let o = vec3<f32>(r.origin[0], r.origin[1], r.origin[2]);
    let d = vec3<f32>(r.direction[0], r.direction[1], r.direction[2]);
    let est = vparams.estimator;
    let lookup = vparams.lookup_filter;
    let scale = vparams.density_scale;
    let tracking = est >= VOLUME_ESTIMATOR_DELTA;
    let passes = select(1u, vparams.spp, tracking);
    var tau = 0.0;
    var mean = 0.0;
    var m2 = 0.0;
    var lookups = 0u;
    var nulls = 0u;
    var status = 0u;
    for (var sample = 0u; sample < passes; sample++) {
        var rng = rng_new(vparams.seed, vparams.ray_offset + i, sample);
        // The march steps over the whole box: one global segment there.
        var walk = walk_start(o, d, r.tmin, r.tmax, vparams.global == 1u || est == VOLUME_ESTIMATOR_MARCH);
        var weight = 1.0;
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
                    status |= VOLUME_STATUS_NEGATIVE;
                }
                // A finished sample 0 still walks on: the CPU refuses a ray with a negative
                // density anywhere along it.
                if !alive {
                    if sample == 0u {
                        continue;
                    }
                    break;
                }
            }
            // Segments of known density: no lookups.
            let known = select(low == high, s.lo == s.hi, est == VOLUME_ESTIMATOR_EXACT);
            if select(known, s.outside, est == VOLUME_ESTIMATOR_MARCH) {
                if est == VOLUME_ESTIMATOR_DELTA {
                    if low > 0.0 && free_flight(&rng, low) < seg_len {
                        alive = false;
                        weight = 0.0;
                    }
                } else if tracking {
                    weight *= exp(-constant_tau(low, seg_len));
                } else {
                    tau += constant_tau(low, seg_len);
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
                    status |= VOLUME_STATUS_MARCH_STEPS;
                    break;
                }
                steps = u32(n);
                h = seg_len / n;
            } else {
                // Ratio tracking of density - control under majorant - control.
                control = select(0.0, low, est == VOLUME_ESTIMATOR_RESIDUAL);
                weight *= exp(-constant_tau(control, seg_len));
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
                        t += free_flight(&rng, mu);
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
                        var up = vec3<f32>(0.0);
                        for (var k = 0u; k < 3u; k++) {
                            up[k] = select(0.0, 1.0, rng_next(&rng) < p[k] - base[k]);
                        }
                        cell = vec3<i32>(base + up);
                    }
                }
                let v = grid_fetch(cell, count);
                if est == VOLUME_ESTIMATOR_EXACT {
                    let piece_length = piece.t1 - piece.t0;
                    if lookup == VOLUME_FILTER_NEAREST {
                        tau += v[0] * scale * piece_length;
                        lookups += 1u;
                    } else {
                        let half = 0.5 * piece_length;
                        let offset = half * INV_SQRT3;
                        var sum = 0.0;
                        for (var q = 0u; q < 2u; q++) {
                            let u = select(half + offset, half - offset, q == 0u);
                            sum += trilinear_lerp(v, piece.entry + u * d - vec3<f32>(piece.cell));
                        }
                        tau += sum * half * scale;
                        lookups += 2u;
                    }
                    continue;
                }
                let value = select(v[0], trilinear_sum(v, p - floor(p)), lookup == VOLUME_FILTER_TRILINEAR);
                let density = value * scale;
                lookups += 1u;
                if est == VOLUME_ESTIMATOR_MARCH {
                    tau += h * density;
                    continue;
                }
                if est == VOLUME_ESTIMATOR_DELTA {
                    if rng_next(&rng) * mu < density {
                        alive = false;
                        weight = 0.0;
                        break;
                    }
                } else {
                    weight *= 1.0 - (density - control) / mu;
                }
                nulls += 1u;
            }
            if weight == 0.0 {
                alive = false;
            }
        }
        if tracking {
            // Welford's running mean and sum of squared deviations.
            let delta = weight - mean;
            mean += delta / f32(sample + 1u);
            m2 += delta * (weight - mean);
        }
    }
    var out: TransmittanceRecord;
    out.transmittance = select(exp(-tau), mean, tracking);
    out.variance = select(0.0, m2 / f32(max(passes, 2u) - 1u), tracking && passes > 1u);
    out.lookups = lookups;
    out.null_collisions = nulls;
    out.status = status;
    results[i] = out;
}
