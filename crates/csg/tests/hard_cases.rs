//! Numerical hard cases of CSG intersection, each against an independent float64 reference
//! written here from the geometry (not from the kernels): far from the origin, grazing and
//! tangent rays, rays starting on surfaces, thin shells, tiny and huge solids, degenerate
//! parameters, zero direction components and coincident faces.

use hytrace_csg::{
    box3, cone, cylinder, phi_cut, polyhedron, sphere, theta_cut, torus, tube, PrimTree, Ray, Real,
    Shape, V3,
};

mod common;
use common::{Random, Rng};
use hytrace_testkit::vec3::{dot, sub};

/// Rounds to what an f32 rays file can hold, so both precisions see the same ray.
fn f32_exact(v: [f64; 3]) -> [f64; 3] {
    v.map(|c| c as f32 as f64)
}

/// First crossing after `tmin`: (t, normal, inside before).
fn cross<T: Real>(
    tree: &PrimTree<T>,
    o: [f64; 3],
    d: [f64; 3],
    tmin: f64,
) -> (f64, [f64; 3], bool) {
    let ray = Ray::from_f64(o, d);
    let s = tree.first_crossing(&ray, T::from_f64(tmin));
    (
        s.t.to_f64(),
        s.normal.normalized().to_f64(),
        s.inside_before,
    )
}

fn prepared<T: Real>(shape: &Shape) -> PrimTree<T> {
    PrimTree::from_shape(shape).unwrap()
}

/// Reference: the two crossings of a line (any direction length) with a sphere, in f64 with
/// the closest-approach form (no cancellation for far origins).
fn sphere_reference(c: [f64; 3], r: f64, o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
    let oc = sub(o, c);
    let a = dot(d, d);
    let tc = -dot(oc, d) / a;
    let h = [oc[0] + tc * d[0], oc[1] + tc * d[1], oc[2] + tc * d[2]];
    let q = (r * r - dot(h, h)) / a;
    (q >= 0.0).then(|| (tc - q.sqrt(), tc + q.sqrt()))
}

/// Reference: entry and exit of a line through an axis-aligned box of half sizes `h`
/// centred on `c`, with rotation rows `rot` (world = rot^T local).
fn box_reference(
    c: [f64; 3],
    rot: [[f64; 3]; 3],
    h: [f64; 3],
    o: [f64; 3],
    d: [f64; 3],
) -> Option<(f64, f64)> {
    let oc = sub(o, c);
    let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        let (ok, dk) = (dot(rot[k], oc), dot(rot[k], d));
        if dk == 0.0 {
            if ok.abs() > h[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-h[k] - ok) / dk, (h[k] - ok) / dk);
        lo = lo.max(a.min(b));
        hi = hi.min(a.max(b));
    }
    (lo <= hi).then_some((lo, hi))
}

/// The first crossing after 0 of a (entry, exit) pair.
fn first_after_zero(span: Option<(f64, f64)>) -> f64 {
    match span {
        Some((a, _)) if a > 0.0 => a,
        Some((_, b)) if b > 0.0 => b,
        _ => f64::INFINITY,
    }
}

#[test]
fn far_from_origin_solids_placed_20_m_out() {
    // Sphere and rotated box placed ~2e4 mm from the origin, rays starting within 0.6 m.
    let c = [20000.0, -15000.0, 20000.0];
    let axis = [1.0 / 3f64.sqrt(); 3];
    let angle = 0.7f64;
    let s = sphere(100.0).unwrap().translate(c[0], c[1], c[2]);
    let b = box3(80.0, 120.0, 60.0)
        .unwrap()
        .rotate(axis, angle)
        .translate(c[0] + 300.0, c[1], c[2]);
    // Rotation rows (local = R^T world) of the same rotation, from Rodrigues' formula.
    let (sn, cs) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - cs;
    let world_from_local = [
        [t * x * x + cs, t * x * y - sn * z, t * x * z + sn * y],
        [t * x * y + sn * z, t * y * y + cs, t * y * z - sn * x],
        [t * x * z - sn * y, t * y * z + sn * x, t * z * z + cs],
    ];
    let local_rows: [[f64; 3]; 3] = std::array::from_fn(|k| {
        [
            world_from_local[0][k],
            world_from_local[1][k],
            world_from_local[2][k],
        ]
    });
    let bc = [c[0] + 300.0, c[1], c[2]];
    let trees32 = [prepared::<f32>(&s), prepared::<f32>(&b)];
    let trees64 = [prepared::<f64>(&s), prepared::<f64>(&b)];
    let mut rng = Rng(7);
    let (mut worst32, mut worst64) = (0.0f64, 0.0f64);
    for i in 0..4000 {
        let which = i % 2;
        let centre = if which == 0 { c } else { bc };
        let dir_out = rng.direction();
        let dist = rng.range(150.0, 600.0);
        let o = f32_exact([
            centre[0] + dist * dir_out[0],
            centre[1] + dist * dir_out[1],
            centre[2] + dist * dir_out[2],
        ]);
        // Within 24 mm of the centre: inside both solids whatever the box's rotation.
        let target = [
            centre[0] + rng.range(-14., 14.),
            centre[1] + rng.range(-14., 14.),
            centre[2] + rng.range(-14., 14.),
        ];
        let d = sub(target, o);
        let l = dot(d, d).sqrt();
        let d = f32_exact(d.map(|v| v / l));
        let reference = if which == 0 {
            first_after_zero(sphere_reference(c, 100.0, o, d))
        } else {
            first_after_zero(box_reference(bc, local_rows, [40.0, 60.0, 30.0], o, d))
        };
        assert!(reference.is_finite());
        worst32 = worst32.max((cross(&trees32[which], o, d, 0.0).0 - reference).abs());
        worst64 = worst64.max((cross(&trees64[which], o, d, 0.0).0 - reference).abs());
    }
    eprintln!("far from the origin: worst error f32 {worst32:.2e} mm, f64 {worst64:.2e} mm");
    assert!(worst32 <= 1e-3, "f32 worst error {worst32} mm");
    assert!(worst64 <= 1e-6, "f64 worst error {worst64} mm");
}

