// The Henyey-Greenstein phase function and its sampling, twins of
// crates/trace/src/render/optics.rs (in f32): the renderer's media and the photons' share
// them.

const RENDER_PI: f32 = 3.14159265358979;

// The direction with cosine `cos_theta` to the unit axis `n` and azimuth 2 pi u (Duff et
// al.'s basis).
fn around(n: vec3<f32>, cos_theta: f32, u: f32) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = vec3<f32>(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bt = vec3<f32>(b, sign + n.y * n.y * a, -n.y);
    let sin_theta = sqrt(max(1.0 - cos_theta * cos_theta, 0.0));
    let phi = 2.0 * RENDER_PI * u;
    return normalize(sin_theta * cos(phi) * t + sin_theta * sin(phi) * bt + cos_theta * n);
}

// The Henyey-Greenstein phase function (per steradian) at cosine `cos` between the travel
// and scattered directions.
fn henyey_greenstein(cos: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos;
    return (1.0 - g * g) / (4.0 * RENDER_PI * denom * sqrt(denom));
}

// A direction drawn from the Henyey-Greenstein phase function around the travel direction
// `d` from uniforms `u`.
fn sample_henyey_greenstein(d: vec3<f32>, g: f32, u: vec2<f32>) -> vec3<f32> {
    var c = 1.0 - 2.0 * u.x;
    if abs(g) >= 1e-3 {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u.x);
        c = clamp((1.0 + g * g - s * s) / (2.0 * g), -1.0, 1.0);
    }
    return around(d, c, u.y);
}
