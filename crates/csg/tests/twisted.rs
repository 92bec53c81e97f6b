//! The twisted solids as exact expressions (G4TwistedTubs: two hyperboloids and two
//! saddles; G4TwistedBox, G4TwistedTrd, G4TwistedTrap: four twisted half-spaces, see
//! `hytrace_csg::geant4`) against their exact inside tests marched along each ray in f64
//! (independent references: at each height the tube's annular sector from atan2, the
//! trapezoid turned back and tested edge by edge): random rays, and named hard cases in f32
//! and f64 (rays grazing a twisted face from inside and outside, rays along and parallel to
//! the axis, the solids 10^6 mm from the origin).

use hytrace_csg::geant4::{G4Geometry, G4Mapping, G4Solid};
use hytrace_csg::{PrimTree, Ray, Real, Shape, V3};

mod common;
use common::{Random, Rng};

/// Reference first crossing: march the exact inside test in steps of 1e-3 up to `len`,
/// then bisect to f64 precision (infinity: no crossing found).
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

/// The test tube: twist -1.1 rad over z in [-5, 5], end radii 3 and 7.5, opening 2.4 rad.
const TWIST: f64 = -1.1;
const ENDS: [f64; 2] = [3.0, 7.5];
const DZ: f64 = 5.0;
const DPHI: f64 = 2.4;

fn tubs() -> G4Solid {
    G4Solid::TwistedTubs {
        twistedangle: TWIST,
        endinnerrad: ENDS[0],
        endouterrad: ENDS[1],
        halfzlen: DZ,
        dphi: DPHI,
    }
}

/// A twisted trap's parameters: twist, dz, theta, phi, dy1, dx1, dx2, dy2, dx3, dx4, alpha.
type TrapParams = [f64; 11];

/// Box 6 x 4 x 5 (half lengths) twisted by 0.9 rad; a trd; a trap with every parameter
/// (its sides planar: dy2 = dy1 (dx3 - dx4) / (dx1 - dx2)).
const BOX: TrapParams = [0.9, 5.0, 0.0, 0.0, 4.0, 6.0, 6.0, 4.0, 6.0, 6.0, 0.0];
const TRD: TrapParams = [-1.2, 5.0, 0.0, 0.0, 3.0, 5.0, 5.0, 4.5, 3.5, 3.5, 0.0];
const TRAP: TrapParams = [0.7, 5.0, 0.3, 0.8, 3.0, 4.0, 5.0, 3.6, 4.4, 5.6, 0.2];

fn trap(p: &TrapParams) -> G4Solid {
    G4Solid::TwistedTrap {
        twistedangle: p[0],
        dz: p[1],
        theta: p[2],
        phi: p[3],
        dy1: p[4],
        dx1: p[5],
        dx2: p[6],
        dy2: p[7],
        dx3: p[8],
        dx4: p[9],
        alpha: p[10],
    }
}

fn exact(solid: &G4Solid) -> Shape {
    match solid.to_geometry(1e-2).unwrap() {
        G4Geometry::Csg(shape) => shape,
        G4Geometry::Mesh(_) => panic!("a twisted solid is an exact expression"),
    }
}

fn kappa() -> f64 {
    (0.5 * TWIST).tan() / DZ
}

/// Exact inside test of the tube: at height z the annular sector between the hyperboloids
/// of waist `end * cos(twist / 2)` over `atan(kappa z) +- dphi / 2`.
fn in_tubs(p: [f64; 3]) -> bool {
    if p[2].abs() > DZ {
        return false;
    }
    let grow = (1.0 + (kappa() * p[2]).powi(2)).sqrt() * (0.5 * TWIST).cos();
    let rho = p[0].hypot(p[1]);
    let pi = std::f64::consts::PI;
    let phi = p[1].atan2(p[0]) - (kappa() * p[2]).atan();
    let phi = (phi + pi).rem_euclid(2.0 * pi) - pi;
    rho >= ENDS[0] * grow && rho <= ENDS[1] * grow && phi.abs() <= 0.5 * DPHI
}

