//! CSG expressions: primitives, booleans and placements.

use std::ops::{Add, Mul, Not, Sub};

use hytrace_foundry::{Transform64, TypeCode};

/// A parameter that cannot describe a solid.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("{primitive}: {problem}")]
pub struct CsgError {
    /// The primitive or operation at fault.
    pub primitive: &'static str,
    /// What is wrong.
    pub problem: String,
}

/// A primitive solid in its own frame (lengths in mm, angles in radians).
#[derive(Clone, Debug, PartialEq)]
pub enum Primitive {
    /// Sphere of `radius` centred on the origin.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// Sphere of `radius` centred on the origin, cut by the planes `z = z1` and `z = z2`.
    ZSphere {
        /// Radius.
        radius: f64,
        /// Lower cut.
        z1: f64,
        /// Upper cut.
        z2: f64,
    },
    /// Axis-aligned box of full side lengths `size`, centred on the origin.
    Box3 {
        /// Full side lengths x, y, z.
        size: [f64; 3],
    },
    /// Cylinder of `radius` along z from `z1` to `z2`.
    Cylinder {
        /// Radius.
        radius: f64,
        /// Lower cap.
        z1: f64,
        /// Upper cap.
        z2: f64,
    },
    /// Tube (annular cylinder) between radii `rmin` and `rmax` along z from `z1` to `z2`.
    Tube {
        /// Inner radius.
        rmin: f64,
        /// Outer radius.
        rmax: f64,
        /// Lower cap.
        z1: f64,
        /// Upper cap.
        z2: f64,
    },
    /// Cone frustum with radius `r1` at `z1` and `r2` at `z2`.
    Cone {
        /// Radius at `z1`.
        r1: f64,
        /// Lower cap.
        z1: f64,
        /// Radius at `z2`.
        r2: f64,
        /// Upper cap.
        z2: f64,
    },
    /// One-sheet hyperboloid `x^2 + y^2 = r0^2 + (tan_stereo z)^2` from `z1` to `z2`.
    Hyperboloid {
        /// Waist radius at z = 0.
        r0: f64,
        /// Tangent of the stereo angle (0: a cylinder).
        tan_stereo: f64,
        /// Lower cap.
        z1: f64,
        /// Upper cap.
        z2: f64,
    },
    /// Torus around z: tube radius `rmax` (hollow inside `rmin`), swept radius `rtor`.
    Torus {
        /// Inner tube radius (0 for a solid tube).
        rmin: f64,
        /// Outer tube radius.
        rmax: f64,
        /// Swept radius.
        rtor: f64,
    },
    /// Paraboloid of revolution with radius `rlo` at `z = -dz` and `rhi` at `z = +dz`.
    Paraboloid {
        /// Radius at -dz.
        rlo: f64,
        /// Radius at +dz.
        rhi: f64,
        /// Half length.
        dz: f64,
    },
    /// Convex polyhedron: the intersection of `dot(n, x) <= d` over planes `[nx, ny, nz, d]`
    /// with unit normals.
    Polyhedron {
        /// The bounding planes.
        planes: Vec<[f64; 4]>,
    },
    /// Half-space `dot(normal, x) <= distance` (unbounded: only inside intersections).
    HalfSpace {
        /// Unit outward normal.
        normal: [f64; 3],
        /// Signed distance of the plane from the origin.
        distance: f64,
    },
    /// Slab `a <= dot(normal, x) <= b` (unbounded).
    Slab {
        /// Unit normal.
        normal: [f64; 3],
        /// Lower bound.
        a: f64,
        /// Upper bound.
        b: f64,
    },
    /// Wedge of azimuth from `phi0` counter-clockwise over `dphi` (unbounded).
    PhiCut {
        /// Start angle.
        phi0: f64,
        /// Opening angle, in (0, 2 pi).
        dphi: f64,
    },
    /// Polar angles between `theta0` and `theta1` from +z, apex at the origin (unbounded).
    ThetaCut {
        /// Smallest polar angle (0: open).
        theta0: f64,
        /// Largest polar angle (pi: open).
        theta1: f64,
    },
    /// Half-space below the hyperbolic paraboloid `y = kappa x z`: the points with
    /// `y <= kappa x z` (unbounded: only inside intersections). Its surface holds the lines
    /// `z = c, y = kappa c x` (through the z axis, turning with z): a side face of
    /// G4TwistedTubs in a frame turned to it.
    Saddle {
        /// Twist rate: `tan(twist / 2) / dz` for a G4TwistedTubs.
        kappa: f64,
    },
    /// The slab `|z| <= half_height` cut by the half-space `dot(normal, q) <= distance`
    /// twisted about z: a point is inside when, turned back by the angle `rate z` about z,
    /// it lies in the half-space (unbounded in x and y: only inside intersections). A
    /// lateral face of G4TwistedBox, G4TwistedTrd and G4TwistedTrap.
    TwistedHalfSpace {
        /// Unit outward normal of the untwisted half-space.
        normal: [f64; 3],
        /// Signed distance of its plane from the origin.
        distance: f64,
        /// Twist angle per unit height (radians per mm).
        rate: f64,
        /// Half height of the slab.
        half_height: f64,
    },
}

