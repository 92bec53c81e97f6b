//! Mesh prims and tessellations against independent references: an extruded L against the
//! CSG union of two boxes, and a twisted box and a twisted tube segment against their exact
//! inside tests marched along each ray in f64.

use hytrace_csg::geant4::{G4Geometry, G4Mapping, G4Solid, XtruSection};
use hytrace_csg::{box3, MeshPrim, PrimTree, Ray, Real, V3};

mod common;
use common::Rng;

fn mesh_of(solid: &G4Solid, tol: f64) -> Vec<[[f64; 3]; 3]> {
    match solid.to_geometry(tol).unwrap() {
        G4Geometry::Mesh(m) => m,
        G4Geometry::Csg(_) => panic!("expected a mesh"),
    }
}

fn ray<T: Real>(o: [f64; 3], d: [f64; 3]) -> Ray<T> {
    Ray {
        origin: V3::from_f64(o),
        direction: V3::from_f64(d),
    }
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

/// Exact inside test of a box of half sizes (dx, dy, dz) twisted by `twist` about z.
fn in_twisted_box(p: [f64; 3], twist: f64, h: [f64; 3]) -> bool {
    if p[2].abs() > h[2] {
        return false;
    }
    let a = -twist * p[2] / (2.0 * h[2]);
    let (s, c) = a.sin_cos();
    let (x, y) = (c * p[0] - s * p[1], s * p[0] + c * p[1]);
    x.abs() <= h[0] && y.abs() <= h[1]
}

/// Reference first crossing: march the exact inside test in steps of `step`, then bisect.
fn marched(o: [f64; 3], d: [f64; 3], inside: &dyn Fn([f64; 3]) -> bool, len: f64) -> f64 {
    let at = |t: f64| [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]];
    let start = inside(at(1e-9));
    let step = 1e-3;
    let mut t = 0.0;
    while t < len {
        let next = t + step;
        if inside(at(next)) != start {
            let (mut lo, mut hi) = (t, next);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if inside(at(mid)) == start {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            return 0.5 * (lo + hi);
        }
        t = next;
    }
    f64::INFINITY
}

#[test]
fn twisted_box_mesh_is_within_its_tolerance_of_the_exact_surface() {
    let (twist, h) = (0.9f64, [6.0, 4.0, 5.0]);
    let solid = G4Solid::TwistedBox {
        twistedangle: twist,
        dx: h[0],
        dy: h[1],
        dz: h[2],
    };
    let tol = 1e-3;
    let mesh = MeshPrim::<f64>::new(&mesh_of(&solid, tol)).unwrap();
    let inside = |p: [f64; 3]| in_twisted_box(p, twist, h);
    let mut rng = Rng(5);
    let (mut checked, mut worst) = (0, 0.0f64);
    for _ in 0..300 {
        let (o, d) = rng.aimed(14.0, 5.6);
        let reference = marched(o, d, &inside, 40.0);
        let step = mesh.first_crossing(&ray::<f64>(o, d), 0.0);
        if reference.is_infinite() {
            continue;
        }
        // Distance error along the ray is the surface error over the cosine of incidence.
        let n = step.normal.normalized().to_f64();
        let cos = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).abs();
        if cos < 0.2 {
            continue;
        }
        let err = (step.t - reference).abs() * cos;
        worst = worst.max(err);
        checked += 1;
        assert!(
            err <= 2.0 * tol,
            "ray {o:?} {d:?}: mesh {} reference {reference}",
            step.t
        );
        assert_eq!(step.inside_before, inside(o));
    }
    assert!(checked > 100, "{checked}");
    eprintln!("twisted box: {checked} rays, worst surface error {worst:.2e} mm (tolerance {tol})");
}

