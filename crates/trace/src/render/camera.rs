//! The camera: which ray each pixel sample shoots.
//!
//! The convention (also what the independent NumPy reference of the tests rebuilds):
//! forward `w = normalize(target - eye)`, right `u = normalize(w x up)`, true up
//! `v = u x w`. Pixel `(i, j)` (column `i` from the left, row `j` from the top) with sample
//! offset `(sx, sy)` in `[0, 1)^2` (the centre is `(0.5, 0.5)`) has screen coordinates
//! `x = (2 (i + sx) / W - 1) * aspect`, `y = 1 - 2 (j + sy) / H`, `aspect = W / H`.
//! - Perspective (vertical field of view `fov`): origin `eye`, direction
//!   `normalize(w + tan(fov / 2) (x u + y v))`.
//! - Orthographic (view height `h`): origin `eye + (h / 2) (x u + y v)`, direction `w`.

use crate::error::{bail, ensure};
use glam::DVec3;
use serde::Deserialize;

/// A camera as written in a scene file's `[camera]` table.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    /// Where the camera is (mm).
    pub eye: [f64; 3],
    /// The point it looks at.
    pub target: [f64; 3],
    /// Up direction (default +z).
    #[serde(default = "z_up")]
    pub up: [f64; 3],
    /// Vertical field of view in degrees (perspective; default 40 unless `orthographic`).
    #[serde(default)]
    pub fov: Option<f64>,
    /// Height of the view in mm (orthographic).
    #[serde(default)]
    pub orthographic: Option<f64>,
}

fn z_up() -> [f64; 3] {
    [0.0, 0.0, 1.0]
}

/// The projection.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Projection {
    /// `tan(fov / 2)`.
    Perspective {
        /// Tangent of half the vertical field of view.
        tan_half_fov: f64,
    },
    /// Half the view height.
    Orthographic {
        /// Half the view height (mm).
        half_height: f64,
    },
}

/// A camera ready to shoot rays at an image of a given size.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: DVec3,
    /// Forward, right and up unit vectors.
    pub w: DVec3,
    /// Right.
    pub u: DVec3,
    /// Up.
    pub v: DVec3,
    /// Projection.
    pub projection: Projection,
    /// Image width and height in pixels.
    pub size: [u32; 2],
}

impl Camera {
    /// Checks `spec` and builds the camera for an image of `size` pixels.
    pub fn new(spec: &CameraSpec, size: [u32; 2]) -> crate::Result<Camera> {
        let finite = |v: [f64; 3]| v.iter().all(|c| c.is_finite());
        ensure!(
            finite(spec.eye) && finite(spec.target) && finite(spec.up),
            "camera: eye, target and up must be finite"
        );
        ensure!(
            size[0] > 0 && size[1] > 0,
            "image size {}x{}: both must be at least 1",
            size[0],
            size[1]
        );
        let (eye, target, up) = (
            DVec3::from(spec.eye),
            DVec3::from(spec.target),
            DVec3::from(spec.up),
        );
        let forward = target - eye;
        ensure!(
            forward.length() > 0.0,
            "camera: eye and target are the same point"
        );
        let w = forward.normalize();
        let right = w.cross(up);
        ensure!(
            right.length() > 1e-9 * up.length(),
            "camera: up {:?} is parallel to the view direction (or zero)",
            spec.up
        );
        let u = right.normalize();
        let v = u.cross(w);
        let projection = match (spec.fov, spec.orthographic) {
            (Some(_), Some(_)) => bail!("camera: give fov or orthographic, not both"),
            (_, Some(h)) => {
                ensure!(
                    h.is_finite() && h > 0.0,
                    "camera: orthographic height must be finite and > 0, got {h}"
                );
                Projection::Orthographic {
                    half_height: 0.5 * h,
                }
            }
            (fov, None) => {
                let fov = fov.unwrap_or(40.0);
                ensure!(
                    fov > 0.0 && fov < 180.0,
                    "camera: fov must be in (0, 180) degrees, got {fov}"
                );
                Projection::Perspective {
                    tan_half_fov: (0.5 * fov.to_radians()).tan(),
                }
            }
        };
        Ok(Camera {
            eye,
            w,
            u,
            v,
            projection,
            size,
        })
    }

    /// The ray (origin, unit direction) of pixel `(i, j)` at sample offset `offset`.
    pub fn ray(&self, i: u32, j: u32, offset: [f64; 2]) -> (DVec3, DVec3) {
        let [width, height] = self.size.map(f64::from);
        let aspect = width / height;
        let x = (2.0 * (i as f64 + offset[0]) / width - 1.0) * aspect;
        let y = 1.0 - 2.0 * (j as f64 + offset[1]) / height;
        match self.projection {
            Projection::Perspective { tan_half_fov } => (
                self.eye,
                (self.w + tan_half_fov * (x * self.u + y * self.v)).normalize(),
            ),
            Projection::Orthographic { half_height } => {
                (self.eye + half_height * (x * self.u + y * self.v), self.w)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> CameraSpec {
        CameraSpec {
            eye: [0.0, -10.0, 0.0],
            target: [0.0; 3],
            up: [0.0, 0.0, 1.0],
            fov: Some(90.0),
            orthographic: None,
        }
    }

    #[test]
    fn corners_of_a_90_degree_square_view_are_at_45_degrees() {
        let cam = Camera::new(&spec(), [2, 2]).unwrap();
        // Top-left corner of the image: left (-x) and up (+z).
        let (_, d) = cam.ray(0, 0, [0.0, 0.0]);
        let expect = DVec3::new(-1.0, 1.0, 1.0).normalize();
        assert!((d - expect).length() < 1e-12, "{d:?}");
        let (_, centre) = cam.ray(1, 1, [0.0, 0.0]);
        assert!((centre - DVec3::Y).length() < 1e-12);
    }

    #[test]
    fn orthographic_rays_are_parallel_and_spread_over_the_height() {
        let mut s = spec();
        s.fov = None;
        s.orthographic = Some(4.0);
        let cam = Camera::new(&s, [4, 2]).unwrap();
        let (o, d) = cam.ray(0, 0, [0.0, 0.0]);
        assert_eq!(d, DVec3::Y);
        assert!((o - DVec3::new(-4.0, -10.0, 2.0)).length() < 1e-12, "{o:?}");
    }

    #[test]
    fn impossible_cameras_are_refused() {
        let mut s = spec();
        s.up = [0.0, 1.0, 0.0];
        assert!(Camera::new(&s, [4, 4]).is_err());
        let mut s = spec();
        s.target = s.eye;
        assert!(Camera::new(&s, [4, 4]).is_err());
        let mut s = spec();
        s.fov = Some(180.0);
        assert!(Camera::new(&s, [4, 4]).is_err());
        assert!(Camera::new(&spec(), [0, 4]).is_err());
        let mut s = spec();
        s.eye[0] = f64::NAN;
        assert!(Camera::new(&s, [4, 4]).is_err());
    }
}
