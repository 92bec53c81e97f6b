// Affine transforms stored as matrix rows (row-major, acting on column vectors).
// #import generated/foundry

fn rows_apply_point(r0: vec4<f32>, r1: vec4<f32>, r2: vec4<f32>, p: vec3<f32>) -> vec3<f32> {
    let h = vec4<f32>(p, 1.0);
    return vec3<f32>(dot(r0, h), dot(r1, h), dot(r2, h));
}

fn transform_apply_point(t: Transform, p: vec3<f32>) -> vec3<f32> {
    return rows_apply_point(t.rows[0], t.rows[1], t.rows[2], p);
}

fn instance_to_local(i: Instance, p: vec3<f32>) -> vec3<f32> {
    return rows_apply_point(i.itra[0], i.itra[1], i.itra[2], p);
}

fn aabb_contains(b: array<f32, 6>, p: vec3<f32>) -> bool {
    return p.x >= b[0] && p.y >= b[1] && p.z >= b[2] && p.x <= b[3] && p.y <= b[4] && p.z <= b[5];
}

// `p` through the rows as a point (w = 1) or a direction (w = 0): the placed media's world
// to index space.
fn rows_apply(r0: vec4<f32>, r1: vec4<f32>, r2: vec4<f32>, p: vec3<f32>, w: f32) -> vec3<f32> {
    return vec3<f32>(dot(r0.xyz, p) + w * r0.w, dot(r1.xyz, p) + w * r1.w, dot(r2.xyz, p) + w * r2.w);
}
