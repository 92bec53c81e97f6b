//! Photon sources ("torch" sources, as Opticks calls them): where photons start, in which
//! direction, with which polarization. Every photon starts at time 0 with the run's
//! wavelength and a random linear polarization perpendicular to its direction.
//!
//! Source specifications (`--source`), lengths in mm:
//! - `point:X,Y,Z`: isotropic from a point;
//! - `beam:X,Y,Z:DX,DY,DZ:R[:A]`: along (DX, DY, DZ) (normalized here), starting uniformly
//!   over the disk of radius R centred on (X, Y, Z) perpendicular to it (R = 0: a pencil
//!   beam); parallel, or with A, directions uniform in solid angle within the cone of
//!   half-angle A degrees (0 to 180) about the axis;
//! - `sphere:X,Y,Z:R:out` or `...:in`: starting uniformly over the sphere of radius R
//!   centred on (X, Y, Z), along its outward or inward normal.

use hytrace_volume::Rng;

use super::bulk::rotate_uz;
use super::{PhotonError, V};
use crate::number_list::{parse_numbers, NumberListError};

/// A photon source.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Source {
    /// Isotropic from a point.
    Point {
        /// Position (mm).
        position: V,
    },
    /// A parallel beam over a disk.
    Beam {
        /// Centre of the disk (mm).
        centre: V,
        /// Unit direction.
        direction: V,
        /// Radius of the disk (mm).
        radius: f64,
        /// Cosine of the divergence half-angle (1: parallel).
        cos_divergence: f64,
    },
    /// From a sphere's surface along its normal.
    Sphere {
        /// Centre (mm).
        centre: V,
        /// Radius (mm).
        radius: f64,
        /// Towards the centre (else away from it).
        inward: bool,
    },
}

/// The wavelength photons start with (`--wavelength`).
#[derive(Clone, Debug, PartialEq)]
pub enum Wavelength {
    /// Every photon at this wavelength (nm).
    Fixed(f64),
    /// Drawn for each photon from an intensity table (intensity per photon energy) of a
    /// material of the scene, as Geant4 draws its emission spectra, e.g.
    /// `LAr:SCINTILLATIONCOMPONENT1`.
    Spectrum {
        /// Material name.
        material: String,
        /// Property name.
        property: String,
    },
}

impl Wavelength {
    /// Parses `NM` (a number of nanometres, checked when a run starts) or
    /// `MATERIAL:PROPERTY`.
    pub fn parse(text: &str) -> Result<Wavelength, PhotonError> {
        let bad = |problem: String| PhotonError::Input(format!("--wavelength `{text}`: {problem}"));
        if let Some((material, property)) = text.rsplit_once(':') {
            if material.trim().is_empty() || property.trim().is_empty() {
                return Err(bad("expected NM or MATERIAL:PROPERTY".into()));
            }
            return Ok(Wavelength::Spectrum {
                material: material.trim().to_string(),
                property: property.trim().to_string(),
            });
        }
        // A number is checked where the run starts, as one given through the library.
        match text.trim().parse::<f64>() {
            Ok(nm) => Ok(Wavelength::Fixed(nm)),
            Err(_) => Err(bad("not a number of nanometres or MATERIAL:PROPERTY".into())),
        }
    }
}

/// A photon's starting position, direction and polarization.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Start {
    /// Position (mm).
    pub position: V,
    /// Unit direction.
    pub direction: V,
    /// Unit polarization, perpendicular to the direction.
    pub polarization: V,
}

fn numbers<const N: usize>(text: &str, spec: &str, what: &str) -> Result<[f64; N], PhotonError> {
    parse_numbers(text).map_err(|e| PhotonError::Source {
        spec: spec.to_string(),
        problem: match e {
            NumberListError::Count { .. } => format!("{what} needs {N} numbers, got `{text}`"),
            NumberListError::NotFinite(item) => format!("{what}: `{item}` is not a finite number"),
        },
    })
}

