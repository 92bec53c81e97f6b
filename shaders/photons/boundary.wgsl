// Fresnel reflection and refraction of a polarized photon at a smooth boundary, with total
// internal reflection: twin of photons::boundary (FresnelStep's decide, refracted and
// reflected).
// #import photons/bulk

const FRESNEL_REFLECTED: u32 = 0u;
const FRESNEL_TOTAL_INTERNAL: u32 = 1u;
const FRESNEL_REFRACTED: u32 = 2u;

// One decision and the amplitudes it was made with.
struct Fresnel {
    what: u32,
    cos1: f32,
    cos2: f32,
    s_axis: vec3<f32>,
    e1_s: f32,
    e1_p: f32,
    e2_s: f32,
    e2_p: f32,
    oblique: bool,
    n1: f32,
    n2: f32,
}

// Decides between reflection and refraction on a facet `facet` facing the photon, from
// index n1 into n2; `transmittance` (a surface's TRANSMITTANCE when positive) replaces
// the Fresnel transmission probability.
fn fresnel_decide(dir: vec3<f32>, pol: vec3<f32>, facet: vec3<f32>, n1: f32, n2: f32, transmittance: f32, u: f32) -> Fresnel {
    var f: Fresnel;
    f.n1 = n1;
    f.n2 = n2;
    f.cos1 = -v3_dot(dir, facet);
    // Normal incidence within Geant4's tolerance (1e-9): at f32's resolution, exactly.
    f.oblique = abs(f.cos1) < 1.0;
    var sin1 = 0.0;
    if f.oblique {
        sin1 = sqrt(1.0 - f.cos1 * f.cos1);
    }
    let sin2 = sin1 * n1 / n2;
    if sin2 >= 1.0 {
        f.what = FRESNEL_TOTAL_INTERNAL;
        return f;
    }
    f.cos2 = sqrt(1.0 - sin2 * sin2);
    if f.cos1 < 0.0 {
        f.cos2 = -f.cos2;
    }
    if f.oblique {
        f.s_axis = normalized(v3_cross(dir, facet));
        f.e1_s = v3_dot(pol, f.s_axis);
        f.e1_p = v3_length(pol - f.s_axis * f.e1_s);
    } else {
        // No plane of incidence: all of the field counts as p.
        f.s_axis = pol;
        f.e1_s = 0.0;
        f.e1_p = 1.0;
    }
    let a = 2.0 * n1 * f.cos1;
    f.e2_s = a * f.e1_s / (n1 * f.cos1 + n2 * f.cos2);
    f.e2_p = a * f.e1_p / (n2 * f.cos1 + n1 * f.cos2);
    var t = 0.0;
    if transmittance > 0.0 {
        t = transmittance;
    } else if f.cos1 != 0.0 {
        t = n2 * f.cos2 * (f.e2_s * f.e2_s + f.e2_p * f.e2_p) / (n1 * f.cos1);
    }
    f.what = select(FRESNEL_REFLECTED, FRESNEL_REFRACTED, u < t);
    return f;
}

// The refracted direction and polarization.
fn fresnel_refracted(f: Fresnel, dir: vec3<f32>, pol: vec3<f32>, facet: vec3<f32>) -> DirPol {
    if !f.oblique {
        return DirPol(dir, pol);
    }
    let k = f.cos1 - f.cos2 * (f.n2 / f.n1);
    let new_dir = normalized(dir + facet * k);
    let p_axis = normalized(v3_cross(new_dir, f.s_axis));
    let norm = sqrt(f.e2_s * f.e2_s + f.e2_p * f.e2_p);
    let new_pol = p_axis * (f.e2_p / norm) + f.s_axis * (f.e2_s / norm);
    return DirPol(new_dir, normalized(new_pol));
}

// Reflects a direction or polarization about the plane with unit normal `n`.
fn mirror(v: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return v - n * (2.0 * v3_dot(v, n));
}

// The direction and polarization after a specular reflection about `axis`.
fn fresnel_reflected(f: Fresnel, dir: vec3<f32>, pol: vec3<f32>, axis: vec3<f32>) -> DirPol {
    let new_dir = mirror(dir, axis);
    if f.what == FRESNEL_TOTAL_INTERNAL {
        return DirPol(new_dir, -pol + axis * (2.0 * v3_dot(pol, axis)));
    }
    if !f.oblique {
        return DirPol(new_dir, select(pol, -pol, f.n2 > f.n1));
    }
    // The reflected amplitudes, from the transmitted ones.
    let r_p = f.n2 * f.e2_p / f.n1 - f.e1_p;
    let r_s = f.e2_s - f.e1_s;
    let norm = sqrt(r_p * r_p + r_s * r_s);
    let p_axis = normalized(v3_cross(new_dir, f.s_axis));
    var new_pol = f.s_axis;
    if norm > 0.0 {
        new_pol = p_axis * (r_p / norm) + f.s_axis * (r_s / norm);
    }
    return DirPol(new_dir, normalized(new_pol));
}
