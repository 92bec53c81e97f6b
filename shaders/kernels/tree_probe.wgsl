// Probes of prepared CSG trees for the twin test (crates/trace/tests/gpu_trees.rs): first
// crossings of rays, and signed distances and inside tests of points, against the CPU's
// hytrace_csg::PrimTree::<f32>.
// #import csg/tree

// One query: o.xyz the ray origin (or point), o.w the tree index (bits), d.xyz the
// direction, d.w the ray's tmin.
struct TreeQuery {
    o: vec4<f32>,
    d: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> queries: array<TreeQuery>;
// Two per query: crossings (normal, t) and (inside_before, 0, 0, 0); points (contains or
// sdf, 0, 0, 0) and zeros. (Three entry points: each pipeline compiles only what it uses.)
@group(0) @binding(1) var<storage, read_write> results: array<vec4<f32>>;

fn tree_probe_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * 64u + gid.x;
}

@compute @workgroup_size(64)
fn crossings(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = tree_probe_index(gid, groups);
    if i >= arrayLength(&queries) {
        return;
    }
    let q = queries[i];
    let step = csg_tree_first_crossing(bitcast<u32>(q.o.w), q.o.xyz, q.d.xyz, q.d.w);
    results[2u * i] = vec4<f32>(step.normal, step.t);
    results[2u * i + 1u] = vec4<f32>(select(0.0, 1.0, step.inside_before), 0.0, 0.0, 0.0);
}

@compute @workgroup_size(64)
fn contains(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = tree_probe_index(gid, groups);
    if i >= arrayLength(&queries) {
        return;
    }
    let q = queries[i];
    let inside = csg_tree_contains(bitcast<u32>(q.o.w), q.o.xyz);
    results[2u * i] = vec4<f32>(select(0.0, 1.0, inside), 0.0, 0.0, 0.0);
}

@compute @workgroup_size(64)
fn sdfs(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = tree_probe_index(gid, groups);
    if i >= arrayLength(&queries) {
        return;
    }
    let q = queries[i];
    results[2u * i] = vec4<f32>(csg_tree_sdf(bitcast<u32>(q.o.w), q.o.xyz), 0.0, 0.0, 0.0);
}
