//! Repeatable timings: warm-up, then the median of repeated runs, on one thread.

use std::time::Instant;

use super::Settings;

/// Times closures as the median over repeated runs after a warm-up run.
#[derive(Clone, Copy, Debug)]
pub struct Timer {
    repeats: usize,
}

impl Timer {
    /// 9 repeats normally, 3 with `--quick`.
    pub fn new(settings: Settings) -> Timer {
        Timer {
            repeats: settings.size(9, 3),
        }
    }

    /// Median nanoseconds per operation of `run`, which performs `ops` operations per call
    /// and returns a value kept from the optimiser.
    pub fn ns_per_op<R>(&self, ops: usize, mut run: impl FnMut() -> R) -> f64 {
        std::hint::black_box(run());
        let mut times: Vec<f64> = (0..self.repeats)
            .map(|_| {
                let start = Instant::now();
                std::hint::black_box(run());
                start.elapsed().as_secs_f64()
            })
            .collect();
        times.sort_by(f64::total_cmp);
        times[times.len() / 2] * 1e9 / ops.max(1) as f64
    }
}
