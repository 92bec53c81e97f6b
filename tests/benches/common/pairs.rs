//! Speed comparisons that hold while the machine's speed drifts between rows (20% and more
//! on the shared VMs): our run and the reference's timed in alternation, pair by pair.

use std::time::Instant;

/// Alternating pairs per comparison.
pub const PAIRS: usize = 7;

/// How many times faster `ours` runs than `theirs` over [`PAIRS`] alternating runs of the
/// two: the median, lowest and highest of the pairs' ratios (their time over ours).
pub fn paired_speed_ratio(mut ours: impl FnMut(), mut theirs: impl FnMut()) -> [f64; 3] {
    let mut ratios: Vec<f64> = (0..PAIRS)
        .map(|_| {
            let t = Instant::now();
            ours();
            let ours = t.elapsed().as_secs_f64();
            let t = Instant::now();
            theirs();
            t.elapsed().as_secs_f64() / ours
        })
        .collect();
    ratios.sort_by(f64::total_cmp);
    [ratios[PAIRS / 2], ratios[0], ratios[PAIRS - 1]]
}
