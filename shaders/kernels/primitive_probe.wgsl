// Probe of the primitive kernels for the twin test crates/trace/tests/gpu_primitives.rs:
// per item, the spans of a ray inside one primitive and the signed distance at the ray's
// origin.
// #import csg/spans
// #import csg/primitive

struct PrimitiveProbeItem {
    code: u32,
    plane_first: u32,
    plane_count: u32,
    pad: u32,
    // p[0..4], then p[4], p[5] and two unused lanes.
    p0: vec4<f32>,
    p1: vec4<f32>,
    origin: vec4<f32>,
    direction: vec4<f32>,
}

// Per item, 13 vec4: (bits of the span count, sdf, 0, 0), then per span (t0, t1, 0, 0),
// (n0, 0), (n1, 0).
const PROBE_STRIDE: u32 = 13u;

@group(0) @binding(0) var<storage, read> probe_items: array<PrimitiveProbeItem>;
@group(0) @binding(1) var<storage, read_write> probe_out: array<vec4<f32>>;

@compute @workgroup_size(64)
fn probe_primitives(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = gid.y * groups.x * 64u + gid.x;
    if i >= arrayLength(&probe_items) {
        return;
    }
    let item = probe_items[i];
    let p = array<f32, 6>(item.p0.x, item.p0.y, item.p0.z, item.p0.w, item.p1.x, item.p1.y);
    let o = item.origin.xyz;
    let spans = primitive_spans(item.code, p, item.plane_first, item.plane_count, o, item.direction.xyz, 0.0);
    let sdf = primitive_sdf(item.code, p, item.plane_first, item.plane_count, o);
    let base = i * PROBE_STRIDE;
    probe_out[base] = vec4<f32>(bitcast<f32>(spans.len), sdf, 0.0, 0.0);
    for (var k = 0u; k < MAX_SPANS; k += 1u) {
        var s = span_everywhere();
        if k < spans.len {
            s = spans.items[k];
        }
        probe_out[base + 1u + 3u * k] = vec4<f32>(s.t0, s.t1, 0.0, 0.0);
        probe_out[base + 2u + 3u * k] = vec4<f32>(s.n0, 0.0);
        probe_out[base + 3u + 3u * k] = vec4<f32>(s.n1, 0.0);
    }
}
