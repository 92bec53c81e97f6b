//! Fresnel reflection and refraction of a polarized photon at a smooth boundary between
//! two dielectrics, with total internal reflection: Geant4's G4OpBoundaryProcess for a
//! polished `dielectric_dielectric` crossing.
//!
//! The photon's polarization is split into its component perpendicular to the plane of
//! incidence (s, along `dir x normal`) and the rest (p); the transmitted amplitudes are
//! `t_s = 2 n1 c1 / (n1 c1 + n2 c2)` and `t_p = 2 n1 c1 / (n2 c1 + n1 c2)` (`c1`, `c2` the
//! cosines of incidence and refraction), and the photon is transmitted with probability
//! `n2 c2 (t_s^2 E_s^2 + t_p^2 E_p^2) / (n1 c1)`, which is `1 - R_s` for s and `1 - R_p`
//! for p polarization. The polarization after reflection or refraction is the normalized
//! field of the reflected or transmitted wave, as Geant4 forms it.

use super::V;

/// Cosines within this of 1 count as normal incidence (Geant4's surface tolerance,
/// 1e-9, used the same way).
pub const NORMAL_INCIDENCE: f64 = 1e-9;

/// What happened at the boundary.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fresnel {
    /// Reflected (Geant4's FresnelReflection).
    Reflected,
    /// Totally internally reflected.
    TotalInternal,
    /// Refracted into the far side.
    Refracted,
}

/// The amplitudes of one incidence: cosines, the polarization split and the transmitted
/// field.
struct Incidence {
    cos1: f64,
    cos2: f64,
    /// Unit vector perpendicular to the plane of incidence (the s direction).
    s_axis: V,
    e1_s: f64,
    e1_p: f64,
    e2_s: f64,
    e2_p: f64,
    oblique: bool,
}

/// `None` for total internal reflection.
fn incidence(dir: V, pol: V, normal: V, n1: f64, n2: f64) -> Option<Incidence> {
    let cos1 = -dir.dot(normal);
    let oblique = cos1.abs() < 1.0 - NORMAL_INCIDENCE;
    let sin1 = if oblique {
        (1.0 - cos1 * cos1).sqrt()
    } else {
        0.0
    };
    let sin2 = sin1 * n1 / n2;
    if sin2 >= 1.0 {
        return None;
    }
    let cos2 = (1.0 - sin2 * sin2).sqrt().copysign(cos1);
    let (s_axis, e1_s, e1_p) = if oblique {
        let s_axis = dir.cross(normal).normalized();
        let e1_s = pol.dot(s_axis);
        let e1_p = (pol - s_axis * e1_s).length();
        (s_axis, e1_s, e1_p)
    } else {
        // Normal incidence: no plane of incidence; all of the field counts as p.
        (pol, 0.0, 1.0)
    };
    let a = 2.0 * n1 * cos1;
    Some(Incidence {
        cos1,
        cos2,
        s_axis,
        e1_s,
        e1_p,
        e2_s: a * e1_s / (n1 * cos1 + n2 * cos2),
        e2_p: a * e1_p / (n2 * cos1 + n1 * cos2),
        oblique,
    })
}

/// The probability that a photon crossing from index `n1` into `n2` is transmitted
/// (0 under total internal reflection). `normal` is the unit normal facing the photon
/// (`dir . normal < 0`).
pub fn transmission_probability(dir: V, pol: V, normal: V, n1: f64, n2: f64) -> f64 {
    match incidence(dir, pol, normal, n1, n2) {
        None => 0.0,
        Some(i) if i.cos1 == 0.0 => 0.0,
        Some(i) => n2 * i.cos2 * (i.e2_s * i.e2_s + i.e2_p * i.e2_p) / (n1 * i.cos1),
    }
}

/// Reflects a direction or polarization about the plane with unit normal `normal`.
pub fn mirror(v: V, normal: V) -> V {
    v - normal * (2.0 * v.dot(normal))
}

/// One Fresnel decision on a facet, before the new direction is chosen.
pub struct FresnelStep {
    /// What happened.
    pub what: Fresnel,
    incidence: Option<Incidence>,
    n1: f64,
    n2: f64,
}

