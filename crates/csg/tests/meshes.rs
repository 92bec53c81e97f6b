//! Mesh prims and tessellations against independent references: an extruded L against the
//! CSG union of two boxes. Extruded solids' exact CSG form (a union of
//! convex polyhedra) against their exact mesh and their marched inside test, on rays across,
//! along and through the faces and edges the convex pieces share.

use hytrace_csg::geant4::{G4Geometry, G4Mapping, G4Solid, XtruSection};
use hytrace_csg::tessellate::{convex_pieces, simple_polygon};
use hytrace_csg::{box3, MeshPrim, PrimTree, Ray, Real, V3};

mod common;
use common::{Random, Rng};

fn mesh_of(solid: &G4Solid, tol: f64) -> Vec<[[f64; 3]; 3]> {
    match solid.to_geometry(tol).unwrap() {
        G4Geometry::Mesh(m) => m,
        G4Geometry::Csg(_) => panic!("expected a mesh"),
    }
}

fn ray<T: Real>(o: [f64; 3], d: [f64; 3]) -> Ray<T> {
    Ray::from_f64(o, d)
}

fn l_shape_case<T: Real>() {
    // L = [0,20]x[0,10] + [0,10]x[10,20], extruded over z in [-5, 5].
    let l = G4Solid::Xtru {
        polygon: vec![
            [0.0, 0.0],
            [20.0, 0.0],
            [20.0, 10.0],
            [10.0, 10.0],
            [10.0, 20.0],
            [0.0, 20.0],
        ],
        sections: vec![
            XtruSection {
                z: -5.0,
                offset: [0.0, 0.0],
                scale: 1.0,
            },
            XtruSection {
                z: 5.0,
                offset: [0.0, 0.0],
                scale: 1.0,
            },
        ],
    };
    let mesh = MeshPrim::<T>::new(&mesh_of(&l, 1e-3)).unwrap();
    let csg = PrimTree::<T>::from_shape(
        &(box3(20.0, 10.0, 10.0).unwrap().translate(10.0, 5.0, 0.0)
            + box3(10.0, 10.0, 10.0).unwrap().translate(5.0, 15.0, 0.0)),
    )
    .unwrap();
    let mut rng = Rng(99);
    let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
    let mut compared = 0;
    for _ in 0..5000 {
        let (o, d) = rng.aimed(24.0, 9.6);
        let o = [o[0] + 8.0, o[1] + 8.0, o[2]];
        let r = ray::<T>(o, d);
        // Skip origins within the tolerance of the shared internal face x <= 10, y = 10.
        let a = mesh.first_crossing(&r, T::ZERO);
        let b = csg.first_crossing(&r, T::ZERO);
        let (ta, tb) = (a.t.to_f64(), b.t.to_f64());
        assert!(
            (ta - tb).abs() <= tol * (1.0 + tb.abs()) || (ta.is_infinite() && tb.is_infinite()),
            "{}: ray {o:?} {d:?}: mesh {ta}, csg {tb}",
            T::NAME
        );
        assert_eq!(a.inside_before, b.inside_before);
        assert_eq!(
            mesh.contains(r.origin),
            csg.contains(r.origin),
            "{}: {o:?}",
            T::NAME
        );
        compared += ta.is_finite() as usize;
    }
    assert!(compared > 1000);
}

#[test]
fn extruded_l_matches_the_union_of_two_boxes_f32() {
    l_shape_case::<f32>();
}

#[test]
fn extruded_l_matches_the_union_of_two_boxes_f64() {
    l_shape_case::<f64>();
}

#[test]
fn bad_meshes_and_sections_are_errors() {
    assert!(MeshPrim::<f64>::new(&[]).is_err());
    assert!(
        MeshPrim::<f64>::new(&[[[0.0, 0.0, f64::NAN], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]]).is_err()
    );
    let self_crossing = G4Solid::Xtru {
        polygon: vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]],
        sections: vec![
            XtruSection {
                z: 0.0,
                offset: [0.0, 0.0],
                scale: 1.0,
            },
            XtruSection {
                z: 1.0,
                offset: [0.0, 0.0],
                scale: 1.0,
            },
        ],
    };
    assert!(self_crossing.to_geometry(1e-3).is_err());
    let one_section = G4Solid::Xtru {
        polygon: vec![[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]],
        sections: vec![XtruSection {
            z: 0.0,
            offset: [0.0, 0.0],
            scale: 1.0,
        }],
    };
    assert!(one_section.to_geometry(1e-3).is_err());
    let twisted = G4Solid::TwistedBox {
        twistedangle: 0.5,
        dx: 1.0,
        dy: -1.0,
        dz: 1.0,
    };
    assert!(twisted.to_geometry(1e-3).is_err());
    assert!(twisted.to_shape().is_err());
}

