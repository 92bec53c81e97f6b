// Probes of the uploaded Foundry: points through `itra`, and a broad-phase locate of world
// points in instances, prims and CSG leaves. CPU twins: crates/trace/src/gpu/probe.rs.
// #import scene_bindings
// #import transform

@group(1) @binding(0) var<storage, read> points: array<vec4<f32>>;
@group(1) @binding(1) var<storage, read> point_transform: array<u32>;
@group(1) @binding(2) var<storage, read_write> out_points: array<vec4<f32>>;
@group(1) @binding(3) var<storage, read_write> out_locate: array<vec4<u32>>;

// Flat invocation index of a 2D dispatch of 64-wide workgroups (see probe.rs).
fn flat_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * 64u + gid.x;
}

// Point i mapped by itra[point_transform[i] - 1] (index 0: unchanged).
@compute @workgroup_size(64)
fn apply_itra(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= arrayLength(&points) {
        return;
    }
    let p = points[i].xyz;
    let t = point_transform[i];
    var q = p;
    if t > 0u {
        q = transform_apply_point(itra[t - 1u], p);
    }
    out_points[i] = vec4<f32>(q, 1.0);
}

// For world point i: how many instances' solid bounds, prim bounds and CSG leaf bounds
// contain it, and the first instance whose solid bounds do (UNSET if none).
@compute @workgroup_size(64)
fn locate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = flat_index(gid, groups);
    if i >= arrayLength(&points) {
        return;
    }
    let p = points[i].xyz;
    var counts = vec4<u32>(0u, 0u, 0u, UNSET);
    for (var k = 0u; k < arrayLength(&inst); k++) {
        let instance = inst[k];
        let s = solid[instance.solid];
        let local = instance_to_local(instance, p);
        if !aabb_contains(s.aabb, local) {
            continue;
        }
        counts.x += 1u;
        if counts.w == UNSET {
            counts.w = k;
        }
        for (var j = s.prim_offset; j < s.prim_offset + s.num_prim; j++) {
            let pr = prim[j];
            if !aabb_contains(pr.aabb, local) {
                continue;
            }
            counts.y += 1u;
            if pr.kind != PRIM_CSG {
                continue;
            }
            for (var n = pr.node_offset; n < pr.node_offset + pr.num_node; n++) {
                let nd = node[n];
                if nd.typecode >= 100u && aabb_contains(nd.aabb, local) {
                    counts.z += 1u;
                }
            }
        }
    }
    out_locate[i] = counts;
}
