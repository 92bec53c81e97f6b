//! Axis-aligned bounds of primitives in their own frame, and of transformed boxes.

use hytrace_foundry::Transform64;

use crate::shape::Primitive;

/// Bounds as min xyz, max xyz in double precision.
pub type Aabb = [f64; 6];

/// The empty bounds (min +inf, max -inf): the identity of bounds unions.
pub const EMPTY_AABB: Aabb = [
    f64::INFINITY,
    f64::INFINITY,
    f64::INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
];

/// Half-size of the box standing for "everywhere" in the bounds of unbounded primitives
/// (finite, so it survives transforms and f32 storage).
pub const UNBOUNDED: f64 = 1e30;

/// Bounds of a primitive in its own frame (unbounded primitives: [`UNBOUNDED`]).
pub fn primitive_bounds(p: &Primitive) -> Aabb {
    let revolution = |r: f64, z1: f64, z2: f64| [-r, -r, z1, r, r, z2];
    match p {
        &Primitive::Sphere { radius: r } => [-r, -r, -r, r, r, r],
        &Primitive::ZSphere { radius: r, z1, z2 } => revolution(r, z1, z2),
        &Primitive::Box3 { size } => {
            let h = size.map(|s| 0.5 * s);
            [-h[0], -h[1], -h[2], h[0], h[1], h[2]]
        }
        &Primitive::Cylinder { radius: r, z1, z2 } => revolution(r, z1, z2),
        &Primitive::Tube { rmax, z1, z2, .. } => revolution(rmax, z1, z2),
        &Primitive::Cone { r1, z1, r2, z2 } => revolution(r1.max(r2), z1, z2),
        &Primitive::Hyperboloid {
            r0,
            tan_stereo,
            z1,
            z2,
        } => {
            let z = z1.abs().max(z2.abs());
            revolution((r0 * r0 + tan_stereo * tan_stereo * z * z).sqrt(), z1, z2)
        }
        &Primitive::Torus { rmax, rtor, .. } => {
            let r = rmax + rtor;
            [-r, -r, -rmax, r, r, rmax]
        }
        &Primitive::Paraboloid { rhi, dz, .. } => revolution(rhi, -dz, dz),
        Primitive::Polyhedron { planes } => {
            let mut b = EMPTY_AABB;
            for v in polyhedron_vertices(planes) {
                for k in 0..3 {
                    b[k] = b[k].min(v[k]);
                    b[k + 3] = b[k + 3].max(v[k]);
                }
            }
            b
        }
        Primitive::HalfSpace { .. }
        | Primitive::Slab { .. }
        | Primitive::PhiCut { .. }
        | Primitive::ThetaCut { .. } => {
            let u = UNBOUNDED;
            [-u, -u, -u, u, u, u]
        }
    }
}

/// The vertices of the convex polyhedron `dot(n, x) <= d` over `planes`: every point where
/// three planes meet that lies inside all the others (empty or fewer than four when the
/// planes do not enclose a solid).
pub fn polyhedron_vertices(planes: &[[f64; 4]]) -> Vec<[f64; 3]> {
    let scale = planes.iter().fold(1.0f64, |a, p| a.max(p[3].abs()));
    let mut out: Vec<[f64; 3]> = Vec::new();
    let n = planes.len();
    for i in 0..n {
        for j in i + 1..n {
            for k in j + 1..n {
                let Some(v) = meet(&planes[i], &planes[j], &planes[k]) else {
                    continue;
                };
                let inside = planes
                    .iter()
                    .all(|p| p[0] * v[0] + p[1] * v[1] + p[2] * v[2] - p[3] <= 1e-9 * scale);
                let new = out
                    .iter()
                    .all(|w| (0..3).any(|c| (w[c] - v[c]).abs() > 1e-9 * scale));
                if inside && new {
                    out.push(v);
                }
            }
        }
    }
    // A region whose vertices all sit on one plane is flat, not a solid.
    if out.len() >= 4 {
        let spread = (0..3).fold(0.0f64, |a, c| {
            let (lo, hi) = out
                .iter()
                .fold((f64::INFINITY, -f64::INFINITY), |(l, h), v| {
                    (l.min(v[c]), h.max(v[c]))
                });
            a.max(hi - lo)
        });
        if spread <= 1e-9 * scale {
            out.clear();
        }
    }
    out
}

/// The point where three planes meet (Cramer's rule), if they are independent.
fn meet(a: &[f64; 4], b: &[f64; 4], c: &[f64; 4]) -> Option<[f64; 3]> {
    let cross = |u: [f64; 3], v: [f64; 3]| {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    };
    let (na, nb, nc) = ([a[0], a[1], a[2]], [b[0], b[1], b[2]], [c[0], c[1], c[2]]);
    let bc = cross(nb, nc);
    let det = na[0] * bc[0] + na[1] * bc[1] + na[2] * bc[2];
    if det.abs() < 1e-12 {
        return None;
    }
    let (ca, ab) = (cross(nc, na), cross(na, nb));
    Some(std::array::from_fn(|k| {
        (a[3] * bc[k] + b[3] * ca[k] + c[3] * ab[k]) / det
    }))
}

/// Bounds of the eight corners of `b` mapped through `t`.
pub fn transform_bounds(b: &Aabb, t: &Transform64) -> Aabb {
    let mut out = EMPTY_AABB;
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
