//! Transmittance `T = exp(-tau)` along rays through a voxel grid: exact, marched and
//! tracked (delta, ratio, residual ratio) estimates.
//!
//! The density at index-space point `p` is `lookup(p) * density_scale`, and the optical depth
//! is `tau = integral of density(o + t d) dt` over the ray's `[tmin, tmax]`: world distance
//! for unit world directions. Outside the range mips' box the density is the background's,
//! so a ray with a non-zero background and `tmax = +inf` has `T = 0`.
//!
//! The trackers walk the ray's [`Segment`]s and use each segment's range as local bounds:
//! majorant `range.max * scale`, minorant `range.min * scale`. Free flights restart at each
//! segment boundary (exponential flights are memoryless, so this is exact). A segment whose
//! range is constant has a known density: no lookups; delta tracking survives it with
//! probability `exp(-density * length)`, ratio tracking multiplies by that factor (its
//! conditional expectation there). The trackers need a density `>= 0`: a segment whose
//! range goes below 0 is an error (the range is halo-inclusive, so this fires when a block
//! next to the ray holds a negative voxel). [`Estimator::Exact`] and [`Estimator::March`]
//! integrate negative densities as they are (then `T > 1`).

use rayon::prelude::*;

use crate::dda::{global_range, CellWalk, IndexRay, Ray, Segment, SegmentWalk, LEVEL_OUTSIDE};
use crate::dense::VolumeError;
use crate::grid::{sample_nearest, sample_stochastic, sample_trilinear, Filter, VoxelGrid};
use crate::ranges::{RangeMips, ValueRange};
use crate::rng::Rng;

/// How the transmittance is computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Estimator {
    /// The optical depth integrated exactly (up to rounding) in f64. Trilinear: per unit
    /// cell piece, where the field along the ray is a cubic in `t`, by 2-point
    /// Gauss-Legendre (exact for cubics); nearest: value times length per voxel. The
    /// stochastic filter's mean field is the trilinear one, which is what `Exact`
    /// integrates for it. Deterministic; `spp` and `seed` are unused.
    Exact,
    /// Midpoint ray marching over the ray's overlap with the range mips' box, in
    /// `ceil(length / step)` equal steps no longer than `step` (world units of `t`); the
    /// outside parts are integrated exactly. Deterministic for the nearest and trilinear
    /// filters (one run whatever `spp`); stochastic lookups use the ray's stream of sample 0.
    March {
        /// Largest step.
        step: f64,
    },
    /// Delta tracking: each sample is 0 or 1.
    Delta,
    /// Ratio tracking: each sample is the product of `1 - density / majorant` over the
    /// tentative collisions.
    Ratio,
    /// Residual ratio tracking with the segment's minorant as control density: each sample
    /// is `exp(-minorant * length)` times ratio tracking of `density - minorant` under
    /// `majorant - minorant`.
    Residual,
}

/// Which ranges bound the density for the trackers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Majorant {
    /// Local ranges: the blocks of the hierarchical walk down to mip `level` (0 = 8^3).
    Local {
        /// Finest mip level walked.
        level: usize,
    },
    /// One range for the whole box ([`global_range`]), to compare null-collision counts.
    Global,
}

/// What to compute.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransmittanceParams {
    /// The estimator.
    pub estimator: Estimator,
    /// Density per unit of lookup value; finite and `>= 0`.
    pub density_scale: f64,
    /// Samples averaged per ray by the trackers; at least 1.
    pub spp: u32,
    /// Seed of the random streams (see [`Rng`]).
    pub seed: u32,
    /// Lookup filter.
    pub filter: Filter,
    /// Local or global bounds.
    pub majorant: Majorant,
}

impl TransmittanceParams {
    /// `estimator` with scale 1, one sample, seed 0, trilinear lookups and local majorants
    /// of the 8^3 blocks.
    pub fn new(estimator: Estimator) -> TransmittanceParams {
        TransmittanceParams {
            estimator,
            density_scale: 1.0,
            spp: 1,
            seed: 0,
            filter: Filter::Trilinear,
            majorant: Majorant::Local { level: 0 },
        }
    }

