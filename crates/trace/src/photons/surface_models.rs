//! Rough and painted optical surfaces: Geant4's glisur and unified models as
//! G4OpBoundaryProcess applies them (facts from Geant4 11; our own code).
//!
//! - **Facets.** A ground finish draws a micro-facet normal per decision. Unified: the
//!   angle `alpha` to the surface normal from a Gaussian of standard deviation
//!   `sigma_alpha` weighted by `sin(alpha)` (rejection with bound `min(1, 4 sigma_alpha)`),
//!   `alpha < pi/2`, azimuth uniform. Glisur: the normal plus `1 - polish` times a point
//!   uniform in the unit ball, normalized. Both redraw facets that face away from the
//!   photon.
//! - **Reflection types** (unified, not polished): spike (specular about the surface
//!   normal) with SPECULARSPIKECONSTANT, lobe (specular about a facet) with
//!   SPECULARLOBECONSTANT, backscatter (straight back) with BACKSCATTERCONSTANT, else
//!   Lambertian about the surface normal.
//! - **dielectric_dielectric** (Geant4's DielectricDielectric): Fresnel on a facet; a photon
//!   that a facet sends back across the surface is decided again (refracted photons from
//!   the far side), until it leaves the surface; the unified model replaces each
//!   reflection by one of the reflection types. Back-painted finishes put a gap of the
//!   surface's RINDEX between the photon and a paint layer: a photon that enters the gap
//!   meets the paint (absorbed with `1 - R - T`, through it with T, else reflected
//!   specularly (polished) or Lambertian (ground)) and crosses the gap's boundary again.
//! - **dielectric_metal** (Geant4's DielectricMetal): reflected with REFLECTIVITY as the
//!   model and finish say, reflections into the metal reflected again.

use std::f64::consts::{FRAC_PI_2, TAU};

use hytrace_volume::Rng;

use super::boundary::{mirror, Fresnel, FresnelStep};
use super::bulk::rotate_uz;
use super::properties::{Finish, Roughness};
use super::V;

/// Geant4's surface tolerance (1e-9 mm), which G4OpBoundaryProcess also uses as a
/// tolerance on the cosine of a reflected photon's direction with the surface normal.
const CAR_TOLERANCE: f64 = 1e-9;

/// Draws past which a sampling loop gives up (Geant4 has no bound; a photon whose
/// direction is not finite would otherwise loop for ever).
const MAX_DRAWS: u32 = 1 << 20;

/// A surface's parameters at the photon's energy.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceAt {
    /// Finish.
    pub finish: Finish,
    /// Model and roughness.
    pub roughness: Roughness,
    /// REFLECTIVITY.
    pub reflectivity: f64,
    /// TRANSMITTANCE.
    pub transmittance: f64,
    /// SPECULARSPIKECONSTANT (unified).
    pub spike: f64,
    /// SPECULARLOBECONSTANT (unified).
    pub lobe: f64,
    /// BACKSCATTERCONSTANT (unified).
    pub backscatter: f64,
}

/// The unified model's reflection types (Geant4's ChooseReflection), and the plain
/// reflections of the other models.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reflection {
    /// Specular about the surface normal.
    Spike,
    /// Specular about a facet.
    Lobe,
    /// Straight back.
    Backscatter,
    /// Lambertian about the surface normal.
    Lambertian,
}

/// How a surface ended for the photon.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurfaceEnd {
    /// The photon left the surface with its new direction and polarization.
    Left,
    /// Absorbed (detected with EFFICIENCY by the caller).
    Absorbed,
}

/// A standard normal deviate (Box-Muller).
fn gaussian(rng: &mut Rng) -> f64 {
    let r = (-2.0 * (1.0 - rng.next_f64()).ln()).sqrt();
    r * (TAU * rng.next_f64()).cos()
}

/// A direction from the cosine-weighted hemisphere about the unit `normal` (Geant4's
/// G4LambertianRand draws the same distribution by rejection).
pub fn lambertian(normal: V, rng: &mut Rng) -> V {
    let u = rng.next_f64();
    let phi = TAU * rng.next_f64();
    let r = u.sqrt();
    rotate_uz(
        V::new(r * phi.cos(), r * phi.sin(), (1.0 - u).sqrt()),
        normal,
    )
    .normalized()
}