/// Band of impact parameters around tangency where hit or miss may go either way, relative
/// to the solid's size: f32 1e-5, f64 1e-10.
fn band<T: Real>() -> f64 {
    if T::NAME == "f32" {
        1e-5
    } else {
        1e-10
    }
}

fn grazing_case<T: Real>() {
    let r = 100.0;
    let sph = prepared::<T>(&sphere(r).unwrap());
    let cyl = prepared::<T>(&cylinder(r, -200.0, 200.0).unwrap());
    // Cone radius 50 at z=-100 to 150 at z=100: radius 100 at z=0.
    let con = prepared::<T>(&cone(50.0, -100.0, 150.0, 100.0).unwrap());
    // Torus: tube 30 around radius 100; a ray along x at height z grazes the top at z = 30.
    let tor = prepared::<T>(&torus(0.0, 30.0, 100.0).unwrap());
    for rel in [1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8] {
        for sign in [-1.0, 1.0] {
            let offset = sign * rel;
            let inside_band = rel <= band::<T>();
            // Sphere and cylinder: ray along x at y = r (1 + offset).
            let y = f32_exact([0.0, r * (1.0 + offset), 0.0])[1];
            for (name, tree) in [("sphere", &sph), ("cylinder", &cyl), ("cone", &con)] {
                let o = [-300.0, y, 0.0];
                let (t, _, _) = cross(tree, o, [1.0, 0.0, 0.0], 0.0);
                let hits = y < r;
                if !inside_band {
                    assert_eq!(
                        t.is_finite(),
                        hits,
                        "{name} {} offset {offset}: t {t}",
                        T::NAME
                    );
                }
                if hits && t.is_finite() {
                    let want = 300.0 - (r * r - y * y).sqrt();
                    let tol = if T::NAME == "f32" { 2e-3 } else { 1e-8 };
                    // Near tangency the chord is ill-conditioned: allow the sqrt's slope.
                    let slack = tol * (1.0 + r / (r * r - y * y).sqrt().max(1e-12)).min(1e6);
                    assert!(
                        (t - want).abs() <= slack,
                        "{name} {}: t {t} want {want}",
                        T::NAME
                    );
                }
            }
            let zt = 30.0 * (1.0 + offset);
            let o = [-300.0, 100.0, zt];
            let (t, _, _) = cross(&tor, o, [1.0, 0.0, 0.0], 0.0);
            if !inside_band {
                assert_eq!(
                    t.is_finite(),
                    zt < 30.0,
                    "torus {} offset {offset}",
                    T::NAME
                );
            }
        }
    }
}

#[test]
fn grazing_and_tangent_rays_f32() {
    grazing_case::<f32>();
}

#[test]
fn grazing_and_tangent_rays_f64() {
    grazing_case::<f64>();
}