    /// Errors on a step that is not finite and positive, `spp == 0`, a scale that is
    /// negative or not finite, a level `mips` lacks, or mips of another background.
    pub fn validate<G: VoxelGrid + ?Sized>(
        &self,
        grid: &G,
        mips: &RangeMips,
    ) -> Result<(), VolumeError> {
        let fail = |why: String| Err(VolumeError(format!("transmittance: {why}")));
        if let Estimator::March { step } = self.estimator {
            if !(step.is_finite() && step > 0.0) {
                return fail(format!("the march step must be finite and > 0, got {step}"));
            }
        }
        if self.spp == 0 {
            return fail("spp must be at least 1".into());
        }
        if !(self.density_scale.is_finite() && self.density_scale >= 0.0) {
            return fail(format!(
                "the density scale must be finite and >= 0, got {}",
                self.density_scale
            ));
        }
        if let Majorant::Local { level } = self.majorant {
            if level >= mips.levels.len() {
                return fail(format!(
                    "mip level {level} requested, the range mips have {} levels",
                    mips.levels.len()
                ));
            }
        }
        if mips.background.to_bits() != grid.background().to_bits() {
            return fail(format!(
                "the range mips' background {} is not the grid's {}: built for another grid?",
                mips.background,
                grid.background()
            ));
        }
        Ok(())
    }
}

/// Most density lookups one tracked sample may expect (the majorant's optical depth along
/// the ray): beyond it a run would not finish in any useful time.
pub const MAX_TRACKED_LOOKUPS: f64 = 1e7;

/// One ray's transmittance estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The estimate (the mean over the samples for the trackers).
    pub transmittance: f64,
    /// Sample variance (denominator `spp - 1`) of the per-sample values; 0 for the
    /// deterministic estimators and for one sample.
    pub variance: f64,
    /// Density lookups over all samples: tentative collisions of the trackers, march
    /// steps, quadrature nodes of `Exact` (2 per trilinear cell piece, 1 per nearest one).
    pub lookups: u64,
    /// Tentative collisions that did not end a sample: for delta tracking all but the real
    /// collisions, for ratio and residual tracking every tentative collision.
    pub null_collisions: u64,
}

/// What every ray of a batch shares.
struct Context<'a, G: ?Sized> {
    grid: &'a G,
    mips: &'a RangeMips,
    params: &'a TransmittanceParams,
    /// The range of the whole box for global majorants.
    global: Option<ValueRange>,
    /// The finest level walked for local majorants.
    level: usize,
}

/// The transmittance of `ray` (world space); `ray_index` selects its random streams.
pub fn transmittance<G: VoxelGrid + ?Sized>(
    grid: &G,
    mips: &RangeMips,
    ray: &Ray,
    ray_index: u32,
    params: &TransmittanceParams,
) -> Result<Estimate, VolumeError> {
    Context::new(grid, mips, params)?.estimate(ray, ray_index)
}

/// Transmittance over one grid prepared once for many rays given in its index space (a grid
/// placed in a scene, whose rays come through the scene's transforms).
pub struct IndexTransmittance<'a, G: ?Sized>(Context<'a, G>);

impl<'a, G: VoxelGrid + ?Sized> IndexTransmittance<'a, G> {
    /// Checks `params` against the grid (see [`TransmittanceParams::validate`]).
    pub fn new(
        grid: &'a G,
        mips: &'a RangeMips,
        params: &'a TransmittanceParams,
    ) -> Result<Self, VolumeError> {
        Context::new(grid, mips, params).map(IndexTransmittance)
    }

    /// The transmittance along `ray`; `ray_index` selects its random streams.
    pub fn estimate(&self, ray: &IndexRay, ray_index: u32) -> Result<Estimate, VolumeError> {
        self.0.estimate_index(ray, ray_index)
    }

    /// The first real collision along `ray` by delta tracking under the local (or global)
    /// majorants: free-flight distance sampling, as a path tracer needs it. `None` when the
    /// ray leaves `[tmin, tmax]` without one, which happens with probability equal to the
    /// transmittance. Errors as the trackers do on negative densities.
    pub fn collision(
        &self,
        ray: &IndexRay,
        rng: &mut Rng,
    ) -> Result<Option<Collision>, VolumeError> {
        let ctx = &self.0;
        let segments = ctx.segments(ray)?;
        ctx.check_trackable(&segments, 0)?;
        let scale = ctx.params.density_scale;
        for s in &segments {
            let (low, high) = (s.range.min as f64 * scale, s.range.max as f64 * scale);
            if high <= 0.0 {
                continue;
            }
            let mut t = s.t0;
            loop {
                t += free_flight(rng, high);
                if t >= s.t1 {
                    break;
                }
                // A constant segment collides wherever the first flight lands.
                let density = if low == high {
                    low
                } else {
                    ctx.density(ray.at(t), rng)
                };
                if low == high || rng.next_f64() * high < density {
                    return Ok(Some(Collision { t, density }));
                }
            }
        }
        Ok(None)
    }
}