impl SurfaceAt {
    fn unified(&self) -> bool {
        matches!(self.roughness, Roughness::Unified { .. })
    }

    /// A facet normal for a photon moving along `dir` onto a surface whose unit normal
    /// `normal` faces it (Geant4's GetFacetNormal): the normal itself when smooth.
    pub fn facet_normal(&self, dir: V, normal: V, rng: &mut Rng) -> V {
        match self.roughness {
            Roughness::Unified { sigma_alpha } if sigma_alpha > 0.0 => {
                let f_max = (4.0 * sigma_alpha).min(1.0);
                for _ in 0..MAX_DRAWS {
                    let (alpha, sin_alpha) = loop {
                        let alpha = sigma_alpha * gaussian(rng);
                        let s = alpha.sin();
                        if rng.next_f64() * f_max <= s && alpha < FRAC_PI_2 {
                            break (alpha, s);
                        }
                    };
                    let phi = TAU * rng.next_f64();
                    let local = V::new(sin_alpha * phi.cos(), sin_alpha * phi.sin(), alpha.cos());
                    let facet = rotate_uz(local, normal);
                    if dir.dot(facet) < 0.0 {
                        return facet;
                    }
                }
                normal
            }
            Roughness::Glisur { polish } if polish < 1.0 => {
                for _ in 0..MAX_DRAWS {
                    let smear = loop {
                        let s = V::new(
                            2.0 * rng.next_f64() - 1.0,
                            2.0 * rng.next_f64() - 1.0,
                            2.0 * rng.next_f64() - 1.0,
                        );
                        if s.dot(s) <= 1.0 {
                            break s;
                        }
                    };
                    let facet = normal + smear * (1.0 - polish);
                    if dir.dot(facet) < 0.0 {
                        return facet.normalized();
                    }
                }
                normal
            }
            _ => normal,
        }
    }

    /// The unified model's choice among its reflection types.
    fn choose_reflection(&self, rng: &mut Rng) -> Reflection {
        let u = rng.next_f64();
        if u < self.spike {
            Reflection::Spike
        } else if u < self.spike + self.lobe {
            Reflection::Lobe
        } else if u < self.spike + self.lobe + self.backscatter {
            Reflection::Backscatter
        } else {
            Reflection::Lambertian
        }
    }

    /// Geant4's DoReflection: Lambertian when so chosen, a lobe about a new facet on a
    /// ground finish, else a spike about the surface normal. Returns the new direction
    /// and polarization.
    fn do_reflection(&self, lambert: bool, dir: V, pol: V, normal: V, rng: &mut Rng) -> (V, V) {
        let (new_dir, facet) = if lambert {
            let d = lambertian(normal, rng);
            (d, (d - dir).normalized())
        } else {
            let facet = if self.finish == Finish::Ground {
                self.facet_normal(dir, normal, rng)
            } else {
                normal
            };
            (mirror(dir, facet), facet)
        };
        (new_dir, -pol + facet * (2.0 * pol.dot(facet)))
    }

    /// A `dielectric_metal` surface that reflects (the photon was not absorbed or passed
    /// with the first uniform: the caller drew it). Changes `dir` and `pol`.
    pub fn metal_reflection(&self, dir: &mut V, pol: &mut V, normal: V, rng: &mut Rng) {
        let plain = !self.unified() || self.finish == Finish::Polished;
        let chosen = if plain {
            None
        } else {
            Some(self.choose_reflection(rng))
        };
        for _ in 0..MAX_DRAWS {
            let (d, p) = match chosen {
                None => self.do_reflection(false, *dir, *pol, normal, rng),
                Some(Reflection::Lambertian) => self.do_reflection(true, *dir, *pol, normal, rng),
                Some(Reflection::Backscatter) => (-*dir, -*pol),
                Some(r) => {
                    let facet = if r == Reflection::Lobe {
                        self.facet_normal(*dir, normal, rng)
                    } else {
                        normal
                    };
                    (mirror(*dir, facet), -*pol + facet * (2.0 * pol.dot(facet)))
                }
            };
            (*dir, *pol) = (d, p);
            // Reflected into the metal by a facet: reflected again.
            if dir.dot(normal) >= 0.0 {
                return;
            }
        }
    }

