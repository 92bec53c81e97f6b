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
        | Primitive::ThetaCut { .. }
        | Primitive::Saddle { .. }
        | Primitive::TwistedHalfSpace { .. } => {
            let u = UNBOUNDED;
            [-u, -u, -u, u, u, u]
        }
    }
}

/// The vertices of the convex polyhedron `dot(n, x) <= d` over `planes` (unit normals):
/// empty when the planes enclose no bounded solid of positive volume.
///
/// Each plane's face is found by clipping a square on the plane, far larger than any solid
/// the planes can bound, by every other plane: `O(n^2)` clip steps over small polygons
/// (enumerating the meets of every three planes, as before, took `O(n^4)`: 17 s for 500
/// planes). The clipping tracks which plane each edge lies on, and every vertex is then
/// computed where its three planes meet, the same way from whichever face finds it. A face
/// that keeps a side of its square means the region is unbounded.
pub fn polyhedron_vertices(planes: &[[f64; 4]]) -> Vec<[f64; 3]> {
    let scale = planes.iter().fold(1.0f64, |a, p| a.max(p[3].abs()));
    let tol = 1e-9 * scale;
    let reach = 1e6 * scale;
    let mut all: Vec<[f64; 3]> = Vec::new();
    for (i, p) in planes.iter().enumerate() {
        let n = [p[0], p[1], p[2]];
        let foot = n.map(|c| c * p[3]);
        let (u, v) = tangents(n);
        let mut face: Vec<Corner> = [(1.0, 1.0), (-1.0, 1.0), (-1.0, -1.0), (1.0, -1.0)]
            .iter()
            .map(|(a, b)| Corner {
                at: std::array::from_fn(|k| foot[k] + reach * (a * u[k] + b * v[k])),
                edge: None,
            })
            .collect();
        for (j, q) in planes.iter().enumerate() {
            if j != i && !face.is_empty() {
                face = clip(&face, j, q, tol);
            }
        }
        for (k, corner) in face.iter().enumerate() {
            let before = face[(k + face.len() - 1) % face.len()].edge;
            let (Some(e0), Some(e1)) = (before, corner.edge) else {
                // A side of the square survived: nothing closes the region there.
                return Vec::new();
            };
            let mut three = [i, e0, e1];
            three.sort_unstable();
            let [a, b, c] = three.map(|m| &planes[m]);
            all.push(meet(a, b, c).unwrap_or(corner.at));
        }
    }
    let vertices = distinct(all, tol);
    if vertices.len() < 4 || is_flat(&vertices, tol) {
        return Vec::new();
    }
    vertices
}

/// A corner of a face being clipped, and the plane its edge to the next corner lies on
/// (`None` for a side of the starting square).
#[derive(Clone, Copy)]
struct Corner {
    at: [f64; 3],
    edge: Option<usize>,
}

/// The part of the convex polygon `face` where `dot(n, x) <= d + tol` for `plane` (index
/// `index`): one pass of Sutherland and Hodgman's clipping; the new edge lies on `plane`.
fn clip(face: &[Corner], index: usize, plane: &[f64; 4], tol: f64) -> Vec<Corner> {
    let side = |x: &[f64; 3]| plane[0] * x[0] + plane[1] * x[1] + plane[2] * x[2] - plane[3];
    let mut out = Vec::with_capacity(face.len() + 1);
    for (k, a) in face.iter().enumerate() {
        let b = &face[(k + 1) % face.len()];
        let (sa, sb) = (side(&a.at), side(&b.at));
        let (a_in, b_in) = (sa <= tol, sb <= tol);
        if a_in {
            out.push(*a);
        }
        if a_in != b_in {
            let t = sa / (sa - sb);
            let at = std::array::from_fn(|c| a.at[c] + t * (b.at[c] - a.at[c]));
            // Leaving: the boundary runs on along the clipping plane; entering: along a's edge.
            let edge = if a_in { Some(index) } else { a.edge };
            out.push(Corner { at, edge });
        }
    }
    out
}