fn on_surface_case<T: Real>() {
    let mut rng = Rng(11);
    let r = 50.0;
    let sph = prepared::<T>(&sphere(r).unwrap());
    let bx = prepared::<T>(&box3(100.0, 100.0, 100.0).unwrap());
    for _ in 0..2000 {
        // A point on the sphere, rays inward (must exit at the far side, no self-hit) and
        // outward (must miss).
        let n = rng.direction();
        // On the surface to the precision's rounding (an f32-rounded point is 1e-6 mm off
        // the surface, a real distance in f64).
        let p = n.map(|c| T::from_f64(r * c).to_f64());
        let mut d = rng.direction();
        if dot(d, n) > 0.0 {
            d = d.map(|c| -c);
        }
        if dot(d, n) > -0.05 {
            continue; // too grazing to call
        }
        let (t, normal, inside_before) = cross(&sph, p, d, 0.0);
        let chord = -2.0 * r * dot(d, n);
        assert!(
            inside_before,
            "{}: from the surface inward the ray is inside",
            T::NAME
        );
        assert!(
            (t - chord).abs() < 1e-3 * r,
            "{}: exit {t}, chord {chord}",
            T::NAME
        );
        assert!(dot(normal, d) > 0.0);
        let out = d.map(|c| -c);
        assert!(
            cross(&sph, p, out, 0.0).0.is_infinite(),
            "{}: self-hit outward",
            T::NAME
        );
        // A point on a box face, inward.
        let face = [50.0, rng.range(-45., 45.), rng.range(-45., 45.)];
        let dir = [-1.0, 0.0, 0.0];
        let (t, ..) = cross(&bx, face, dir, 0.0);
        assert!((t - 100.0).abs() < 1e-4, "{}: box exit {t}", T::NAME);
    }
    // tmin: from outside, tmin beyond the entry gives the exit.
    let (t_in, ..) = cross(&sph, [-100.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0);
    let (t_out, _, inside) = cross(&sph, [-100.0, 0.0, 0.0], [1.0, 0.0, 0.0], t_in);
    assert!((t_in - 50.0).abs() < 1e-5 && (t_out - 150.0).abs() < 1e-4 && inside);
}

#[test]
fn rays_starting_on_surfaces_find_exits_without_self_hits_f32() {
    on_surface_case::<f32>();
}

#[test]
fn rays_starting_on_surfaces_find_exits_without_self_hits_f64() {
    on_surface_case::<f64>();
}

fn thin_shell_case<T: Real>() {
    let r = 1000.0;
    let inner = r * (1.0 - 1e-4); // 0.1 mm shell
    let shell = prepared::<T>(&(sphere(r).unwrap() - sphere(inner).unwrap()));
    let mut rng = Rng(3);
    for _ in 0..1000 {
        let d = rng.direction();
        let o = f32_exact(d.map(|c| -3000.0 * c));
        // Walk the crossings: enter shell, leave into the hollow, enter, leave.
        let want = [2000.0, 3000.0 - inner, 3000.0 + inner, 4000.0];
        let mut tmin = 0.0;
        for (k, w) in want.iter().enumerate() {
            let (t, _, inside) = cross(&shell, o, d, tmin);
            assert!(
                (t - w).abs() < 2e-3,
                "{} crossing {k}: {t} want {w}",
                T::NAME
            );
            assert_eq!(inside, k % 2 == 1);
            tmin = t;
        }
        assert!(cross(&shell, o, d, tmin).0.is_infinite());
    }
}

#[test]
fn thin_shells_one_ten_thousandth_of_the_radius_f32() {
    thin_shell_case::<f32>();
}

#[test]
fn thin_shells_one_ten_thousandth_of_the_radius_f64() {
    thin_shell_case::<f64>();
}

fn scale_case<T: Real>(size: f64) {
    let mut rng = Rng(5);
    let sph = prepared::<T>(&sphere(size).unwrap());
    let bx = prepared::<T>(&box3(2.0 * size, 2.0 * size, 2.0 * size).unwrap());
    let rel = if T::NAME == "f32" { 2e-6 } else { 1e-12 };
    for _ in 0..1000 {
        let o = f32_exact(rng.direction().map(|c| 3.0 * size * c));
        let target = [
            rng.range(-0.5, 0.5),
            rng.range(-0.5, 0.5),
            rng.range(-0.5, 0.5),
        ]
        .map(|c| c * size);
        let d = sub(target, o);
        let l = dot(d, d).sqrt();
        let d = d.map(|c| c / l);
        let want = first_after_zero(sphere_reference([0.0; 3], size, o, d));
        let (t, ..) = cross(&sph, o, d, 0.0);
        assert!(
            (t - want).abs() <= rel * 4.0 * size,
            "{} size {size}: {t} vs {want}",
            T::NAME
        );
        let identity = [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]];
        let want = first_after_zero(box_reference([0.0; 3], identity, [size; 3], o, d));
        let (t, ..) = cross(&bx, o, d, 0.0);
        assert!(
            (t - want).abs() <= rel * 4.0 * size,
            "{} box size {size}: {t} vs {want}",
            T::NAME
        );
    }
}

