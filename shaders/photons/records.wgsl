// Step points of the photon kernel (--records K): twin of photons::output::record_point as
// the propagation loop records them. Every label of the history gets the point where the
// photon is when it is pushed: its position, time, direction, wavelength and polarization
// as it leaves the point, then the label code; the first K of each photon are written to
// `psteps` (12 floats a point, K points a photon, zeros past its end).
// #import photons/bindings
// #import photons/bulk

@group(2) @binding(10) var<storage, read_write> psteps: array<f32>;

// Label `n` of history `h`: the last one pushed, or one of the first 16 kept in it.
fn history_label(h: History, n: u32) -> u32 {
    if n + 1u == h.len {
        return h.last;
    }
    if n < 8u {
        return (h.lo >> (4u * n)) & 15u;
    }
    return (h.hi >> (4u * (n - 8u))) & 15u;
}

// Writes the points of the labels of `h` not yet recorded (from `*recorded` on), the photon
// being at `pos` at time `time` with `dp` and `wavelength`; photon `i` of the batch.
fn record_points(i: u32, recorded: ptr<function, u32>, h: History, pos: vec3<f32>, time: f32, dp: DirPol, wavelength: f32) {
    let k = pparams.records;
    for (var n = *recorded; n < min(h.len, k); n += 1u) {
        let base = (i * k + n) * 12u;
        var point = array<f32, 12>(pos.x, pos.y, pos.z, time, dp.dir.x, dp.dir.y, dp.dir.z, wavelength, dp.pol.x, dp.pol.y, dp.pol.z, f32(history_label(h, n)));
        for (var c = 0u; c < 12u; c += 1u) {
            psteps[base + c] = point[c];
        }
    }
    *recorded = max(*recorded, min(h.len, k));
}
