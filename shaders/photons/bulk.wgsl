// Bulk processes and the vector helpers of the photon kernel: twins of
// photons::bulk (sample_distance, rotate_uz, isotropic, rayleigh_scatter) and
// V3::normalized.
// #import real
// #import volume/rng

const TAU: f32 = 6.283185307179586;

// The CPU's V3::normalized.
fn normalized(v: vec3<f32>) -> vec3<f32> {
    let l = v3_length(v);
    if l > 0.0 {
        return v * (1.0 / l);
    }
    return v;
}

// A distance to the next interaction with mean free path `mean` (mm), from a uniform u.
fn sample_distance(mean: f32, u: f32) -> f32 {
    return -mean * log(1.0 - u);
}

// `v` given in the frame whose z axis is the unit vector `axis`, in the world frame
// (CLHEP's rotateUz).
fn rotate_uz(v: vec3<f32>, axis: vec3<f32>) -> vec3<f32> {
    let perp2 = axis.x * axis.x + axis.y * axis.y;
    if perp2 > 0.0 {
        let perp = sqrt(perp2);
        return vec3<f32>(
            (axis.x * axis.z * v.x - axis.y * v.y) / perp + axis.x * v.z,
            (axis.y * axis.z * v.x + axis.x * v.y) / perp + axis.y * v.z,
            -perp * v.x + axis.z * v.z,
        );
    }
    if axis.z >= 0.0 {
        return v;
    }
    return vec3<f32>(-v.x, v.y, -v.z);
}

// Most draws of the Rayleigh pattern's rejection loop (its acceptance is 1/2 on average).
const RAYLEIGH_MAX_DRAWS: u32 = 1000u;

struct DirPol {
    dir: vec3<f32>,
    pol: vec3<f32>,
}

// A photon as it starts: where, which way, its polarization, time (ns) and energy (MeV).
struct Emitted {
    position: vec3<f32>,
    direction: vec3<f32>,
    polarization: vec3<f32>,
    time: f32,
    energy: f32,
}

// A direction uniform over the sphere and a random polarization perpendicular to it.
fn isotropic(rng: ptr<function, VolumeRng>) -> DirPol {
    let c = 1.0 - 2.0 * rng_next(rng);
    let s = sqrt((1.0 - c) * (1.0 + c));
    let phi = TAU * rng_next(rng);
    let dir = vec3<f32>(s * cos(phi), s * sin(phi), c);
    let a = TAU * rng_next(rng);
    return DirPol(dir, normalized(rotate_uz(vec3<f32>(cos(a), sin(a), 0.0), dir)));
}

// Rayleigh scattering of a linearly polarized photon, drawn as Geant4 draws it.
fn rayleigh_scatter(dir: vec3<f32>, pol: vec3<f32>, rng: ptr<function, VolumeRng>) -> DirPol {
    var out = DirPol(dir, pol);
    for (var k = 0u; k < RAYLEIGH_MAX_DRAWS; k += 1u) {
        var cos_t = rng_next(rng);
        let sin_t = sqrt(1.0 - cos_t * cos_t);
        if rng_next(rng) < 0.5 {
            cos_t = -cos_t;
        }
        let phi = TAU * rng_next(rng);
        let local = vec3<f32>(sin_t * cos(phi), sin_t * sin(phi), cos_t);
        let new_dir = normalized(rotate_uz(local, dir));
        let projected = pol - new_dir * v3_dot(new_dir, pol);
        var new_pol: vec3<f32>;
        if v3_length(projected) == 0.0 {
            let a = TAU * rng_next(rng);
            new_pol = rotate_uz(vec3<f32>(cos(a), sin(a), 0.0), new_dir);
        } else {
            let e = normalized(projected);
            new_pol = select(e, -e, rng_next(rng) < 0.5);
        }
        let c = v3_dot(new_pol, pol);
        out = DirPol(new_dir, new_pol);
        if c * c >= rng_next(rng) {
            break;
        }
    }
    return out;
}
