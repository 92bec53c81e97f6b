// The photon kernel (hytrace photons --backend gpu): one invocation propagates one photon
// to its end, twin of photons::propagate (PhotonScene::photon and lineage) with the CPU
// tracer in f32 (photons::tracer::Precision::F32), compared photon by photon in
// crates/trace/tests/gpu_photons.rs. Physics by module as in Rust: photons/sources
// (sources.rs), photons/gensteps (gensteps.rs, cherenkov.rs), photons/scintillation and
// photons/reemission (scintillation.rs, REEMISSIONPROB), photons/spectra (properties.rs'
// Spectrum), photons/bulk (bulk.rs), photons/boundary (boundary.rs), photons/surfaces
// (surfaces.rs), photons/surface_models (surface_models.rs), photons/wls (wavelength
// shifting, properties.rs' Wls), photons/media (media.rs), photons/bindings (the
// flattened tables, gpu_tables.rs, and the history, output.rs), photons/records (step
// points, output.rs). The geometry is the scan's scene traversal (trace/scene): the
// navigator's step from the volume the photon is in (`cross_from`) and the locate
// (`locate_point`).
// #import generated/trace_records
// #import trace/scene
// #import loop_budget
// #import photons/bindings
// #import photons/bulk
// #import photons/sources
// #import photons/surfaces
// #if reemission
// #import photons/reemission
// #endif
// #if records
// #import photons/records
// #endif
// #if wls
// #import photons/wls
// #endif
// #if media
// #import photons/media
// #endif

// In a streamed pass (a medium read from a brick store through the brick pool,
// volume/stream) invocation i propagates photon first + phistories[i].x (the host lists the
// pass's photons there), and its outputs go to slot i. A photon that read an absent brick is
// marked PHOTON_MISSING_BRICK; the host discards its results and runs it again from its
// start in a later pass.

// Twin of PhotonScene::next_boundary: the next boundary from `pos` along `dir` inside
// instance `current`; a crossing of the surface the photon sits on, found again at a
// rounding distance with the wrong orientation, is skipped.
fn next_boundary(pos: vec3<f32>, dir: vec3<f32>, current: u32) -> Hit {
    let eps = 1e-7 * max(v3_max_abs(pos), 1.0);
    var located = UNSET;
    if pparams.hierarchical != 0u {
        located = current;
    }
    var tmin = 0.0;
    var found = no_hit();
    for (var k = 0u; k < 8u; k += 1u) {
        let h = cross_from(located, pos, vec3<f32>(0.0), dir, tmin, INF);
        if !h.found {
            return h;
        }
        let leaving = h.instance == current;
        let outward = v3_dot(h.normal, dir) > 0.0;
        if leaving == outward || h.t > eps {
            return h;
        }
        tmin = h.t;
        found = h;
    }
    return found;
}

// Twin of PhotonScene::next_volume: the instance past the boundary `h` (UNSET: outside
// the world).
fn next_volume(pos: vec3<f32>, dir: vec3<f32>, current: u32, h: Hit, status: ptr<function, u32>) -> u32 {
    if pparams.hierarchical != 0u && h.instance != current {
        return h.instance;
    }
    let probe = pos + dir * (1e-6 * max(v3_max_abs(pos), 1.0));
    let c = locate_point(probe, vec3<f32>(0.0), status);
    if c != UNSET && c != current {
        return c;
    }
    return pinstances[current].mother;
}

fn velocity(m: u32, e: f32) -> f32 {
    if m == UNSET {
        return C_LIGHT_MM_PER_NS;
    }
    return property_value(pmaterials[m].groupvel, e, C_LIGHT_MM_PER_NS);
}

// A distance drawn from table `t` (INF without one, drawing nothing).
fn draw_distance(t: u32, e: f32, rng: ptr<function, VolumeRng>) -> f32 {
    if t == UNSET {
        return INF;
    }
    return sample_distance(property_value(t, e, 0.0), rng_next(rng));
}