/// A real collision found by [`IndexTransmittance::collision`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Collision {
    /// Where, in the ray's `t`.
    pub t: f64,
    /// The density there.
    pub density: f64,
}

/// The transmittances of `rays`, in parallel; ray `i` uses the random streams of index `i`.
pub fn transmittance_batch<G: VoxelGrid + ?Sized>(
    grid: &G,
    mips: &RangeMips,
    rays: &[Ray],
    params: &TransmittanceParams,
) -> Result<Vec<Estimate>, VolumeError> {
    if u32::try_from(rays.len()).is_err() {
        return Err(VolumeError(format!(
            "transmittance: {} rays in one batch, at most {}",
            rays.len(),
            u32::MAX
        )));
    }
    let ctx = Context::new(grid, mips, params)?;
    rays.par_iter()
        .enumerate()
        .map(|(i, ray)| ctx.estimate(ray, i as u32))
        .collect()
}

/// Optical depth of a stretch of constant density (0 for zero density, also when the
/// length is infinite).
fn constant_tau(density: f64, length: f64) -> f64 {
    if density == 0.0 {
        0.0
    } else {
        density * length
    }
}

/// A free-flight distance under majorant `mu > 0`: exponential, from a uniform in [0, 1).
fn free_flight(rng: &mut Rng, mu: f64) -> f64 {
    -(1.0 - rng.next_f64()).ln() / mu
}

/// The tracker a sample runs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Tracker {
    Delta,
    Ratio,
    Residual,
}

/// Lookup and collision counts of one ray.
#[derive(Default)]
struct Counts {
    lookups: u64,
    null_collisions: u64,
}