/// The cross product `a x b`.
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The point where three planes meet (Cramer's rule), if they are independent.
fn meet(a: &[f64; 4], b: &[f64; 4], c: &[f64; 4]) -> Option<[f64; 3]> {
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

/// Whether `points` (at least one) lie within `tol` of one plane: the plane through the
/// first point, the point farthest from it and the point farthest from their line.
fn is_flat(points: &[[f64; 3]], tol: f64) -> bool {
    let o = points[0];
    let d = |x: &[f64; 3]| [x[0] - o[0], x[1] - o[1], x[2] - o[2]];
    let dot = |x: [f64; 3], y: [f64; 3]| x[0] * y[0] + x[1] * y[1] + x[2] * y[2];
    let farthest = |key: &dyn Fn(&[f64; 3]) -> f64| {
        points
            .iter()
            .max_by(|a, b| key(a).total_cmp(&key(b)))
            .copied()
            .unwrap_or(o)
    };
    let a = d(&farthest(&|x| dot(d(x), d(x))));
    let b = d(&farthest(&|x| {
        let c = cross(a, d(x));
        dot(c, c)
    }));
    let n = cross(a, b);
    let len = dot(n, n).sqrt();
    len == 0.0 || points.iter().all(|x| dot(n, d(x)).abs() <= tol * len)
}

/// Two unit vectors perpendicular to the unit `n` and to each other.
fn tangents(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = cross(n, a);
    let l = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
    let u = u.map(|c| c / l);
    (u, cross(n, u))
}

/// `points` with those within `tol` of an earlier one (in every coordinate) removed.
fn distinct(mut points: Vec<[f64; 3]>, tol: f64) -> Vec<[f64; 3]> {
    points.sort_by(|a, b| a[0].total_cmp(&b[0]));
    let mut out: Vec<[f64; 3]> = Vec::new();
    for p in points {
        // Earlier points within `tol` in x are the last ones kept.
        let seen = out
            .iter()
            .rev()
            .take_while(|q| p[0] - q[0] <= tol)
            .any(|q| (0..3).all(|c| (p[c] - q[c]).abs() <= tol));
        if !seen {
            out.push(p);
        }
    }
    out
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

#[cfg(test)]
mod tests {
    use super::*;
    use hytrace_testkit::{Random, XorShift64};

    /// The reference: every point where three planes meet that lies inside all of them.
    fn triple_meets(planes: &[[f64; 4]], tol: f64) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for i in 0..planes.len() {
            for j in i + 1..planes.len() {
                for k in j + 1..planes.len() {
                    let (a, b, c) = (planes[i], planes[j], planes[k]);
                    let m = [[a[0], a[1], a[2]], [b[0], b[1], b[2]], [c[0], c[1], c[2]]];
                    let det = |m: [[f64; 3]; 3]| {
                        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
                    };
                    let d = det(m);
                    if d.abs() < 1e-12 {
                        continue;
                    }
                    // Cramer's rule, column by column.
                    let x: [f64; 3] = std::array::from_fn(|col| {
                        let mut mc = m;
                        for (row, r) in mc.iter_mut().enumerate() {
                            r[col] = [a[3], b[3], c[3]][row];
                        }
                        det(mc) / d
                    });
                    if planes
                        .iter()
                        .all(|p| p[0] * x[0] + p[1] * x[1] + p[2] * x[2] - p[3] <= tol)
                    {
                        out.push(x);
                    }
                }
            }
        }
        distinct(out, tol)
    }

    fn plane(n: [f64; 3], d: f64) -> [f64; 4] {
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        [n[0] / l, n[1] / l, n[2] / l, d]
    }

    #[test]
    fn face_clipping_finds_the_vertices_three_plane_meets_find() {
        let mut rng = XorShift64(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.uniform();
        for trial in 0..20 {
            // Planes tangent to a sphere of radius 10 about (3, -2, 5), in a cube of side 24.
            let mut planes: Vec<[f64; 4]> = (0..6)
                .map(|k| {
                    let mut n = [0.0; 3];
                    n[k % 3] = if k < 3 { 1.0 } else { -1.0 };
                    let c = [3.0, -2.0, 5.0][k % 3] * n[k % 3];
                    plane(n, c + 12.0)
                })
                .collect();
            for _ in 0..4 + trial {
                let n = [next() - 0.5, next() - 0.5, next() - 0.5];
                let p = plane(n, 0.0);
                planes.push([
                    p[0],
                    p[1],
                    p[2],
                    10.0 + 3.0 * p[0] - 2.0 * p[1] + 5.0 * p[2],
                ]);
            }
            let got = polyhedron_vertices(&planes);
            let want = triple_meets(&planes, 1e-9 * 40.0);
            assert_eq!(got.len(), want.len(), "trial {trial}");
            let near = |a: &[f64; 3], b: &[f64; 3]| (0..3).all(|k| (a[k] - b[k]).abs() < 1e-7);
            for g in &got {
                assert!(want.iter().any(|w| near(g, w)), "trial {trial}: {g:?}");
            }
        }
    }

    #[test]
    fn unbounded_and_flat_regions_have_no_vertices() {
        // A square prism closed at one end only: its four bottom corners are three-plane
        // meets inside every plane, but the region is unbounded.
        let prism = [
            plane([1.0, 0.0, 0.0], 1.0),
            plane([-1.0, 0.0, 0.0], 1.0),
            plane([0.0, 1.0, 0.0], 1.0),
            plane([0.0, -1.0, 0.0], 1.0),
            plane([0.0, 0.0, -1.0], 1.0),
        ];
        assert!(polyhedron_vertices(&prism).is_empty());
        // A box of zero height.
        let mut flat = prism.to_vec();
        flat.push(plane([0.0, 0.0, 1.0], -1.0));
        assert!(polyhedron_vertices(&flat).is_empty());
        // The unit cube, closed: its eight corners.
        let mut cube = prism.to_vec();
        cube.push(plane([0.0, 0.0, 1.0], 1.0));
        assert_eq!(polyhedron_vertices(&cube).len(), 8);
    }

    #[test]
    fn thousands_of_planes_are_bounded_in_quadratic_time() {
        // 4096 planes tangent to the unit sphere (a Fibonacci lattice of normals): the
        // vertices lie between the sphere and the circumscribed shell.
        let n = 4096;
        let planes: Vec<[f64; 4]> = (0..n)
            .map(|i| {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
                let r = (1.0 - z * z).sqrt();
                [r * phi.cos(), r * phi.sin(), z, 1.0]
            })
            .collect();
        let vertices = polyhedron_vertices(&planes);
        assert!(vertices.len() > n);
        for v in vertices {
            let r = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((1.0..1.01).contains(&r), "{r}");
        }
    }
}