/// An extruded solid's exact inside test: the section at z (scale and offset linear between
/// sections), then even-odd in the polygon.
fn in_xtru(poly: &[[f64; 2]], sections: &[XtruSection], p: [f64; 3]) -> bool {
    let Some(k) = sections
        .windows(2)
        .position(|w| w[0].z <= p[2] && p[2] <= w[1].z)
    else {
        return false;
    };
    let (a, b) = (&sections[k], &sections[k + 1]);
    let f = (p[2] - a.z) / (b.z - a.z);
    let s = a.scale + f * (b.scale - a.scale);
    let q = [0, 1].map(|i| (p[i] - (a.offset[i] + f * (b.offset[i] - a.offset[i]))) / s);
    let mut odd = false;
    for i in 0..poly.len() {
        let (u, v) = (poly[i], poly[(i + 1) % poly.len()]);
        if (u[1] > q[1]) != (v[1] > q[1])
            && q[0] < u[0] + (v[0] - u[0]) * (q[1] - u[1]) / (v[1] - u[1])
        {
            odd = !odd;
        }
    }
    odd
}

fn section_point(s: &XtruSection, p: [f64; 2]) -> [f64; 3] {
    [
        s.scale * p[0] + s.offset[0],
        s.scale * p[1] + s.offset[1],
        s.z,
    ]
}

fn lerp3(a: [f64; 3], b: [f64; 3], f: f64) -> [f64; 3] {
    [0, 1, 2].map(|k| a[k] + f * (b[k] - a[k]))
}

fn unit3(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    v.map(|c| c / l)
}

