// Re-emission by a scintillator (REEMISSIONPROB, the Opticks/JUNO convention): twin of
// photons::properties::Reemission::reemits and of the scintillation component's pick,
// energy and delay (photons::scintillation::Scintillator).
// #import photons/bindings
// #import photons/bulk
// #import photons/spectra

// Draws of the rejection loop of a profile with a rise time (the CPU's loop is unbounded;
// its acceptance is at least 1 - exp(-1) for rise times below the decay time).
const DELAY_MAX_DRAWS: u32 = 4096u;

// A delay (ns) from a component's time profile: exponential with the decay time, or with a
// rise time G4Scintillation's profile, sampled under the exponential envelope.
fn scintillation_delay(decay: f32, rise: f32, rng: ptr<function, VolumeRng>) -> f32 {
    if rise == 0.0 {
        return -decay * log(1.0 - rng_next(rng));
    }
    var t = 0.0;
    for (var k = 0u; k < DELAY_MAX_DRAWS; k += 1u) {
        t = -decay * log(1.0 - rng_next(rng));
        if rng_next(rng) <= 1.0 - exp(-t / rise) {
            break;
        }
    }
    return t;
}

// A photon absorbed in material m at `*energy` is emitted again with the material's
// REEMISSIONPROB: from a component drawn by its yield, at an energy from its spectrum,
// after a delay from its profile, isotropic. Returns whether it was; draws nothing for a
// material without re-emission.
fn reemit(m: u32, energy: ptr<function, f32>, time: ptr<function, f32>, dp: ptr<function, DirPol>, rng: ptr<function, VolumeRng>) -> bool {
    let mat = pmaterials[m];
    if mat.reemission == UNSET || rng_next(rng) >= property_value(mat.reemission, *energy, 0.0) {
        return false;
    }
    var sum = 0.0;
    for (var k = 0u; k < mat.components; k += 1u) {
        sum += mat.weight[k];
    }
    var u = rng_next(rng) * sum;
    var pick = mat.components - 1u;
    for (var k = 0u; k < mat.components; k += 1u) {
        if u < mat.weight[k] {
            pick = k;
            break;
        }
        u -= mat.weight[k];
    }
    *energy = spectrum_energy(mat.spectrum[pick], rng_next(rng));
    *time += scintillation_delay(mat.decay[pick], mat.rise[pick], rng);
    *dp = isotropic(rng);
    return true;
}
