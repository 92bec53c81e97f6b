//! The WGSL primitive kernels (shaders/csg/{quadric,planar,cuts,twisted,primitive}.wgsl)
//! agree with their CPU twins, `hytrace_csg::kernel::primitive_spans::<f32>` (for twisted
//! half-spaces, which the CPU solves in f64, `twisted_spans_in::<f32>`) and
//! `primitive_sdf::<f32>`, ray by ray: random rays plus named hard cases (zero direction
//! components, rays along faces and axes, tangent rays, rays along the rulings of saddles and
//! twisted half-spaces, origins inside and 1e5 mm away, non-unit and zero directions) for
//! every primitive type but the torus.
//!
//! Agreement of one item: the same number of spans; every span end within
//! `1e-6 * max(|t|, 1)` of the CPU's (GPU values with |x| >= 1e38 count as the CPU's
//! infinities of the same sign); normals within 1e-5 after normalization (or both zero); the
//! signed distance at the origin within `1e-6 * max(|sdf|, 1)` (plus `4 ulp(pi) |x|` for
//! the theta cut, whose distance multiplies an ulp of `atan2` by `|x|`). At least 99.9% of the items
//! of every primitive type must agree. With HYTRACE_REQUIRE_GPU=1 a missing adapter fails.

use std::ops::Range;

use bytemuck::{Pod, Zeroable};
use hytrace_csg::kernel::{primitive_sdf, primitive_spans, twisted_spans_in};
use hytrace_csg::V3;
use hytrace_foundry::TypeCode;
use hytrace_trace::gpu::oneshot::{run, Buffer};
use hytrace_trace::gpu::GpuContext;

/// Mirrors `PrimitiveProbeItem` in shaders/kernels/primitive_probe.wgsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Item {
    code: u32,
    plane_first: u32,
    plane_count: u32,
    pad: u32,
    p: [f32; 8],
    origin: [f32; 4],
    direction: [f32; 4],
}

/// vec4s per item in the probe's output.
const STRIDE: usize = 13;
/// GPU values at least this large stand for infinities.
const GPU_INF: f32 = 1.0e38;

