//! Bulk processes: absorption and Rayleigh scattering (Geant4's G4OpAbsorption and
//! G4OpRayleigh).
//!
//! Both are exponential in path length with their material's mean free path (ABSLENGTH,
//! RAYLEIGH) at the photon's energy. Since exponential distances have no memory, drawing a
//! fresh distance at every step (here) and carrying the remaining number of mean free
//! paths across steps (Geant4) give the same distribution.

use hytrace_volume::Rng;

use super::V;

/// A distance to the next interaction with mean free path `mean` (mm; infinite: never),
/// from a uniform `u` in [0, 1).
pub fn sample_distance(mean: f64, u: f64) -> f64 {
    if mean.is_finite() {
        -mean * (1.0 - u).ln()
    } else {
        f64::INFINITY
    }
}

/// `v` given in the frame whose z axis is the unit vector `axis`, in the world frame
/// (CLHEP's `rotateUz`).
pub fn rotate_uz(v: V, axis: V) -> V {
    let perp2 = axis.x * axis.x + axis.y * axis.y;
    if perp2 > 0.0 {
        let perp = perp2.sqrt();
        V::new(
            (axis.x * axis.z * v.x - axis.y * v.y) / perp + axis.x * v.z,
            (axis.y * axis.z * v.x + axis.x * v.y) / perp + axis.y * v.z,
            -perp * v.x + axis.z * v.z,
        )
    } else if axis.z >= 0.0 {
        v
    } else {
        V::new(-v.x, v.y, -v.z)
    }
}

/// A direction uniform over the sphere and a polarization uniform among those
/// perpendicular to it (Geant4's draw for scintillation and re-emitted photons).
pub fn isotropic(rng: &mut Rng) -> (V, V) {
    let cos = 1.0 - 2.0 * rng.next_f64();
    let sin = ((1.0 - cos) * (1.0 + cos)).sqrt();
    let phi = std::f64::consts::TAU * rng.next_f64();
    let dir = V::new(sin * phi.cos(), sin * phi.sin(), cos);
    let a = std::f64::consts::TAU * rng.next_f64();
    (
        dir,
        rotate_uz(V::new(a.cos(), a.sin(), 0.0), dir).normalized(),
    )
}

