// Scattering functions of the renderer: twins of crates/trace/src/render/optics.rs (in f32);
// the phase function's in render/phase (which photons share).
// #import render/phase

// Unpolarized Fresnel reflectance at cosine `cos_i` for the index ratio `eta`
// (transmitted over incident); 1 under total internal reflection.
fn fresnel(cos_i: f32, eta: f32) -> f32 {
    let sin2_t = max(1.0 - cos_i * cos_i, 0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = sqrt(1.0 - sin2_t);
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    return 0.5 * (rs * rs + rp * rp);
}

fn mirror(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - 2.0 * dot(d, n) * n;
}

// Refraction of `d` through a surface whose normal `n` faces the incident side; `ok` false
// under total internal reflection.
struct Refracted {
    ok: bool,
    d: vec3<f32>,
}

fn refraction(d: vec3<f32>, n: vec3<f32>, eta: f32) -> Refracted {
    let cos_i = -dot(d, n);
    let sin2_t = max(1.0 - cos_i * cos_i, 0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return Refracted(false, d);
    }
    let cos_t = sqrt(1.0 - sin2_t);
    return Refracted(true, normalize(d / eta + (cos_i / eta - cos_t) * n));
}

// A cosine-distributed direction around `n` from uniforms `u`.
fn cosine_direction(n: vec3<f32>, u: vec2<f32>) -> vec3<f32> {
    return around(n, sqrt(u.x), u.y);
}
