// Where photons start: torch sources (twin of photons::sources::Source::sample, with the
// energy fixed or drawn from a spectrum) or gensteps, as PhotonScene::photon starts them.
// #import photons/bindings
// #import photons/bulk
// #import photons/spectra
// #if gensteps
// #import photons/gensteps
// #endif

struct Start {
    position: vec3<f32>,
    direction: vec3<f32>,
    polarization: vec3<f32>,
}

fn torch_start(rng: ptr<function, VolumeRng>) -> Start {
    let at = pparams.source_at.xyz;
    var position = at;
    var direction: vec3<f32>;
    if pparams.source_kind == PHOTON_SOURCE_BEAM {
        let axis = pparams.source_direction.xyz;
        let r = pparams.source_radius * sqrt(rng_next(rng));
        let phi = TAU * rng_next(rng);
        position = at + rotate_uz(vec3<f32>(r * cos(phi), r * sin(phi), 0.0), axis);
        direction = axis;
        let cd = pparams.cos_divergence;
        if cd < 1.0 {
            // Uniform in solid angle: the cosine uniform in [cos A, 1].
            let c = 1.0 - (1.0 - cd) * rng_next(rng);
            let s = sqrt(max(1.0 - c * c, 0.0));
            let psi = TAU * rng_next(rng);
            direction = normalized(rotate_uz(vec3<f32>(s * cos(psi), s * sin(psi), c), axis));
        }
    } else {
        let cos_t = 1.0 - 2.0 * rng_next(rng);
        let sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
        let phi = TAU * rng_next(rng);
        let n = vec3<f32>(sin_t * cos(phi), sin_t * sin(phi), cos_t);
        direction = n;
        if pparams.source_kind == PHOTON_SOURCE_SPHERE {
            position = at + n * pparams.source_radius;
            direction = select(n, -n, pparams.inward != 0u);
        }
    }
    let a = TAU * rng_next(rng);
    let polarization = normalized(rotate_uz(vec3<f32>(cos(a), sin(a), 0.0), direction));
    return Start(position, direction, polarization);
}

// Photon (lo, hi) of the run as it starts, drawn from its stream `rng`.
fn emitted_photon(lo: u32, hi: u32, rng: ptr<function, VolumeRng>) -> Emitted {
    // #if gensteps
    if pparams.source_kind == PHOTON_SOURCE_GENSTEPS {
        return genstep_photon(lo, hi, rng);
    }
    // #endif
    let s = torch_start(rng);
    var e = Emitted(s.position, s.direction, s.polarization, 0.0, pparams.energy);
    // #if spectrum
    e.energy = spectrum_energy(pparams.spectrum, rng_next(rng));
    // #endif
    return e;
}