impl FresnelStep {
    /// Decides between reflection and refraction of a photon (unit `dir` and `pol`) on a
    /// facet with unit normal `facet` facing it, from index `n1` into `n2`; `u` uniform in
    /// [0, 1); `transmittance` (a surface's TRANSMITTANCE when positive) replaces the
    /// Fresnel transmission probability, as in Geant4.
    pub fn decide(dir: V, pol: V, facet: V, n1: f64, n2: f64, transmittance: f64, u: f64) -> Self {
        let incidence = incidence(dir, pol, facet, n1, n2);
        let what = match &incidence {
            None => Fresnel::TotalInternal,
            Some(i) => {
                let e2_total = i.e2_s * i.e2_s + i.e2_p * i.e2_p;
                let t = if transmittance > 0.0 {
                    transmittance
                } else if i.cos1 != 0.0 {
                    n2 * i.cos2 * e2_total / (n1 * i.cos1)
                } else {
                    0.0
                };
                if u < t {
                    Fresnel::Refracted
                } else {
                    Fresnel::Reflected
                }
            }
        };
        FresnelStep {
            what,
            incidence,
            n1,
            n2,
        }
    }

    /// The refracted direction and polarization (the step must be [`Fresnel::Refracted`]).
    pub fn refracted(&self, dir: V, pol: V, facet: V) -> (V, V) {
        let i = self
            .incidence
            .as_ref()
            .expect("a refraction has amplitudes");
        if !i.oblique {
            return (dir, pol);
        }
        let k = i.cos1 - i.cos2 * (self.n2 / self.n1);
        let new_dir = (dir + facet * k).normalized();
        let p_axis = new_dir.cross(i.s_axis).normalized();
        let norm = (i.e2_s * i.e2_s + i.e2_p * i.e2_p).sqrt();
        let new_pol = p_axis * (i.e2_p / norm) + i.s_axis * (i.e2_s / norm);
        (new_dir, new_pol.normalized())
    }