impl Source {
    /// Parses a source specification (see the module doc).
    pub fn parse(spec: &str) -> Result<Source, PhotonError> {
        let bad = |problem: &str| PhotonError::Source {
            spec: spec.to_string(),
            problem: problem.to_string(),
        };
        let parts: Vec<&str> = spec.split(':').collect();
        match parts[..] {
            ["point", xyz] => {
                let [x, y, z] = numbers::<3>(xyz, spec, "the position")?;
                Ok(Source::Point {
                    position: V::new(x, y, z),
                })
            }
            ["beam", xyz, dxyz, r] => Self::beam(spec, xyz, dxyz, r, None),
            ["beam", xyz, dxyz, r, a] => Self::beam(spec, xyz, dxyz, r, Some(a)),
            ["sphere", xyz, r, side] => {
                let [x, y, z] = numbers::<3>(xyz, spec, "the centre")?;
                let [radius] = numbers::<1>(r, spec, "the radius")?;
                if radius <= 0.0 {
                    return Err(bad("the radius must be positive"));
                }
                let inward = match side {
                    "in" => true,
                    "out" => false,
                    _ => return Err(bad("the side must be `in` or `out`")),
                };
                Ok(Source::Sphere {
                    centre: V::new(x, y, z),
                    radius,
                    inward,
                })
            }
            ["point", ..] => Err(bad("expected point:X,Y,Z")),
            ["beam", ..] => Err(bad("expected beam:X,Y,Z:DX,DY,DZ:R[:A]")),
            ["sphere", ..] => Err(bad("expected sphere:X,Y,Z:R:in or sphere:X,Y,Z:R:out")),
            _ => Err(bad(
                "unknown source (expected point:X,Y,Z, beam:X,Y,Z:DX,DY,DZ:R[:A] or sphere:X,Y,Z:R:in|out)",
            )),
        }
    }

    /// A beam from its specification's parts.
    fn beam(
        spec: &str,
        xyz: &str,
        dxyz: &str,
        r: &str,
        divergence: Option<&str>,
    ) -> Result<Source, PhotonError> {
        let bad = |problem: &str| PhotonError::Source {
            spec: spec.to_string(),
            problem: problem.to_string(),
        };
        let [x, y, z] = numbers::<3>(xyz, spec, "the centre")?;
        let [dx, dy, dz] = numbers::<3>(dxyz, spec, "the direction")?;
        let [radius] = numbers::<1>(r, spec, "the radius")?;
        let d = V::new(dx, dy, dz);
        if d.length() == 0.0 {
            return Err(bad("the direction is zero"));
        }
        if radius < 0.0 {
            return Err(bad("the radius is negative"));
        }
        let half_angle = match divergence {
            Some(a) => numbers::<1>(a, spec, "the divergence")?[0],
            None => 0.0,
        };
        if !(0.0..=180.0).contains(&half_angle) {
            return Err(bad("the divergence half-angle must be 0 to 180 degrees"));
        }
        Ok(Source::Beam {
            centre: V::new(x, y, z),
            direction: d.normalized(),
            radius,
            cos_divergence: half_angle.to_radians().cos(),
        })
    }

