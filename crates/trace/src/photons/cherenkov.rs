//! Cherenkov light as Geant4 11's G4Cerenkov emits it along a charged particle's step.
//!
//! A particle of speed `beta c` in a material of refractive index `n(E)` radiates at the
//! photon energies where `beta n > 1`, on the cone `cos theta = 1 / (beta n)` about its
//! direction, with a number of photons per unit energy proportional to
//! `sin^2 theta = 1 - 1 / (beta n)^2`. G4Cerenkov draws the energy uniformly between the
//! first and last energies of RINDEX and accepts it with `sin^2 theta` over its largest
//! value (at the largest index), draws the azimuth uniformly, and polarizes the photon in
//! the plane of the cone (the plane of the particle's and the photon's directions).

use hytrace_foundry::optics::Material;
use hytrace_volume::Rng;

use super::bulk::rotate_uz;
use super::properties::{property, Property};
use super::{PhotonError, V};

/// Subintervals per row interval of RINDEX in [`Cherenkov::relative_yield`]'s integral.
const YIELD_STEPS: usize = 64;

/// A material's Cherenkov emission: its RINDEX.
#[derive(Clone, Debug)]
pub struct Cherenkov {
    rindex: Property,
}

impl Cherenkov {
    /// The Cherenkov emission of material `m`, which needs RINDEX.
    pub fn new(m: &Material) -> Result<Cherenkov, PhotonError> {
        let owner = format!("material `{}`", m.name);
        match property(&m.properties, "RINDEX", &owner)? {
            Some(rindex) => Ok(Cherenkov { rindex }),
            None => Err(PhotonError::Input(format!(
                "{owner} has no RINDEX: it emits no Cherenkov light"
            ))),
        }
    }

    /// The largest refractive index: a particle radiates when `beta` times it exceeds 1.
    pub fn max_index(&self) -> f64 {
        self.rindex.max_value()
    }

    /// The number of photons per unit length at speed `beta`, up to a constant factor
    /// (the charge squared and the fine-structure constant): `integral of
    /// max(0, 1 - 1 / (beta n(E))^2) dE` over RINDEX's energies (MeV).
    pub fn relative_yield(&self, beta: f64) -> f64 {
        let es = self.rindex.energies();
        let sin2 = |e: f64| {
            let c = 1.0 / (beta * self.rindex.value(e));
            ((1.0 - c) * (1.0 + c)).max(0.0)
        };
        // Midpoint rule on each row interval (the index is linear there).
        es.windows(2)
            .map(|w| {
                let h = (w[1] - w[0]) / YIELD_STEPS as f64;
                (0..YIELD_STEPS)
                    .map(|i| sin2(w[0] + (i as f64 + 0.5) * h) * h)
                    .sum::<f64>()
            })
            .sum()
    }