/// Exact inside test of a twisted trap: remove the (theta, phi) shift at height z, turn
/// back by `twist z / (2 dz)`, then test the trapezoid of that height: `|y| <= dy(z)` and
/// `|x - y tan(alpha)|` within the half width interpolated across y.
fn in_trap(q: &TrapParams, p: [f64; 3]) -> bool {
    let [twist, dz, theta, phi, dy1, dx1, dx2, dy2, dx3, dx4, alpha] = *q;
    let z = p[2];
    if z.abs() > dz {
        return false;
    }
    let (tx, ty) = (theta.tan() * phi.cos(), theta.tan() * phi.sin());
    let (x, y) = (p[0] - z * tx, p[1] - z * ty);
    let (s, c) = (-twist * z / (2.0 * dz)).sin_cos();
    let (x, y) = (c * x - s * y, s * x + c * y);
    let f = (z + dz) / (2.0 * dz);
    let dy = dy1 + f * (dy2 - dy1);
    let (dxa, dxb) = (dx1 + f * (dx3 - dx1), dx2 + f * (dx4 - dx2));
    let half_width = dxa + (y + dy) / (2.0 * dy) * (dxb - dxa);
    y.abs() <= dy && (x - y * alpha.tan()).abs() <= half_width
}

/// An exact inside test.
type Inside = Box<dyn Fn([f64; 3]) -> bool>;

/// The ray in `T`, and the same ray read back in f64 (what `T` traces exactly).
fn ray<T: Real>(o: [f64; 3], d: [f64; 3]) -> (Ray<T>, [f64; 3], [f64; 3]) {
    let r = Ray::<T>::from_f64(o, d);
    (r, r.origin.to_f64(), r.direction.to_f64())
}

/// Largest error allowed against the marched reference, in mm along the ray: f64 to
/// rounding; f32 to a few ulps of the solids' 10 mm size over the cosine of incidence.
fn allowed<T: Real>(t: f64, cos: f64) -> f64 {
    if T::NAME == "f32" {
        1e-5 * (10.0 + t) / cos.max(1e-3)
    } else {
        1e-9 * (10.0 + t)
    }
}

/// The tree's first crossing from the ray's start against the marched reference from
/// `local` (the ray's start in the solid's frame), which must exist or not as `hit` says,
/// and the inside answers at the start; returns the error (NaN: both miss).
fn check_ray<T: Real>(
    tree: &PrimTree<T>,
    inside: &dyn Fn([f64; 3]) -> bool,
    r: &Ray<T>,
    local: [f64; 3],
    d: [f64; 3],
    hit: Option<bool>,
) -> f64 {
    let want = marched(local, d, inside, 40.0);
    if let Some(hit) = hit {
        assert_eq!(
            want.is_finite(),
            hit,
            "reference of {local:?} {d:?}: {want}"
        );
    }
    let step = tree.first_crossing(r, T::ZERO);
    let got = step.t.to_f64();
    let n = step.normal.normalized().to_f64();
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let cos = (n[0] * d[0] + n[1] * d[1] + n[2] * d[2]).abs() / len;
    let ok = if want.is_infinite() {
        got.is_infinite()
    } else {
        (got - want).abs() <= allowed::<T>(want, cos)
    };
    assert!(
        ok,
        "{}: ray {local:?} {d:?}: expression {got}, reference {want} (cosine {cos:.2e})",
        T::NAME
    );
    assert_eq!(step.inside_before, inside(local), "{}: {local:?}", T::NAME);
    (got - want).abs()
}

/// Whether the inside test flips within `eps` of `p` along an axis (keeps f32's points,
/// rounded by a few ulps of the solid's size, off the surface).
fn near_surface(inside: &dyn Fn([f64; 3]) -> bool, p: [f64; 3], eps: f64) -> bool {
    (0..6).any(|k| {
        let mut q = p;
        q[k / 2] += if k % 2 == 0 { eps } else { -eps };
        inside(q) != inside(p)
    })
}

/// Random rays aimed at the solid and random points around it.
fn random_rays<T: Real>(solid: &G4Solid, inside: &dyn Fn([f64; 3]) -> bool, seed: u64) {
    let tree = PrimTree::<T>::from_shape(&exact(solid)).unwrap();
    let mut rng = Rng(seed);
    let (mut hits, mut worst) = (0, 0.0f64);
    for _ in 0..300 {
        let (o, d) = rng.aimed(12.0, 7.0);
        let (r, o, d) = ray::<T>(o, d);
        let err = check_ray(&tree, inside, &r, o, d, None);
        if err.is_finite() {
            hits += 1;
            worst = worst.max(err);
        }
    }
    assert!(hits > 100, "{hits}");
    eprintln!(
        "{} {}: {hits} crossings, worst error {worst:.2e} mm",
        solid.kind(),
        T::NAME
    );
    for _ in 0..3000 {
        let x = V3::<T>::from_f64(rng.in_cube(9.0));
        let q = x.to_f64();
        if T::NAME == "f32" && near_surface(inside, q, 1e-4) {
            continue;
        }
        assert_eq!(tree.contains(x), inside(q), "{}: {q:?}", T::NAME);
    }
}

