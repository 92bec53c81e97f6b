// Which optical surface applies to a crossing (twin of
// photons::gpu_tables::FlatSurfaces::between) and what a photon does at a boundary: twin
// of photons::surfaces::cross (dielectric_dielectric and dielectric_metal surfaces of the
// glisur and unified models, every plain finish, and no surface at all).
// #import photons/bindings
// #import photons/surface_models

// The surface of a crossing from instance `pre` into `post` (UNSET for none).
fn surface_between(pre: u32, post: u32) -> u32 {
    let a = pinstances[pre];
    let b = pinstances[post];
    if b.mother == pre {
        return b.enter_surface;
    }
    if a.mother == post {
        return a.leave_surface;
    }
    // Border surfaces between instances that are not mother and daughter, sorted by
    // (pre, post): a binary search.
    var lo = 0u;
    var hi = arrayLength(&pborders);
    loop {
        if lo >= hi {
            break;
        }
        let mid = lo + (hi - lo) / 2u;
        let m = pborders[mid];
        if m.pre < pre || (m.pre == pre && m.post < post) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if lo < arrayLength(&pborders) && pborders[lo].pre == pre && pborders[lo].post == post {
        return pborders[lo].surface;
    }
    return select(b.sibling_enter, a.sibling_leave, a.sibling_leave != UNSET);
}

// What a photon did at a boundary (photons::surfaces::Crossing).
const CROSS_TRANSMITTED: u32 = 0u;
const CROSS_REFLECTED: u32 = 1u;
const CROSS_SURFACE_REFLECTED: u32 = 2u;
const CROSS_DIFFUSE_REFLECTED: u32 = 3u;
const CROSS_ABSORBED: u32 = 4u;
const CROSS_DETECTED: u32 = 5u;

// A reflected direction within this of the mirror image of the incoming one counts as
// specular (the CPU's 1e-7, widened to f32's rounding of a reflection).
const SPECULAR_TOLERANCE: f32 = 1e-5;

// Absorption at a surface, detected with probability `efficiency`.
fn absorb(efficiency: f32, rng: ptr<function, VolumeRng>) -> u32 {
    return select(CROSS_ABSORBED, CROSS_DETECTED, rng_next(rng) < efficiency);
}

// The refractive index of material m at energy e, or a negative number without RINDEX.
fn rindex_of(m: u32, e: f32) -> f32 {
    if m == UNSET || pmaterials[m].rindex == UNSET {
        return -1.0;
    }
    return property_value(pmaterials[m].rindex, e, 1.0);
}

// The boundary process at a crossing from material m1 into m2 through surface `surface`
// (UNSET: none); `normal` faces the photon. `dp` changes in place.
fn cross_boundary(m1: u32, m2: u32, surface: u32, dp: ptr<function, DirPol>, energy: f32, normal: vec3<f32>, rng: ptr<function, VolumeRng>) -> u32 {
    let n1 = rindex_of(m1, energy);
    if n1 < 0.0 {
        return CROSS_ABSORBED;
    }
    // No surface: polished dielectric_dielectric (glisur, polish 1) with REFLECTIVITY 1.
    var at = SurfaceAt(PHOTON_FINISH_POLISHED, false, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0);
    var kind = PHOTON_SURFACE_DIELECTRIC;
    var efficiency = 0.0;
    // The gap's RINDEX behind a back-painted finish.
    var gap = n1;
    if surface != UNSET {
        let s = psurfaces[surface];
        kind = s.kind;
        at.finish = s.finish;
        at.unified = s.unified != 0u;
        at.roughness = s.roughness;
        at.reflectivity = property_value(s.reflectivity, energy, 1.0);
        at.transmittance = property_value(s.transmittance, energy, 0.0);
        efficiency = property_value(s.efficiency, energy, 0.0);
        // #if rough_surfaces
        at.spike = property_value(s.spike, energy, 0.0);
        at.lobe = property_value(s.lobe, energy, 0.0);
        at.backscatter = property_value(s.backscatter, energy, 0.0);
        if back_painted(at.finish) {
            // Without RINDEX the photon dies in the gap (Geant4's NoRINDEX).
            if s.rindex == UNSET {
                return CROSS_ABSORBED;
            }
            gap = property_value(s.rindex, energy, 1.0);
        }
        // #endif
    }
    let incoming = (*dp).dir;
    var end = SURFACE_LEFT;
    if kind == PHOTON_SURFACE_METAL {
        let u = rng_next(rng);
        if u > at.reflectivity {
            if u > at.reflectivity + at.transmittance {
                return absorb(efficiency, rng);
            }
            return CROSS_TRANSMITTED;
        }
        metal_reflection(at, dp, normal, rng);
    } else {
        let plain = at.finish == PHOTON_FINISH_POLISHED || at.finish == PHOTON_FINISH_GROUND;
        var n2 = gap;
        if plain {
            if m1 == m2 {
                return CROSS_TRANSMITTED;
            }
            n2 = rindex_of(m2, energy);
            if n2 < 0.0 {
                return CROSS_ABSORBED;
            }
        }
        if back_painted(at.finish) {
            end = dielectric(at, dp, normal, n1, n2, rng);
        } else {
            let u = rng_next(rng);
            if u > at.reflectivity + at.transmittance {
                return absorb(efficiency, rng);
            }
            if u > at.reflectivity {
                return CROSS_TRANSMITTED;
            }
            if plain {
                end = dielectric(at, dp, normal, n1, n2, rng);
            } else {
                // Front paint: specular (polished) or Lambertian (ground).
                *dp = do_reflection(at, at.finish == PHOTON_FINISH_GROUND_FRONT_PAINTED, (*dp).dir, (*dp).pol, normal, rng);
            }
        }
    }
    if end == SURFACE_ABSORBED {
        return absorb(efficiency, rng);
    }
    if v3_dot((*dp).dir, normal) < 0.0 {
        return CROSS_TRANSMITTED;
    }
    if v3_length((*dp).dir - mirror(incoming, normal)) > SPECULAR_TOLERANCE {
        return CROSS_DIFFUSE_REFLECTED;
    }
    if kind == PHOTON_SURFACE_METAL {
        return CROSS_SURFACE_REFLECTED;
    }
    return CROSS_REFLECTED;
}
