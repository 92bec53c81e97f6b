// Affine frames as the CPU's `hytrace_csg::kernel::Frame` applies them: a parent point p
// maps to inverse * (p - origin); row k of a FrameRecord is (inverse[k], origin[k]).
// Subtracting the origin first keeps f32 exact for solids far from the world origin.
// #import generated/trace_records

fn frame_origin(f: FrameRecord) -> vec3<f32> {
    return vec3<f32>(f.rows[0].w, f.rows[1].w, f.rows[2].w);
}

fn frame_linear(f: FrameRecord, v: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(f.rows[0].xyz, v), dot(f.rows[1].xyz, v), dot(f.rows[2].xyz, v));
}

// A parent-frame point in the frame.
fn frame_point_to_local(f: FrameRecord, p: vec3<f32>) -> vec3<f32> {
    return frame_linear(f, p - frame_origin(f));
}

// A normal of the frame in the parent frame (inverse transpose; not normalized).
fn frame_normal_to_parent(f: FrameRecord, n: vec3<f32>) -> vec3<f32> {
    return f.rows[0].xyz * n.x + f.rows[1].xyz * n.y + f.rows[2].xyz * n.z;
}