#[test]
fn tiny_solids_of_a_hundredth_of_a_millimetre() {
    // 0.01 is not an f32 value: the f64 kernels use the Foundry's double-precision
    // parameters, the f32 kernels the rounded ones (within their relative tolerance).
    scale_case::<f32>(0.01);
    scale_case::<f64>(0.01);
}

#[test]
fn huge_solids_of_ten_thousand_metres() {
    scale_case::<f32>(1e7);
    scale_case::<f64>(1e7);
}

#[test]
fn degenerate_parameters_are_errors_or_special_cases() {
    assert!(sphere(0.0).unwrap_err().to_string().contains("radius"));
    assert!(cylinder(10.0, 5.0, 5.0).is_err());
    assert!(tube(5.0, 5.0, -1.0, 1.0).is_err());
    assert!(torus(0.0, 5.0, 4.0).is_err());
    assert!(phi_cut(0.0, 0.0).is_err());
    assert!(phi_cut(0.0, 2.0 * std::f64::consts::PI).is_err());
    assert!(theta_cut(0.0, std::f64::consts::PI).is_err());
    assert!(cone(0.0, -1.0, 0.0, 1.0).is_err());
    // Four planes that leave the region open on one side.
    let open = [
        [1.0, 0.0, 0.0, 1.0],
        [-1.0, 0.0, 0.0, 1.0],
        [0.0, 1.0, 0.0, 1.0],
        [0.0, 0.0, 1.0, 1.0],
    ];
    assert!(polyhedron(&open).is_err());
    // r1 == r2 cone is a cylinder, and traces as one.
    let c = cone(10.0, -5.0, 10.0, 5.0).unwrap();
    assert_eq!(c, cylinder(10.0, -5.0, 5.0).unwrap());
    let tree = prepared::<f64>(&c);
    assert!((cross(&tree, [-20.0, 0.0, 0.0], [1.0, 0.0, 0.0], 0.0).0 - 10.0).abs() < 1e-12);
    // A cone with an apex traces on both sides of it.
    let apex = prepared::<f64>(&cone(0.0, 0.0, 10.0, 10.0).unwrap());
    let (t, ..) = cross(&apex, [-20.0, 0.0, 5.0], [1.0, 0.0, 0.0], 0.0);
    assert!((t - 15.0).abs() < 1e-12, "{t}");
}

fn zero_component_case<T: Real>() {
    // Axis-aligned rays (two direction components exactly zero) through boxes, cylinders,
    // cones, spheres, polyhedra and phi wedges, against the f64 references.
    let bx = prepared::<T>(&box3(20.0, 40.0, 60.0).unwrap());
    let wedge = prepared::<T>(&(cylinder(10.0, -5.0, 5.0).unwrap() * phi_cut(0.0, 1.5).unwrap()));
    let sph = prepared::<T>(&sphere(10.0).unwrap());
    let mut rng = Rng(17);
    let identity = [[1., 0., 0.], [0., 1., 0.], [0., 0., 1.]];
    for _ in 0..3000 {
        let o = f32_exact([
            rng.range(-15., 15.),
            rng.range(-25., 25.),
            rng.range(-35., 35.),
        ]);
        let axis = (rng.uniform() * 6.0) as usize;
        let mut d = [0.0; 3];
        d[axis % 3] = if axis < 3 { 1.0 } else { -1.0 };
        let want = first_after_zero(box_reference([0.0; 3], identity, [10.0, 20.0, 30.0], o, d));
        let (t, ..) = cross(&bx, o, d, 0.0);
        let tol = if T::NAME == "f32" { 1e-4 } else { 1e-10 };
        // Origins within the tolerance of a face are the surface itself.
        let near_face = (0..3).any(|k| (o[k].abs() - [10.0, 20.0, 30.0][k]).abs() < 1e-3);
        if !near_face {
            assert!(
                (t - want).abs() <= tol || (t.is_infinite() && want.is_infinite()),
                "{}: box {o:?} {d:?}: {t} vs {want}",
                T::NAME
            );
        }
        let want = first_after_zero(sphere_reference([0.0; 3], 10.0, o, d));
        let (t, ..) = cross(&sph, o, d, 0.0);
        assert!(
            (t - want).abs() <= 10.0 * tol || (t.is_infinite() && want.is_infinite()),
            "{}: sphere {o:?} {d:?}: {t} vs {want}",
            T::NAME
        );
    }
    // A ray parallel to z inside the wedge's angle crosses only the caps.
    let (t, ..) = cross(&wedge, [5.0, 1.0, -20.0], [0.0, 0.0, 1.0], 0.0);
    assert!((t - 15.0).abs() < 1e-5, "{t}");
    // Outside the wedge's angle it misses.
    assert!(cross(&wedge, [-5.0, 1.0, -20.0], [0.0, 0.0, 1.0], 0.0)
        .0
        .is_infinite());
}

