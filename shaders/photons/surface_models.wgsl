// Optical surface models of the photon kernel: twin of photons::surface_models (Geant4's
// glisur and unified models as G4OpBoundaryProcess applies them). Facets, the unified
// model's reflection types and paint are composed in only for scenes with a finish other
// than polished (feature `rough_surfaces`); without it every surface is polished and the
// facet is the surface's normal.
// #import photons/bindings
// #import photons/boundary

// Geant4's tolerance on the cosine of a reflected direction with the surface normal.
const CAR_TOLERANCE: f32 = 1e-9;
// Decisions of one dielectric crossing before the photon leaves the surface, and crossings
// of a back-painted gap (unbounded in Geant4; the CPU stops after 2^20).
const SURFACE_MAX_DECISIONS: u32 = 256u;
// Draws of a rejection loop (facets facing away, reflections into a metal).
const SURFACE_MAX_DRAWS: u32 = 4096u;

const HALF_PI: f32 = 1.5707963267948966;

// How a surface ended for the photon (photons::surface_models::SurfaceEnd).
const SURFACE_LEFT: u32 = 0u;
const SURFACE_ABSORBED: u32 = 1u;

// A surface's parameters at the photon's energy (photons::surface_models::SurfaceAt).
struct SurfaceAt {
    finish: u32,
    unified: bool,
    // sigma_alpha (unified) or polish (glisur).
    roughness: f32,
    reflectivity: f32,
    transmittance: f32,
    spike: f32,
    lobe: f32,
    backscatter: f32,
}

// The unified model's reflection types (photons::surface_models::Reflection); NONE: the
// plain reflection of the other models and of polished finishes.
const REFLECTION_NONE: u32 = 0u;
const REFLECTION_SPIKE: u32 = 1u;
const REFLECTION_LOBE: u32 = 2u;
const REFLECTION_BACKSCATTER: u32 = 3u;
const REFLECTION_LAMBERTIAN: u32 = 4u;

fn back_painted(finish: u32) -> bool {
    return finish == PHOTON_FINISH_POLISHED_BACK_PAINTED || finish == PHOTON_FINISH_GROUND_BACK_PAINTED;
}

// #if rough_surfaces
// A standard normal deviate (Box-Muller).
fn gaussian(rng: ptr<function, VolumeRng>) -> f32 {
    let u = rng_next(rng);
    let r = sqrt(-2.0 * log(1.0 - u));
    let v = rng_next(rng);
    return r * cos(TAU * v);
}

// A direction from the cosine-weighted hemisphere about the unit `normal`.
fn lambertian(normal: vec3<f32>, rng: ptr<function, VolumeRng>) -> vec3<f32> {
    let u = rng_next(rng);
    let phi = TAU * rng_next(rng);
    let r = sqrt(u);
    return normalized(rotate_uz(vec3<f32>(r * cos(phi), r * sin(phi), sqrt(1.0 - u)), normal));
}

// A facet normal for a photon moving along `dir` onto a surface whose unit normal faces
// it (Geant4's GetFacetNormal): the normal itself when smooth.
fn facet_normal(at: SurfaceAt, dir: vec3<f32>, normal: vec3<f32>, rng: ptr<function, VolumeRng>) -> vec3<f32> {
    if at.unified && at.roughness > 0.0 {
        let f_max = min(4.0 * at.roughness, 1.0);
        for (var k = 0u; k < SURFACE_MAX_DRAWS; k += 1u) {
            // alpha from a Gaussian times sin(alpha), below pi/2, by rejection.
            var alpha = 0.0;
            var sin_alpha = 0.0;
            for (var j = 0u; j < SURFACE_MAX_DRAWS; j += 1u) {
                alpha = at.roughness * gaussian(rng);
                sin_alpha = sin(alpha);
                if rng_next(rng) * f_max <= sin_alpha && alpha < HALF_PI {
                    break;
                }
            }
            let phi = TAU * rng_next(rng);
            let local = vec3<f32>(sin_alpha * cos(phi), sin_alpha * sin(phi), cos(alpha));
            let facet = rotate_uz(local, normal);
            if v3_dot(dir, facet) < 0.0 {
                return facet;
            }
        }
        return normal;
    }
    if !at.unified && at.roughness < 1.0 {
        for (var k = 0u; k < SURFACE_MAX_DRAWS; k += 1u) {
            // A point uniform in the unit ball, by rejection from the cube.
            var smear = vec3<f32>(0.0);
            for (var j = 0u; j < SURFACE_MAX_DRAWS; j += 1u) {
                let x = 2.0 * rng_next(rng) - 1.0;
                let y = 2.0 * rng_next(rng) - 1.0;
                let z = 2.0 * rng_next(rng) - 1.0;
                smear = vec3<f32>(x, y, z);
                if v3_dot(smear, smear) <= 1.0 {
                    break;
                }
            }
            let facet = normal + smear * (1.0 - at.roughness);
            if v3_dot(dir, facet) < 0.0 {
                return normalized(facet);
            }
        }
    }
    return normal;
}

