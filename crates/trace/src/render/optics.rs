//! The scattering functions the renderer samples: Fresnel reflection and refraction at
//! smooth dielectrics, Lambertian (cosine) directions and the Henyey-Greenstein phase
//! function.

use std::f64::consts::PI;

use glam::DVec3;

/// Unpolarized Fresnel reflectance of a smooth interface for light arriving at `cos_i`
/// (cosine to the normal on its side, in [0, 1]) when `eta` is the index ratio
/// `n_transmitted / n_incident`; 1 under total internal reflection.
pub fn fresnel(cos_i: f64, eta: f64) -> f64 {
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// Mirror reflection of direction `d` about the unit normal `n`.
pub fn reflect(d: DVec3, n: DVec3) -> DVec3 {
    d - 2.0 * d.dot(n) * n
}

/// The refracted direction of `d` through a surface with unit normal `n` facing the
/// incident side (`d . n < 0`), index ratio `eta = n_transmitted / n_incident`; `None`
/// under total internal reflection.
pub fn refract(d: DVec3, n: DVec3, eta: f64) -> Option<DVec3> {
    let cos_i = -d.dot(n);
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((d / eta + (cos_i / eta - cos_t) * n).normalize())
}

/// An orthonormal basis `(t, b)` perpendicular to the unit vector `n` (Duff et al.'s
/// branchless construction).
pub fn basis(n: DVec3) -> (DVec3, DVec3) {
    let sign = 1f64.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        DVec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        DVec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// The direction with cosine `cos_theta` to the unit axis `n` and azimuth `2 pi u`.
fn around(n: DVec3, cos_theta: f64, u: f64) -> DVec3 {
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    let phi = 2.0 * PI * u;
    let (t, b) = basis(n);
    (sin_theta * phi.cos() * t + sin_theta * phi.sin() * b + cos_theta * n).normalize()
}

/// A cosine-distributed direction on the hemisphere around `n` from uniforms `u`.
pub fn cosine_direction(n: DVec3, u: [f64; 2]) -> DVec3 {
    around(n, u[0].sqrt(), u[1])
}

/// The Henyey-Greenstein phase function (per steradian) for light travelling along `d`
/// scattered into `w` (`cos = d . w`); `g > 0` scatters forward.
pub fn henyey_greenstein(cos: f64, g: f64) -> f64 {
    let denom = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * denom * denom.sqrt())
}

/// A direction drawn from the Henyey-Greenstein phase function around the travel
/// direction `d` (the phase function is its own density, so the sample's weight is 1).
pub fn sample_henyey_greenstein(d: DVec3, g: f64, u: [f64; 2]) -> DVec3 {
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u[0]
    } else {
        let s = (1.0 - g * g) / (1.0 - g + 2.0 * g * u[0]);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    around(d, cos, u[1])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_matches_normal_incidence_and_total_internal_reflection() {
        // ((n - 1) / (n + 1))^2 at normal incidence.
        assert!((fresnel(1.0, 1.5) - 0.04).abs() < 1e-12);
        assert!((fresnel(1.0, 1.0 / 1.5) - 0.04).abs() < 1e-12);
        // Beyond the critical angle asin(1 / 1.5) from inside.
        let cos = (42.0f64).to_radians().cos();
        assert_eq!(fresnel(cos, 1.0 / 1.5), 1.0);
        // Grazing incidence reflects everything.
        assert!((fresnel(0.0, 1.5) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn refraction_obeys_snell() {
        let n = DVec3::Z;
        let d = DVec3::new(0.6, 0.0, -0.8);
        let t = refract(d, n, 1.5).unwrap();
        let sin_i = 0.6;
        let sin_t = t.x.hypot(t.y);
        assert!((sin_i - 1.5 * sin_t).abs() < 1e-12);
        assert!(t.z < 0.0 && (t.length() - 1.0).abs() < 1e-12);
        assert!(refract(DVec3::new(0.9, 0.0, -(0.19f64).sqrt()), n, 1.0 / 1.5).is_none());
    }

    #[test]
    fn henyey_greenstein_integrates_to_one_and_samples_its_mean_cosine() {
        for g in [-0.7, 0.0, 0.3, 0.9] {
            // Midpoint rule over cos in [-1, 1]: 2 pi * integral p d(cos).
            let n = 200_000;
            let sum: f64 = (0..n)
                .map(|i| henyey_greenstein(-1.0 + (i as f64 + 0.5) * 2.0 / n as f64, g))
                .sum::<f64>()
                * 2.0
                / n as f64
                * 2.0
                * PI;
            assert!((sum - 1.0).abs() < 1e-4, "g = {g}: {sum}");
            // The mean cosine of HG is g.
            let m = 400;
            let mut mean = 0.0;
            for a in 0..m {
                for b in 0..4 {
                    let u = [(a as f64 + 0.5) / m as f64, (b as f64 + 0.5) / 4.0];
                    mean += sample_henyey_greenstein(DVec3::X, g, u).x;
                }
            }
            mean /= (4 * m) as f64;
            assert!((mean - g).abs() < 2e-3, "g = {g}: mean cosine {mean}");
        }
    }

    #[test]
    fn basis_is_orthonormal_even_for_negative_z() {
        for n in [
            DVec3::Z,
            -DVec3::Z,
            DVec3::new(0.3, -0.4, -0.866).normalize(),
        ] {
            let (t, b) = basis(n);
            for (x, y) in [(t, b), (t, n), (b, n)] {
                assert!(x.dot(y).abs() < 1e-12);
            }
            assert!((t.length() - 1.0).abs() < 1e-12 && (b.length() - 1.0).abs() < 1e-12);
        }
    }
}