#[test]
fn zero_direction_components_f32() {
    zero_component_case::<f32>();
}

#[test]
fn zero_direction_components_f64() {
    zero_component_case::<f64>();
}

fn coincident_case<T: Real>() {
    // A box with a square hole through it: hole faces share the box's top and bottom.
    let holed = prepared::<T>(&(box3(20.0, 20.0, 20.0).unwrap() - box3(10.0, 10.0, 20.0).unwrap()));
    // Through the hole along z: no crossing at all (no spurious hit on the shared caps).
    assert!(
        cross(&holed, [0.0, 0.0, -50.0], [0.0, 0.0, 1.0], 0.0)
            .0
            .is_infinite(),
        "{}",
        T::NAME
    );
    // Through the material: enter at the bottom, leave at the top.
    let (t, n, _) = cross(&holed, [7.5, 0.0, -50.0], [0.0, 0.0, 1.0], 0.0);
    assert!(
        (t - 40.0).abs() < 1e-4 && n[2] < -0.99,
        "{}: {t} {n:?}",
        T::NAME
    );
    // Abutting union: two boxes sharing the face x = 0; no crossing at x = 0.
    let pair = prepared::<T>(
        &(box3(10.0, 10.0, 10.0).unwrap().translate(-5.0, 0.0, 0.0)
            + box3(10.0, 10.0, 10.0).unwrap().translate(5.0, 0.0, 0.0)),
    );
    let (t_in, ..) = cross(&pair, [-50.0, 1.0, 2.0], [1.0, 0.0, 0.0], 0.0);
    let (t_out, n, inside) = cross(&pair, [-50.0, 1.0, 2.0], [1.0, 0.0, 0.0], t_in);
    assert!(
        (t_in - 40.0).abs() < 1e-4 && (t_out - 60.0).abs() < 1e-4 && inside,
        "{}: {t_in} {t_out}",
        T::NAME
    );
    assert!(n[0] > 0.99);
    // From inside one half, the first crossing is the far face of the other.
    let (t, ..) = cross(&pair, [-3.0, 1.0, 2.0], [1.0, 0.0, 0.0], 0.0);
    assert!((t - 13.0).abs() < 1e-4, "{}: {t}", T::NAME);
    // A pocket flush with the top face: rays into it hit the pocket's floor.
    let pocket = prepared::<T>(
        &(box3(20.0, 20.0, 20.0).unwrap()
            - box3(10.0, 10.0, 10.0).unwrap().translate(0.0, 0.0, 5.0)),
    );
    let (t, n, _) = cross(&pocket, [1.0, 1.0, 50.0], [0.0, 0.0, -1.0], 0.0);
    assert!(
        (t - 50.0).abs() < 1e-4 && n[2] > 0.99,
        "{}: pocket floor {t} {n:?}",
        T::NAME
    );
    // A tube with coincident inner and outer caps (G4Tubs-like difference of cylinders).
    let tubes =
        prepared::<T>(&(cylinder(10.0, -5.0, 5.0).unwrap() - cylinder(5.0, -5.0, 5.0).unwrap()));
    assert!(cross(&tubes, [0.0, 0.0, -20.0], [0.0, 0.0, 1.0], 0.0)
        .0
        .is_infinite());
    let (t, ..) = cross(&tubes, [7.0, 0.0, -20.0], [0.0, 0.0, 1.0], 0.0);
    assert!((t - 15.0).abs() < 1e-4, "{}: {t}", T::NAME);
}

#[test]
fn coincident_faces_give_no_internal_hits_f32() {
    coincident_case::<f32>();
}

#[test]
fn coincident_faces_give_no_internal_hits_f64() {
    coincident_case::<f64>();
}

#[test]
fn theta_cut_spheres_match_the_cone_geometry() {
    // A sphere cut to theta in [30, 60] degrees: a ray along z at x = 0 misses (axis is at
    // theta 0); a ray along -x at height z crosses the 60 and 30 degree cones.
    let cut = prepared::<f64>(
        &(sphere(100.0).unwrap() * theta_cut(30f64.to_radians(), 60f64.to_radians()).unwrap()),
    );
    assert!(cross(&cut, [0.0, 0.0, -200.0], [0.0, 0.0, 1.0], 0.0)
        .0
        .is_infinite());
    let z = 20.0;
    let (t, ..) = cross(&cut, [200.0, 0.0, z], [-1.0, 0.0, 0.0], 0.0);
    let x60 = z * 60f64.to_radians().tan();
    // The cut angles are stored in f32: 1e-8 rad moves the crossing by ~1e-6 mm here.
    assert!((t - (200.0 - x60)).abs() < 1e-5, "{t}");
    let (t2, ..) = cross(&cut, [200.0, 0.0, z], [-1.0, 0.0, 0.0], t);
    let x30 = z * 30f64.to_radians().tan();
    assert!((t2 - (200.0 - x30)).abs() < 1e-5, "{t2}");
}