    /// One photon of a particle of speed `beta` (above threshold: `beta *
    /// max_index() > 1`) moving along the unit vector `axis`: its direction, polarization
    /// and energy (MeV).
    pub fn sample(&self, beta: f64, axis: V, rng: &mut Rng) -> (V, V, f64) {
        let es = self.rindex.energies();
        let (pmin, pmax) = (es[0], es[es.len() - 1]);
        let max_cos = 1.0 / (beta * self.max_index());
        let max_sin2 = (1.0 - max_cos) * (1.0 + max_cos);
        let (energy, cos, sin2) = loop {
            let e = pmin + rng.next_f64() * (pmax - pmin);
            let cos = 1.0 / (beta * self.rindex.value(e));
            let sin2 = (1.0 - cos) * (1.0 + cos);
            if rng.next_f64() * max_sin2 <= sin2 {
                break (e, cos, sin2);
            }
        };
        let sin = sin2.sqrt();
        let phi = std::f64::consts::TAU * rng.next_f64();
        let (sp, cp) = phi.sin_cos();
        let dir = rotate_uz(V::new(sin * cp, sin * sp, cos), axis);
        let pol = rotate_uz(V::new(cos * cp, cos * sp, -sin), axis);
        (dir.normalized(), pol.normalized(), energy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::output::chi2_survival;
    use hytrace_foundry::optics::Table;

    /// Water-like: n from 1.33 at 2 eV to 1.36 at 3.5 eV (MeV energies).
    fn water() -> Cherenkov {
        Cherenkov::new(&Material {
            name: "Water".into(),
            properties: vec![(
                "RINDEX".into(),
                Table {
                    columns: 2,
                    values: vec![2.0e-6, 1.33, 2.75e-6, 1.345, 3.5e-6, 1.36],
                },
            )],
        })
        .unwrap()
    }

    #[test]
    fn photons_lie_on_the_cone_with_the_spectrum_sin2_theta_says() {
        let c = water();
        let axis = V::new(0.3, -0.4, 0.5).normalized();
        // Near threshold (1 / 1.36 = 0.735) the spectrum varies strongly with energy.
        let beta = 0.75;
        let mut rng = Rng::new(11, 0, 0);
        let bins = 15;
        let (lo, hi) = (2.0e-6, 3.5e-6);
        let mut counts = vec![0u64; bins];
        let n = 60_000;
        for _ in 0..n {
            let (dir, pol, e) = c.sample(beta, axis, &mut rng);
            // The cone, exactly: cos theta = 1 / (beta n(E)).
            let want = 1.0 / (beta * c.rindex.value(e));
            assert!(
                (dir.dot(axis) - want).abs() < 1e-12,
                "{} {want}",
                dir.dot(axis)
            );
            // Polarization transverse, in the plane of the axis and the direction.
            assert!(dir.dot(pol).abs() < 1e-12 && (pol.length() - 1.0).abs() < 1e-12);
            assert!(pol.dot(axis.cross(dir)).abs() < 1e-12);
            counts[(((e - lo) / (hi - lo)) * bins as f64).min(bins as f64 - 1.0) as usize] += 1;
        }
        // Expected counts: the integral of sin^2 theta over each bin (fine midpoint sums).
        let sin2 = |e: f64| {
            let k = 1.0 / (beta * c.rindex.value(e));
            (1.0 - k * k).max(0.0)
        };
        let weights: Vec<f64> = (0..bins)
            .map(|b| {
                let w = (hi - lo) / bins as f64;
                (0..200)
                    .map(|i| sin2(lo + w * (b as f64 + (i as f64 + 0.5) / 200.0)))
                    .sum::<f64>()
            })
            .collect();
        let total: f64 = weights.iter().sum();
        // Bins expecting under 5 photons (below threshold: none) must be (nearly) empty.
        let mut ndf = -1.0;
        let mut chi2 = 0.0;
        for (&k, w) in counts.iter().zip(&weights) {
            let e = w / total * n as f64;
            if e < 5.0 {
                assert!(k < 20, "{k} photons where {e} are expected");
                continue;
            }
            chi2 += (k as f64 - e).powi(2) / e;
            ndf += 1.0;
        }
        assert!(counts[0] == 0 && ndf >= 12.0);
        let p = chi2_survival(chi2, ndf);
        assert!(p > 1e-3, "chi2 {chi2} p {p} {counts:?}");
        // A flat spectrum is rejected.
        let flat: f64 = counts
            .iter()
            .map(|&k| (k as f64 - n as f64 / bins as f64).powi(2) / (n as f64 / bins as f64))
            .sum();
        assert!(chi2_survival(flat, (bins - 1) as f64) < 1e-6);
    }

    #[test]
    fn the_yield_follows_the_frank_tamm_integral() {
        // Constant n: the integral is (1 - 1 / (beta n)^2) times the energy range.
        let c = Cherenkov::new(&Material {
            name: "Glass".into(),
            properties: vec![(
                "RINDEX".into(),
                Table {
                    columns: 2,
                    values: vec![2.0e-6, 1.5, 4.0e-6, 1.5],
                },
            )],
        })
        .unwrap();
        for beta in [0.7, 0.9, 1.0] {
            let want = (1.0 - 1.0 / (beta * 1.5f64).powi(2)) * 2.0e-6;
            assert!((c.relative_yield(beta) - want).abs() < 1e-15 * 1e3);
        }
        assert_eq!(c.relative_yield(0.6), 0.0);
        assert!(water().relative_yield(0.74) < water().relative_yield(0.8));
    }
}