/// The exit of a ray starting inside the solid, marched in steps of 2e-3 and bisected.
fn marched_exit(inside: &dyn Fn([f64; 3]) -> bool, o: [f64; 3], d: [f64; 3]) -> f64 {
    let at = |t: f64| [0, 1, 2].map(|k| o[k] + t * d[k]);
    let mut t = 0.0;
    while inside(at(t + 2e-3)) {
        t += 2e-3;
        assert!(t < 1e3, "no exit");
    }
    let (mut lo, mut hi) = (t, t + 2e-3);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if inside(at(mid)) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

fn comb() -> Vec<[f64; 2]> {
    // Four teeth of width 1 on a base [0, 7] x [0, 1], 3 high; scaled by 2.
    let mut p = vec![[0.0, 0.0], [7.0, 0.0]];
    for t in (0..4).rev() {
        let x = 2.0 * t as f64;
        p.extend([[x + 1.0, 3.0], [x, 3.0]]);
        if t > 0 {
            p.extend([[x, 1.0], [x - 1.0, 1.0]]);
        }
    }
    p.iter()
        .map(|q| [2.0 * q[0] - 7.0, 2.0 * q[1] - 3.0])
        .collect()
}

fn star() -> Vec<[f64; 2]> {
    (0..16)
        .map(|k| {
            let a = k as f64 * std::f64::consts::PI / 8.0;
            let r = if k % 2 == 0 { 8.0 } else { 3.0 };
            [r * a.cos(), r * a.sin()]
        })
        .collect()
}

/// GDML's scaledSolids U (clockwise, three corners on one line), scaled down 30 times.
fn u_shape() -> Vec<[f64; 2]> {
    [
        [-300.0, -300.0],
        [-300.0, 300.0],
        [300.0, 300.0],
        [300.0, -300.0],
        [150.0, -300.0],
        [150.0, 150.0],
        [-150.0, 150.0],
        [-150.0, -300.0],
    ]
    .iter()
    .map(|p| [p[0] / 30.0, p[1] / 30.0])
    .collect()
}

fn l_polygon() -> Vec<[f64; 2]> {
    vec![
        [-10.0, -10.0],
        [10.0, -10.0],
        [10.0, 0.0],
        [0.0, 0.0],
        [0.0, 10.0],
        [-10.0, 10.0],
    ]
}

fn sections(list: &[(f64, [f64; 2], f64)]) -> Vec<XtruSection> {
    list.iter()
        .map(|&(z, offset, scale)| XtruSection { z, offset, scale })
        .collect()
}

/// The exact CSG form of an extruded solid against its exact mesh (rays from outside) and
/// against the marched inside test (rays from inside across, along and through the faces
/// and edges the convex pieces share, which must not show).
fn xtru_case<T: Real>(name: &str, polygon: &[[f64; 2]], secs: &[XtruSection], seed: u64) {
    let solid = G4Solid::Xtru {
        polygon: polygon.to_vec(),
        sections: secs.to_vec(),
    };
    let csg = PrimTree::<T>::from_shape(&solid.to_shape().unwrap()).unwrap();
    let mesh = MeshPrim::<T>::new(&mesh_of(&solid, 1e-3)).unwrap();
    let poly = simple_polygon(polygon).unwrap();
    let pieces = convex_pieces(&poly, 32).unwrap();
    let inside = |p: [f64; 3]| in_xtru(&poly, secs, p);
    let size = poly
        .iter()
        .fold(0.0f64, |m, p| m.max(p[0].abs()).max(p[1].abs()))
        * secs.iter().fold(0.0f64, |m, s| m.max(s.scale))
        + secs
            .iter()
            .fold(0.0f64, |m, s| {
                m.max(s.offset[0].abs()).max(s.offset[1].abs())
            })
            .max(secs[secs.len() - 1].z.abs())
            .max(secs[0].z.abs());
    let tol = |t: f64| {
        if T::NAME == "f32" {
            1e-5 * (size + t.abs())
        } else {
            1e-10 * (size + t.abs())
        }
    };
    let mut rng = Rng(seed);
    // Rays from outside: the CSG agrees with the mesh.
    let mut hits = 0;
    for _ in 0..2000 {
        let (o, d) = rng.aimed(1.5 * size, 0.7 * size);
        let r = ray::<T>(o, d);
        let (a, b) = (
            mesh.first_crossing(&r, T::ZERO),
            csg.first_crossing(&r, T::ZERO),
        );
        let (ta, tb) = (a.t.to_f64(), b.t.to_f64());
        assert!(
            (ta - tb).abs() <= tol(ta) || (ta.is_infinite() && tb.is_infinite()),
            "{name} {}: ray {o:?} {d:?}: mesh {ta}, csg {tb}",
            T::NAME
        );
        assert_eq!(a.inside_before, b.inside_before, "{name}: {o:?} {d:?}");
        assert_eq!(csg.contains(r.origin), inside(o), "{name}: {o:?}");
        hits += tb.is_finite() as usize;
    }
    assert!(hits > 500, "{name}: {hits}");
    // Shared faces: the diagonals between pieces, swept between each pair of sections.
    let diagonals: Vec<(usize, usize)> = pieces
        .iter()
        .flat_map(|p| (0..p.len()).map(move |k| (p[k], p[(k + 1) % p.len()])))
        .filter(|&(a, b)| a < b && b != a + 1 && !(a == 0 && b == poly.len() - 1))
        .collect();
    assert_eq!(diagonals.len(), pieces.len() - 1, "{name}");
    let mut checked = 0;
    let mut check = |o: [f64; 3], d: [f64; 3], what: &str| {
        if !inside(o) {
            return;
        }
        let want = marched_exit(&inside, o, d);
        let step = csg.first_crossing(&ray::<T>(o, d), T::ZERO);
        let got = step.t.to_f64();
        assert!(
            (got - want).abs() <= tol(want) && step.inside_before,
            "{name} {} {what}: ray {o:?} {d:?}: exit {want}, csg {got} (inside before {})",
            T::NAME,
            step.inside_before
        );
        checked += 1;
    };
    for &(i, j) in &diagonals {
        for pair in secs.windows(2) {
            let (sa, sb) = (&pair[0], &pair[1]);
            for _ in 0..20 {
                let (u, v) = (rng.range(0.05, 0.95), rng.range(0.05, 0.95));
                let at = |s: &XtruSection| {
                    let p = [0, 1].map(|k| poly[i][k] + u * (poly[j][k] - poly[i][k]));
                    section_point(s, p)
                };
                let o = lerp3(at(sa), at(sb), v);
                // The face's points are inside (the members' signed distances are 0 there,
                // or about the rounding of the point to T).
                assert!(
                    !inside(o) || csg.contains(V3::from_f64(o)),
                    "{name} {}: {o:?} on a shared face",
                    T::NAME
                );
                // Across the face from either side, and from a point on it.
                let d = rng.direction();
                let n = [d[0], d[1], d[2]];
                check(o, n, "from a shared face");
                let back = rng.range(0.1, 0.5);
                let back = [0, 1, 2].map(|k| o[k] - back * d[k]);
                check(back, n, "across a shared face");
                // Along the face: a direction in its plane (unless other corners are in line
                // with the diagonal: the plane then holds outer faces, where a ray running
                // along the surface may count as inside or outside).
                let in_line = (0..poly.len()).any(|k| {
                    let (p, q, r) = (poly[i], poly[j], poly[k]);
                    k != i
                        && k != j
                        && ((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])).abs()
                            < 1e-9
                });
                if in_line {
                    continue;
                }
                let (f1, f2) = (rng.range(-1.0, 1.0), rng.range(-1.0, 1.0));
                let along = unit3(std::array::from_fn(|k| {
                    let e1 = section_point(sa, poly[j])[k] - section_point(sa, poly[i])[k];
                    let e2 = at(sb)[k] - at(sa)[k];
                    // Rounding leaves ~1e-17 across an axis-aligned face (see
                    // `list_culling_of_a_ray_grazing_a_shared_face`).
                    f1 * e1 + f2 * e2
                }));
                check(o, along, "along a shared face");
                check(o, along.map(|c| -c), "along a shared face");
            }
        }
    }
    // Where the shared faces meet the solid's surface (its side edges at the diagonals'
    // corners, reflex or not, and its caps) the inside test is the signed distance's.
    for &(i, j) in &diagonals {
        let last = &secs[secs.len() - 1];
        for _ in 0..10 {
            let c = poly[if rng.uniform() < 0.5 { i } else { j }];
            let k = (rng.uniform() * (secs.len() - 1) as f64) as usize;
            let side = lerp3(
                section_point(&secs[k], c),
                section_point(&secs[k + 1], c),
                rng.range(0.0, 1.0),
            );
            let u = rng.range(0.05, 0.95);
            let p = [0, 1].map(|k| poly[i][k] + u * (poly[j][k] - poly[i][k]));
            let cap = section_point(if rng.uniform() < 0.5 { &secs[0] } else { last }, p);
            for o in [side, cap] {
                let x = V3::<T>::from_f64(o);
                assert_eq!(
                    csg.contains(x),
                    csg.sdf(x) < T::ZERO,
                    "{name} {}: {o:?} on the surface",
                    T::NAME
                );
            }
        }
    }
    // Shared edges and faces of the middle sections: the diagonals and the pieces' caps.
    for s in &secs[1..secs.len() - 1] {
        for &(i, j) in &diagonals {
            for _ in 0..20 {
                let u = rng.range(0.05, 0.95);
                let p = [0, 1].map(|k| poly[i][k] + u * (poly[j][k] - poly[i][k]));
                let e = section_point(s, p);
                assert!(
                    csg.contains(V3::from_f64(e)),
                    "{name} {}: {e:?} on a shared edge",
                    T::NAME
                );
                let d = rng.direction();
                check(e, d, "from a shared edge");
                let back = rng.range(0.2, 0.8);
                let o = [0, 1, 2].map(|k| e[k] - back * d[k]);
                check(o, d, "through a shared edge");
                // In the section's plane, exactly.
                let a = rng.range(0.0, std::f64::consts::TAU);
                check(e, [a.cos(), a.sin(), 0.0], "in a section plane");
            }
        }
        // Through the corners of the section (where up to all pieces meet). Only in f64:
        // in f32 the rounded ray passes up to ~1e-6 mm beside the corner, and one leaving
        // it nearly along a side face may legitimately graze out there.
        if T::NAME == "f64" {
            for c in &poly {
                let e = section_point(s, *c);
                for _ in 0..5 {
                    let d = rng.direction();
                    let back = rng.range(0.2, 0.8);
                    let o = [0, 1, 2].map(|k| e[k] - back * d[k]);
                    check(o, d, "through a corner");
                }
            }
        }
    }
    assert!(checked >= 60, "{name}: {checked}");
    eprintln!(
        "{name} {}: {} pieces, {} sections, {hits} hits from outside, {checked} rays over \
         shared faces and edges",
        T::NAME,
        pieces.len(),
        secs.len()
    );
}

