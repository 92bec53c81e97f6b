//! Photon sources ("torch" sources, as Opticks calls them): where photons start, in which
//! direction, with which polarization. Every photon starts at time 0 with the run's
//! wavelength and a random linear polarization perpendicular to its direction.
//!
//! Source specifications (`--source`), lengths in mm:
//! - `point:X,Y,Z`: isotropic from a point;
//! - `beam:X,Y,Z:DX,DY,DZ:R`: parallel along (DX, DY, DZ) (normalized here), starting
//!   uniformly over the disk of radius R centred on (X, Y, Z) perpendicular to it (R = 0:
//!   a pencil beam).

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
    },
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
            ["beam", xyz, dxyz, r] => {
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
                Ok(Source::Beam {
                    centre: V::new(x, y, z),
                    direction: d.normalized(),
                    radius,
                })
            }
            ["point", ..] => Err(bad("expected point:X,Y,Z")),
            ["beam", ..] => Err(bad("expected beam:X,Y,Z:DX,DY,DZ:R")),
            _ => Err(bad(
                "unknown source (expected point:X,Y,Z or beam:X,Y,Z:DX,DY,DZ:R)",
            )),
        }
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
            } => {
                let r = radius * rng.next_f64().sqrt();
                let phi = std::f64::consts::TAU * rng.next_f64();
                let offset = rotate_uz(V::new(r * phi.cos(), r * phi.sin(), 0.0), direction);
                (centre + offset, direction)
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
}
