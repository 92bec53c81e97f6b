//! Draws of rays around a torus (core radius `rtor`, tube radius `r`, centred on the
//! origin, axis z), shared by the CPU kernel's torus tests and the GPU twin's.

use crate::vec3::{add, scale};
use crate::Random;

/// The point of the core circle at azimuth `phi` plus `rad` along the tube direction
/// `(theta, phi)`, and that unit direction.
pub fn tube_point(rtor: f64, phi: f64, theta: f64, rad: f64) -> ([f64; 3], [f64; 3]) {
    let n = [
        theta.cos() * phi.cos(),
        theta.cos() * phi.sin(),
        theta.sin(),
    ];
    (
        add([rtor * phi.cos(), rtor * phi.sin(), 0.0], scale(n, rad)),
        n,
    )
}

/// Ray draws around a torus, for every generator.
pub trait TorusRays: Random {
    /// A point in the torus's bounding box scaled by `k`.
    fn torus_near(&mut self, r: f64, rtor: f64, k: f64) -> [f64; 3] {
        let s = k * (rtor + r);
        [
            self.range(-s, s),
            self.range(-s, s),
            self.range(-k * r, k * r),
        ]
    }

    /// Ray `case` of the axis-aligned family, `(origin, direction)`: by `case % 5`, along
    /// a coordinate axis; with one zero direction component; with zero components in both
    /// origin and direction; parallel to the z axis, on it or through the tube; in the
    /// equatorial plane through the axis.
    fn torus_axis_ray(&mut self, r: f64, rtor: f64, case: usize) -> ([f64; 3], [f64; 3]) {
        let mut o = self.torus_near(r, rtor, 2.0);
        let k = self.below(3);
        let sign = if self.uniform() < 0.5 { -1.0 } else { 1.0 };
        let mut d = [0.0; 3];
        match case % 5 {
            0 => d[k] = sign,
            1 => {
                d = self.direction();
                d[k] = 0.0;
            }
            2 => {
                d = self.direction();
                d[k] = 0.0;
                o[(k + 1) % 3] = 0.0;
            }
            3 => {
                d[2] = sign;
                o[0] = if self.uniform() < 0.2 {
                    0.0
                } else {
                    self.range(0.0, 1.2 * (rtor + r))
                };
                o[1] = 0.0;
            }
            _ => {
                d[k.min(1)] = sign;
                o = [0.0; 3];
                o[k.min(1)] = -sign * self.range(0.0, 3.0) * (rtor + r);
            }
        }
        (o, d)
    }
}

impl<R: Random> TorusRays for R {}