/// Deterministic pseudo-random numbers in [0, 1) (the volume crate's PCG generator).
struct Rng(hytrace_volume::Rng);
impl Rng {
    fn new(seed: u32) -> Self {
        Rng(hytrace_volume::Rng::new(seed, 0, 0))
    }
    fn next(&mut self) -> f32 {
        self.0.next_f64() as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
    fn point(&mut self, half: f32) -> [f32; 3] {
        [0; 3].map(|_| self.range(-half, half))
    }
}

/// One primitive with parameters and the rays to shoot at it.
struct Case {
    name: &'static str,
    code: TypeCode,
    params: [f32; 6],
    planes: Range<usize>,
    /// Rough half-size of the primitive (scale of random rays).
    size: f32,
    /// Named hard rays (origin, direction) besides the generic ones.
    special: Vec<([f32; 3], [f32; 3])>,
}

fn case(
    name: &'static str,
    code: TypeCode,
    params: [f32; 6],
    size: f32,
    special: Vec<([f32; 3], [f32; 3])>,
) -> Case {
    Case {
        name,
        code,
        params,
        planes: 0..0,
        size,
        special,
    }
}

/// Unit (cos, sin) of an angle in degrees, rounded from f64.
fn cs(deg: f64) -> (f32, f32) {
    let r = deg.to_radians();
    (r.cos() as f32, r.sin() as f32)
}

fn phicut(name: &'static str, phi0: f64, phi1: f64) -> Case {
    let (c0, s0) = cs(phi0);
    let (c1, s1) = cs(phi1);
    let (cm, sm) = cs(0.5 * (phi0 + phi1));
    // Rays in the bounding half-planes, through the axis, and along it.
    let special = vec![
        ([-20.0 * c0, -20.0 * s0, 1.0], [c0, s0, 0.0]),
        ([5.0 * c0, 5.0 * s0, -3.0], [c0, s0, 0.0]),
        ([5.0 * c1, 5.0 * s1, 2.0], [-c1, -s1, 0.0]),
        ([5.0 * c0, 5.0 * s0, 0.0], [0.0, 0.0, 1.0]),
        ([5.0 * c1, 5.0 * s1, 0.0], [0.0, 0.0, -1.0]),
        ([0.0, 0.0, 3.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 3.0], [1.0, 1.0, 0.0]),
        ([-5.0, -5.0, 0.0], [1.0, 1.0, 0.0]),
        ([-1.0e5, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ([0.0, 1.0e5, 4.0], [0.0, -1.0, 0.0]),
        // From the axis (and through it) into the wedge, out of it and along its planes:
        // the line meets both half-planes at one point.
        ([0.0, 0.0, 2.0], [cm, sm, 0.0]),
        ([0.0, 0.0, 2.0], [-cm, -sm, 0.3]),
        ([0.0, 0.0, -1.0], [c0, s0, 0.0]),
        ([0.0, 0.0, -1.0], [c1, s1, 0.5]),
        ([-7.0 * cm, -7.0 * sm, 1.0], [cm, sm, 0.0]),
        ([3.0 * cm, 3.0 * sm, 1.0], [-cm, -sm, 0.0]),
    ];
    case(
        name,
        TypeCode::PhiCut,
        [c0, s0, c1, s1, 0.0, 0.0],
        10.0,
        special,
    )
}

fn thetacut(name: &'static str, theta0: f32, theta1: f32) -> Case {
    let (c0, s0) = (theta0.cos(), theta0.sin());
    let (c1, s1) = (theta1.cos(), theta1.sin());
    let mid = 0.5 * (theta0 + theta1);
    let (cm, sm) = (mid.cos(), mid.sin());
    let special = vec![
        // Along the cone surfaces through the apex, and from the apex.
        ([-10.0 * s0, 0.0, -10.0 * c0], [s0, 0.0, c0]),
        ([0.0, -10.0 * s1, -10.0 * c1], [0.0, s1, c1]),
        ([0.0, 0.0, 0.0], [s0, 0.0, c0]),
        ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        // Along the axis, through and beside the apex.
        ([0.0, 0.0, -10.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 10.0], [0.0, 0.0, -1.0]),
        ([1.0, 0.0, -10.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 5.0], [1.0, 0.0, 0.0]),
        ([0.0, 0.0, -5.0], [0.0, 1.0, 0.0]),
        ([3.0, 4.0, 0.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 1.0e5], [0.0, 0.0, -1.0]),
        ([1.0e5, 0.0, 3.0], [-1.0, 0.0, 0.0]),
        // From the apex and through it into the shell and out of it: the line meets the
        // cones at one point.
        ([0.0, 0.0, 0.0], [sm, 0.0, cm]),
        ([0.0, 0.0, 0.0], [-sm, 0.0, -cm]),
        ([-6.0 * sm, 0.0, -6.0 * cm], [sm, 0.0, cm]),
        ([0.0, 4.0 * sm, 4.0 * cm], [0.0, -sm, -cm]),
    ];
    case(
        name,
        TypeCode::ThetaCut,
        [theta0, theta1, 0.0, 0.0, 0.0, 0.0],
        10.0,
        special,
    )
}

/// Unit outward plane of a normal and a point on it.
fn plane(n: [f64; 3], at: [f64; 3]) -> [f32; 4] {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let u = n.map(|c| c / l);
    let d = u[0] * at[0] + u[1] * at[1] + u[2] * at[2];
    [u[0] as f32, u[1] as f32, u[2] as f32, d as f32]
}

/// Every case; convex polyhedra take their planes from `planes`.
fn cases(planes: &mut Vec<[f32; 4]>) -> Vec<Case> {
    let mut out = vec![
        case(
            "sphere",
            TypeCode::Sphere,
            [0.0, 0.0, 0.0, 10.0, 0.0, 0.0],
            10.0,
            vec![
                ([10.0, 0.0, -30.0], [0.0, 0.0, 1.0]),
                ([-30.0, 10.0, 0.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 10.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 10.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "sphere offset",
            TypeCode::Sphere,
            [3.0, -2.0, 5.0, 7.5, 0.0, 0.0],
            10.0,
            vec![([10.5, -2.0, -30.0], [0.0, 0.0, 2.0])],
        ),
        case(
            "sphere radius 0",
            TypeCode::Sphere,
            [1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
            2.0,
            vec![([1.0, 1.0, -5.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "zsphere",
            TypeCode::ZSphere,
            [0.0, 0.0, 0.0, 10.0, -5.0, 7.0],
            10.0,
            vec![
                ([-30.0, 0.0, -5.0], [1.0, 0.0, 0.0]),
                ([-30.0, 0.0, 7.0], [1.0, 0.0, 0.0]),
                ([10.0, 0.0, -30.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "zsphere offset open below",
            TypeCode::ZSphere,
            [1.0, 2.0, 3.0, 20.0, -20.0, 5.0],
            20.0,
            vec![([1.0, 2.0, -50.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "cylinder",
            TypeCode::Cylinder,
            [0.0, 0.0, 0.0, 10.0, -20.0, 20.0],
            20.0,
            vec![
                ([10.0, 0.0, -50.0], [0.0, 0.0, 1.0]),
                ([-50.0, 10.0, 0.0], [1.0, 0.0, 0.0]),
                ([-50.0, 0.0, 20.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "cylinder offset",
            TypeCode::Cylinder,
            [5.0, -3.0, 0.0, 2.5, 0.0, 100.0],
            50.0,
            vec![([7.5, -3.0, -10.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "tube",
            TypeCode::Disc,
            [0.0, 0.0, 5.0, 10.0, -20.0, 20.0],
            20.0,
            vec![
                ([5.0, 0.0, -50.0], [0.0, 0.0, 1.0]),
                ([-50.0, 5.0, 0.0], [1.0, 0.0, 0.0]),
                ([-50.0, 7.0, 20.0], [1.0, 0.0, 0.0]),
                ([7.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            ],
        ),
        case(
            "tube rin 0",
            TypeCode::Disc,
            [1.0, 1.0, 0.0, 10.0, -5.0, 5.0],
            10.0,
            vec![([11.0, 1.0, -50.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "cone",
            TypeCode::Cone,
            [10.0, -20.0, 5.0, 20.0, 0.0, 0.0],
            20.0,
            vec![
                // Along the side line in the xz plane.
                ([10.0, 0.0, -20.0], [-5.0, 0.0, 40.0]),
                ([-50.0, 0.0, -20.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, -50.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "cone apex",
            TypeCode::Cone,
            [0.0, -10.0, 10.0, 10.0, 0.0, 0.0],
            10.0,
            vec![
                ([0.0, 0.0, -30.0], [0.0, 0.0, 1.0]),
                ([0.0, 0.0, -10.0], [1.0, 0.0, 2.0]),
                ([-10.0, 0.0, 10.0], [1.0, 0.0, -2.0]),
            ],
        ),
        case(
            "cone as cylinder",
            TypeCode::Cone,
            [10.0, -5.0, 10.0, 5.0, 0.0, 0.0],
            10.0,
            vec![([10.0, 0.0, -20.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "hyperboloid",
            TypeCode::Hyperboloid,
            [5.0, 0.5, -10.0, 10.0, 0.0, 0.0],
            10.0,
            vec![
                ([5.0, 0.0, -30.0], [0.0, 0.0, 1.0]),
                ([-30.0, 5.0, 0.0], [1.0, 0.0, 0.0]),
                // Along an asymptote-parallel ruling of the surface.
                ([5.0, -5.0, -10.0], [0.0, 0.5, 1.0]),
            ],
        ),
        case(
            "hyperboloid tan 0",
            TypeCode::Hyperboloid,
            [5.0, 0.0, -10.0, 10.0, 0.0, 0.0],
            10.0,
            vec![([5.0, 0.0, -30.0], [0.0, 0.0, 1.0])],
        ),
        case(
            "paraboloid",
            TypeCode::Paraboloid,
            [2.0, 10.0, 15.0, 0.0, 0.0, 0.0],
            15.0,
            vec![
                ([0.0, 0.0, -50.0], [0.0, 0.0, 1.0]),
                ([-50.0, 0.0, -15.0], [1.0, 0.0, 0.0]),
                ([2.0, 0.0, -40.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "paraboloid narrowing",
            TypeCode::Paraboloid,
            [10.0, 0.0, 5.0, 0.0, 0.0, 0.0],
            10.0,
            vec![([0.0, 0.0, 20.0], [0.0, 0.0, -1.0])],
        ),
        case(
            "box",
            TypeCode::Box3,
            [10.0, 20.0, 30.0, 0.0, 0.0, 0.0],
            15.0,
            vec![
                // Along faces and edges.
                ([5.0, 0.0, -50.0], [0.0, 0.0, 1.0]),
                ([5.0, 10.0, -50.0], [0.0, 0.0, 1.0]),
                ([-50.0, -10.0, 15.0], [1.0, 0.0, 0.0]),
                ([-5.0, -10.0, -15.0], [1.0, 2.0, 3.0]),
                ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            ],
        ),
        case(
            "box unit",
            TypeCode::Box3,
            [1.0, 1.0, 1.0, 0.0, 0.0, 0.0],
            1.0,
            vec![([0.5, 0.5, 0.5], [-1.0, -1.0, -1.0])],
        ),
        case(
            "box flat",
            TypeCode::Box3,
            [10.0, 0.0, 10.0, 0.0, 0.0, 0.0],
            10.0,
            vec![
                ([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                ([0.0, -5.0, 0.0], [0.0, 1.0, 0.0]),
            ],
        ),
        case(
            "halfspace",
            TypeCode::HalfSpace,
            [0.0, 0.0, 1.0, 5.0, 0.0, 0.0],
            10.0,
            vec![
                ([-10.0, 0.0, 5.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 5.0], [0.0, 0.0, 1.0]),
            ],
        ),
        case(
            "halfspace oblique",
            TypeCode::HalfSpace,
            [0.6, 0.8, 0.0, -2.0, 0.0, 0.0],
            10.0,
            vec![([-1.2, -1.6, 0.0], [0.8, -0.6, 0.0])],
        ),
        case(
            "halfspace non-unit",
            TypeCode::HalfSpace,
            [1.0, 1.0, 1.0, 3.0, 0.0, 0.0],
            10.0,
            vec![([1.0, 1.0, 1.0], [1.0, -1.0, 0.0])],
        ),
        case(
            "slab",
            TypeCode::Slab,
            [0.0, 0.0, 1.0, 0.0, -5.0, 5.0],
            10.0,
            vec![
                ([-10.0, 0.0, 5.0], [1.0, 0.0, 0.0]),
                ([-10.0, 0.0, -5.0], [1.0, 0.0, 0.0]),
            ],
        ),
        case(
            "slab oblique",
            TypeCode::Slab,
            [0.6, 0.0, 0.8, 0.0, 0.0, 10.0],
            10.0,
            vec![([0.0, 0.0, 0.0], [0.8, 0.0, -0.6])],
        ),
        case(
            "saddle",
            TypeCode::Saddle,
            [0.08, 0.0, 0.0, 0.0, 0.0, 0.0],
            10.0,
            vec![
                // Along rulings in the surface (z = 3, y = 0.24 x; the z and x axes), across
                // them, and in planes x = c and z = c (one crossing).
                ([-10.0, -2.4, 3.0], [1.0, 0.24, 0.0]),
                ([0.0, 0.0, -20.0], [0.0, 0.0, 1.0]),
                ([-20.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                ([2.0, 1.0, -20.0], [0.0, 0.0, 1.0]),
                ([-10.0, 1.0, 4.0], [1.0, 0.0, 0.0]),
                ([-10.0, -3.0, -10.0], [1.0, 0.2, 1.0]),
                ([1.0e5, 0.0, 3.0], [-1.0, 0.0, 0.0]),
            ],
        ),
        case(
            "saddle flat",
            TypeCode::Saddle,
            [0.0; 6],
            10.0,
            vec![([-10.0, 0.0, 2.0], [1.0, 0.0, 0.0])],
        ),
        case(
            "twisted halfspace",
            TypeCode::TwistedHalfSpace,
            [0.0, 1.0, 0.0, 4.0, 0.09, 5.0],
            10.0,
            vec![
                // Along the axis, along the face line at z = 0 (y = 4) and inside it, across
                // the caps, and horizontal at heights where the face has turned.
                ([0.0, 0.0, -20.0], [0.0, 0.0, 1.0]),
                ([-20.0, 4.0, 0.0], [1.0, 0.0, 0.0]),
                ([-20.0, 3.9, 0.0], [1.0, 0.0, 0.0]),
                ([1.0, 3.0, -20.0], [0.0, 0.2, 1.0]),
                ([-20.0, 3.0, 4.0], [1.0, 0.0, 0.0]),
                ([3.0, -20.0, -3.0], [0.0, 1.0, 0.0]),
                ([1.0e5, 2.0, 1.0], [-1.0, 0.0, 0.0]),
            ],
        ),
        case(
            "twisted halfspace tilted",
            TypeCode::TwistedHalfSpace,
            [0.6, 0.0, 0.8, 2.0, -0.15, 6.0],
            10.0,
            vec![
                ([0.0, 0.0, -20.0], [0.0, 0.0, 1.0]),
                ([-20.0, 1.0, 2.0], [1.0, 0.0, 0.0]),
                ([5.0, 5.0, 5.0], [-1.0, -1.0, -1.0]),
            ],
        ),
        phicut("phicut 0..90", 0.0, 90.0),
        phicut("phicut 30..300", 30.0, 300.0),
        phicut("phicut 0..180", 0.0, 180.0),
        phicut("phicut -45..45", -45.0, 45.0),
        thetacut("thetacut 0.5..1.2", 0.5, 1.2),
        thetacut("thetacut 0..0.7", 0.0, 0.7),
        thetacut("thetacut 2..pi", 2.0, std::f32::consts::PI),
        thetacut("thetacut pi/2..2.5", std::f32::consts::FRAC_PI_2, 2.5),
        thetacut("thetacut 0.3..pi/2", 0.3, std::f32::consts::FRAC_PI_2),
    ];
    // A tetrahedron and a hexagonal prism.
    let tet_first = planes.len();
    let s = 10.0;
    for n in [
        [1.0, 1.0, 1.0],
        [-1.0, -1.0, 1.0],
        [-1.0, 1.0, -1.0],
        [1.0, -1.0, -1.0],
    ] {
        planes.push(plane(n, [n[0] * s / 3.0, n[1] * s / 3.0, n[2] * s / 3.0]));
    }
    let hex_first = planes.len();
    for k in 0..6 {
        let a = (k as f64 * 60.0).to_radians();
        let n = [a.cos(), a.sin(), 0.0];
        planes.push(plane(n, [n[0] * 8.0, n[1] * 8.0, 0.0]));
    }
    planes.push(plane([0.0, 0.0, 1.0], [0.0, 0.0, 12.0]));
    planes.push(plane([0.0, 0.0, -1.0], [0.0, 0.0, -12.0]));
    for (name, range, special) in [
        (
            "tetrahedron",
            tet_first..hex_first,
            vec![
                ([-20.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]),
                ([10.0, 10.0, 10.0], [-1.0, -1.0, -1.0]),
            ],
        ),
        (
            "hexagonal prism",
            hex_first..planes.len(),
            vec![
                ([8.0, -30.0, 0.0], [0.0, 1.0, 0.0]),
                ([-30.0, 0.0, 12.0], [1.0, 0.0, 0.0]),
                ([0.0, 0.0, 0.0], [0.0, 0.0, 1.0]),
            ],
        ),
    ] {
        let count = range.len() as u32;
        let first = f32::from_bits(range.start as u32);
        out.push(Case {
            name,
            code: TypeCode::ConvexPolyhedron,
            params: [first, f32::from_bits(count), 0.0, 0.0, 0.0, 0.0],
            planes: range,
            size: 12.0,
            special,
        });
    }
    out
}

/// The rays shot at a case: its named ones, generic hard ones, then random ones.
fn rays(c: &Case, rng: &mut Rng, random: usize) -> Vec<([f32; 3], [f32; 3])> {
    let s = c.size;
    let mut out = c.special.clone();
    // Through the origin along every axis, from inside and from outside.
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut d = [0.0; 3];
            d[axis] = sign;
            let mut o = [0.0; 3];
            out.push((o, d));
            o[axis] = -3.0 * s * sign;
            out.push((o, d));
            // Along the axis 1e5 away.
            o[axis] = -1.0e5 * sign;
            out.push((o, d));
        }
    }
    // Far away, aimed at the primitive along a diagonal; a non-unit tiny and huge direction;
    // no direction at all from inside and from outside.
    let k = 1.0e5 / 3f32.sqrt();
    out.push(([k, k, k], [-1.0, -1.0, -1.0]));
    out.push(([-k, 0.3 * s, k], [1.0, 0.0, -1.0]));
    out.push(([0.1 * s, -2.0 * s, 0.2 * s], [1.0e-3, 2.0e-3, 0.0]));
    out.push(([-2.0 * s, 0.1 * s, 0.3 * s], [1.0e3, 0.0, 1.0]));
    out.push(([0.0; 3], [0.0; 3]));
    out.push(([3.0 * s, 0.0, 0.0], [0.0; 3]));
    for i in 0..random {
        let o = rng.point(2.0 * s);
        let mut d = if i % 4 == 0 {
            rng.point(1.0)
        } else {
            let target = rng.point(s);
            [target[0] - o[0], target[1] - o[1], target[2] - o[2]]
        };
        // Some rays with zero direction components, scaled directions throughout.
        if i % 5 == 1 {
            d[i % 3] = 0.0;
        }
        if i % 7 == 2 {
            d[(i + 1) % 3] = 0.0;
            d[(i + 2) % 3] = 0.0;
        }
        let scale = 10f32.powf(rng.range(-1.0, 1.0));
        out.push((o, d.map(|x| x * scale)));
    }
    out
}

/// [`near`] for signed distances, except the theta cut's: `|x| sin(theta0 - theta)` with
/// `theta` from `atan2`, whose last-ulp differences between libms are multiplied by the
/// distance `|x|` from the apex; it is allowed `4 ulp(pi) |x|` more.
fn sdf_near(code: TypeCode, gpu: f32, cpu: f32, x: V3<f32>) -> bool {
    if code == TypeCode::ThetaCut && cpu.is_finite() {
        let slack = 4.0 * std::f32::consts::PI * f32::EPSILON * x.length();
        return (gpu - cpu).abs() <= 1.0e-6 * cpu.abs().max(1.0) + slack;
    }
    near(gpu, cpu)
}

fn near(gpu: f32, cpu: f32) -> bool {
    if cpu.is_infinite() {
        return gpu.abs() >= GPU_INF && (gpu > 0.0) == (cpu > 0.0);
    }
    if cpu.is_nan() {
        return gpu.is_nan();
    }
    (gpu - cpu).abs() <= 1.0e-6 * cpu.abs().max(1.0)
}

/// Bit-identical (GPU +-1e38 standing for the CPU's infinities).
fn same_bits(gpu: f32, cpu: f32) -> bool {
    if cpu.is_infinite() {
        return near(gpu, cpu);
    }
    gpu.to_bits() == cpu.to_bits() || (gpu == 0.0 && cpu == 0.0)
}

fn normal_near(gpu: [f32; 3], cpu: V3<f32>) -> bool {
    let c = [cpu.x, cpu.y, cpu.z];
    let len = |v: [f32; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let (lg, lc) = (len(gpu), len(c));
    if lg == 0.0 || lc == 0.0 {
        return lg == lc;
    }
    (0..3).all(|k| (gpu[k] / lg - c[k] / lc).abs() <= 1.0e-5)
}

/// A readable summary of the CPU's spans.
fn cpu_summary(spans: &hytrace_csg::kernel::spans::Spans<f32>) -> String {
    let ends: Vec<_> = spans
        .as_slice()
        .iter()
        .map(|s| {
            format!(
                "[{:e} {:?} .. {:e} {:?}]",
                s.t0,
                [s.n0.x, s.n0.y, s.n0.z],
                s.t1,
                [s.n1.x, s.n1.y, s.n1.z]
            )
        })
        .collect();
    ends.join(" ")
}

#[test]
fn gpu_primitive_kernels_match_cpu_f32() {
    let Some(ctx) = GpuContext::for_tests() else {
        return;
    };
    let mut planes = Vec::new();
    let cases = cases(&mut planes);
    let mut rng = Rng::new(42);
    let mut items = Vec::new();
    let mut owner = Vec::new();
    for (ci, c) in cases.iter().enumerate() {
        for (o, d) in rays(c, &mut rng, 300) {
            let p = c.params;
            items.push(Item {
                code: c.code as u32,
                plane_first: c.planes.start as u32,
                plane_count: c.planes.len() as u32,
                pad: 0,
                p: [p[0], p[1], p[2], p[3], p[4], p[5], 0.0, 0.0],
                origin: [o[0], o[1], o[2], 0.0],
                direction: [d[0], d[1], d[2], 0.0],
            });
            owner.push(ci);
        }
    }
    let out_bytes = (items.len() * STRIDE * 16) as u64;
    let outputs = run(
        &ctx,
        "kernels/primitive_probe",
        "probe_primitives",
        items.len() as u32,
        &[
            vec![
                Buffer::Input(bytemuck::cast_slice(&items)),
                Buffer::Output(out_bytes),
            ],
            vec![Buffer::Input(bytemuck::cast_slice(&planes))],
        ],
    )
    .expect("the probe runs");
    let gpu: &[[f32; 4]] = bytemuck::cast_slice(&outputs[0]);

    // Per primitive type: items, agreeing items, bit-identical items.
    let mut tally: Vec<(TypeCode, usize, usize, usize)> = Vec::new();
    let mut shown = 0;
    for (i, item) in items.iter().enumerate() {
        let c = &cases[owner[i]];
        let o = V3::new(item.origin[0], item.origin[1], item.origin[2]);
        let d = V3::new(item.direction[0], item.direction[1], item.direction[2]);
        // The CPU solves twisted half-spaces in f64 for either precision; its twin of the
        // WGSL kernel's f32 steps is `twisted_spans_in::<f32>`.
        let cpu = if c.code == TypeCode::TwistedHalfSpace {
            twisted_spans_in::<f32>(&c.params, o, d, 0.0)
        } else {
            primitive_spans::<f32>(c.code, &c.params, &planes[c.planes.clone()], o, d, 0.0)
        };
        let cpu_sdf = primitive_sdf::<f32>(c.code, &c.params, &planes[c.planes.clone()], o);
        let g = &gpu[i * STRIDE..(i + 1) * STRIDE];
        let len = g[0][0].to_bits() as usize;
        let mut same = len == cpu.as_slice().len() && sdf_near(c.code, g[0][1], cpu_sdf, o);
        let mut exact = same && same_bits(g[0][1], cpu_sdf);
        if same {
            for (k, s) in cpu.as_slice().iter().enumerate() {
                let (t, n0, n1) = (g[1 + 3 * k], g[2 + 3 * k], g[3 + 3 * k]);
                same &= near(t[0], s.t0) && near(t[1], s.t1);
                same &= normal_near([n0[0], n0[1], n0[2]], s.n0);
                same &= normal_near([n1[0], n1[1], n1[2]], s.n1);
                exact &= same_bits(t[0], s.t0) && same_bits(t[1], s.t1);
                exact &=
                    (0..3).all(|j| same_bits(n0[j], s.n0.get(j)) && same_bits(n1[j], s.n1.get(j)));
            }
        }
        exact &= same;
        match tally.iter_mut().find(|e| e.0 == c.code) {
            Some(e) => {
                e.1 += 1;
                e.2 += same as usize;
                e.3 += exact as usize;
            }
            None => tally.push((c.code, 1, same as usize, exact as usize)),
        }
        if !same && shown < 20 {
            shown += 1;
            let gpu_spans: Vec<_> = (0..len.min(4))
                .map(|k| {
                    let (t, n0, n1) = (g[1 + 3 * k], g[2 + 3 * k], g[3 + 3 * k]);
                    format!("[{:e} {:?} .. {:e} {:?}]", t[0], &n0[..3], t[1], &n1[..3])
                })
                .collect();
            println!(
                "DISAGREE {} params {:?} o {:?} d {:?}\n  cpu sdf {:e} spans {}\n  gpu sdf {:e} spans {}",
                c.name,
                c.params,
                &item.origin[..3],
                &item.direction[..3],
                cpu_sdf,
                cpu_summary(&cpu),
                g[0][1],
                gpu_spans.join(" ")
            );
        }
    }
    println!(
        "{:<20} {:>6} {:>6} {:>8} {:>6}",
        "primitive", "items", "agree", "rate", "exact"
    );
    let mut failing = Vec::new();
    for (code, n, ok, exact) in &tally {
        let rate = *ok as f64 / *n as f64;
        println!(
            "{:<20} {n:>6} {ok:>6} {:>7.3}% {exact:>6}",
            format!("{code:?}"),
            100.0 * rate
        );
        if rate < 0.999 {
            failing.push(*code);
        }
    }
    assert!(
        failing.is_empty(),
        "primitive types below 99.9% agreement: {failing:?}"
    );
}
