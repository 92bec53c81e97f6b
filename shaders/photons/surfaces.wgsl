// Which optical surface applies to a crossing (twin of
// photons::gpu_tables::FlatSurfaces::between) and what a photon does at a boundary: twin
// of photons::surfaces::cross for the surfaces the kernel models (polished
// dielectric_dielectric and dielectric_metal, and no surface at all).
// #import photons/bindings
// #import photons/boundary

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
const CROSS_ABSORBED: u32 = 4u;
const CROSS_DETECTED: u32 = 5u;

// Geant4's tolerance on the cosine of a reflected direction with the surface normal.
const CAR_TOLERANCE: f32 = 1e-9;
// Most decisions of a polished dielectric crossing (a photon refracted back across the
// surface by rounding is decided again).
const DIELECTRIC_MAX_DECISIONS: u32 = 16u;

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
    var kind = PHOTON_SURFACE_DIELECTRIC;
    var reflectivity = 1.0;
    var transmittance = 0.0;
    var efficiency = 0.0;
    if surface != UNSET {
        let s = psurfaces[surface];
        kind = s.kind;
        reflectivity = property_value(s.reflectivity, energy, 1.0);
        transmittance = property_value(s.transmittance, energy, 0.0);
        efficiency = property_value(s.efficiency, energy, 0.0);
    }
    if kind == PHOTON_SURFACE_METAL {
        let u = rng_next(rng);
        if u > reflectivity {
            if u > reflectivity + transmittance {
                return absorb(efficiency, rng);
            }
            return CROSS_TRANSMITTED;
        }
        // Polished: specular about the surface normal.
        let pol = (*dp).pol;
        (*dp).dir = mirror((*dp).dir, normal);
        (*dp).pol = -pol + normal * (2.0 * v3_dot(pol, normal));
        if v3_dot((*dp).dir, normal) < 0.0 {
            return CROSS_TRANSMITTED;
        }
        return CROSS_SURFACE_REFLECTED;
    }
    if m1 == m2 {
        return CROSS_TRANSMITTED;
    }
    let n2_of = rindex_of(m2, energy);
    if n2_of < 0.0 {
        return CROSS_ABSORBED;
    }
    let u = rng_next(rng);
    if u > reflectivity + transmittance {
        return absorb(efficiency, rng);
    }
    if u > reflectivity {
        return CROSS_TRANSMITTED;
    }
    // Polished dielectric_dielectric: Fresnel on the surface itself, decided again while
    // the photon is sent back across it.
    var a = n1;
    var b = n2_of;
    var facing = normal;
    var through = false;
    for (var k = 0u; k < DIELECTRIC_MAX_DECISIONS; k += 1u) {
        if through {
            through = false;
            facing = -facing;
            let t = a;
            a = b;
            b = t;
        }
        let f = fresnel_decide((*dp).dir, (*dp).pol, facing, a, b, transmittance, rng_next(rng));
        let refracted = f.what == FRESNEL_REFRACTED;
        var next: DirPol;
        if refracted {
            through = true;
            next = fresnel_refracted(f, (*dp).dir, (*dp).pol, facing);
        } else {
            next = fresnel_reflected(f, (*dp).dir, (*dp).pol, facing);
        }
        (*dp).dir = normalized(next.dir);
        (*dp).pol = normalized(next.pol);
        let c = v3_dot((*dp).dir, facing);
        if (refracted && c <= 0.0) || (!refracted && c >= -CAR_TOLERANCE) {
            break;
        }
    }
    if v3_dot((*dp).dir, normal) < 0.0 {
        return CROSS_TRANSMITTED;
    }
    return CROSS_REFLECTED;
}