/// Rayleigh scattering of a linearly polarized photon: new direction and polarization,
/// drawn as Geant4 draws them. A direction uniform over the sphere and one of the two
/// polarizations perpendicular to it, in the plane of the new direction and the old
/// polarization, are accepted with probability `cos^2` of the angle between the old and
/// new polarizations (the dipole pattern `1 - (e . k')^2`; averaged over polarizations,
/// `1 + cos^2` of the scattering angle).
pub fn rayleigh_scatter(dir: V, pol: V, rng: &mut Rng) -> (V, V) {
    loop {
        let mut cos_t = rng.next_f64();
        let sin_t = (1.0 - cos_t * cos_t).sqrt();
        if rng.next_f64() < 0.5 {
            cos_t = -cos_t;
        }
        let phi = std::f64::consts::TAU * rng.next_f64();
        let local = V::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
        let new_dir = rotate_uz(local, dir).normalized();
        let projected = pol - new_dir * new_dir.dot(pol);
        let new_pol = if projected.length() == 0.0 {
            let a = std::f64::consts::TAU * rng.next_f64();
            rotate_uz(V::new(a.cos(), a.sin(), 0.0), new_dir)
        } else {
            let e = projected.normalized();
            if rng.next_f64() < 0.5 {
                -e
            } else {
                e
            }
        };
        let c = new_pol.dot(pol);
        if c * c >= rng.next_f64() {
            return (new_dir, new_pol);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photons::output::chi2_survival;

    #[test]
    fn absorbed_fraction_before_d_follows_beer_lambert() {
        let mean = 250.0;
        let n = 100_000;
        let mut rng = Rng::new(5, 0, 0);
        let draws: Vec<f64> = (0..n)
            .map(|_| sample_distance(mean, rng.next_f64()))
            .collect();
        for d in [10.0, 100.0, 250.0, 600.0] {
            let expected = 1.0 - (-d / mean).exp();
            let got = draws.iter().filter(|&&x| x < d).count() as f64 / n as f64;
            let sigma = (expected * (1.0 - expected) / n as f64).sqrt();
            assert!(
                (got - expected).abs() < 4.0 * sigma,
                "d {d}: {got} vs {expected}"
            );
        }
        assert_eq!(sample_distance(f64::INFINITY, 0.3), f64::INFINITY);
    }

    #[test]
    fn rotate_uz_takes_z_to_the_axis_and_keeps_lengths() {
        for axis in [
            V::new(0.0, 0.0, 1.0),
            V::new(0.0, 0.0, -1.0),
            V::new(0.6, 0.0, 0.8),
            V::new(-0.3, 0.5, -0.2).normalized(),
        ] {
            assert!((rotate_uz(V::new(0.0, 0.0, 1.0), axis) - axis).length() < 1e-12);
            let w = rotate_uz(V::new(1.0, 0.0, 0.0), axis);
            assert!(w.dot(axis).abs() < 1e-12 && (w.length() - 1.0).abs() < 1e-12);
        }
    }

    /// Unpolarized light (polarization random about the direction) scatters with angular
    /// density proportional to 1 + cos^2: a chi2 test over 20 bins of cos(theta).
    #[test]
    fn unpolarized_rayleigh_angles_follow_one_plus_cos_squared() {
        let n = 200_000;
        let bins = 20;
        let mut counts = vec![0u64; bins];
        let mut rng = Rng::new(11, 0, 0);
        let dir = V::new(0.0, 0.0, 1.0);
        for _ in 0..n {
            let a = std::f64::consts::TAU * rng.next_f64();
            let pol = V::new(a.cos(), a.sin(), 0.0);
            let (d, p) = rayleigh_scatter(dir, pol, &mut rng);
            assert!(d.dot(p).abs() < 1e-9);
            let c = d.dot(dir);
            counts[(((c + 1.0) / 2.0 * bins as f64) as usize).min(bins - 1)] += 1;
        }
        // Probability of each bin: integral of (3/8)(1 + c^2) over it.
        let cdf = |c: f64| 3.0 / 8.0 * (c + c * c * c / 3.0);
        let mut chi2 = 0.0;
        for (k, &count) in counts.iter().enumerate() {
            let (a, b) = (
                -1.0 + 2.0 * k as f64 / bins as f64,
                -1.0 + 2.0 * (k + 1) as f64 / bins as f64,
            );
            let expected = n as f64 * (cdf(b) - cdf(a));
            chi2 += (count as f64 - expected).powi(2) / expected;
        }
        let p = chi2_survival(chi2, (bins - 1) as f64);
        assert!(
            p > 1e-3,
            "chi2 {chi2} for {} degrees of freedom: p {p}",
            bins - 1
        );
        // And a flat distribution fails the same test (the test can fail).
        let flat = n as f64 / bins as f64;
        let chi2_flat: f64 = counts
            .iter()
            .map(|&c| (c as f64 - flat).powi(2) / flat)
            .sum();
        assert!(chi2_survival(chi2_flat, (bins - 1) as f64) < 1e-6);
    }

    /// Polarized light: the dipole pattern, no scattering along the polarization.
    #[test]
    fn polarized_rayleigh_avoids_the_polarization_axis() {
        let mut rng = Rng::new(12, 0, 0);
        let (dir, pol) = (V::new(0.0, 0.0, 1.0), V::new(1.0, 0.0, 0.0));
        let n = 100_000;
        // <(e . k')^2> for density (1 - (e.k')^2): integral gives 1/5.
        let mean: f64 = (0..n)
            .map(|_| rayleigh_scatter(dir, pol, &mut rng).0.dot(pol).powi(2))
            .sum::<f64>()
            / n as f64;
        assert!((mean - 0.2).abs() < 0.005, "{mean}");
    }
}