// The unified model's choice among its reflection types.
fn choose_reflection(at: SurfaceAt, rng: ptr<function, VolumeRng>) -> u32 {
    let u = rng_next(rng);
    if u < at.spike {
        return REFLECTION_SPIKE;
    }
    if u < at.spike + at.lobe {
        return REFLECTION_LOBE;
    }
    if u < at.spike + at.lobe + at.backscatter {
        return REFLECTION_BACKSCATTER;
    }
    return REFLECTION_LAMBERTIAN;
}
// #endif

// The reflection type a surface draws for a reflection: one of the unified model's on a
// finish other than polished, else NONE (drawing nothing).
fn chosen_reflection(at: SurfaceAt, rng: ptr<function, VolumeRng>) -> u32 {
    // #if rough_surfaces
    if at.unified && at.finish != PHOTON_FINISH_POLISHED {
        return choose_reflection(at, rng);
    }
    // #endif
    return REFLECTION_NONE;
}

// A facet normal on a finish other than polished, else the surface's normal.
fn facet_of(at: SurfaceAt, dir: vec3<f32>, normal: vec3<f32>, rng: ptr<function, VolumeRng>) -> vec3<f32> {
    // #if rough_surfaces
    if at.finish != PHOTON_FINISH_POLISHED {
        return facet_normal(at, dir, normal, rng);
    }
    // #endif
    return normal;
}

// Specular reflection about `axis`, the polarization mirrored with it.
fn specular(dir: vec3<f32>, pol: vec3<f32>, axis: vec3<f32>) -> DirPol {
    return DirPol(mirror(dir, axis), -mirror(pol, axis));
}

// Geant4's DoReflection: Lambertian when `lambert`, a lobe about a new facet on a ground
// finish, else a spike about the surface normal.
fn do_reflection(at: SurfaceAt, lambert: bool, dir: vec3<f32>, pol: vec3<f32>, normal: vec3<f32>, rng: ptr<function, VolumeRng>) -> DirPol {
    var facet = normal;
    // #if rough_surfaces
    if lambert {
        let d = lambertian(normal, rng);
        let f = normalized(d - dir);
        return DirPol(d, -mirror(pol, f));
    }
    if at.finish == PHOTON_FINISH_GROUND {
        facet = facet_normal(at, dir, normal, rng);
    }
    // #endif
    return specular(dir, pol, facet);
}

// A dielectric_metal surface that reflects (the caller drew the uniform that chose
// reflection); reflections into the metal reflect again.
fn metal_reflection(at: SurfaceAt, dp: ptr<function, DirPol>, normal: vec3<f32>, rng: ptr<function, VolumeRng>) {
    let chosen = chosen_reflection(at, rng);
    for (var k = 0u; k < SURFACE_MAX_DRAWS; k += 1u) {
        let dir = (*dp).dir;
        let pol = (*dp).pol;
        if chosen == REFLECTION_NONE || chosen == REFLECTION_LAMBERTIAN {
            *dp = do_reflection(at, chosen == REFLECTION_LAMBERTIAN, dir, pol, normal, rng);
        } else if chosen == REFLECTION_BACKSCATTER {
            *dp = DirPol(-dir, -pol);
        } else if chosen == REFLECTION_LOBE {
            *dp = specular(dir, pol, facet_of(at, dir, normal, rng));
        } else {
            *dp = specular(dir, pol, normal);
        }
        if v3_dot((*dp).dir, normal) >= 0.0 {
            return;
        }
    }
}