    /// A reflection on a `dielectric_dielectric` surface where the Fresnel `step` reflected
    /// the photon on `facet`: the unified model's reflection types on rough finishes,
    /// else specular about the facet. Returns the new direction and polarization, and
    /// whether the reflection was Lambertian.
    fn dielectric_reflection(
        &self,
        step: &FresnelStep,
        (dir, pol): (V, V),
        facet: V,
        normal: V,
        rng: &mut Rng,
    ) -> (V, V, bool) {
        let chosen = (self.unified() && self.finish != Finish::Polished)
            .then(|| self.choose_reflection(rng));
        let (d, p) = match chosen {
            Some(Reflection::Lambertian) => self.do_reflection(true, dir, pol, normal, rng),
            Some(Reflection::Backscatter) => (-dir, -pol),
            Some(Reflection::Spike) => step.reflected(dir, pol, normal),
            Some(Reflection::Lobe) | None => step.reflected(dir, pol, facet),
        };
        (d, p, chosen == Some(Reflection::Lambertian))
    }

    /// Geant4's DielectricDielectric for a photon crossing from index `n1` into `n2` (for
    /// back-painted finishes `n2` is the gap's RINDEX): the photon's `dir` and `pol`
    /// change in place; `normal` is the surface's unit normal facing the photon. The
    /// photon ends on the side its final direction points to.
    pub fn dielectric(
        &self,
        dir: &mut V,
        pol: &mut V,
        normal: V,
        (n1, n2): (f64, f64),
        rng: &mut Rng,
    ) -> SurfaceEnd {
        let (mut n1, mut n2, mut normal) = (n1, n2, normal);
        let mut inside = false;
        let mut swap = false;
        let (mut refracted, mut lambertian);
        'leap: for _ in 0..MAX_DRAWS {
            let mut through = false;
            loop {
                if through {
                    swap = !swap;
                    through = false;
                    normal = -normal;
                    std::mem::swap(&mut n1, &mut n2);
                }
                let facet = if self.finish == Finish::Polished {
                    normal
                } else {
                    self.facet_normal(*dir, normal, rng)
                };
                let step = FresnelStep::decide(
                    *dir,
                    *pol,
                    facet,
                    n1,
                    n2,
                    self.transmittance,
                    rng.next_f64(),
                );
                refracted = step.what == Fresnel::Refracted;
                let (d, p) = if refracted {
                    inside = !inside;
                    through = true;
                    lambertian = false;
                    step.refracted(*dir, *pol, facet)
                } else {
                    swap = false;
                    let (d, p, l) =
                        self.dielectric_reflection(&step, (*dir, *pol), facet, normal, rng);
                    lambertian = l;
                    (d, p)
                };
                *dir = d.normalized();
                *pol = p.normalized();
                let done = if refracted {
                    dir.dot(normal) <= 0.0
                } else {
                    dir.dot(normal) >= -CAR_TOLERANCE
                };
                if done {
                    break;
                }
            }
            if !(inside && !swap && self.finish.back_painted()) {
                return SurfaceEnd::Left;
            }
            // In the gap, at the paint.
            let u = rng.next_f64();
            if u > self.reflectivity + self.transmittance {
                return SurfaceEnd::Absorbed;
            }
            if u > self.reflectivity {
                return SurfaceEnd::Left;
            }
            if refracted {
                swap = !swap;
                std::mem::swap(&mut n1, &mut n2);
            } else {
                normal = -normal;
            }
            // Ground paint reflects as Lambertian; so does polished paint after a
            // Lambertian reflection in the gap (Geant4 keeps that status).
            let lambert = lambertian || self.finish == Finish::GroundBackPainted;
            // Geant4 keeps the polarization it had before the paint's reflection.
            let (d, _) = self.do_reflection(lambert, *dir, *pol, normal, rng);
            normal = -normal;
            *dir = d;
            continue 'leap;
        }
        SurfaceEnd::Left
    }

    /// A front-painted `dielectric_dielectric` surface that reflects: specular about the
    /// normal (polished paint) or Lambertian (ground paint).
    pub fn paint_reflection(&self, dir: &mut V, pol: &mut V, normal: V, rng: &mut Rng) {
        let lambert = self.finish == Finish::GroundFrontPainted;
        (*dir, *pol) = self.do_reflection(lambert, *dir, *pol, normal, rng);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const N: usize = 200_000;

    fn surface(finish: Finish, roughness: Roughness) -> SurfaceAt {
        SurfaceAt {
            finish,
            roughness,
            reflectivity: 1.0,
            transmittance: 0.0,
            spike: 0.0,
            lobe: 0.0,
            backscatter: 0.0,
        }
    }

    fn up() -> V {
        V::new(0.0, 0.0, 1.0)
    }

    /// A photon arriving on the plane z = 0 from above at `theta`, s or p polarized.
    fn arriving(theta: f64, p_polarized: bool) -> (V, V) {
        let dir = V::new(theta.sin(), 0.0, -theta.cos());
        let s = V::new(0.0, 1.0, 0.0);
        (dir, if p_polarized { dir.cross(s) } else { s })
    }

    fn within_sigmas(mean: f64, expected: f64, sd: f64, n: usize, what: &str) {
        let sigma = sd / (n as f64).sqrt();
        assert!(
            (mean - expected).abs() < 4.0 * sigma,
            "{what}: {mean} vs {expected} (sigma {sigma})"
        );
    }

    #[test]
    fn lambertian_directions_have_the_cosine_law_moments() {
        // Cosine-weighted hemisphere: E[cos] = 2/3 (sd sqrt(1/18)), P(cos < 1/2) = 1/4.
        let mut rng = Rng::new(1, 0, 0);
        let normal = V::new(0.3, -0.4, 0.5).normalized();
        let cos: Vec<f64> = (0..N)
            .map(|_| lambertian(normal, &mut rng).dot(normal))
            .collect();
        assert!(cos.iter().all(|&c| c >= 0.0));
        let mean = cos.iter().sum::<f64>() / N as f64;
        within_sigmas(mean, 2.0 / 3.0, (1.0f64 / 18.0).sqrt(), N, "mean cosine");
        let low = cos.iter().filter(|&&c| c < 0.5).count() as f64 / N as f64;
        within_sigmas(low, 0.25, (0.25f64 * 0.75).sqrt(), N, "P(cos < 1/2)");
    }

    #[test]
    fn unified_facet_angles_follow_a_gaussian_times_sine() {
        // The mean facet angle against the integral of alpha g(alpha) sin(alpha) over
        // [0, pi/2) (Simpson's rule), at normal incidence where no facet is redrawn.
        let sigma_alpha = 0.2;
        let s = surface(Finish::Ground, Roughness::Unified { sigma_alpha });
        let weight = |a: f64| (-a * a / (2.0 * sigma_alpha * sigma_alpha)).exp() * a.sin();
        let simpson = |f: &dyn Fn(f64) -> f64| {
            let (n, h) = (2000, FRAC_PI_2 / 2000.0);
            (0..=n)
                .map(|i| {
                    let w = if i == 0 || i == n {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    w * f(i as f64 * h)
                })
                .sum::<f64>()
                * h
                / 3.0
        };
        let z = simpson(&weight);
        let mean = simpson(&|a| a * weight(a)) / z;
        let sd = (simpson(&|a| a * a * weight(a)) / z - mean * mean).sqrt();
        let mut rng = Rng::new(2, 0, 0);
        let angles: Vec<f64> = (0..N)
            .map(|_| {
                s.facet_normal(-up(), up(), &mut rng)
                    .dot(up())
                    .clamp(-1.0, 1.0)
                    .acos()
            })
            .collect();
        let sampled = angles.iter().sum::<f64>() / N as f64;
        within_sigmas(sampled, mean, sd, N, "mean facet angle");
    }

    #[test]
    fn facets_always_face_the_photon() {
        let mut rng = Rng::new(3, 0, 0);
        for roughness in [
            Roughness::Unified { sigma_alpha: 0.8 },
            Roughness::Glisur { polish: 0.0 },
        ] {
            let s = surface(Finish::Ground, roughness);
            let (dir, _) = arriving(1.5, false);
            for _ in 0..10_000 {
                let f = s.facet_normal(dir, up(), &mut rng);
                assert!(dir.dot(f) < 0.0 && (f.length() - 1.0).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn unified_metal_reflection_types_do_what_they_say() {
        let (dir0, pol0) = arriving(0.6, false);
        let mut rng = Rng::new(4, 0, 0);
        let mut s = surface(Finish::Ground, Roughness::Unified { sigma_alpha: 0.3 });
        s.spike = 1.0;
        let (mut d, mut p) = (dir0, pol0);
        s.metal_reflection(&mut d, &mut p, up(), &mut rng);
        assert!((d - mirror(dir0, up())).length() < 1e-15);
        s.spike = 0.0;
        s.backscatter = 1.0;
        let (mut d, mut p) = (dir0, pol0);
        s.metal_reflection(&mut d, &mut p, up(), &mut rng);
        assert_eq!((d, p), (-dir0, -pol0));
        // Lobes about rough facets: reflected back out, polarization transverse.
        s.backscatter = 0.0;
        s.lobe = 1.0;
        for _ in 0..10_000 {
            let (mut d, mut p) = (dir0, pol0);
            s.metal_reflection(&mut d, &mut p, up(), &mut rng);
            assert!(d.dot(up()) >= 0.0 && p.dot(d).abs() < 1e-9);
        }
    }

    #[test]
    fn a_smooth_unified_lobe_reflects_as_fresnel_says() {
        // Ground with sigma_alpha 0 and every reflection a lobe is the polished boundary:
        // unpolarized light on glass at 60 degrees reflects (R_s + R_p) / 2.
        let (n1, n2, theta) = (1.0f64, 1.5f64, 60f64.to_radians());
        let c1 = theta.cos();
        let c2 = (1.0 - (n1 / n2 * theta.sin()).powi(2)).sqrt();
        let rs = ((n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)).powi(2);
        let rp = ((n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)).powi(2);
        let expected = 0.5 * (rs + rp);
        let mut s = surface(Finish::Ground, Roughness::Unified { sigma_alpha: 0.0 });
        s.lobe = 1.0;
        let mut rng = Rng::new(5, 0, 0);
        let reflected = (0..N)
            .filter(|k| {
                let (mut d, mut p) = arriving(theta, k % 2 == 0);
                s.dielectric(&mut d, &mut p, up(), (n1, n2), &mut rng);
                d.dot(up()) > 0.0
            })
            .count() as f64
            / N as f64;
        within_sigmas(
            reflected,
            expected,
            (expected * (1.0 - expected)).sqrt(),
            N,
            "R",
        );
    }

    #[test]
    fn a_smooth_back_painted_mirror_reflects_every_photon_specularly() {
        // Parallel interfaces and a specular paint with REFLECTIVITY 1: whatever the gap
        // does, the photon comes back out as the mirror image of its incoming direction.
        // (Glisur: the unified model's reflections on a non-polished finish default to
        // Lambertian.)
        let s = surface(
            Finish::PolishedBackPainted,
            Roughness::Glisur { polish: 1.0 },
        );
        let mut rng = Rng::new(6, 0, 0);
        for k in 0..20_000 {
            let (dir0, pol0) = arriving(1.5 * (k as f64 / 20_000.0), k % 2 == 0);
            let (mut d, mut p) = (dir0, pol0);
            let end = s.dielectric(&mut d, &mut p, up(), (1.0, 1.3), &mut rng);
            assert_eq!(end, SurfaceEnd::Left);
            assert!((d - mirror(dir0, up())).length() < 1e-12, "{k}: {d:?}");
        }
    }

    #[test]
    fn ground_paint_reflects_lambertian() {
        let s = surface(
            Finish::GroundFrontPainted,
            Roughness::Glisur { polish: 1.0 },
        );
        let mut rng = Rng::new(7, 0, 0);
        let mean = (0..N)
            .map(|_| {
                let (mut d, mut p) = arriving(0.9, false);
                s.paint_reflection(&mut d, &mut p, up(), &mut rng);
                d.dot(up())
            })
            .sum::<f64>()
            / N as f64;
        within_sigmas(mean, 2.0 / 3.0, (1.0f64 / 18.0).sqrt(), N, "mean cosine");
    }
}
