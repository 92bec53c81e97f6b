// Emission spectra of the photon kernel: twin of photons::properties::Spectrum (the
// trapezoid integral of an intensity over photon energy, inverted linearly between rows as
// G4PhysicsVector::GetEnergy inverts it) and of wavelength_of_energy.
// #import photons/bindings

// h c in eV nm (photons::properties::HC_EV_NM).
const HC_EV_NM: f32 = 1239.84198;

// Wavelength in nm of a photon energy in MeV.
fn wavelength_of_energy(mev: f32) -> f32 {
    return HC_EV_NM / (mev * 1e6);
}

// The energy (MeV) drawn by the uniform `u` from spectrum table `t`, whose rows are
// `(energy, integral up to it)`.
fn spectrum_energy(t: u32, u: f32) -> f32 {
    let table = ptables[t];
    let first = table.first;
    let last = first + table.count - 1u;
    let c = u * prows[last].y;
    if last == first || c <= prows[first].y {
        return prows[first].x;
    }
    if c >= prows[last].y {
        return prows[last].x;
    }
    // The first row whose integral is not below c (a partition point): c lies in
    // (row lo - 1, row lo].
    var lo = first;
    var hi = last;
    loop {
        if lo >= hi {
            break;
        }
        let mid = lo + (hi - lo) / 2u;
        if prows[mid].y < c {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    let a = prows[lo - 1u];
    let b = prows[lo];
    let del = b.y - a.y;
    if del > 0.0 {
        return a.x + (c - a.y) * (b.x - a.x) / del;
    }
    return a.x;
}
