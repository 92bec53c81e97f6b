//! The media along a ray, as the renderer needs them: the emission-absorption integral and
//! the first real collision (delta tracking), over every placed medium the ray crosses.

use crate::error::Context;
use glam::DVec3;
use hytrace_volume::{global_range, sample_trilinear, IndexRay, Rng, SegmentWalk, LEVEL_GLOBAL};

use super::spec::MediumOptics;
use crate::cpu::media::SceneMedia;

/// A real collision in a medium.
pub struct MediumEvent {
    /// Where along the ray.
    pub t: f64,
    /// The medium's optical properties.
    pub optics: MediumOptics,
    /// The grid value there (density over the medium's density scale).
    pub value: f64,
}

/// The placed media of a scene with their optical properties.
pub struct Media<'a> {
    /// Segments, grids and transmittance of the scene's media.
    pub scene: SceneMedia<'a, f32>,
    /// Optical properties per medium (index into the Foundry's `optics.media`).
    pub optics: Vec<MediumOptics>,
    /// Emission-absorption march step in voxels.
    pub step: f64,
    /// Emission-absorption: shadow rays take the march's transmittance.
    pub march: bool,
}

impl Media<'_> {
    /// Emitted radiance reaching the origin from the media over `[t0, t1]` of the ray and
    /// their transmittance, by midpoint compositing over the ray's part inside each
    /// medium's range-mips box (the GPU kernel marches the same points), in steps of `step`
    /// voxels of the finest medium: each step of extinction `sigma` and source `j` adds
    /// `T * j / sigma * (1 - exp(-sigma h))` and multiplies `T` by `exp(-sigma h)`
    /// (exact for piecewise-constant media; the error falls as the step squared).
    /// Overlapping media add their extinctions and sources.
    pub fn emission_absorption(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
    ) -> crate::Result<(DVec3, f64)> {
        let segments = self
            .scene
            .segments(origin.into(), dir.into(), t0, t1)
            .context("emission-absorption")?;
        if segments.is_empty() {
            return Ok((DVec3::ZERO, 1.0));
        }
        // Each medium's part: the ray over [t0, t1] inside its range mips' box (where its
        // values can differ from the zero background), as the GPU's walk finds it.
        let mut spans = Vec::with_capacity(segments.len());
        for s in &segments {
            let full = IndexRay::new(s.ray.origin, s.ray.dir, t0, t1)?;
            let mips = self.scene.grid(s.medium).ranges();
            let inside = SegmentWalk::global(mips, &full, global_range(mips))?
                .find(|piece| piece.level == LEVEL_GLOBAL);
            spans.push(inside.map(|piece| (piece.t0, piece.t1)));
        }
        let (mut a, mut b, mut h) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
        for (s, span) in segments.iter().zip(&spans) {
            let Some((s0, s1)) = *span else { continue };
            a = a.min(s0);
            b = b.max(s1);
            let voxels_per_t = DVec3::from(s.ray.dir).length();
            h = h.min(self.step / voxels_per_t);
        }
        if a >= b {
            return Ok((DVec3::ZERO, 1.0));
        }
        let n = ((b - a) / h).ceil().max(1.0);
        crate::error::ensure!(
            n <= 1e8,
            "emission-absorption: {n} steps of {h} over [{a}, {b}]: the step is too small"
        );
        let h = (b - a) / n;
        let (mut radiance, mut transmittance) = (DVec3::ZERO, 1.0);
        for k in 0..n as u64 {
            let t = a + (k as f64 + 0.5) * h;
            let (mut sigma, mut source) = (0.0, DVec3::ZERO);
            for (s, span) in segments.iter().zip(&spans) {
                match span {
                    Some((s0, s1)) if (*s0..=*s1).contains(&t) => {}
                    _ => continue,
                }
                // Trilinear lookups, as the GPU's march reads the grid.
                let value = sample_trilinear(self.scene.grid(s.medium), s.ray.at(t));
                let density = value * self.scene.params(s.medium, s.placement).density_scale;
                sigma += density;
                source += density * value * DVec3::from(self.optics[s.medium as usize].emission);
            }
            if sigma <= 0.0 {
                continue;
            }
            let step_t = (-sigma * h).exp();
            radiance += transmittance * source / sigma * (1.0 - step_t);
            transmittance *= step_t;
        }
        Ok((radiance, transmittance))
    }

    /// The first real collision with any medium over `[t0, t1]` of the ray, by delta
    /// tracking ([`SceneMedia::collision`]).
    pub fn collision(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        rng: &mut Rng,
    ) -> crate::Result<Option<MediumEvent>> {
        let found = self
            .scene
            .collision(origin.into(), dir.into(), t0, t1, rng)?;
        Ok(found.map(|c| MediumEvent {
            t: c.t,
            optics: self.optics[c.medium as usize],
            value: c.density
                / self
                    .scene
                    .params(c.medium, 0)
                    .density_scale
                    .max(f64::MIN_POSITIVE),
        }))
    }

    /// Transmittance of the media over `[t0, t1]` of the ray: the emission-absorption
    /// march's own when `march` (so shadow rays see the media the camera sees), else by the
    /// estimator the media were opened with (ratio tracking) on a stream drawn from `rng`.
    pub fn transmittance(
        &self,
        origin: DVec3,
        dir: DVec3,
        t0: f64,
        t1: f64,
        rng: &mut Rng,
    ) -> crate::Result<f64> {
        if t1 <= t0 {
            return Ok(1.0);
        }
        if self.march {
            return Ok(self.emission_absorption(origin, dir, t0, t1)?.1);
        }
        Ok(self
            .scene
            .transmittance_to(origin.into(), dir.into(), t0, t1, rng.next_u32())?
            .0)
    }
}
