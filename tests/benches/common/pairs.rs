//! Speed comparisons that hold while the machine's speed drifts between rows (20% and more
//! on the shared VMs): our run and the reference's timed in alternation, pair by pair.

use std::time::Instant;

use hytrace_csg::simd::{self, SimdPath};
use hytrace_csg::Ray;
use hytrace_trace::cpu::CpuScene;
use rayon::prelude::*;

use crate::batched::trace_batches;

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

/// How many times faster `work` runs on the selected SIMD path ([`simd::selected`]) than
/// on the portable one, over [`PAIRS`] alternating pairs ([`paired_speed_ratio`]); `None`
/// when the selected path is the portable one. The selected path is restored afterwards.
fn paired_simd_ratio(work: impl Fn()) -> Option<[f64; 3]> {
    let chosen = simd::selected();
    if chosen == SimdPath::Portable {
        return None;
    }
    let on = |path: SimdPath| {
        simd::select(path).expect("a supported path");
        work();
    };
    let ratio = paired_speed_ratio(|| on(chosen), || on(SimdPath::Portable));
    simd::select(chosen).expect("a supported path");
    Some(ratio)
}

/// The selected SIMD path against the portable one on `scene`, side by side
/// ([`paired_simd_ratio`]): closest hits in batches (as `hytrace scan`) and any hits ray by
/// ray, as a line of text; `None` on the portable path.
pub fn simd_over_portable(scene: &CpuScene<f32>, rays: &[Ray<f64>]) -> Option<String> {
    let [median, low, high] = paired_simd_ratio(|| {
        trace_batches(scene, rays, |h| h.map(|h| h.t));
    })?;
    let [any_median, any_low, any_high] = paired_simd_ratio(|| {
        rays.par_iter().for_each(|r| {
            scene.occluded(r, 0.0, f32::INFINITY);
        })
    })?;
    Some(format!(
        "{} over portable, {PAIRS} alternating pairs: closest hit in batches (CpuScene::trace_batch) median {median:.2}x, range {low:.2}-{high:.2}x; any hit (CpuScene::occluded) median {any_median:.2}x, range {any_low:.2}-{any_high:.2}x",
        simd::selected()
    ))
}

/// The line naming the SIMD path the kernels run on, and the others this CPU has.
pub fn simd_line() -> String {
    let names: Vec<String> = SimdPath::available()
        .iter()
        .map(|p| p.to_string())
        .collect();
    format!(
        "SIMD path: {} (this CPU: {}; HYTRACE_SIMD=portable|avx2|avx512 forces one)",
        simd::selected(),
        names.join(", ")
    )
}
