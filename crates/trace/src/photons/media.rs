//! A scene's sparse volumes as media for photons: absorbing and scattering clouds of a
//! grid's density (a `.toml` scene's `[volumes.NAME]`, its Foundry medium record).
//!
//! Inside a medium the extinction is `density_scale * grid value` per mm, gray (the same at
//! every wavelength). Each step the distance to the first real collision with the media
//! along the photon's path is drawn by delta tracking under the media's stored local
//! majorants (the volume crate's tracker, through
//! [`crate::cpu::media::SceneMedia::collision`]), over the step the material's bulk
//! processes and the next boundary leave: the nearest of them happens. At a collision the photon is absorbed with probability `1 - albedo` (label
//! AB), else scattered (label SC) into a direction drawn from the Henyey-Greenstein phase
//! function of the medium's `g`, its polarization the old one projected onto the plane
//! perpendicular to the new direction (as Geant4's Mie scattering, G4OpMieHG, carries it),
//! or a random one perpendicular to it where the old one lies along the new direction.

use glam::DVec3;
use hytrace_csg::Real;
use hytrace_foundry::Foundry;
use hytrace_volume::{global_range, Estimator, Rng, TransmittanceParams};

use super::bulk::rotate_uz;
use super::tracer::PhotonTracer;
use super::{PhotonError, V};
use crate::cpu::media::OpenMedia;
use crate::cpu::CpuScene;
use crate::render::optics::sample_henyey_greenstein;

/// Most majorant optical depth across a medium's bounds: delta tracking looks the density up
/// about that many times crossing it (as the volume crate's trackers bound a sample).
const MAX_OPTICAL_DEPTH: f64 = hytrace_volume::MAX_TRACKED_LOOKUPS;

/// What a collision with a medium does to a photon.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scattering {
    /// Chance that a collision scatters (else it absorbs), in [0, 1].
    pub albedo: f64,
    /// Henyey-Greenstein asymmetry, in (-1, 1).
    pub g: f64,
}

/// A real collision on a photon's step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumHit {
    /// Distance along the step (mm).
    pub t: f64,
    /// The medium's scattering.
    pub scattering: Scattering,
}

/// The scene's media opened for photons.
pub struct PhotonMedia {
    open: OpenMedia,
    scattering: Vec<Scattering>,
    /// Each medium's source and density scale, for `--explain`.
    described: Vec<String>,
}

impl PhotonMedia {
    /// Opens the media of `f` on the scene `tracer` navigates (`None` without placed
    /// media), each medium read as stored in a brick store holding at most `memory` bytes
    /// resident (its tables and a cache of bricks read on demand).
    /// Errors name the medium and its source: a grid that cannot be opened (a `memory` too
    /// small for a store among them), a density below zero (delta tracking needs `>= 0`),
    /// or a medium so dense that tracking across it would take more than 10^7 density
    /// lookups.
    pub fn new(
        f: &Foundry,
        tracer: &PhotonTracer,
        memory: u64,
    ) -> Result<Option<Self>, PhotonError> {
        if f.optics.media.is_empty() {
            return Ok(None);
        }
        let (open, placed) = match tracer {
            PhotonTracer::F64(s) => opened(s, f, memory)?,
            PhotonTracer::F32(s) => opened(s, f, memory)?,
        };
        // Media no instance places are never met.
        if !placed {
            return Ok(None);
        }
        let scattering = f
            .optics
            .media
            .iter()
            .map(|m| Scattering {
                albedo: m.albedo,
                g: m.g,
            })
            .collect();
        let described = f
            .optics
            .media
            .iter()
            .map(|m| format!("`{}` x {} /mm", m.source, m.density_scale))
            .collect();
        Ok(Some(PhotonMedia {
            open,
            scattering,
            described,
        }))
    }

    /// The first real collision of the photon at `pos` going `dir` with the media within
    /// `step` mm, drawn from `rng` by delta tracking.
    pub fn collision(
        &self,
        tracer: &PhotonTracer,
        pos: V,
        dir: V,
        step: f64,
        rng: &mut Rng,
    ) -> Option<MediumHit> {
        let (o, d) = (pos.to_f64(), dir.to_f64());
        let found = match tracer {
            PhotonTracer::F64(s) => self.open.on(s).collision(o, d, 0.0, step, rng),
            PhotonTracer::F32(s) => self.open.on(s).collision(o, d, 0.0, step, rng),
        };
        // `new` refused what the tracker refuses (negative densities, too many lookups).
        let found = found.expect("media checked when opened for photons");
        found.map(|c| MediumHit {
            t: c.t,
            scattering: self.scattering[c.medium as usize],
        })
    }

    /// The media opened, to answer queries on the scene they were opened for (the GPU
    /// kernel's upload reads their grids and placements).
    pub(crate) fn open(&self) -> &OpenMedia {
        &self.open
    }

    /// Each medium's scattering, in the Foundry's order.
    pub fn scattering(&self) -> &[Scattering] {
        &self.scattering
    }

    /// An error naming the store when a medium read as stored could not read a brick since
    /// it was opened: those lookups read the background, so the photons propagated
    /// meanwhile went through a wrong medium and must not be written.
    pub fn check_reads(&self, tracer: &PhotonTracer) -> Result<(), PhotonError> {
        let checked = match tracer {
            PhotonTracer::F64(s) => self.open.on(s).check_reads(),
            PhotonTracer::F32(s) => self.open.on(s).check_reads(),
        };
        checked.map_err(|e| PhotonError::Scene(crate::error::report(&e)))
    }