#[test]
fn twisted_tubs_agrees_with_its_marched_inside_test_f64() {
    random_rays::<f64>(&tubs(), &in_tubs, 17);
}

#[test]
fn twisted_tubs_agrees_with_its_marched_inside_test_f32() {
    random_rays::<f32>(&tubs(), &in_tubs, 17);
}

#[test]
fn twisted_box_trd_and_trap_agree_with_their_marched_inside_tests_f64() {
    for q in [BOX, TRD, TRAP] {
        random_rays::<f64>(&trap(&q), &|p| in_trap(&q, p), 5);
    }
}

#[test]
fn twisted_box_trd_and_trap_agree_with_their_marched_inside_tests_f32() {
    for q in [BOX, TRD, TRAP] {
        random_rays::<f32>(&trap(&q), &|p| in_trap(&q, p), 5);
    }
}

/// The smallest offsets from a face each precision resolves: 1e-9 mm in f64, 1e-3 mm in
/// f32 (1e-4 of the solids' size, well above f32's rounding of the face functions).
fn grazing_offset<T: Real>() -> f64 {
    if T::NAME == "f32" {
        1e-3
    } else {
        1e-9
    }
}

/// Horizontal rays along a straight line of a twisted face at several heights, offset by
/// `delta` along the face's outward normal (inside when negative), from outside the solid
/// across it: inside they enter and cross the solid running along the face, outside they
/// miss. The tube's side `a = +dphi / 2` holds the lines `(x, kappa z x, z)` turned by `a`;
/// the trap's +y side at height z is the line `y = dy(z)` of its trapezoid, turned by the
/// twist there and shifted.
fn grazing<T: Real>(delta: f64) {
    let tree = PrimTree::<T>::from_shape(&exact(&tubs())).unwrap();
    let (s, c) = (0.5 * DPHI).sin_cos();
    let turn = |v: [f64; 2]| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
    for z in [-4.0, -0.5, 0.0, 2.5, 4.9] {
        let k = kappa() * z;
        let l = (1.0 + k * k).sqrt();
        let (along, normal) = ([-1.0 / l, -k / l], [-k / l, 1.0 / l]);
        // From x = 12, outside the outer hyperboloid (radius x l against r_out l).
        let local = [12.0 + delta * normal[0], 12.0 * k + delta * normal[1]];
        let (o, d) = (turn(local), turn(along));
        let (r, o, d) = ray::<T>([o[0], o[1], z], [d[0], d[1], 0.0]);
        check_ray(&tree, &in_tubs, &r, o, d, Some(delta < 0.0));
    }
    for q in [BOX, TRD, TRAP] {
        let tree = PrimTree::<T>::from_shape(&exact(&trap(&q))).unwrap();
        let [twist, dz, theta, phi, dy1, _, _, dy2, _, _, _] = q;
        let (tx, ty) = (theta.tan() * phi.cos(), theta.tan() * phi.sin());
        for z in [-4.0, -0.5, 0.0, 2.5, 4.9] {
            let dy = dy1 + (z + dz) / (2.0 * dz) * (dy2 - dy1);
            let (s, c) = (twist * z / (2.0 * dz)).sin_cos();
            let turn = |v: [f64; 2]| [c * v[0] - s * v[1] + z * tx, s * v[0] + c * v[1] + z * ty];
            let o = turn([-15.0, dy + delta]);
            let e = turn([15.0, dy + delta]);
            let (r, o, d) = ray::<T>([o[0], o[1], z], [e[0] - o[0], e[1] - o[1], 0.0]);
            check_ray(&tree, &|p| in_trap(&q, p), &r, o, d, Some(delta < 0.0));
        }
    }
}

#[test]
fn rays_grazing_a_twisted_face_from_inside_cross_the_solid_f64() {
    grazing::<f64>(-grazing_offset::<f64>());
}