impl<'a, G: VoxelGrid + ?Sized> Context<'a, G> {
    fn new(
        grid: &'a G,
        mips: &'a RangeMips,
        params: &'a TransmittanceParams,
    ) -> Result<Context<'a, G>, VolumeError> {
        params.validate(grid, mips)?;
        let (global, level) = match params.majorant {
            Majorant::Local { level } => (None, level),
            Majorant::Global => (Some(global_range(mips)), 0),
        };
        Ok(Context {
            grid,
            mips,
            params,
            global,
            level,
        })
    }

    fn estimate(&self, ray: &Ray, ray_index: u32) -> Result<Estimate, VolumeError> {
        self.estimate_index(&IndexRay::from_world(ray, self.grid.map())?, ray_index)
    }

    /// The ray's segments under local or global majorants.
    fn segments(&self, ray: &IndexRay) -> Result<Vec<Segment>, VolumeError> {
        Ok(match self.global {
            Some(range) => SegmentWalk::global(self.mips, ray, range)?.collect(),
            None => SegmentWalk::new(self.mips, ray, self.level)?.collect(),
        })
    }

    fn estimate_index(&self, ray: &IndexRay, ray_index: u32) -> Result<Estimate, VolumeError> {
        let ray = *ray;
        let segments = self.segments(&ray)?;
        let deterministic = |(tau, lookups): (f64, u64)| Estimate {
            transmittance: (-tau).exp(),
            variance: 0.0,
            lookups,
            null_collisions: 0,
        };
        match self.params.estimator {
            Estimator::Exact => Ok(deterministic(self.exact_tau(&ray, &segments))),
            Estimator::March { step } => self
                .march_tau(&ray, &segments, step, ray_index)
                .map(deterministic),
            Estimator::Delta => self.track(&ray, &segments, ray_index, Tracker::Delta),
            Estimator::Ratio => self.track(&ray, &segments, ray_index, Tracker::Ratio),
            Estimator::Residual => self.track(&ray, &segments, ray_index, Tracker::Residual),
        }
    }

    /// Density at index-space point `p`; the stochastic filter draws from `rng`.
    fn density(&self, p: [f64; 3], rng: &mut Rng) -> f64 {
        let value = match self.params.filter {
            Filter::Trilinear => sample_trilinear(self.grid, p),
            Filter::Nearest => sample_nearest(self.grid, p) as f64,
            Filter::Stochastic => {
                let u = [rng.next_f64(), rng.next_f64(), rng.next_f64()];
                sample_stochastic(self.grid, p, u) as f64
            }
        };
        value * self.params.density_scale
    }

    /// Voxel `ijk`, the background beyond i32 coordinates.
    fn voxel(&self, ijk: [i64; 3]) -> f64 {
        let coord = ijk.map(i32::try_from);
        match coord {
            [Ok(x), Ok(y), Ok(z)] => self.grid.voxel([x, y, z]) as f64,
            _ => self.grid.background() as f64,
        }
    }

    /// Exact optical depth and the number of quadrature nodes.
    fn exact_tau(&self, ray: &IndexRay, segments: &[Segment]) -> (f64, u64) {
        let scale = self.params.density_scale;
        let (mut tau, mut nodes) = (0.0, 0u64);
        for s in segments {
            if s.range.min == s.range.max {
                tau += constant_tau(s.range.min as f64 * scale, s.t1 - s.t0);
                continue;
            }
            if self.params.filter == Filter::Nearest {
                for piece in CellWalk::nearest(ray, s.t0, s.t1) {
                    tau += self.voxel(piece.cell) * scale * (piece.t1 - piece.t0);
                    nodes += 1;
                }
                continue;
            }
            for piece in CellWalk::trilinear(ray, s.t0, s.t1) {
                let corners: [f64; 8] = std::array::from_fn(|c| {
                    self.voxel(std::array::from_fn(|k| piece.cell[k] + (c >> k & 1) as i64))
                });
                let half = 0.5 * (piece.t1 - piece.t0);
                // Gauss-Legendre nodes at half * (1 -+ 1/sqrt(3)) from the piece's start.
                let offset = half / 3f64.sqrt();
                let mut sum = 0.0;
                for u in [half - offset, half + offset] {
                    let f: [f64; 3] = std::array::from_fn(|k| {
                        piece.entry[k] + u * ray.dir[k] - piece.cell[k] as f64
                    });
                    sum += trilinear(&corners, f);
                }
                tau += sum * half * scale;
                nodes += 2;
            }
        }
        (tau, nodes)
    }

    /// Marched optical depth and the number of steps.
    fn march_tau(
        &self,
        ray: &IndexRay,
        segments: &[Segment],
        step: f64,
        ray_index: u32,
    ) -> Result<(f64, u64), VolumeError> {
        let scale = self.params.density_scale;
        let (mut tau, mut a, mut b) = (0.0, f64::INFINITY, f64::NEG_INFINITY);
        for s in segments {
            if s.level == LEVEL_OUTSIDE {
                tau += constant_tau(s.range.min as f64 * scale, s.t1 - s.t0);
            } else {
                (a, b) = (a.min(s.t0), b.max(s.t1));
            }
        }
        if a >= b {
            return Ok((tau, 0));
        }
        let n = ((b - a) / step).ceil().max(1.0);
        if n > u32::MAX as f64 {
            return Err(VolumeError(format!(
                "transmittance: a march step of {step} needs {n} steps over [{a}, {b}], at most {}",
                u32::MAX
            )));
        }
        let h = (b - a) / n;
        let mut rng = Rng::new(self.params.seed, ray_index, 0);
        for i in 0..n as u64 {
            tau += h * self.density(ray.at(a + (i as f64 + 0.5) * h), &mut rng);
        }
        Ok((tau, n as u64))
    }

    /// Errors when a segment may hold a negative (or NaN) density: the trackers need
    /// densities >= 0.
    fn check_trackable(&self, segments: &[Segment], ray_index: u32) -> Result<(), VolumeError> {
        let scale = self.params.density_scale;
        // The expected density lookups of one sample: the majorant's optical depth over the
        // segments whose density is not known.
        let lookups: f64 = segments
            .iter()
            .filter(|s| s.range.min != s.range.max)
            .map(|s| s.range.max as f64 * scale * (s.t1 - s.t0))
            .sum();
        if lookups > MAX_TRACKED_LOOKUPS {
            return Err(VolumeError(format!(
                "transmittance: the majorant's optical depth along ray {ray_index} is {lookups:.3e} \
                 (density scale {scale:e}): tracking would look the density up that many times \
                 per sample, more than {MAX_TRACKED_LOOKUPS:e}; use the exact estimator or a \
                 smaller density scale"
            )));
        }
        for s in segments {
            let low = s.range.min as f64 * scale;
            if low < 0.0 || s.range.min.is_nan() || s.range.max.is_nan() {
                return Err(VolumeError(format!(
                    "transmittance: values down to {} (range {:?}) on [{}, {}] of ray {ray_index}; \
                     delta, ratio and residual tracking need a density >= 0",
                    s.range.min, s.range, s.t0, s.t1
                )));
            }
        }
        Ok(())
    }

    /// The mean and sample variance over `spp` tracked samples.
    fn track(
        &self,
        ray: &IndexRay,
        segments: &[Segment],
        ray_index: u32,
        tracker: Tracker,
    ) -> Result<Estimate, VolumeError> {
        self.check_trackable(segments, ray_index)?;
        let mut counts = Counts::default();
        // Welford's running mean and sum of squared deviations.
        let (mut mean, mut m2) = (0.0, 0.0);
        for sample in 0..self.params.spp {
            let mut rng = Rng::new(self.params.seed, ray_index, sample);
            let x = self.track_sample(ray, segments, &mut rng, tracker, &mut counts);
            let delta = x - mean;
            mean += delta / (sample + 1) as f64;
            m2 += delta * (x - mean);
        }
        let n = self.params.spp as f64;
        Ok(Estimate {
            transmittance: mean,
            variance: if n > 1.0 { m2 / (n - 1.0) } else { 0.0 },
            lookups: counts.lookups,
            null_collisions: counts.null_collisions,
        })
    }

    /// One tracked sample of the transmittance.
    fn track_sample(
        &self,
        ray: &IndexRay,
        segments: &[Segment],
        rng: &mut Rng,
        tracker: Tracker,
        counts: &mut Counts,
    ) -> f64 {
        let scale = self.params.density_scale;
        let mut weight = 1.0;
        for s in segments {
            let (low, high) = (s.range.min as f64 * scale, s.range.max as f64 * scale);
            let length = s.t1 - s.t0;
            if low == high {
                // Known density, no lookups.
                if tracker == Tracker::Delta {
                    if low > 0.0 && free_flight(rng, low) < length {
                        return 0.0;
                    }
                } else {
                    weight *= (-constant_tau(low, length)).exp();
                }
                continue;
            }
            // Ratio tracking of density - control under majorant - control.
            let control = if tracker == Tracker::Residual {
                low
            } else {
                0.0
            };
            weight *= (-constant_tau(control, length)).exp();
            let mu = high - control;
            let mut t = s.t0;
            loop {
                t += free_flight(rng, mu);
                if t >= s.t1 {
                    break;
                }
                counts.lookups += 1;
                let density = self.density(ray.at(t), rng);
                if tracker == Tracker::Delta {
                    if rng.next_f64() * mu < density {
                        return 0.0;
                    }
                } else {
                    weight *= 1.0 - (density - control) / mu;
                }
                counts.null_collisions += 1;
            }
            if weight == 0.0 {
                break;
            }
        }
        weight
    }
}