/// Rays parallel to a phi cut's half-plane at 270 degrees (whose stored cosine is a
/// rounding residue, so the plane is crossed 10^17 mm away): the wedge's state must follow
/// from that crossing, not from the ray direction lying on the boundary. From Geant4's
/// G01 solids (a 270-degree G4Polycone) where a ray along +y used to be lost.
fn parallel_to_cut_case<T: Real>() {
    let wedge = |s: Shape| s * phi_cut(0.0, 1.5 * std::f64::consts::PI).unwrap();
    let ball = prepared::<T>(&wedge(sphere(1000.0).unwrap()));
    let ring = prepared::<T>(&wedge(
        cone(250.0, -500.0, 100.0, 0.0).unwrap() - cone(160.0, -500.0, 80.0, 0.0).unwrap(),
    ));
    let tol = band::<T>();
    for (o, d) in [
        ([-138.3, -204.2, -493.3], [0.0, 1.0, 0.0]),
        ([-138.3, -204.2, -493.3], [0.0, -1.0, 0.0]),
        ([-300.0, 50.0, 10.0], [1.0, 0.0, 0.0]),
        ([-300.0, -50.0, 10.0], [-1.0, 0.0, 0.0]),
    ] {
        // Inside the wedge all along (x < 0 or y > 0 never meets the cut): the sphere exit.
        let want = first_after_zero(sphere_reference([0.0; 3], 1000.0, o, d));
        let (t, _, inside) = cross(&ball, o, d, 0.0);
        assert!(
            inside && (t - want).abs() <= tol * 1000.0,
            "{} {o:?} {d:?}: {t} vs {want}",
            T::NAME
        );
    }
    // In the ring at phi 236 degrees moving +y: out through the inner cone at
    // y = -sqrt(r_in^2 - x^2), r_in = 160 - 80 (z + 500) / 500.
    let (o, d) = ([-138.3, -204.2, -493.3], [0.0, 1.0, 0.0]);
    let r_in: f64 = 160.0 - 80.0 * (o[2] + 500.0) / 500.0;
    let want = o[1].abs() - (r_in * r_in - o[0] * o[0]).sqrt();
    let (t, _, inside) = cross(&ring, o, d, 0.0);
    assert!(
        inside && (t - want).abs() <= tol * 1000.0,
        "{} ring: {t} vs {want}",
        T::NAME
    );
}

#[test]
fn rays_parallel_to_a_270_degree_phi_cut_f32() {
    parallel_to_cut_case::<f32>();
}

#[test]
fn rays_parallel_to_a_270_degree_phi_cut_f64() {
    parallel_to_cut_case::<f64>();
}

fn contains<T: Real>(tree: &PrimTree<T>, p: [f64; 3]) -> bool {
    tree.contains(V3::from_f64(p))
}

/// Boxes of side `s` centred on `c`, as one shape each.
fn cube_at(s: f64, c: [f64; 3]) -> Shape {
    box3(s, s, s).unwrap().translate(c[0], c[1], c[2])
}

