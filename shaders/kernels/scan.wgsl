// The scan kernels (hytrace scan --backend gpu), twins of CpuScene::<f32>::trace_flagged,
// compared ray by ray in crates/trace/tests/gpu_scan.rs. Every scene runs `locate_rays`
// (in hierarchical scenes the navigator's locate of every origin; in all, the flags of
// starts near a surface, whose signed distances stay out of the scan kernel's code) and
// then `scan`.
// #import generated/trace_records
// #import trace/scene
// #import loop_budget

@group(2) @binding(0) var<storage, read> params: ScanParams;
@group(2) @binding(1) var<storage, read> rays: array<RayRecord>;
@group(2) @binding(2) var<storage, read_write> hits: array<HitRecord>;
// The instance each ray's origin is located in (UNSET: none), from `locate_rays`
// (hierarchical scenes only).
@group(2) @binding(3) var<storage, read_write> located: array<u32>;

fn ray_index(gid: vec3<u32>, groups_: vec3<u32>) -> u32 {
    return gid.y * groups_.x * 64u + gid.x;
}

fn ray_origin(r: RayRecord) -> vec3<f32> {
    return vec3<f32>(r.origin[0], r.origin[1], r.origin[2]);
}

// The rest of the origin after its rounding to f32 (`ray_origin`).
fn ray_origin_lo(r: RayRecord) -> vec3<f32> {
    return vec3<f32>(r.origin_lo[0], r.origin_lo[1], r.origin_lo[2]);
}

@compute @workgroup_size(64)
fn locate_rays(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let i = ray_index(gid, groups_);
    if i >= params.ray_count {
        return;
    }
    var status = 0u;
    let r = rays[i];
    var start_in = UNSET;
    if params.hierarchical != 0u {
        start_in = locate_point(ray_origin(r), ray_origin_lo(r), &status);
        located[i] = start_in;
    }
    // What the f32 trace cannot decide where the ray starts (CpuScene::trace_flagged).
    let d = vec3<f32>(r.direction[0], r.direction[1], r.direction[2]);
    status |= start_flags(start_in, ray_origin(r), ray_origin_lo(r), d, r.tmin);
    if loops_cut_short(params.probe_trips) {
        status |= STATUS_LOOPS_CUT;
    }
    hits[i].status = status;
}

@compute @workgroup_size(64)
fn scan(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let i = ray_index(gid, groups_);
    if i >= params.ray_count {
        return;
    }
    let r = rays[i];
    let d = vec3<f32>(r.direction[0], r.direction[1], r.direction[2]);
    var start_in = UNSET;
    // The first pass's status: its locate's and the start's flags.
    var status = hits[i].status;
    if params.hierarchical != 0u {
        start_in = located[i];
    }
    let h = cross_from(start_in, ray_origin(r), ray_origin_lo(r), d, r.tmin, min(r.tmax, INF));
    // A short span dropped, or a mesh triangle decided within rounding, not beyond the answer
    // (CpuScene::trace_flagged): the host traces such rays again in f64.
    if trace_dropped_at < INF && trace_dropped_at <= h.t {
        status |= STATUS_DROPPED_SPAN;
    }
    var out: HitRecord;
    out.normal = array<f32, 3>(h.normal.x, h.normal.y, h.normal.z);
    out.t = h.t;
    out.instance = h.instance;
    out.prim = h.prim;
    if loops_cut_short(params.probe_trips) {
        status |= STATUS_LOOPS_CUT;
    }
    out.status = status;
    out.pad = 0u;
    hits[i] = out;
}
