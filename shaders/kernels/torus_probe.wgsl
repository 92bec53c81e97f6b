// Probe of the torus primitive for its twin test (crates/trace/tests/gpu_torus.rs): per
// item, the spans of a ray inside a torus and the signed distance at the ray origin, as
// hytrace_csg::kernel::{primitive_spans, primitive_sdf} give them for TypeCode::Torus.
// #import csg/torus

// Per item, 16 floats: params [rmin, rmax, rtor, 0, 0, 0], 2 unused, origin xyz, 1 unused,
// direction xyz, 1 unused.
@group(0) @binding(0) var<storage, read> torus_items: array<f32>;
// Per item, 36 floats: span count, sdf at the origin, 2 unused, then 4 spans of 8 floats
// (t0, t1, n0 xyz, n1 xyz).
@group(0) @binding(1) var<storage, read_write> torus_out: array<f32>;

@compute @workgroup_size(64)
fn torus_probe(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.y * groups.x * 64u + gid.x;
    if i >= arrayLength(&torus_items) / 16u {
        return;
    }
    let b = i * 16u;
    var p: array<f32, 6>;
    for (var k = 0u; k < 6u; k += 1u) {
        p[k] = torus_items[b + k];
    }
    let o = vec3<f32>(torus_items[b + 8u], torus_items[b + 9u], torus_items[b + 10u]);
    let d = vec3<f32>(torus_items[b + 12u], torus_items[b + 13u], torus_items[b + 14u]);
    var spans = torus_spans(p, o, d);
    let w = i * 36u;
    torus_out[w] = f32(spans.len);
    torus_out[w + 1u] = torus_prim_sdf(p, o);
    for (var k = 0u; k < spans.len; k += 1u) {
        let s = spans.items[k];
        let v = w + 4u + 8u * k;
        torus_out[v] = s.t0;
        torus_out[v + 1u] = s.t1;
        torus_out[v + 2u] = s.n0.x;
        torus_out[v + 3u] = s.n0.y;
        torus_out[v + 4u] = s.n0.z;
        torus_out[v + 5u] = s.n1.x;
        torus_out[v + 6u] = s.n1.y;
        torus_out[v + 7u] = s.n1.z;
    }
}

