//! Closest hits the way `hytrace scan` traces them: [`CpuScene::trace_batch`], handed
//! [`BATCH`] rays at a time by each rayon thread, which keeps its scratch space.

use hytrace_csg::Ray;
use hytrace_trace::cpu::{CpuScene, Hit, TraceScratch, BATCH};
use rayon::prelude::*;

/// `keep` of the closest hit of every ray (`tmin` 0, no `tmax`; rays in f64, as the
/// tracer takes them), in order.
pub fn trace_batches<R: Send + Clone + Default>(
    scene: &CpuScene<f32>,
    rays: &[Ray<f64>],
    keep: impl Fn(&Option<Hit<f32>>) -> R + Sync,
) -> Vec<R> {
    let mut kept = vec![R::default(); rays.len()];
    kept.par_chunks_mut(BATCH)
        .zip(rays.par_chunks(BATCH))
        .for_each_init(
            || (TraceScratch::default(), Vec::new(), Vec::new()),
            |(scratch, queries, hits), (kept, chunk)| {
                queries.clear();
                queries.extend(chunk.iter().map(|r| (*r, 0.0, f32::INFINITY)));
                scene.trace_batch(queries, scratch, hits);
                for (k, h) in kept.iter_mut().zip(hits.iter()) {
                    *k = keep(h);
                }
            },
        );
    kept
}
