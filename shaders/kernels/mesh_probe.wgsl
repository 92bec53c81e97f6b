// Probes of the mesh prims for the twin test crates/trace/tests/gpu_meshes.rs: first
// crossings of rays and inside tests of points, against MeshPrim::<f32>.
// #import mesh/mesh

// A ray: origin and tmin (w), direction and the mesh index (w, as bits).
struct ProbeRay {
    o: vec4<f32>,
    d: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> probe_rays: array<ProbeRay>;
// Per ray: (t, normal), then (inside_before, 0, 0, 0).
@group(0) @binding(1) var<storage, read_write> probe_steps: array<vec4<f32>>;
// Points (xyz) and mesh index (w, as bits).
@group(0) @binding(2) var<storage, read> probe_points: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> probe_inside: array<u32>;

fn probe_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.y * groups.x * 64u + gid.x;
}

@compute @workgroup_size(64)
fn first_crossing(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = probe_index(gid, groups);
    if i >= arrayLength(&probe_rays) {
        return;
    }
    let r = probe_rays[i];
    let s = mesh_first_crossing(bitcast<u32>(r.d.w), r.o.xyz, r.d.xyz, r.o.w);
    probe_steps[2u * i] = vec4<f32>(s.t, s.normal);
    probe_steps[2u * i + 1u] = vec4<f32>(select(0.0, 1.0, s.inside_before), 0.0, 0.0, 0.0);
}

@compute @workgroup_size(64)
fn contains(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = probe_index(gid, groups);
    if i >= arrayLength(&probe_points) {
        return;
    }
    let p = probe_points[i];
    probe_inside[i] = select(0u, 1u, mesh_contains(bitcast<u32>(p.w), p.xyz));
}

// The exact edge function of (px, py, qx, qy) = probe_points[i], as f32 bits.
@compute @workgroup_size(64)
fn exact_edge(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = probe_index(gid, groups);
    if i >= arrayLength(&probe_points) {
        return;
    }
    let p = probe_points[i];
    probe_inside[i] = bitcast<u32>(mesh_exact_edge(p.x, p.y, p.z, p.w));
}