/// Exact inside test of a G4TwistedTubs: at height z the annular sector between the
/// hyperboloids of waist `end * cos(twist / 2)` over `atan(kappa z) +- dphi / 2`.
fn in_twisted_tubs(p: [f64; 3], twist: f64, ends: [f64; 2], dz: f64, dphi: f64) -> bool {
    if p[2].abs() > dz {
        return false;
    }
    let kappa = (0.5 * twist).tan() / dz;
    let grow = (1.0 + (kappa * p[2]).powi(2)).sqrt() * (0.5 * twist).cos();
    let rho = p[0].hypot(p[1]);
    let phi = p[1].atan2(p[0]) - (kappa * p[2]).atan();
    let phi =
        (phi + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    rho >= ends[0] * grow && rho <= ends[1] * grow && phi.abs() <= 0.5 * dphi
}

/// Signed volume of a closed mesh (divergence theorem): positive when outward-facing.
fn mesh_volume(mesh: &[[[f64; 3]; 3]]) -> f64 {
    mesh.iter()
        .map(|t| {
            let [a, b, c] = *t;
            (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                + a[2] * (b[0] * c[1] - b[1] * c[0]))
                / 6.0
        })
        .sum()
}

#[test]
fn twisted_tubs_mesh_is_closed_and_within_its_tolerance() {
    let (twist, ends, dz, dphi) = (-1.1f64, [3.0, 7.5], 5.0, 2.4);
    let solid = G4Solid::TwistedTubs {
        twistedangle: twist,
        endinnerrad: ends[0],
        endouterrad: ends[1],
        halfzlen: dz,
        dphi,
    };
    let tol = 1e-3;
    let tris = mesh_of(&solid, tol);
    // Watertight: every directed edge is matched by its reverse, vertices bit for bit.
    let mut edges = std::collections::HashMap::new();
    for t in &tris {
        for k in 0..3 {
            let key = |p: [f64; 3]| p.map(f64::to_bits);
            let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
            *edges.entry((a, b)).or_insert(0i32) += 1;
            *edges.entry((b, a)).or_insert(0i32) -= 1;
        }
    }
    assert!(edges.values().all(|&v| v == 0), "open or inconsistent mesh");
    // Volume: the sector area dphi / 2 (r_out^2 - r_in^2) (1 + (kappa z)^2) over z.
    let kappa = (0.5 * twist).tan() / dz;
    let c2 = (0.5 * twist).cos().powi(2);
    let exact = 0.5
        * dphi
        * (ends[1] * ends[1] - ends[0] * ends[0])
        * c2
        * (2.0 * dz + 2.0 * kappa * kappa * dz.powi(3) / 3.0);
    let v = mesh_volume(&tris);
    let area_bound = 2.0 * dphi * ends[1] * 2.0 * dz * 3.0;
    assert!(
        (v - exact).abs() <= tol * area_bound,
        "volume {v}, exact {exact}"
    );
    let mesh = MeshPrim::<f64>::new(&tris).unwrap();
    let inside = |p: [f64; 3]| in_twisted_tubs(p, twist, ends, dz, dphi);
    let mut rng = Rng(17);
    let (mut checked, mut worst) = (0, 0.0f64);
    for _ in 0..400 {
        let (o, d) = rng.aimed(12.0, 7.0);
        let reference = marched(o, d, &inside, 40.0);
        let step = mesh.first_crossing(&ray::<f64>(o, d), 0.0);
        if reference.is_infinite() {
            continue;
        }
        let n = step.normal.normalized().to_f64();
        let cos = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).abs();
        if cos < 0.2 {
            continue;
        }
        let err = (step.t - reference).abs() * cos;
        worst = worst.max(err);
        checked += 1;
        assert!(
            err <= 2.0 * tol,
            "ray {o:?} {d:?}: mesh {} reference {reference}",
            step.t
        );
        assert_eq!(step.inside_before, inside(o));
    }
    assert!(checked > 100, "{checked}");
    eprintln!(
        "twisted tubs: {} triangles, {checked} rays, worst surface error {worst:.2e} mm \
         (tolerance {tol})",
        tris.len()
    );
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
    assert!(G4Solid::TwistedBox {
        twistedangle: 0.5,
        dx: 1.0,
        dy: 1.0,
        dz: 1.0
    }
    .to_geometry(0.0)
    .is_err());
    assert!(twisted.to_shape().is_err());
}