fn xtru_cases<T: Real>() {
    let prism = sections(&[(-5.0, [0.0, 0.0], 1.0), (5.0, [0.0, 0.0], 1.0)]);
    let tapered = sections(&[
        (-5.0, [0.0, 0.0], 1.0),
        (-1.0, [1.0, -0.5], 0.8),
        (4.0, [-0.5, 1.0], 1.2),
    ]);
    for (name, poly) in [
        ("L", l_polygon()),
        ("comb", comb()),
        ("star", star()),
        ("U", u_shape()),
    ] {
        xtru_case::<T>(name, &poly, &prism, 3);
        xtru_case::<T>(name, &poly, &tapered, 4);
    }
}

#[test]
fn xtru_csg_is_exact_and_hides_shared_faces_f32() {
    xtru_cases::<f32>();
}

#[test]
fn xtru_csg_is_exact_and_hides_shared_faces_f64() {
    xtru_cases::<f64>();
}

/// Regression: a list member was skipped when `ray_meets_bounds(ray, member_bounds, tau,
/// inf)` failed, with no tolerance. A ray lying in a shared axis-aligned face (here the
/// star's core/spike face x = 3 cos 22.5 deg), with a ~1e-17 direction component across it,
/// leaves the core's bounding box at t = 0 by the slab test while the core's own plane
/// (rounded the same way as the spike's) keeps it inside up to t = 0.41, where the spike's
/// plane lets it go: the core was culled after the first step and the union reported a
/// miss from outside. In f32 only (the ray origin rounds onto the box face; f64 origins
/// keep the box's f32 slack). Members' boxes are now widened by the surface tolerance.
#[test]
fn list_culling_of_a_ray_grazing_a_shared_face() {
    let solid = G4Solid::Xtru {
        polygon: star(),
        sections: sections(&[(-5.0, [0.0, 0.0], 1.0), (5.0, [0.0, 0.0], 1.0)]),
    };
    let csg = PrimTree::<f32>::from_shape(&solid.to_shape().unwrap()).unwrap();
    let o = [
        3.0 * 22.5f64.to_radians().cos(),
        0.5613129582616644,
        -0.4607880721460695,
    ];
    let d = [
        8.453081870745347e-18,
        0.08530487735748947,
        0.9963548955563091,
    ];
    let step = csg.first_crossing(&ray::<f32>(o, d), 0.0);
    assert!(step.inside_before);
    assert!((step.t - 5.480766).abs() < 1e-4, "{step:?}");
}

/// Regression: the union's signed distance is the minimum over its members, exactly 0 on
/// a face two convex pieces share when the point lies on that plane in floating point, and
/// `contains` wanted it negative: the L's pieces meet on the diagonal x = y, and (-5, -5,
/// 0) read as outside.
#[test]
fn points_exactly_on_a_shared_face_are_inside() {
    let solid = G4Solid::Xtru {
        polygon: l_polygon(),
        sections: sections(&[(-5.0, [0.0, 0.0], 1.0), (5.0, [0.0, 0.0], 1.0)]),
    };
    let csg = PrimTree::<f64>::from_shape(&solid.to_shape().unwrap()).unwrap();
    assert!(csg.contains(V3::from_f64([-5.0, -4.9, 0.0])));
    assert!(csg.contains(V3::from_f64([-5.0, -5.0, 0.0])));
}
