//! Watertightness of the mesh prims' ray/triangle test: rays aimed exactly at the shared
//! edges and vertices of closed meshes (an icosphere, a subdivided cube) always hit, in f32
//! and f64; open meshes give first hits with the triangle's geometric normal.

use hytrace_csg::{tessellate, MeshPrim, Ray, Real, V3};

mod common;
use common::{cross, grid, sub, Random, Rng};
use hytrace_testkit::vec3::{dot, normalized as unit};

type Tri = [[f64; 3]; 3];

/// An icosphere of radius `r` about `centre`, `levels` times subdivided, counter-clockwise
/// from outside, vertices shared exactly between neighbours.
fn icosphere(r: f64, centre: [f64; 3], levels: usize) -> Vec<Tri> {
    let (verts, faces) = tessellate::icosphere(levels);
    let place = |v: [f64; 3]| [0, 1, 2].map(|k| centre[k] + r * v[k]);
    faces.iter().map(|f| f.map(|i| place(verts[i]))).collect()
}

/// The cube `[-h, h]^3` about `centre` with each face split into `n x n` quads of two
/// triangles, lattice points computed once so neighbours share vertices exactly.
fn subdivided_cube(h: f64, centre: [f64; 3], n: usize) -> Vec<Tri> {
    let at =
        |i: [usize; 3]| [0, 1, 2].map(|k| centre[k] + h * (2.0 * i[k] as f64 / n as f64 - 1.0));
    let mut tris = Vec::new();
    for axis in 0..3 {
        for side in [0, n] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            for i in 0..n {
                for j in 0..n {
                    let corner = |di: usize, dj: usize| {
                        let mut p = [0; 3];
                        p[axis] = side;
                        p[u] = i + di;
                        p[v] = j + dj;
                        at(p)
                    };
                    let (a, b, c, d) = (corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1));
                    for t in [[a, b, c], [a, c, d]] {
                        let mut outward = [0.0; 3];
                        outward[axis] = if side == 0 { -1.0 } else { 1.0 };
                        let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
                        tris.push(if dot(n, outward) > 0.0 {
                            t
                        } else {
                            [t[0], t[2], t[1]]
                        });
                    }
                }
            }
        }
    }
    tris
}

/// Targets on the mesh: every vertex, every edge's midpoint and points at fractions of it.
fn edge_and_vertex_targets(tris: &[Tri]) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            out.push(a);
            for f in [0.5, 1.0 / 3.0, 0.123_456_789] {
                out.push([0, 1, 2].map(|c| a[c] + f * (b[c] - a[c])));
            }
        }
    }
    out
}

/// Rays from outside aimed exactly at every target (coming in within 24 degrees of
/// the outward direction from `centre`, so none grazes a silhouette) must all hit, at the
/// target's distance.
fn assert_watertight<T: Real>(name: &str, tris: &[Tri], centre: [f64; 3], seed: u64) {
    let mesh = MeshPrim::<T>::new(tris).unwrap();
    let mut rng = Rng(seed);
    let targets = edge_and_vertex_targets(tris);
    let mut misses = Vec::new();
    for p in &targets {
        let out = unit(sub(*p, centre));
        let wobble = rng.direction();
        let from = unit([0, 1, 2].map(|k| out[k] + 0.4 * wobble[k]));
        let dist = rng.range(0.5, 50.0);
        let o = [0, 1, 2].map(|k| p[k] + dist * from[k]);
        let d = unit(sub(*p, o));
        let ray = Ray {
            origin: V3::<T>::from_f64(o),
            direction: V3::<T>::from_f64(d),
        };
        let step = mesh.first_crossing(&ray, T::ZERO);
        let expected = dot(sub(*p, o), d);
        let tol = if T::NAME == "f32" { 1e-3 } else { 1e-9 };
        if !step.is_hit() || (step.t.to_f64() - expected).abs() > tol * (1.0 + expected) {
            misses.push((o, d, expected, step.t.to_f64()));
        }
    }
    assert!(
        misses.is_empty(),
        "{name} ({}): {} of {} rays at edges and vertices went wrong, e.g. {:?}",
        T::NAME,
        misses.len(),
        targets.len(),
        &misses[..misses.len().min(5)]
    );
}

fn closed_cases<T: Real>() {
    let c = [5.1, -3.7, 2.2];
    assert_watertight::<T>("icosphere", &icosphere(37.3, c, 3), c, 1);
    assert_watertight::<T>("subdivided cube", &subdivided_cube(12.5, c, 7), c, 2);
    // Far from the origin, where f32 rounding of the sheared vertices is coarse.
    let far = [1e4, -2e4, 3e3];
    assert_watertight::<T>("far icosphere", &icosphere(3.0, far, 2), far, 3);
}

#[test]
fn rays_at_shared_edges_and_vertices_hit_f32() {
    closed_cases::<f32>();
}

#[test]
fn rays_at_shared_edges_and_vertices_hit_f64() {
    closed_cases::<f64>();
}

fn open_case<T: Real>() {
    // A heightfield: an open sheet over a grid, counter-clockwise from above.
    let tris = grid(8, |x, y| {
        ((x as usize * 7 + y as usize * 3) % 5) as f64 * 0.2
    });
    let mesh = MeshPrim::<T>::new(&tris).unwrap();
    // Straight down and straight up at every grid vertex and edge midpoint: a hit at the
    // surface, the normal up (the triangles' geometric normal) either way, "inside" only
    // when coming from below (behind the triangles).
    for i in 0..=16 {
        for j in 0..=16 {
            let (x, y) = (i as f64 * 0.5, j as f64 * 0.5);
            for (oz, dz) in [(10.0, -1.0), (-10.0, 1.0)] {
                let ray = Ray {
                    origin: V3::<T>::from_f64([x, y, oz]),
                    direction: V3::<T>::from_f64([0.0, 0.0, dz]),
                };
                let step = mesh.first_crossing(&ray, T::ZERO);
                assert!(step.is_hit(), "({x}, {y}) from z = {oz}");
                assert!(
                    step.normal.z > T::ZERO,
                    "({x}, {y}): normal {:?}",
                    step.normal
                );
                assert_eq!(step.inside_before, dz > 0.0);
                let height = ((i / 2 * 7 + j / 2 * 3) % 5) as f64 * 0.2;
                if i % 2 == 0 && j % 2 == 0 {
                    let t = step.t.to_f64();
                    assert!((t - (oz - height).abs()).abs() < 1e-5, "({x}, {y}): t {t}");
                }
            }
        }
    }
}

#[test]
fn open_meshes_give_first_hits() {
    open_case::<f32>();
    open_case::<f64>();
}

#[test]
fn closed_meshes_contain_their_inside() {
    let c = [1.0, 2.0, 3.0];
    let mesh = MeshPrim::<f64>::new(&icosphere(10.0, c, 2)).unwrap();
    assert!(mesh.contains(V3::from_f64(c)));
    assert!(!mesh.contains(V3::from_f64([12.0, 2.0, 3.0])));
}