fn shared_face_case<T: Real>() {
    let name = T::NAME;
    // Two boxes sharing the face x = 0 (a binary union): the face's points are inside, the
    // solid's surface (where the face meets it too) outside.
    let pair = prepared::<T>(&(cube_at(10.0, [-5.0, 0.0, 0.0]) + cube_at(10.0, [5.0, 0.0, 0.0])));
    for p in [[0.0, 1.0, 2.0], [0.0, -4.9, 4.9], [0.0, 0.0, 0.0]] {
        assert!(contains(&pair, p), "{name}: pair {p:?}");
    }
    for p in [
        [0.0, 5.0, 2.0],
        [0.0, 5.0, 5.0],
        [0.0, -5.0, -5.0],
        [10.0, 1.0, 2.0],
        [-10.0, 0.0, 0.0],
        [3.0, 5.0, 0.0],
        [0.0, 5.0 + 1e-3, 0.0],
        [20.0, 0.0, 0.0],
    ] {
        assert!(!contains(&pair, p), "{name}: pair {p:?}");
    }
    // Eight unit cubes of a 2 x 2 x 2 block (a list): faces, edges and the corner the
    // members share are inside; the block's faces, edges and corners outside.
    let mut block = None;
    for c in [-0.5, 0.5] {
        for d in [-0.5, 0.5] {
            for e in [-0.5, 0.5] {
                let cube = cube_at(1.0, [c, d, e]);
                block = Some(match block {
                    None => cube,
                    Some(b) => b + cube,
                });
            }
        }
    }
    let block = prepared::<T>(&block.unwrap());
    assert_eq!(block.height(), 0, "{name}: the block is one list");
    for p in [
        [0.0, 0.3, -0.2],
        [0.0, 0.0, 0.7],
        [0.0, 0.0, 0.0],
        [0.5, 0.0, 0.25],
    ] {
        assert!(contains(&block, p), "{name}: block {p:?}");
    }
    for p in [
        [0.0, 0.0, 1.0],
        [0.0, 1.0, 1.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.5],
        [1.0, 1.0, 1.0],
    ] {
        assert!(!contains(&block, p), "{name}: block {p:?}");
    }
    // An L of two boxes sharing part of the face y = 1: the shared part is inside, the
    // rest of that face and the reflex edge at x = y = 1 are the surface.
    let l = prepared::<T>(
        &(box3(2.0, 1.0, 1.0).unwrap().translate(1.0, 0.5, 0.5)
            + box3(1.0, 1.0, 1.0).unwrap().translate(0.5, 1.5, 0.5)),
    );
    assert!(contains(&l, [0.5, 1.0, 0.5]), "{name}: L shared face");
    for p in [
        [1.0, 1.0, 0.5],
        [1.5, 1.0, 0.5],
        [0.0, 1.0, 0.5],
        [0.5, 1.0, 1.0],
    ] {
        assert!(!contains(&l, p), "{name}: L {p:?}");
    }
    // Nested: the union's shared face is inside where the rest of the tree keeps it.
    let halves = cube_at(10.0, [-5.0, 0.0, 0.0]) + cube_at(10.0, [5.0, 0.0, 0.0]);
    let carved = prepared::<T>(&(halves.clone() - cube_at(4.0, [0.0, 3.0, 0.0])));
    assert!(contains(&carved, [0.0, -2.0, 0.0]), "{name}: carved");
    assert!(!contains(&carved, [0.0, 3.0, 0.0]), "{name}: carved hole");
    assert!(
        !contains(&carved, [0.0, 1.0, 0.0]),
        "{name}: carved hole face"
    );
    let cut = prepared::<T>(&(halves * cube_at(6.0, [0.0, 0.0, 0.0])));
    assert!(contains(&cut, [0.0, 1.0, 1.0]), "{name}: cut");
    assert!(!contains(&cut, [0.0, 3.0, 1.0]), "{name}: cut face");

    // The pair turned and moved: points of the shared face, rounded to T, are inside;
    // points of the solid's surface are as the signed distance says (outside when on it).
    let axis = [1.0, 2.0, 3.0];
    let placed = |s: Shape| s.rotate(axis, 0.7).translate(5.0, -3.0, 2.0);
    let turned = prepared::<T>(&placed(
        cube_at(10.0, [-5.0, 0.0, 0.0]) + cube_at(10.0, [5.0, 0.0, 0.0]),
    ));
    let place = hytrace_foundry::Transform64::translation([5.0, -3.0, 2.0])
        .compose(&hytrace_foundry::Transform64::rotation(axis, 0.7));
    let mut rng = Rng(71);
    for _ in 0..500 {
        let local = [0.0, rng.range(-4.9, 4.9), rng.range(-4.9, 4.9)];
        let p = f32_exact(place.apply_point(local));
        assert!(contains(&turned, p), "{name}: turned shared face {local:?}");
        // On the outer face x = 10, and where the shared face meets the top.
        let q = f32_exact(place.apply_point([10.0, local[1], local[2]]));
        let x = V3::from_f64(q);
        assert_eq!(
            turned.contains(x),
            turned.sdf(x) < T::ZERO,
            "{name}: turned outer face {local:?}"
        );
        let edge = place.apply_point([0.0, 5.0, local[2]]);
        let e = V3::from_f64(edge);
        assert_eq!(
            turned.contains(e),
            turned.sdf(e) < T::ZERO,
            "{name}: turned edge {local:?}"
        );
    }
}

#[test]
fn points_of_faces_members_share_are_inside_f32() {
    shared_face_case::<f32>();
}

#[test]
fn points_of_faces_members_share_are_inside_f64() {
    shared_face_case::<f64>();
}

