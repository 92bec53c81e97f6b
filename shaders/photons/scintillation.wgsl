// Scintillation light's time profile: twin of photons::scintillation::Scintillator::delay,
// shared by re-emission and scintillation gensteps.
// #import photons/bindings
// #import photons/spectra
// #import volume/rng

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
