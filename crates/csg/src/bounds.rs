//! Axis-aligned bounds of primitives in their own frame, and of transformed boxes.

use hytrace_foundry::Transform64;

use crate::shape::Primitive;

/// Bounds as min xyz, max xyz in double precision.
pub type Aabb = [f64; 6];

/// Bounds of a primitive in its own frame.
pub fn primitive_bounds(p: &Primitive) -> Aabb {
    match *p {
        Primitive::Sphere { radius: r } => [-r, -r, -r, r, r, r],
        Primitive::Box3 { size } => {
            let h = size.map(|s| 0.5 * s);
            [-h[0], -h[1], -h[2], h[0], h[1], h[2]]
        }
        Primitive::Cylinder { radius: r, z1, z2 } => [-r, -r, z1, r, r, z2],
        Primitive::Cone { r1, z1, r2, z2 } => {
            let r = r1.max(r2);
            [-r, -r, z1, r, r, z2]
        }
        Primitive::Torus { rmax, rtor, .. } => {
            let r = rmax + rtor;
            [-r, -r, -rmax, r, r, rmax]
        }
    }
}

/// Bounds of the eight corners of `b` mapped through `t`.
pub fn transform_bounds(b: &Aabb, t: &Transform64) -> Aabb {
    let mut out = [
        f64::INFINITY,
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for corner in 0..8 {
        let p = [0, 1, 2].map(|k| if corner >> k & 1 == 0 { b[k] } else { b[k + 3] });
        let q = t.apply_point(p);
        for k in 0..3 {
            out[k] = out[k].min(q[k]);
            out[k + 3] = out[k + 3].max(q[k]);
        }
    }
    out
}