/// A CSG expression.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A primitive.
    Leaf(Primitive),
    /// An operator (`Union`, `Intersection` or `Difference`) and its operands.
    Op(TypeCode, Box<Shape>, Box<Shape>),
    /// A placed sub-expression: `transform` maps the operand's frame into the parent's.
    Placed(Transform64, Box<Shape>),
    /// The complement (inside-out) of a sub-expression.
    Complement(Box<Shape>),
}

fn check(
    primitive: &'static str,
    ok: bool,
    problem: impl FnOnce() -> String,
) -> Result<(), CsgError> {
    if ok {
        Ok(())
    } else {
        Err(CsgError {
            primitive,
            problem: problem(),
        })
    }
}

fn positive(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

fn non_negative(v: f64) -> bool {
    v.is_finite() && v >= 0.0
}

fn z_range(primitive: &'static str, z1: f64, z2: f64) -> Result<(), CsgError> {
    check(
        primitive,
        z1.is_finite() && z2.is_finite() && z1 < z2,
        || format!("needs finite z1 < z2, got {z1} {z2}"),
    )
}

fn unit(primitive: &'static str, n: [f64; 3]) -> Result<[f64; 3], CsgError> {
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    check(primitive, len.is_finite() && len > 0.0, || {
        format!("needs a finite non-zero normal, got {n:?}")
    })?;
    Ok(n.map(|v| v / len))
}

fn leaf(p: Primitive) -> Result<Shape, CsgError> {
    Ok(Shape::Leaf(p))
}

/// A sphere of `radius` centred on the origin.
pub fn sphere(radius: f64) -> Result<Shape, CsgError> {
    check("sphere", positive(radius), || {
        format!("radius must be finite and > 0, got {radius}")
    })?;
    leaf(Primitive::Sphere { radius })
}

/// A sphere of `radius` cut to `z1 <= z <= z2` (cuts outside the sphere are ignored).
pub fn zsphere(radius: f64, z1: f64, z2: f64) -> Result<Shape, CsgError> {
    check("zsphere", positive(radius), || {
        format!("radius must be finite and > 0, got {radius}")
    })?;
    z_range("zsphere", z1, z2)?;
    check("zsphere", z1 < radius && z2 > -radius, || {
        format!("cuts {z1}..{z2} leave nothing of radius {radius}")
    })?;
    leaf(Primitive::ZSphere {
        radius,
        z1: z1.max(-radius),
        z2: z2.min(radius),
    })
}

/// A box of full side lengths `x`, `y`, `z` centred on the origin.
pub fn box3(x: f64, y: f64, z: f64) -> Result<Shape, CsgError> {
    check("box", [x, y, z].into_iter().all(positive), || {
        format!("sides must be finite and > 0, got {x} {y} {z}")
    })?;
    leaf(Primitive::Box3 { size: [x, y, z] })
}

/// A cylinder of `radius` along z from `z1` to `z2`.
pub fn cylinder(radius: f64, z1: f64, z2: f64) -> Result<Shape, CsgError> {
    check("cylinder", positive(radius), || {
        format!("radius must be finite and > 0, got {radius}")
    })?;
    z_range("cylinder", z1, z2)?;
    leaf(Primitive::Cylinder { radius, z1, z2 })
}

/// A tube between radii `rmin` and `rmax` along z from `z1` to `z2` (`rmin = 0`: a
/// cylinder).
pub fn tube(rmin: f64, rmax: f64, z1: f64, z2: f64) -> Result<Shape, CsgError> {
    check(
        "tube",
        non_negative(rmin) && positive(rmax) && rmin < rmax,
        || format!("needs 0 <= rmin < rmax, got {rmin} {rmax}"),
    )?;
    z_range("tube", z1, z2)?;
    if rmin == 0.0 {
        return cylinder(rmax, z1, z2);
    }
    leaf(Primitive::Tube { rmin, rmax, z1, z2 })
}

/// A cone frustum with radius `r1` at `z1` and `r2` at `z2` (`r1 == r2`: a cylinder).
pub fn cone(r1: f64, z1: f64, r2: f64, z2: f64) -> Result<Shape, CsgError> {
    check(
        "cone",
        non_negative(r1) && non_negative(r2) && r1.max(r2) > 0.0,
        || format!("radii must be finite, >= 0 and not both 0, got {r1} {r2}"),
    )?;
    z_range("cone", z1, z2)?;
    if r1 == r2 {
        return cylinder(r1, z1, z2);
    }
    leaf(Primitive::Cone { r1, z1, r2, z2 })
}

/// A one-sheet hyperboloid of waist radius `r0` and stereo angle tangent `tan_stereo`, from
/// `z1` to `z2` (`tan_stereo = 0`: a cylinder).
pub fn hyperboloid(r0: f64, tan_stereo: f64, z1: f64, z2: f64) -> Result<Shape, CsgError> {
    check(
        "hyperboloid",
        positive(r0) && non_negative(tan_stereo),
        || format!("needs r0 > 0 and tan(stereo) >= 0, got {r0} {tan_stereo}"),
    )?;
    z_range("hyperboloid", z1, z2)?;
    if tan_stereo == 0.0 {
        return cylinder(r0, z1, z2);
    }
    leaf(Primitive::Hyperboloid {
        r0,
        tan_stereo,
        z1,
        z2,
    })
}

/// A torus around z with tube radius `rmax` (hollow inside `rmin`) swept at radius `rtor`.
pub fn torus(rmin: f64, rmax: f64, rtor: f64) -> Result<Shape, CsgError> {
    check(
        "torus",
        non_negative(rmin) && positive(rmax) && rmin < rmax,
        || format!("needs 0 <= rmin < rmax, got {rmin} {rmax}"),
    )?;
    check("torus", positive(rtor) && rtor >= rmax, || {
        format!("swept radius must be >= rmax, got {rtor} (rmax {rmax})")
    })?;
    leaf(Primitive::Torus { rmin, rmax, rtor })
}

/// A paraboloid with radius `rlo` at `z = -dz` and `rhi > rlo` at `z = +dz`.
pub fn paraboloid(rlo: f64, rhi: f64, dz: f64) -> Result<Shape, CsgError> {
    check(
        "paraboloid",
        non_negative(rlo) && positive(rhi) && rlo < rhi && positive(dz),
        || format!("needs 0 <= rlo < rhi and dz > 0, got {rlo} {rhi} {dz}"),
    )?;
    leaf(Primitive::Paraboloid { rlo, rhi, dz })
}

/// Most planes a [`polyhedron`] may have.
pub const MAX_POLYHEDRON_PLANES: usize = 4096;

/// A convex polyhedron bounded by planes `[nx, ny, nz, d]` (`dot(n, x) <= d` inside;
/// normals are normalized here). Needs at least four planes enclosing a bounded region.
pub fn polyhedron(planes: &[[f64; 4]]) -> Result<Shape, CsgError> {
    check("polyhedron", planes.len() >= 4, || {
        format!("needs at least 4 planes, got {}", planes.len())
    })?;
    check("polyhedron", planes.len() <= MAX_POLYHEDRON_PLANES, || {
        format!(
            "{} planes, more than {MAX_POLYHEDRON_PLANES} (every ray tests every plane: a finer \
             convex solid is a mesh's job)",
            planes.len()
        )
    })?;
    let mut unit_planes = Vec::with_capacity(planes.len());
    for p in planes {
        let n = unit("polyhedron", [p[0], p[1], p[2]])?;
        let len = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        check("polyhedron", p[3].is_finite(), || {
            format!("plane distance must be finite, got {}", p[3])
        })?;
        unit_planes.push([n[0], n[1], n[2], p[3] / len]);
    }
    let shape = Primitive::Polyhedron {
        planes: unit_planes,
    };
    check(
        "polyhedron",
        crate::bounds::polyhedron_vertices(match &shape {
            Primitive::Polyhedron { planes } => planes,
            _ => unreachable!(),
        })
        .len()
            >= 4,
        || "the planes do not enclose a bounded solid".to_string(),
    )?;
    leaf(shape)
}

/// The half-space `dot(normal, x) <= distance` (for intersections and differences).
pub fn halfspace(normal: [f64; 3], distance: f64) -> Result<Shape, CsgError> {
    let len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
    let normal = unit("halfspace", normal)?;
    check("halfspace", distance.is_finite(), || {
        format!("distance must be finite, got {distance}")
    })?;
    leaf(Primitive::HalfSpace {
        normal,
        distance: distance / len,
    })
}

/// The slab `a <= dot(normal, x) <= b` (for intersections and differences).
pub fn slab(normal: [f64; 3], a: f64, b: f64) -> Result<Shape, CsgError> {
    let len = (normal[0] * normal[0] + normal[1] * normal[1] + normal[2] * normal[2]).sqrt();
    let normal = unit("slab", normal)?;
    check("slab", a.is_finite() && b.is_finite() && a < b, || {
        format!("needs finite a < b, got {a} {b}")
    })?;
    leaf(Primitive::Slab {
        normal,
        a: a / len,
        b: b / len,
    })
}

/// The wedge of azimuths from `phi0` over `dphi` radians, `0 < dphi < 2 pi`.
pub fn phi_cut(phi0: f64, dphi: f64) -> Result<Shape, CsgError> {
    check(
        "phicut",
        phi0.is_finite() && dphi > 0.0 && dphi < 2.0 * std::f64::consts::PI,
        || format!("needs 0 < dphi < 2 pi, got phi0 {phi0} dphi {dphi}"),
    )?;
    leaf(Primitive::PhiCut { phi0, dphi })
}

/// Polar angles from `theta0` to `theta1` (radians from +z, `0 <= theta0 < theta1 <= pi`,
/// not both open).
pub fn theta_cut(theta0: f64, theta1: f64) -> Result<Shape, CsgError> {
    let pi = std::f64::consts::PI;
    check(
        "thetacut",
        theta0 >= 0.0 && theta1 <= pi && theta0 < theta1 && (theta0 > 0.0 || theta1 < pi),
        || format!("needs 0 <= theta0 < theta1 <= pi, not 0..pi, got {theta0} {theta1}"),
    )?;
    leaf(Primitive::ThetaCut { theta0, theta1 })
}

/// The half-space `dot(normal, q) <= distance` twisted about z by `rate` radians per mm
/// (`q` is the point turned back by `rate z`), capped at `|z| <= half_height`.
pub fn twisted_halfspace(
    normal: [f64; 3],
    distance: f64,
    rate: f64,
    half_height: f64,
) -> Result<Shape, CsgError> {
    let normal = unit("twisted halfspace", normal)?;
    check(
        "twisted halfspace",
        distance.is_finite() && rate.is_finite() && positive(half_height),
        || {
            format!("needs a finite distance and rate and a half height > 0, got {distance} {rate} {half_height}")
        },
    )?;
    leaf(Primitive::TwistedHalfSpace {
        normal,
        distance,
        rate,
        half_height,
    })
}

/// The half-space `y <= kappa x z` below a hyperbolic paraboloid (finite `kappa`; 0 is the
/// half-space `y <= 0`).
pub fn saddle(kappa: f64) -> Result<Shape, CsgError> {
    check("saddle", kappa.is_finite(), || {
        format!("needs a finite kappa, got {kappa}")
    })?;
    leaf(Primitive::Saddle { kappa })
}

impl Primitive {
    /// The Foundry typecode and node parameters in f32 (see [`TypeCode`]'s conventions):
    /// [`Primitive::node_params64`] rounded. Convex polyhedra return their plane count in
    /// `param[1]`; the caller sets the first plane.
    pub fn node_params(&self) -> (TypeCode, [f32; 4], [f32; 2]) {
        let (code, p) = self.node_params64();
        if let Primitive::Polyhedron { planes } = self {
            return (
                code,
                [0.0, f32::from_bits(planes.len() as u32), 0.0, 0.0],
                [0.0; 2],
            );
        }
        let f = |v: f64| v as f32;
        (
            code,
            [f(p[0]), f(p[1]), f(p[2]), f(p[3])],
            [f(p[4]), f(p[5])],
        )
    }

    /// The Foundry typecode and the six node parameters in double precision (`param` then
    /// `param_ext`; zeros for convex polyhedra, whose parameters are plane indices).
    pub fn node_params64(&self) -> (TypeCode, [f64; 6]) {
        match self {
            &Primitive::Sphere { radius } => (TypeCode::Sphere, [0.0, 0.0, 0.0, radius, 0.0, 0.0]),
            &Primitive::ZSphere { radius, z1, z2 } => {
                (TypeCode::ZSphere, [0.0, 0.0, 0.0, radius, z1, z2])
            }
            &Primitive::Box3 { size } => {
                (TypeCode::Box3, [size[0], size[1], size[2], 0.0, 0.0, 0.0])
            }
            &Primitive::Cylinder { radius, z1, z2 } => {
                (TypeCode::Cylinder, [0.0, 0.0, 0.0, radius, z1, z2])
            }
            &Primitive::Tube { rmin, rmax, z1, z2 } => {
                (TypeCode::Disc, [0.0, 0.0, rmin, rmax, z1, z2])
            }
            &Primitive::Cone { r1, z1, r2, z2 } => (TypeCode::Cone, [r1, z1, r2, z2, 0.0, 0.0]),
            &Primitive::Hyperboloid {
                r0,
                tan_stereo,
                z1,
                z2,
            } => (TypeCode::Hyperboloid, [r0, tan_stereo, z1, z2, 0.0, 0.0]),
            &Primitive::Torus { rmin, rmax, rtor } => {
                (TypeCode::Torus, [rmin, rmax, rtor, 0.0, 0.0, 0.0])
            }
            &Primitive::Paraboloid { rlo, rhi, dz } => {
                (TypeCode::Paraboloid, [rlo, rhi, dz, 0.0, 0.0, 0.0])
            }
            Primitive::Polyhedron { .. } => (TypeCode::ConvexPolyhedron, [0.0; 6]),
            &Primitive::HalfSpace { normal, distance } => (
                TypeCode::HalfSpace,
                [normal[0], normal[1], normal[2], distance, 0.0, 0.0],
            ),
            &Primitive::Slab { normal, a, b } => {
                (TypeCode::Slab, [normal[0], normal[1], normal[2], 0.0, a, b])
            }
            &Primitive::PhiCut { phi0, dphi } => {
                let phi1 = phi0 + dphi;
                (
                    TypeCode::PhiCut,
                    [phi0.cos(), phi0.sin(), phi1.cos(), phi1.sin(), 0.0, 0.0],
                )
            }
            &Primitive::ThetaCut { theta0, theta1 } => {
                (TypeCode::ThetaCut, [theta0, theta1, 0.0, 0.0, 0.0, 0.0])
            }
            &Primitive::Saddle { kappa } => (TypeCode::Saddle, [kappa, 0.0, 0.0, 0.0, 0.0, 0.0]),
            &Primitive::TwistedHalfSpace {
                normal,
                distance,
                rate,
                half_height,
            } => (
                TypeCode::TwistedHalfSpace,
                [normal[0], normal[1], normal[2], distance, rate, half_height],
            ),
        }
    }

    /// Whether the primitive encloses a bounded region.
    pub fn is_bounded(&self) -> bool {
        !matches!(
            self,
            Primitive::HalfSpace { .. }
                | Primitive::Slab { .. }
                | Primitive::PhiCut { .. }
                | Primitive::ThetaCut { .. }
                | Primitive::Saddle { .. }
                | Primitive::TwistedHalfSpace { .. }
        )
    }
}

impl Shape {
    /// This shape placed by `transform` (operand frame to parent frame).
    pub fn placed(self, transform: Transform64) -> Shape {
        Shape::Placed(transform, Box::new(self))
    }

    /// This shape moved by `(x, y, z)`.
    pub fn translate(self, x: f64, y: f64, z: f64) -> Shape {
        self.placed(Transform64::translation([x, y, z]))
    }

    /// This shape rotated by `angle` radians about the unit `axis` (right-handed).
    pub fn rotate(self, axis: [f64; 3], angle: f64) -> Shape {
        self.placed(Transform64::rotation(axis, angle))
    }

    /// This shape scaled by `(x, y, z)` (an ellipsoid is a scaled sphere).
    pub fn scale(self, x: f64, y: f64, z: f64) -> Shape {
        self.placed(Transform64::scaling([x, y, z]))
    }

    fn op(code: TypeCode, a: Shape, b: Shape) -> Shape {
        Shape::Op(code, Box::new(a), Box::new(b))
    }
}

impl Add for Shape {
    type Output = Shape;
    /// Union.
    fn add(self, rhs: Shape) -> Shape {
        Shape::op(TypeCode::Union, self, rhs)
    }
}

impl Mul for Shape {
    type Output = Shape;
    /// Intersection.
    fn mul(self, rhs: Shape) -> Shape {
        Shape::op(TypeCode::Intersection, self, rhs)
    }
}

impl Sub for Shape {
    type Output = Shape;
    /// Difference.
    fn sub(self, rhs: Shape) -> Shape {
        Shape::op(TypeCode::Difference, self, rhs)
    }
}

impl Not for Shape {
    type Output = Shape;
    /// Complement.
    fn not(self) -> Shape {
        Shape::Complement(Box::new(self))
    }
}
