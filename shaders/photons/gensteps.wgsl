// Photons emitted by gensteps (--gensteps): twin of photons::gensteps::Gensteps::emit with
// photons::cherenkov::Cherenkov::sample (G4Cerenkov's cone and spectrum, the point along
// the step by the yields at its ends) and the scintillation components (G4Scintillation:
// isotropic, the component's spectrum and time profile). Photon i of the run is photon i
// of the gensteps, numbered through them in order.
// #import photons/bindings
// #import photons/bulk
// #import photons/scintillation

@group(2) @binding(11) var<storage, read> pgensteps: array<PhotonGenstep>;

// Draws of a rejection loop (the CPU's are unbounded).
const GENSTEP_MAX_DRAWS: u32 = 4096u;

// Where (xyz) and when (w) along genstep `g` a photon is emitted at the fraction `u` of
// the step: the particle's speed taken as linear along it.
fn along(g: PhotonGenstep, u: f32) -> vec4<f32> {
    let start = vec3<f32>(g.start[0], g.start[1], g.start[2]);
    let step = vec3<f32>(g.end[0], g.end[1], g.end[2]) - start;
    let v0 = g.beta[0] * C_LIGHT_MM_PER_NS;
    let v1 = g.beta[1] * C_LIGHT_MM_PER_NS;
    let t = g.time + u * v3_length(step) / (v0 + u * (v1 - v0) / 2.0);
    return vec4<f32>(start + step * u, t);
}

// Whether the 64-bit index (hi, lo) `a` is at most `b`.
fn at_most(a: array<u32, 2>, b_lo: u32, b_hi: u32) -> bool {
    return a[1] < b_hi || (a[1] == b_hi && a[0] <= b_lo);
}

// Photon (lo, hi) of the gensteps.
fn genstep_photon(lo: u32, hi: u32, rng: ptr<function, VolumeRng>) -> Emitted {
    // The first genstep whose end lies above the index (a partition point).
    var a = 0u;
    var b = arrayLength(&pgensteps);
    loop {
        if a >= b {
            break;
        }
        let mid = a + (b - a) / 2u;
        if at_most(pgensteps[mid].end_index, lo, hi) {
            a = mid + 1u;
        } else {
            b = mid;
        }
    }
    let g = pgensteps[a];
    // The index within the step, below 2^32 (the host refuses larger steps): the low
    // words' difference, wrapping.
    var local = lo;
    if a > 0u {
        local = lo - pgensteps[a - 1u].end_index[0];
    }
    var e: Emitted;
    if g.kind == PHOTON_GENSTEP_CHERENKOV {
        // The energy uniform over RINDEX's range, accepted with sin^2 theta / sin^2 theta_max.
        let t = pmaterials[g.material].rindex;
        let table = ptables[t];
        let pmin = prows[table.first].x;
        let pmax = prows[table.first + table.count - 1u].x;
        var cos_t = 0.0;
        var sin2 = 0.0;
        for (var k = 0u; k < GENSTEP_MAX_DRAWS; k += 1u) {
            e.energy = pmin + rng_next(rng) * (pmax - pmin);
            cos_t = 1.0 / (g.mean_beta * property_value(t, e.energy, 1.0));
            sin2 = (1.0 - cos_t) * (1.0 + cos_t);
            if rng_next(rng) * g.max_sin2 <= sin2 {
                break;
            }
        }
        let sin_t = sqrt(sin2);
        let phi = TAU * rng_next(rng);
        let sp = sin(phi);
        let cp = cos(phi);
        let axis = vec3<f32>(g.axis[0], g.axis[1], g.axis[2]);
        e.direction = normalized(rotate_uz(vec3<f32>(sin_t * cp, sin_t * sp, cos_t), axis));
        e.polarization = normalized(rotate_uz(vec3<f32>(cos_t * cp, cos_t * sp, -sin_t), axis));
        // The point along the step: density linear between the yields at its ends.
        let y0 = g.yields[0];
        let y1 = g.yields[1];
        var u = 0.0;
        for (var k = 0u; k < GENSTEP_MAX_DRAWS; k += 1u) {
            u = rng_next(rng);
            if rng_next(rng) * max(y0, y1) <= y0 - u * (y0 - y1) {
                break;
            }
        }
        let at = along(g, u);
        e.position = at.xyz;
        e.time = at.w;
        return e;
    }
    // Scintillation: the component whose photons hold the index.
    var k = 0u;
    var first = g.counts[0];
    for (var j = 0u; j < 2u; j += 1u) {
        if local < first {
            break;
        }
        k += 1u;
        first += g.counts[k];
    }
    e.energy = spectrum_energy(g.spectrum[k], rng_next(rng));
    let dp = isotropic(rng);
    e.direction = dp.dir;
    e.polarization = dp.pol;
    var u = 1.0;
    if g.charge != 0.0 {
        u = rng_next(rng);
    }
    let at = along(g, u);
    e.position = at.xyz;
    e.time = at.w + scintillation_delay(g.decay[k], g.rise[k], rng);
    return e;
}