// A reflection on a dielectric_dielectric surface where the Fresnel decision `f` reflected
// the photon on `facet`: the unified model's reflection types on rough finishes, else
// specular about the facet; `lambertian` says whether it was Lambertian.
fn dielectric_reflection(at: SurfaceAt, f: Fresnel, dir: vec3<f32>, pol: vec3<f32>, facet: vec3<f32>, normal: vec3<f32>, rng: ptr<function, VolumeRng>, lambertian: ptr<function, bool>) -> DirPol {
    let chosen = chosen_reflection(at, rng);
    *lambertian = chosen == REFLECTION_LAMBERTIAN;
    if chosen == REFLECTION_LAMBERTIAN {
        return do_reflection(at, true, dir, pol, normal, rng);
    }
    if chosen == REFLECTION_BACKSCATTER {
        return DirPol(-dir, -pol);
    }
    if chosen == REFLECTION_SPIKE {
        return fresnel_reflected(f, dir, pol, normal);
    }
    return fresnel_reflected(f, dir, pol, facet);
}

// Geant4's DielectricDielectric from index n1 into n2 (for back-painted finishes n2 is the
// gap's RINDEX); `normal` faces the photon. The photon ends on the side its final
// direction points to.
fn dielectric(at: SurfaceAt, dp: ptr<function, DirPol>, normal_in: vec3<f32>, n1_in: f32, n2_in: f32, rng: ptr<function, VolumeRng>) -> u32 {
    var n1 = n1_in;
    var n2 = n2_in;
    var normal = normal_in;
    var inside = false;
    var swap = false;
    var refracted = false;
    var lambertian = false;
    for (var leap = 0u; leap < SURFACE_MAX_DECISIONS; leap += 1u) {
        var through = false;
        for (var k = 0u; k < SURFACE_MAX_DECISIONS; k += 1u) {
            if through {
                swap = !swap;
                through = false;
                normal = -normal;
                let t = n1;
                n1 = n2;
                n2 = t;
            }
            let dir = (*dp).dir;
            let pol = (*dp).pol;
            let facet = facet_of(at, dir, normal, rng);
            let f = fresnel_decide(dir, pol, facet, n1, n2, at.transmittance, rng_next(rng));
            refracted = f.what == FRESNEL_REFRACTED;
            var next: DirPol;
            if refracted {
                inside = !inside;
                through = true;
                lambertian = false;
                next = fresnel_refracted(f, dir, pol, facet);
            } else {
                swap = false;
                next = dielectric_reflection(at, f, dir, pol, facet, normal, rng, &lambertian);
            }
            (*dp).dir = normalized(next.dir);
            (*dp).pol = normalized(next.pol);
            let c = v3_dot((*dp).dir, normal);
            if (refracted && c <= 0.0) || (!refracted && c >= -CAR_TOLERANCE) {
                break;
            }
        }
        if !(inside && !swap && back_painted(at.finish)) {
            return SURFACE_LEFT;
        }
        // #if rough_surfaces
        // In the gap, at the paint.
        let u = rng_next(rng);
        if u > at.reflectivity + at.transmittance {
            return SURFACE_ABSORBED;
        }
        if u > at.reflectivity {
            return SURFACE_LEFT;
        }
        if refracted {
            swap = !swap;
            let t = n1;
            n1 = n2;
            n2 = t;
        } else {
            normal = -normal;
        }
        // Ground paint reflects as Lambertian; so does polished paint after a Lambertian
        // reflection in the gap. The polarization is kept (as Geant4 keeps it).
        let lambert = lambertian || at.finish == PHOTON_FINISH_GROUND_BACK_PAINTED;
        let d = do_reflection(at, lambert, (*dp).dir, (*dp).pol, normal, rng);
        normal = -normal;
        (*dp).dir = d.dir;
        // #endif
    }
    return SURFACE_LEFT;
}
