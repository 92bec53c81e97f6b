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

/// A primitive solid in its own frame (all lengths in mm).
#[derive(Clone, Debug, PartialEq)]
pub enum Primitive {
    /// Sphere of `radius` centred on the origin.
    Sphere {
        /// Radius.
        radius: f64,
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
    /// Torus around z: tube radius `rmax` (hollow inside `rmin`), swept radius `rtor`.
    Torus {
        /// Inner tube radius (0 for a solid tube).
        rmin: f64,
        /// Outer tube radius.
        rmax: f64,
        /// Swept radius.
        rtor: f64,
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

/// A sphere of `radius` centred on the origin.
pub fn sphere(radius: f64) -> Result<Shape, CsgError> {
    check("sphere", positive(radius), || {
        format!("radius must be finite and > 0, got {radius}")
    })?;
    Ok(Shape::Leaf(Primitive::Sphere { radius }))
}

/// A box of full side lengths `x`, `y`, `z` centred on the origin.
pub fn box3(x: f64, y: f64, z: f64) -> Result<Shape, CsgError> {
    check("box", [x, y, z].into_iter().all(positive), || {
        format!("sides must be finite and > 0, got {x} {y} {z}")
    })?;
    Ok(Shape::Leaf(Primitive::Box3 { size: [x, y, z] }))
}

/// A cylinder of `radius` along z from `z1` to `z2`.
pub fn cylinder(radius: f64, z1: f64, z2: f64) -> Result<Shape, CsgError> {
    check("cylinder", positive(radius), || {
        format!("radius must be finite and > 0, got {radius}")
    })?;
    check(
        "cylinder",
        z1.is_finite() && z2.is_finite() && z1 < z2,
        || format!("needs finite z1 < z2, got {z1} {z2}"),
    )?;
    Ok(Shape::Leaf(Primitive::Cylinder { radius, z1, z2 }))
}

/// A cone frustum with radius `r1` at `z1` and `r2` at `z2`.
pub fn cone(r1: f64, z1: f64, r2: f64, z2: f64) -> Result<Shape, CsgError> {
    let ok_r = |r: f64| r.is_finite() && r >= 0.0;
    check("cone", ok_r(r1) && ok_r(r2) && r1.max(r2) > 0.0, || {
        format!("radii must be finite, >= 0 and not both 0, got {r1} {r2}")
    })?;
    check("cone", z1.is_finite() && z2.is_finite() && z1 < z2, || {
        format!("needs finite z1 < z2, got {z1} {z2}")
    })?;
    Ok(Shape::Leaf(Primitive::Cone { r1, z1, r2, z2 }))
}

/// A torus around z with tube radius `rmax` (hollow inside `rmin`) swept at radius `rtor`.
pub fn torus(rmin: f64, rmax: f64, rtor: f64) -> Result<Shape, CsgError> {
    check(
        "torus",
        rmin.is_finite() && rmin >= 0.0 && positive(rmax) && rmin < rmax,
        || format!("needs 0 <= rmin < rmax, got {rmin} {rmax}"),
    )?;
    check("torus", positive(rtor) && rtor >= rmax, || {
        format!("swept radius must be >= rmax, got {rtor} (rmax {rmax})")
    })?;
    Ok(Shape::Leaf(Primitive::Torus { rmin, rmax, rtor }))
}

impl Primitive {
    /// The Foundry typecode and node parameters (see [`TypeCode`]'s conventions).
    pub fn node_params(&self) -> (TypeCode, [f32; 4], [f32; 2]) {
        let f = |v: f64| v as f32;
        match *self {
            Primitive::Sphere { radius } => {
                (TypeCode::Sphere, [0.0, 0.0, 0.0, f(radius)], [0.0; 2])
            }
            Primitive::Box3 { size } => (
                TypeCode::Box3,
                [f(size[0]), f(size[1]), f(size[2]), 0.0],
                [0.0; 2],
            ),
            Primitive::Cylinder { radius, z1, z2 } => (
                TypeCode::Cylinder,
                [0.0, 0.0, 0.0, f(radius)],
                [f(z1), f(z2)],
            ),
            Primitive::Cone { r1, z1, r2, z2 } => {
                (TypeCode::Cone, [f(r1), f(z1), f(r2), f(z2)], [0.0; 2])
            }
            Primitive::Torus { rmin, rmax, rtor } => {
                (TypeCode::Torus, [f(rmin), f(rmax), f(rtor), 0.0], [0.0; 2])
            }
        }
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
        let n = (axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]).sqrt();
        let [x, y, z] = axis.map(|a| a / n);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        self.placed(Transform64 {
            rows: [
                [t * x * x + c, t * x * y - s * z, t * x * z + s * y, 0.0],
                [t * x * y + s * z, t * y * y + c, t * y * z - s * x, 0.0],
                [t * x * z - s * y, t * y * z + s * x, t * z * z + c, 0.0],
                [0.0, 0.0, 0.0, 1.0],
            ],
        })
    }

    /// This shape scaled by `(x, y, z)` (an ellipsoid is a scaled sphere).
    pub fn scale(self, x: f64, y: f64, z: f64) -> Shape {
        let mut t = Transform64::IDENTITY;
        t.rows[0][0] = x;
        t.rows[1][1] = y;
        t.rows[2][2] = z;
        self.placed(t)
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