#[test]
fn rays_grazing_a_twisted_face_from_inside_cross_the_solid_f32() {
    grazing::<f32>(-grazing_offset::<f32>());
}

#[test]
fn rays_grazing_a_twisted_face_from_outside_miss_f64() {
    grazing::<f64>(grazing_offset::<f64>());
}

#[test]
fn rays_grazing_a_twisted_face_from_outside_miss_f32() {
    grazing::<f32>(grazing_offset::<f32>());
}

/// Along the axis (the tube: inside its inner hyperboloid, a miss; the box: through both
/// caps), and parallel to it at azimuths and radii where the ray enters through the bottom
/// cap and leaves through a side as the section turns, or crosses the caps only.
fn along_the_axis<T: Real>() {
    let cases: [(G4Solid, Inside, Option<bool>); 2] = [
        (tubs(), Box::new(in_tubs), Some(false)),
        (trap(&BOX), Box::new(|p| in_trap(&BOX, p)), Some(true)),
    ];
    for (solid, inside, on_axis) in &cases {
        let tree = PrimTree::<T>::from_shape(&exact(solid)).unwrap();
        for dir in [1.0, -1.0] {
            let (r, o, d) = ray::<T>([0.0, 0.0, -20.0 * dir], [0.0, 0.0, dir]);
            check_ray(&tree, inside, &r, o, d, *on_axis);
        }
        for phi in [-1.5f64, -1.0, 0.0, 0.6, 0.9, 1.5] {
            for rho in [3.2, 5.0, 6.5, 7.4] {
                let (s, c) = phi.sin_cos();
                let (r, o, d) = ray::<T>([rho * c, rho * s, -20.0], [0.0, 0.0, 1.0]);
                check_ray(&tree, inside, &r, o, d, None);
            }
        }
    }
}

#[test]
fn rays_along_and_parallel_to_the_axis_f64() {
    along_the_axis::<f64>();
}

#[test]
fn rays_along_and_parallel_to_the_axis_f32() {
    along_the_axis::<f32>();
}

/// The solids 10^6 mm from the origin (an offset exact in f32), random rays from within
/// 12 mm of them: the error is the solid's own rounding, not the offset's.
fn far_from_the_origin<T: Real>() {
    let offset = [600000.0, -480000.0, 640000.0];
    let cases: [(G4Solid, Inside); 2] = [
        (tubs(), Box::new(in_tubs)),
        (trap(&TRAP), Box::new(|p| in_trap(&TRAP, p))),
    ];
    for (solid, inside) in &cases {
        let placed = exact(solid).translate(offset[0], offset[1], offset[2]);
        let tree = PrimTree::<T>::from_shape(&placed).unwrap();
        let mut rng = Rng(23);
        let mut hits = 0;
        for _ in 0..200 {
            let (o, d) = rng.aimed(12.0, 7.0);
            let (r, o, d) = ray::<T>([0, 1, 2].map(|k| o[k] + offset[k]), d);
            let local = [0, 1, 2].map(|k| o[k] - offset[k]);
            hits += check_ray(&tree, inside, &r, local, d, None).is_finite() as usize;
        }
        assert!(hits > 60, "{}: {hits}", solid.kind());
    }
}

#[test]
fn twisted_solids_far_from_the_origin_f64() {
    far_from_the_origin::<f64>();
}

#[test]
fn twisted_solids_far_from_the_origin_f32() {
    far_from_the_origin::<f32>();
}

/// Geant4 refuses a twisted trap whose untwisted x sides are not planar, and so does the
/// mapping (a typed error naming the solid); bad lengths and angles too.
#[test]
fn impossible_twisted_traps_are_errors() {
    let mut warped = TRAP;
    warped[7] += 0.1;
    for q in [
        warped,
        {
            let mut q = BOX;
            q[9] = 7.0; // a rectangular bottom and a trapezoid top
            q
        },
        {
            let mut q = BOX;
            q[4] = 0.0;
            q
        },
        {
            let mut q = BOX;
            q[0] = f64::NAN;
            q
        },
    ] {
        let err = trap(&q).to_shape().unwrap_err();
        assert_eq!(err.primitive, "twistedTrap", "{err}");
        assert!(trap(&q).to_geometry(1e-2).is_err());
    }
}