/// Trilinear blend of `corners` (index `x + 2y + 4z`) at fractions `f` within the cell.
fn trilinear(corners: &[f64; 8], f: [f64; 3]) -> f64 {
    let lerp = |a: f64, b: f64, w: f64| a + (b - a) * w;
    let x: [f64; 4] = std::array::from_fn(|i| lerp(corners[2 * i], corners[2 * i + 1], f[0]));
    let y = [lerp(x[0], x[1], f[1]), lerp(x[2], x[3], f[1])];
    lerp(y[0], y[1], f[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DenseGrid;

    #[test]
    fn cell_polynomial_is_the_trilinear_lookup() {
        let mut g = DenseGrid::new([0; 3], [2, 2, 2], 0.0).unwrap();
        for (i, v) in g.values.iter_mut().enumerate() {
            *v = (i * i) as f32 - 3.0;
        }
        let corners: [f64; 8] = std::array::from_fn(|i| g.values[i] as f64);
        for f in [[0.0; 3], [1.0; 3], [0.25, 0.5, 0.75], [0.9, 0.1, 0.3]] {
            assert!((trilinear(&corners, f) - sample_trilinear(&g, f)).abs() < 1e-12);
        }
    }

    #[test]
    fn zero_density_over_infinite_length_is_transparent() {
        assert_eq!(constant_tau(0.0, f64::INFINITY), 0.0);
        assert_eq!(constant_tau(0.5, f64::INFINITY), f64::INFINITY);
        assert_eq!(constant_tau(0.5, 4.0), 2.0);
    }
}