@compute @workgroup_size(64)
fn propagate_photons(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let i = gid.y * groups_.x * 64u + gid.x;
    if i >= pparams.photon_count {
        return;
    }
    // Photon index first + p, as 64 bits.
    var p = i;
    // #if streamed
    p = phistories[i].x;
    // #endif
    let lo = pparams.first_lo + p;
    let hi = pparams.first_hi + select(0u, 1u, lo < p);
    var rng = rng_new(pparams.seed, lo, hi);
    let start = emitted_photon(lo, hi, &rng);
    var energy = start.energy;
    // A fixed wavelength as given; else from the photon's energy.
    var wavelength = pparams.wavelength_nm;
    if wavelength == 0.0 {
        wavelength = wavelength_of_energy(energy);
    }
    var out: PhotonRecord;
    out.instance = UNSET;
    var status = 0u;
    // The navigator's STATUS_* bits.
    var nav = 0u;
    var history = History(0u, 0u, 0u, 0u, 0u);
    history_push(&history, LABEL_TO);
    var pos = start.position;
    var dp = DirPol(start.direction, start.polarization);
    var time = start.time;
    var steps = 0u;
    var current = locate_point(pos, vec3<f32>(0.0), &nav);
    var ended = current == UNSET;
    if ended {
        history_push(&history, LABEL_MI);
    }
    // #if records
    // Labels whose step points are written: each is written at the next loop's start or
    // after the loop, where the photon is once its label's event is done.
    var recorded = 0u;
    // #endif
    loop {
        // #if records
        record_points(i, &recorded, history, pos, time, dp, wavelength);
        // #endif
        if ended {
            break;
        }
        if steps >= pparams.max_steps {
            history_push(&history, LABEL_TR);
            break;
        }
        steps += 1u;
        let m = pinstances[current].material;
        var d_abs = INF;
        var d_sc = INF;
        var d_wls = INF;
        if m != UNSET {
            d_abs = draw_distance(pmaterials[m].abslength, energy, &rng);
            d_sc = draw_distance(pmaterials[m].rayleigh, energy, &rng);
            // #if wls
            d_wls = draw_distance(pmaterials[m].wlsabslength, energy, &rng);
            // #endif
        }
        let h = next_boundary(pos, dp.dir, current);
        let t_b = select(INF, h.t, h.found);
        let step = min(min(min(t_b, d_abs), d_sc), d_wls);
        if step >= INF {
            history_push(&history, LABEL_MI);
            break;
        }
        // #if media
        let c = media_collision(pos, dp.dir, step, &rng);
        if c.collided {
            pos = pos + dp.dir * c.t;
            time += c.t / velocity(m, energy);
            if !medium_collide(c.placement, &dp, &rng) {
                history_push(&history, LABEL_AB);
                break;
            }
            history_push(&history, LABEL_SC);
            continue;
        }
        // #endif
        pos = pos + dp.dir * step;
        time += step / velocity(m, energy);
        if d_abs == step && d_abs < t_b {
            // #if reemission
            if reemit(m, &energy, &time, &dp, &rng) {
                wavelength = wavelength_of_energy(energy);
                history_push(&history, LABEL_RE);
                continue;
            }
            // #endif
            history_push(&history, LABEL_AB);
            break;
        }
        if d_sc == step && d_sc < t_b {
            dp = rayleigh_scatter(dp.dir, dp.pol, &rng);
            history_push(&history, LABEL_SC);
            continue;
        }
        // #if wls
        if d_wls == step && d_wls < t_b {
            let w = wls_absorb(m, &energy, &time, &dp, &rng);
            if w == WLS_ONE {
                wavelength = wavelength_of_energy(energy);
                history_push(&history, LABEL_RE);
                continue;
            }
            if w == WLS_SEVERAL {
                status |= PHOTON_SEVERAL_EMITTED;
                break;
            }
            history_push(&history, LABEL_AB);
            break;
        }
        // #endif
        let post = next_volume(pos, dp.dir, current, h, &nav);
        if post == UNSET {
            history_push(&history, LABEL_MI);
            break;
        }
        var normal = h.normal;
        if v3_dot(normal, dp.dir) > 0.0 {
            normal = -normal;
        }
        let surface = surface_between(current, post);
        let what = cross_boundary(m, pinstances[post].material, surface, &dp, energy, normal, &rng);
        if what == CROSS_TRANSMITTED {
            history_push(&history, LABEL_BT);
            current = post;
        } else if what == CROSS_REFLECTED {
            history_push(&history, LABEL_BR);
        } else if what == CROSS_SURFACE_REFLECTED {
            history_push(&history, LABEL_SR);
        } else if what == CROSS_DIFFUSE_REFLECTED {
            history_push(&history, LABEL_DR);
        } else if what == CROSS_ABSORBED {
            history_push(&history, LABEL_SA);
            break;
        } else {
            history_push(&history, LABEL_SD);
            out.instance = h.instance;
            status |= PHOTON_DETECTED;
            break;
        }
    }
    // #if records
    record_points(i, &recorded, history, pos, time, dp, wavelength);
    // #endif
    out.position = array<f32, 3>(pos.x, pos.y, pos.z);
    out.time = time;
    out.wavelength = wavelength;
    out.direction = array<f32, 3>(dp.dir.x, dp.dir.y, dp.dir.z);
    out.polarization = array<f32, 3>(dp.pol.x, dp.pol.y, dp.pol.z);
    out.history[0] = history.lo;
    out.history[1] = history.hi;
    out.mask = history.mask;
    out.labels = history.len;
    out.steps = steps;
    if (nav & STATUS_DEPTH_LIMIT) != 0u {
        status |= PHOTON_DEPTH_LIMIT;
    }
    if loops_cut_short(pparams.probe_trips) {
        status |= PHOTON_LOOPS_CUT;
    }
    // #if streamed
    if stream_missing {
        status |= PHOTON_MISSING_BRICK;
    }
    // #endif
    out.status = status;
    phistories[i] = vec2<u32>(history.lo, history.hi);
    // Only the photons the host needs more of: detected, or to be propagated again.
    if status != 0u {
        out.photon = i;
        precords[atomicAdd(&pcount, 1u)] = out;
    }
}
