// Re-emission by a scintillator (REEMISSIONPROB, the Opticks/JUNO convention): twin of
// photons::properties::Reemission::reemits and of the scintillation component's pick
// (photons::scintillation::Scintillator::pick).
// #import photons/bindings
// #import photons/bulk
// #import photons/scintillation

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
