// The camera rays: twin of crates/trace/src/render/camera.rs (Camera::ray).
// #import render/bindings

// The camera ray of pixel (i, j) at sample offset `offset` (render::camera::Camera::ray).
fn camera_origin(i: u32, j: u32, offset: vec2<f32>) -> vec3<f32> {
    let eye = vec3<f32>(rparams.eye[0], rparams.eye[1], rparams.eye[2]);
    if rparams.orthographic == 0u {
        return eye;
    }
    let xy = screen(i, j, offset);
    return eye + rparams.extent * (xy.x * v3a(rparams.u) + xy.y * v3a(rparams.v));
}

fn camera_direction(i: u32, j: u32, offset: vec2<f32>) -> vec3<f32> {
    let w = v3a(rparams.w);
    if rparams.orthographic != 0u {
        return w;
    }
    let xy = screen(i, j, offset);
    return normalize(w + rparams.extent * (xy.x * v3a(rparams.u) + xy.y * v3a(rparams.v)));
}

fn screen(i: u32, j: u32, offset: vec2<f32>) -> vec2<f32> {
    let width = f32(rparams.width);
    let height = f32(rparams.height);
    let x = (2.0 * (f32(i) + offset.x) / width - 1.0) * (width / height);
    let y = 1.0 - 2.0 * (f32(j) + offset.y) / height;
    return vec2<f32>(x, y);
}