    /// Each medium's source, extinction scale and scattering, for `--explain`.
    pub fn describe(&self) -> impl Iterator<Item = String> + '_ {
        self.described
            .iter()
            .zip(&self.scattering)
            .map(|(d, s)| format!("{d}, albedo {}, g {}", s.albedo, s.g))
    }
}

/// The media of `f` opened on `scene` and checked for delta tracking (see
/// [`PhotonMedia::new`]), and whether any is placed.
fn opened<T: Real>(
    scene: &CpuScene<T>,
    f: &Foundry,
    memory: u64,
) -> Result<(OpenMedia, bool), PhotonError> {
    let params = TransmittanceParams::new(Estimator::Delta);
    let open = OpenMedia::open(scene, f, &params, memory)
        .map_err(|e| PhotonError::Scene(crate::error::report(&e)))?;
    let media = open.on(scene);
    let placements: Vec<(u32, u32)> = media.placements().map(|(k, _)| k).collect();
    for (i, m) in f.optics.media.iter().enumerate() {
        let range = global_range(media.grid(i as u32).ranges());
        let name = format!("medium {i} ({})", m.source);
        if range.min < 0.0 || range.min.is_nan() || range.max.is_nan() {
            return Err(PhotonError::Scene(format!(
                "{name}: grid values down to {}: a medium's density must be >= 0",
                range.min
            )));
        }
        // The majorant's optical depth along the longest line through each placement.
        for &(instance, _) in placements.iter().filter(|(_, k)| *k == i as u32) {
            let [lo, hi] = scene.instance_bounds(instance as usize);
            let diagonal = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
            let depth = f64::from(range.max) * m.density_scale * diagonal;
            if depth > MAX_OPTICAL_DEPTH {
                return Err(PhotonError::Scene(format!(
                    "{name}: a majorant optical depth of {depth:.3e} across its {diagonal:.4} mm: \
                     tracking photons through it would look its density up more than \
                     {MAX_OPTICAL_DEPTH:e} times; lower its density scale"
                )));
            }
        }
    }
    let placed = !placements.is_empty();
    Ok((open, placed))
}

/// A collision with a medium of `scattering`: `None` when it absorbs the photon, else its
/// new direction and polarization.
pub fn collide(scattering: Scattering, dir: V, pol: V, rng: &mut Rng) -> Option<(V, V)> {
    if rng.next_f64() >= scattering.albedo {
        return None;
    }
    let u = [rng.next_f64(), rng.next_f64()];
    let new = sample_henyey_greenstein(DVec3::from(dir.to_f64()), scattering.g, u);
    let new_dir = V::from_f64(new.to_array()).normalized();
    let projected = pol - new_dir * new_dir.dot(pol);
    let new_pol = if projected.length() > 1e-9 {
        projected.normalized()
    } else {
        let a = std::f64::consts::TAU * rng.next_f64();
        rotate_uz(V::new(a.cos(), a.sin(), 0.0), new_dir).normalized()
    };
    Some((new_dir, new_pol))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::output::chi2_survival;

    /// Scattering angles against the Henyey-Greenstein CDF by a chi2 over 20 bins of the
    /// cosine (and isotropic angles rejected), polarizations perpendicular to the new
    /// directions, and absorption at the rate `1 - albedo`.
    #[test]
    fn collisions_scatter_as_henyey_greenstein_and_absorb_one_minus_albedo() {
        let (g, albedo) = (0.7, 0.6);
        let s = Scattering { albedo, g };
        let mut rng = Rng::new(3, 0, 0);
        let (dir, pol) = (V::new(0.0, 0.6, 0.8), V::new(1.0, 0.0, 0.0));
        let n = 100_000;
        let bins = 20;
        let (mut counts, mut absorbed) = (vec![0u64; bins], 0u64);
        for _ in 0..n {
            let Some((d, p)) = collide(s, dir, pol, &mut rng) else {
                absorbed += 1;
                continue;
            };
            assert!(d.dot(p).abs() < 1e-9 && (p.length() - 1.0).abs() < 1e-9);
            let c = d.dot(dir);
            counts[(((c + 1.0) / 2.0 * bins as f64) as usize).min(bins - 1)] += 1;
        }
        let sigma = (albedo * (1.0 - albedo) / n as f64).sqrt();
        let got = absorbed as f64 / n as f64;
        assert!((got - (1.0 - albedo)).abs() < 4.0 * sigma, "absorbed {got}");
        let scattered: u64 = counts.iter().sum();
        // The HG CDF in cos: (1 - g^2) / (2 g) (1 / sqrt(1 + g^2 - 2 g c) - 1 / (1 + g)).
        let cdf = |c: f64| {
            (1.0 - g * g) / (2.0 * g) * (1.0 / (1.0 + g * g - 2.0 * g * c).sqrt() - 1.0 / (1.0 + g))
        };
        let chi2 = |expected: &dyn Fn(f64, f64) -> f64| {
            let mut chi2 = 0.0;
            for (k, &count) in counts.iter().enumerate() {
                let a = -1.0 + 2.0 * k as f64 / bins as f64;
                let b = a + 2.0 / bins as f64;
                let e = scattered as f64 * expected(a, b);
                chi2 += (count as f64 - e).powi(2) / e;
            }
            chi2_survival(chi2, (bins - 1) as f64)
        };
        assert!((cdf(1.0) - 1.0).abs() < 1e-12 && cdf(-1.0).abs() < 1e-12);
        let p = chi2(&|a, b| cdf(b) - cdf(a));
        assert!(p > 1e-3, "HG: p {p}");
        assert!(chi2(&|a, b| (b - a) / 2.0) < 1e-6, "isotropic not rejected");
    }
}
