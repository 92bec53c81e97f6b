// Wavelength shifting (G4OpWLS): twin of photons::properties::Wls (sample_count,
// sample_energy) and of the propagation loop's shifting absorption. The kernel carries one
// photon: an absorption that emits one goes on as it; one that emits several is left to the
// CPU twin (PHOTON_SEVERAL_EMITTED), which propagates the photon and all it emitted.
// #import photons/bindings
// #import photons/bulk
// #import photons/spectra

// What a shifting absorption did.
const WLS_NOTHING: u32 = 0u;
const WLS_ONE: u32 = 1u;
const WLS_SEVERAL: u32 = 2u;

// Photons counted at most by the Poisson inversion (photons::properties::POISSON_MAX).
const POISSON_MAX: u32 = 1000u;
// Spectrum draws for one photon no more energetic than the absorbed one (Geant4's 100).
const WLS_ENERGY_DRAWS: u32 = 100u;

// The number of photons one absorption emits: G4Poisson with mean `mean` (inversion up to
// 16, a rounded Gaussian above); 1 for a negative mean (none given).
fn wls_count(mean: f32, rng: ptr<function, VolumeRng>) -> u32 {
    if mean < 0.0 {
        return 1u;
    }
    if mean <= 16.0 {
        let u = rng_next(rng);
        var term = exp(-mean);
        var sum = term;
        var n = 0u;
        loop {
            if sum > u || n >= POISSON_MAX {
                break;
            }
            n += 1u;
            term *= mean / f32(n);
            sum += term;
        }
        return n;
    }
    let a = rng_next(rng);
    let r = sqrt(-2.0 * log(1.0 - a));
    let b = rng_next(rng);
    let value = mean + r * cos(TAU * b) * sqrt(mean) + 0.5;
    return select(u32(value), 0u, value <= 0.0);
}

// A photon of energy `*energy` absorbed by the shifter of material m: how many photons it
// emits; for one, `*energy`, `*time` and `dp` become the emitted photon's.
fn wls_absorb(m: u32, energy: ptr<function, f32>, time: ptr<function, f32>, dp: ptr<function, DirPol>, rng: ptr<function, VolumeRng>) -> u32 {
    let mat = pmaterials[m];
    if mat.wls_spectrum == UNSET {
        return WLS_NOTHING;
    }
    let count = wls_count(mat.wls_mean, rng);
    var emitted = 0u;
    var first = 0.0;
    for (var c = 0u; c < count; c += 1u) {
        for (var k = 0u; k < WLS_ENERGY_DRAWS; k += 1u) {
            let e = spectrum_energy(mat.wls_spectrum, rng_next(rng));
            if e <= *energy {
                if emitted == 0u {
                    first = e;
                }
                emitted += 1u;
                break;
            }
        }
        // The CPU twin propagates the photon again, with all it emits.
        if emitted > 1u {
            return WLS_SEVERAL;
        }
    }
    if emitted == 0u {
        return WLS_NOTHING;
    }
    *time += mat.wls_delay;
    *dp = isotropic(rng);
    *energy = first;
    return WLS_ONE;
}