    /// The direction and polarization after a specular reflection about `axis` (the facet
    /// the decision was made on, or for the unified model's spike the surface's normal).
    /// Total internal reflection mirrors the field; Fresnel reflection takes the reflected
    /// wave's field, as Geant4 forms it.
    pub fn reflected(&self, dir: V, pol: V, axis: V) -> (V, V) {
        let new_dir = mirror(dir, axis);
        let Some(i) = &self.incidence else {
            return (new_dir, -pol + axis * (2.0 * pol.dot(axis)));
        };
        if !i.oblique {
            let new_pol = if self.n2 > self.n1 { -pol } else { pol };
            return (new_dir, new_pol);
        }
        // The reflected amplitudes, from the transmitted ones.
        let r_p = self.n2 * i.e2_p / self.n1 - i.e1_p;
        let r_s = i.e2_s - i.e1_s;
        let norm = (r_p * r_p + r_s * r_s).sqrt();
        let p_axis = new_dir.cross(i.s_axis).normalized();
        let new_pol = if norm > 0.0 {
            p_axis * (r_p / norm) + i.s_axis * (r_s / norm)
        } else {
            i.s_axis
        };
        (new_dir, new_pol.normalized())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hytrace_volume::Rng;

    /// A polished boundary: one decision, then the new direction and polarization.
    fn dielectric_dielectric(
        dir: V,
        pol: V,
        normal: V,
        n1: f64,
        n2: f64,
        transmittance: f64,
        u: f64,
    ) -> (Fresnel, V, V) {
        let step = FresnelStep::decide(dir, pol, normal, n1, n2, transmittance, u);
        let (d, p) = match step.what {
            Fresnel::Refracted => step.refracted(dir, pol, normal),
            _ => step.reflected(dir, pol, normal),
        };
        (step.what, d, p)
    }

    fn v(x: f64, y: f64, z: f64) -> V {
        V::new(x, y, z)
    }

    /// The textbook reflectances: R_s and R_p of Fresnel's equations.
    fn textbook(n1: f64, n2: f64, theta1: f64) -> (f64, f64) {
        let c1 = theta1.cos();
        let s2 = n1 / n2 * theta1.sin();
        if s2 >= 1.0 {
            return (1.0, 1.0);
        }
        let c2 = (1.0 - s2 * s2).sqrt();
        let rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2);
        let rp = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2);
        (rs * rs, rp * rp)
    }

    /// A photon arriving on the plane z = 0 from above at angle theta in the x-z plane.
    fn arriving(theta: f64) -> V {
        v(theta.sin(), 0.0, -theta.cos())
    }

    #[test]
    fn transmission_is_one_minus_fresnel_reflectance_for_s_and_p() {
        let normal = v(0.0, 0.0, 1.0);
        for (n1, n2) in [(1.0, 1.5), (1.5, 1.0), (1.333, 1.1), (1.0, 2.4)] {
            for k in 0..89 {
                let theta = (k as f64).to_radians();
                let dir = arriving(theta);
                let s_pol = v(0.0, 1.0, 0.0);
                let p_pol = dir.cross(s_pol).normalized();
                let (rs, rp) = textbook(n1, n2, theta);
                let ts = transmission_probability(dir, s_pol, normal, n1, n2);
                let tp = transmission_probability(dir, p_pol, normal, n1, n2);
                assert!(
                    (ts - (1.0 - rs)).abs() < 1e-12,
                    "s n {n1}->{n2} theta {k}: {ts} vs {}",
                    1.0 - rs
                );
                if k > 0 {
                    assert!(
                        (tp - (1.0 - rp)).abs() < 1e-12,
                        "p n {n1}->{n2} theta {k}: {tp} vs {}",
                        1.0 - rp
                    );
                }
            }
        }
    }

    #[test]
    fn brewster_angle_transmits_all_p_light() {
        let (n1, n2) = (1.0f64, 1.5);
        let theta = (n2 / n1).atan();
        let dir = arriving(theta);
        let p_pol = dir.cross(v(0.0, 1.0, 0.0)).normalized();
        let t = transmission_probability(dir, p_pol, v(0.0, 0.0, 1.0), n1, n2);
        assert!((t - 1.0).abs() < 1e-12, "{t}");
    }

    #[test]
    fn total_internal_reflection_above_the_critical_angle_only() {
        let (n1, n2) = (1.5f64, 1.0);
        let critical = (n2 / n1).asin();
        let normal = v(0.0, 0.0, 1.0);
        let pol = v(0.0, 1.0, 0.0);
        for (theta, tir) in [(critical + 1e-6, true), (critical - 1e-6, false)] {
            let dir = arriving(theta);
            assert_eq!(
                transmission_probability(dir, pol, normal, n1, n2) == 0.0,
                tir
            );
            for u in [0.0, 0.5, 0.999] {
                let (what, d, p) = dielectric_dielectric(dir, pol, normal, n1, n2, 0.0, u);
                if tir {
                    assert_eq!(what, Fresnel::TotalInternal);
                    assert!((d - v(dir.x, 0.0, -dir.z)).length() < 1e-12);
                    assert!(p.dot(d).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn refraction_obeys_snell_and_keeps_polarization_transverse() {
        let (n1, n2) = (1.0, 1.5);
        let normal = v(0.0, 0.0, 1.0);
        let mut rng = Rng::new(3, 0, 0);
        for k in 0..200 {
            let theta = (k as f64 * 0.44).to_radians();
            let dir = arriving(theta);
            let phi = std::f64::consts::TAU * rng.next_f64();
            let s = v(0.0, 1.0, 0.0);
            let p = dir.cross(s).normalized();
            let pol = s * phi.cos() + p * phi.sin();
            let (what, d, q) = dielectric_dielectric(dir, pol, normal, n1, n2, 0.0, 0.0);
            assert_eq!(what, Fresnel::Refracted);
            let sin2 = (d.x * d.x + d.y * d.y).sqrt();
            assert!((n1 * theta.sin() - n2 * sin2).abs() < 1e-12);
            assert!(d.z < 0.0 && (d.length() - 1.0).abs() < 1e-12);
            assert!(q.dot(d).abs() < 1e-12 && (q.length() - 1.0).abs() < 1e-12);
            let (what, d, q) = dielectric_dielectric(dir, pol, normal, n1, n2, 0.0, 0.9999999);
            assert_eq!(what, Fresnel::Reflected);
            assert!((d - v(dir.x, dir.y, -dir.z)).length() < 1e-12);
            assert!(q.dot(d).abs() < 1e-12 && (q.length() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn sampled_reflection_rate_matches_fresnel() {
        // Unpolarized light on glass at 60 degrees: R = (R_s + R_p) / 2.
        let (n1, n2, theta) = (1.0, 1.5, 60f64.to_radians());
        let (rs, rp) = textbook(n1, n2, theta);
        let expected = 0.5 * (rs + rp);
        let dir = arriving(theta);
        let s = v(0.0, 1.0, 0.0);
        let p = dir.cross(s).normalized();
        let n = 200_000;
        let mut rng = Rng::new(9, 1, 0);
        let reflected = (0..n)
            .filter(|_| {
                let phi = std::f64::consts::TAU * rng.next_f64();
                let pol = s * phi.cos() + p * phi.sin();
                let u = rng.next_f64();
                let (what, _, _) =
                    dielectric_dielectric(dir, pol, v(0.0, 0.0, 1.0), n1, n2, 0.0, u);
                what == Fresnel::Reflected
            })
            .count();
        let rate = reflected as f64 / n as f64;
        let sigma = (expected * (1.0 - expected) / n as f64).sqrt();
        assert!(
            (rate - expected).abs() < 4.0 * sigma,
            "{rate} vs {expected}"
        );
    }
}