/// Rays whose line passes through the edge of a cut, from Geant4's solid unit tests
/// (testG4Tubs, testG4Torus, testG4Sphere, testG4Cons): from the axis of a phi segment of
/// exactly pi (its two half-planes one plane) or less, through the axis from outside, and
/// from the apex of a theta cone. The ray goes from the side of -d to the side of d there;
/// a ray along a cut's surface runs on it, outside, as Geant4 has it. References from the
/// geometry: the walls at r = 90, 45 and 50.
fn through_cut_edges_case<T: Real>() {
    let pi = std::f64::consts::PI;
    let half_tube =
        prepared::<T>(&(tube(90.0, 110.0, -105.0, 105.0).unwrap() * phi_cut(0.0, pi).unwrap()));
    let shell = prepared::<T>(
        &((sphere(50.0).unwrap() - sphere(45.0).unwrap()) * phi_cut(-pi / 4.0, pi / 2.0).unwrap()),
    );
    let cone45 = prepared::<T>(&(sphere(50.0).unwrap() * theta_cut(0.0, pi / 4.0).unwrap()));
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let cases = [
        // From the axis into the half-plane's side, and out of it.
        (&half_tube, [0.0; 3], [0.0, 1.0, 0.0], 90.0),
        (&half_tube, [0.0; 3], [0.0, -1.0, 0.0], f64::INFINITY),
        // Along the cut plane from the axis: on the surface, never inside.
        (&half_tube, [0.0; 3], [1.0, 0.0, 0.0], f64::INFINITY),
        // Through the axis from the outside half.
        (&half_tube, [0.0, -10.0, 3.0], [0.0, 1.0, 0.0], 100.0),
        (&half_tube, [0.0, 1.0, 0.0], [0.0, 1.0, 0.0], 89.0),
        // From the centre of a sphere's phi segment of 90 degrees.
        (&shell, [0.0; 3], [1.0, 0.0, 0.0], 45.0),
        (&shell, [0.0; 3], [-1.0, 0.0, 0.0], f64::INFINITY),
        (&shell, [0.0; 3], [h, h, 0.0], f64::INFINITY),
        // From the apex of a theta cone: in along its axis, out of it backwards.
        (&cone45, [0.0; 3], [0.0, 0.0, 1.0], 50.0),
        (&cone45, [0.0; 3], [0.0, 0.0, -1.0], f64::INFINITY),
    ];
    for (tree, o, d, want) in cases {
        let (t, ..) = cross(tree, o, d, 0.0);
        let ok = if want.is_finite() {
            (t - want).abs() < 1e-4
        } else {
            t.is_infinite()
        };
        assert!(ok, "{}: {o:?} {d:?}: {t}, want {want}", T::NAME);
    }
    // Along a theta cone's side from the apex: on the surface.
    let s = 45f64.to_radians().sin();
    let (t, ..) = cross(&cone45, [0.0; 3], [s, 0.0, s], 0.0);
    assert!(t.is_infinite(), "{}: along the cone {t}", T::NAME);
}

#[test]
fn rays_through_the_edges_of_cuts_f32() {
    through_cut_edges_case::<f32>();
}

#[test]
fn rays_through_the_edges_of_cuts_f64() {
    through_cut_edges_case::<f64>();
}

/// Rays tangent to the inner wall of a tube (testG4UnionSolid, testG4Tubs): the touch
/// neither ends the tube's span (a union of the tube and the cylinder filling its hole
/// stopped there, at the faces the two share) nor hides the entry through a phi plane at
/// the same point. References from the geometry: 15 + sqrt(50^2 - 45^2), and the phi
/// plane y = 0 met at the tangent point (50, 0).
fn tangent_to_inner_wall_case<T: Real>() {
    let pi = std::f64::consts::PI;
    let filled = prepared::<T>(
        &(tube(45.0, 50.0, -50.0, 50.0).unwrap() + cylinder(45.0, -50.0, 50.0).unwrap()),
    );
    let (t, ..) = cross(&filled, [-15.0, -45.0, 0.0], [1.0, 0.0, 0.0], 0.0);
    let want = 15.0 + (50.0f64 * 50.0 - 45.0 * 45.0).sqrt();
    assert!((t - want).abs() < 1e-4, "{}: {t}, want {want}", T::NAME);
    let sector =
        prepared::<T>(&(tube(50.0, 100.0, -50.0, 50.0).unwrap() * phi_cut(0.0, 1.5 * pi).unwrap()));
    let (t, ..) = cross(&sector, [50.0, -20.0, 0.0], [0.0, 1.0, 0.0], 0.0);
    assert!((t - 20.0).abs() < 1e-4, "{}: {t}", T::NAME);
}

#[test]
fn rays_tangent_to_a_tubes_inner_wall_f32() {
    tangent_to_inner_wall_case::<f32>();
}

#[test]
fn rays_tangent_to_a_tubes_inner_wall_f64() {
    tangent_to_inner_wall_case::<f64>();
}
