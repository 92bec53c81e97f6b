// Transmittance along rays through a bricked grid (hytrace volume transmittance --backend
// gpu), the twin of hytrace_volume::transmittance_batch in f32, compared ray by ray in
// crates/trace/tests/gpu_volume.rs. Rays come in the grid's index space, moved near the
// grid by the host (crates/trace/src/gpu/transmittance.rs), so only lengths of t matter here.
// Every estimator is one call of `estimate_sample` (volume/estimate) per sample. Composed
// with `streamed`, it reads a brick store through the brick pool (volume/stream): a ray
// that missed a brick is marked VOLUME_STATUS_MISSING and run again in a later pass.
// #import generated/trace_records
// #import volume/bindings
// #import volume/rng
// #import volume/estimate
// #import loop_budget

@group(1) @binding(0) var<storage, read> rays: array<RayRecord>;
@group(1) @binding(1) var<storage, read_write> results: array<TransmittanceRecord>;
// #if streamed
// The random stream of each ray of a streamed pass (its index among all the rays: a
// pass reruns the rays that missed bricks, not a contiguous range).
@group(1) @binding(2) var<storage, read> ray_streams: array<u32>;
// #endif

// The random stream of ray `i` of the batch.
fn ray_stream(i: u32) -> u32 {
    // #if streamed
    return ray_streams[i];
    // #endif
    return vparams.ray_offset + i;
}

@compute @workgroup_size(64)
fn transmittance(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let i = gid.y * groups_.x * 64u + gid.x;
    use_volume(0u);
    if i >= vparams.ray_count {
        return;
    }
    let r = rays[i];
    let o = vec3<f32>(r.origin[0], r.origin[1], r.origin[2]);
    let d = vec3<f32>(r.direction[0], r.direction[1], r.direction[2]);
    let est = vparams.estimator;
    let tracking = est >= VOLUME_ESTIMATOR_DELTA;
    let passes = select(1u, vparams.spp, tracking);
    // The march steps over the whole box: one global segment there.
    let global = vparams.global == 1u || est == VOLUME_ESTIMATOR_MARCH;
    var tau = 0.0;
    var mean = 0.0;
    var m2 = 0.0;
    var lookups = 0u;
    var nulls = 0u;
    var status = 0u;
    for (var sample = 0u; sample < passes; sample++) {
        var rng = rng_new(vparams.seed, ray_stream(i), sample);
        // Sample 0 walks the whole ray: the CPU refuses a ray with a negative density
        // anywhere along it.
        let e = estimate_sample(o, d, r.tmin, r.tmax, est, global, &rng, sample == 0u);
        tau += e.tau;
        lookups += e.lookups;
        nulls += e.nulls;
        status |= e.status;
        if tracking {
            // Welford's running mean and sum of squared deviations.
            let delta = e.weight - mean;
            mean += delta / f32(sample + 1u);
            m2 += delta * (e.weight - mean);
        }
    }
    var out: TransmittanceRecord;
    out.transmittance = select(exp(-tau), mean, tracking);
    out.variance = select(0.0, m2 / f32(max(passes, 2u) - 1u), tracking && passes > 1u);
    out.lookups = lookups;
    out.null_collisions = nulls;
    if loops_cut_short(vparams.probe_trips) {
        status |= VOLUME_STATUS_LOOPS_CUT;
    }
    // #if streamed
    if stream_missing {
        status |= VOLUME_STATUS_MISSING;
    }
    // #endif
    out.status = status;
    results[i] = out;
}