    /// Draws one photon's start.
    pub fn sample(&self, rng: &mut Rng) -> Start {
        let (position, direction) = match *self {
            Source::Point { position } => {
                let cos_t = 1.0 - 2.0 * rng.next_f64();
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = std::f64::consts::TAU * rng.next_f64();
                (
                    position,
                    V::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t),
                )
            }
            Source::Beam {
                centre,
                direction,
                radius,
                cos_divergence,
            } => {
                let r = radius * rng.next_f64().sqrt();
                let phi = std::f64::consts::TAU * rng.next_f64();
                let offset = rotate_uz(V::new(r * phi.cos(), r * phi.sin(), 0.0), direction);
                let d = if cos_divergence < 1.0 {
                    // Uniform in solid angle: the cosine uniform in [cos A, 1].
                    let c = 1.0 - (1.0 - cos_divergence) * rng.next_f64();
                    let s = (1.0 - c * c).max(0.0).sqrt();
                    let psi = std::f64::consts::TAU * rng.next_f64();
                    rotate_uz(V::new(s * psi.cos(), s * psi.sin(), c), direction).normalized()
                } else {
                    direction
                };
                (centre + offset, d)
            }
            Source::Sphere {
                centre,
                radius,
                inward,
            } => {
                let cos_t = 1.0 - 2.0 * rng.next_f64();
                let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
                let phi = std::f64::consts::TAU * rng.next_f64();
                let n = V::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t);
                (centre + n * radius, if inward { -n } else { n })
            }
        };
        let a = std::f64::consts::TAU * rng.next_f64();
        let polarization = rotate_uz(V::new(a.cos(), a.sin(), 0.0), direction).normalized();
        Start {
            position,
            direction,
            polarization,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specifications_parse_and_bad_ones_name_the_problem() {
        assert_eq!(
            Source::parse("point:1,2,3").unwrap(),
            Source::Point {
                position: V::new(1.0, 2.0, 3.0)
            }
        );
        let Source::Beam {
            direction, radius, ..
        } = Source::parse("beam:0,0,-10:0,0,2:1.5").unwrap()
        else {
            panic!("not a beam")
        };
        assert_eq!((direction, radius), (V::new(0.0, 0.0, 1.0), 1.5));
        for (spec, needle) in [
            ("laser:0,0,0", "unknown source"),
            ("point:1,2", "3 numbers"),
            ("point:1,x,2", "`x`"),
            ("beam:0,0,0:0,0,0:1", "zero"),
            ("beam:0,0,0:0,0,1:-1", "negative"),
            ("beam:0,0,0:0,0,1", "expected beam"),
            ("beam:0,0,0:0,0,1:1:190", "0 to 180"),
            ("beam:0,0,0:0,0,1:1:-5", "0 to 180"),
            ("sphere:0,0,0:0:in", "positive"),
            ("sphere:0,0,0:5:up", "`in` or `out`"),
            ("sphere:0,0,0:5", "expected sphere"),
        ] {
            let e = Source::parse(spec).unwrap_err().to_string();
            assert!(e.contains(spec) && e.contains(needle), "{spec}: {e}");
        }
    }

    #[test]
    fn photons_start_isotropic_or_on_the_disk_with_transverse_polarization() {
        let mut rng = Rng::new(1, 2, 0);
        let point = Source::parse("point:0,0,0").unwrap();
        let n = 50_000;
        let mut mean = V::new(0.0, 0.0, 0.0);
        let mut up = 0;
        for _ in 0..n {
            let s = point.sample(&mut rng);
            assert!(s.direction.dot(s.polarization).abs() < 1e-12);
            assert!((s.polarization.length() - 1.0).abs() < 1e-12);
            mean = mean + s.direction * (1.0 / n as f64);
            up += usize::from(s.direction.z > 0.5);
        }
        assert!(mean.length() < 0.02, "{mean:?}");
        // A quarter of the sphere has cos(theta) > 1/2.
        assert!((up as f64 / n as f64 - 0.25).abs() < 0.01);
        let beam = Source::parse("beam:1,1,1:1,0,0:2").unwrap();
        let mut inner = 0;
        for _ in 0..n {
            let s = beam.sample(&mut rng);
            let off = s.position - V::new(1.0, 1.0, 1.0);
            assert!(off.x.abs() < 1e-12 && off.length() <= 2.0 + 1e-12);
            assert_eq!(s.direction, V::new(1.0, 0.0, 0.0));
            assert!(s.polarization.x.abs() < 1e-12);
            inner += usize::from(off.length() < 1.0);
        }
        // Uniform over the area: a quarter within half the radius.
        assert!((inner as f64 / n as f64 - 0.25).abs() < 0.01);
    }

    #[test]
    fn divergent_beams_fill_their_cone_uniformly_in_solid_angle() {
        // Half-angle 30 degrees: every direction within it, the cosine uniform on
        // [cos 30, 1] (mean (1 + cos 30) / 2, standard deviation (1 - cos 30) / sqrt 12).
        let mut rng = Rng::new(3, 0, 0);
        let beam = Source::parse("beam:0,0,0:0,1,0:0:30").unwrap();
        let c30 = 30f64.to_radians().cos();
        let n = 100_000;
        let mut sum = 0.0;
        for _ in 0..n {
            let s = beam.sample(&mut rng);
            let c = s.direction.y;
            assert!(c >= c30 - 1e-12 && s.direction.dot(s.polarization).abs() < 1e-12);
            sum += c;
        }
        let sigma = (1.0 - c30) / 12f64.sqrt() / (n as f64).sqrt();
        assert!((sum / n as f64 - (1.0 + c30) / 2.0).abs() < 4.0 * sigma);
    }

    #[test]
    fn sphere_sources_start_on_the_sphere_along_its_normal() {
        let mut rng = Rng::new(4, 0, 0);
        let centre = V::new(1.0, -2.0, 3.0);
        for (spec, sign) in [("sphere:1,-2,3:5:out", 1.0), ("sphere:1,-2,3:5:in", -1.0)] {
            let source = Source::parse(spec).unwrap();
            let n = 50_000;
            let mut above = 0;
            for _ in 0..n {
                let s = source.sample(&mut rng);
                let r = s.position - centre;
                assert!((r.length() - 5.0).abs() < 1e-12);
                assert!((s.direction - r * (sign / 5.0)).length() < 1e-12);
                above += usize::from(r.z > 2.5);
            }
            // Uniform over the area: a quarter of it lies above z = R / 2.
            assert!((above as f64 / n as f64 - 0.25).abs() < 0.01);
        }
    }
}
