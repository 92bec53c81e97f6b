//! A small text language for CSG expressions, used by scene files.
//!
//! ```text
//! (tube(0, 100, -50, 50) - sphere(30).translate(0, 0, 50)) * !box(20, 20, 200)
//! ```
//!
//! - `+` union, `-` difference (same precedence, left to right), `*` intersection (binds
//!   tighter), `!` complement (prefix), parentheses.
//! - Placement methods apply to the expression before them: `.translate(x, y, z)`,
//!   `.rotate(ax, ay, az, degrees)` (right-handed about the axis), `.scale(sx, sy, sz)`.
//! - Primitives (lengths in mm, angles in degrees): `sphere(r)`, `zsphere(r, z1, z2)`,
//!   `box(x, y, z)` (full side lengths), `cylinder(r, z1, z2)`, `tube(rmin, rmax, z1, z2)`,
//!   `cone(r1, z1, r2, z2)`, `hyperboloid(r0, tan_stereo, z1, z2)`,
//!   `torus(rmin, rmax, rtor)`, `paraboloid(rlo, rhi, dz)`, `halfspace(nx, ny, nz, d)`,
//!   `slab(nx, ny, nz, a, b)`, `phicut(phi0, dphi)`, `thetacut(theta0, theta1)`,
//!   `saddle(kappa)` (the half-space `y <= kappa x z`),
//!   `polyhedron(nx, ny, nz, d, ...)` (four numbers per plane).
//! - Numbers: decimal literals, `pi`, unary minus, and `*` `/` between them
//!   (`-2*pi/3`).

use hytrace_foundry::{Transform64, TypeCode};

use crate::shape::{
    box3, cone, cylinder, halfspace, hyperboloid, paraboloid, phi_cut, polyhedron, saddle, slab,
    sphere, theta_cut, torus, tube, zsphere, CsgError, Shape,
};

/// A syntax or parameter error, with the byte offset where it was found.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("at column {}: {message}", .offset + 1)]
pub struct ExprError {
    /// Byte offset in the expression.
    pub offset: usize,
    /// What is wrong.
    pub message: String,
}

/// An operator waiting on the parser's stack, with the precedence it binds by.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Pending {
    /// `(`: a barrier only its `)` removes.
    Group,
    /// `+`, `-` or `*`.
    Binary(TypeCode),
    /// Prefix `!`.
    Complement,
}

impl Pending {
    fn precedence(self) -> u8 {
        match self {
            Pending::Group => 0,
            Pending::Binary(TypeCode::Intersection) => 2,
            Pending::Binary(_) => 1,
            Pending::Complement => 3,
        }
    }
}

/// Deepest shape (levels of operators, placements and complements) an expression may
/// build after its chains are joined: what the tree builder, whose trees are at most
/// [`hytrace_foundry::MAX_TREE_HEIGHT`] deep after regrouping, walks recursively.
pub const MAX_EXPRESSION_DEPTH: u32 = 1000;

/// A shape and its depth (levels on its longest path; a primitive is 1).
struct Deep {
    shape: Shape,
    depth: u32,
}

/// An operand on the parser's stack: a shape, or a chain of one operator not built yet.
/// Unions and intersections gather operands from both sides (`a + (b + c)` is one chain
/// of three), a difference chain its subtracted operands (`a - b - c` is `a - (b + c)`),
/// and a chain becomes a balanced tree when it is used, so long chains written either way
/// never make deep shapes.
enum Operand {
    Shape(Deep),
    Chain(TypeCode, Vec<Deep>),
}

impl Operand {
    /// The operand as a shape; a chain as a balanced tree of its operator.
    fn build(self) -> Deep {
        match self {
            Operand::Shape(s) => s,
            Operand::Chain(TypeCode::Difference, mut items) => {
                let minuend = items.remove(0);
                let subtracted = balanced(TypeCode::Union, items);
                Deep {
                    depth: 1 + minuend.depth.max(subtracted.depth),
                    shape: minuend.shape - subtracted.shape,
                }
            }
            Operand::Chain(code, items) => balanced(code, items),
        }
    }

    /// The operands of a chain of `code` this operand adds to it (itself when it is no such
    /// chain).
    fn into_chain(self, code: TypeCode) -> Vec<Deep> {
        match self {
            Operand::Chain(c, items) if c == code => items,
            other => vec![other.build()],
        }
    }
}

/// A balanced tree of `code` over `items` (at least one).
fn balanced(code: TypeCode, mut items: Vec<Deep>) -> Deep {
    while items.len() > 1 {
        let mut paired = Vec::with_capacity(items.len().div_ceil(2));
        let mut it = items.into_iter();
        while let Some(a) = it.next() {
            paired.push(match it.next() {
                Some(b) => Deep {
                    depth: 1 + a.depth.max(b.depth),
                    shape: Shape::Op(code, Box::new(a.shape), Box::new(b.shape)),
                },
                None => a,
            });
        }
        items = paired;
    }
    items.pop().expect("at least one operand")
}

/// An error at byte `at` when `depth` exceeds [`MAX_EXPRESSION_DEPTH`].
fn check_depth(depth: u32, at: usize) -> Result<(), ExprError> {
    if depth > MAX_EXPRESSION_DEPTH {
        return Err(ExprError {
            offset: at,
            message: format!(
                "the expression nests more than {MAX_EXPRESSION_DEPTH} levels of operators, \
                 placements and complements (after joining chains of one operator), far \
                 more than a CSG tree can hold ({} levels)",
                hytrace_foundry::MAX_TREE_HEIGHT
            ),
        });
    }
    Ok(())
}

/// Applies `op` (found at byte `at`) to the operands on top of the stack.
fn apply(operands: &mut Vec<Operand>, op: Pending, at: usize) -> Result<(), ExprError> {
    let missing = || ExprError {
        offset: at,
        message: "an operator lacks an operand".into(),
    };
    let result = match op {
        Pending::Complement => {
            // A complement of a complement is the shape itself.
            let Deep { shape, depth } = operands.pop().ok_or_else(missing)?.build();
            let (shape, depth) = match shape {
                Shape::Complement(inner) => (*inner, depth - 1),
                s => (!s, depth + 1),
            };
            check_depth(depth, at)?;
            Operand::Shape(Deep { shape, depth })
        }
        Pending::Binary(code) => {
            let b = operands.pop().ok_or_else(missing)?;
            let a = operands.pop().ok_or_else(missing)?;
            let mut items = a.into_chain(code);
            if code == TypeCode::Difference {
                items.push(b.build());
            } else {
                items.extend(b.into_chain(code));
            }
            // The chain's tree: its deepest operand plus the levels pairing adds.
            let deepest = items.iter().map(|d| d.depth).max().unwrap_or(0);
            let pairing = usize::BITS - (items.len() - 1).leading_zeros();
            check_depth(deepest + pairing + 1, at)?;
            Operand::Chain(code, items)
        }
        Pending::Group => return Err(missing()),
    };
    operands.push(result);
    Ok(())
}

/// Parses a CSG expression (see the module docs).
pub fn parse_shape(text: &str) -> Result<Shape, ExprError> {
    let mut p = Parser { text, pos: 0 };
    let shape = p.expression()?;
    p.skip_space();
    if p.pos < text.len() {
        return Err(p.error(format!("unexpected `{}`", p.rest_preview())));
    }
    Ok(shape)
}

struct Parser<'a> {
    text: &'a str,
    pos: usize,
}

impl Parser<'_> {
    fn error(&self, message: String) -> ExprError {
        ExprError {
            offset: self.pos,
            message,
        }
    }

    fn rest_preview(&self) -> String {
        self.text[self.pos..].chars().take(12).collect()
    }

    fn skip_space(&mut self) {
        while let Some(c) = self.text[self.pos..].chars().next() {
            if !c.is_whitespace() {
                break;
            }
            self.pos += c.len_utf8();
        }
    }

    fn peek(&mut self) -> Option<char> {
        self.skip_space();
        self.text[self.pos..].chars().next()
    }

    fn eat(&mut self, c: char) -> bool {
        if self.peek() == Some(c) {
            self.pos += c.len_utf8();
            true
        } else {
            false
        }
    }

    fn expect(&mut self, c: char) -> Result<(), ExprError> {
        if self.eat(c) {
            Ok(())
        } else {
            Err(self.error(format!("expected `{c}`, found `{}`", self.rest_preview())))
        }
    }

    fn identifier(&mut self) -> Option<&str> {
        self.skip_space();
        let start = self.pos;
        let len = self.text[start..]
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(self.text.len() - start);
        if len == 0 || self.text[start..].starts_with(|c: char| c.is_ascii_digit()) {
            return None;
        }
        self.pos += len;
        Some(&self.text[start..start + len])
    }

    /// The whole expression, by operator precedence over explicit stacks (no recursion, so
    /// any nesting the memory holds parses): operands and pending operators are pushed, and
    /// an operator is applied when one of lower or equal precedence, a `)` or the end
    /// follows it.
    fn expression(&mut self) -> Result<Shape, ExprError> {
        let mut operands: Vec<Operand> = Vec::new();
        let mut operators: Vec<(Pending, usize)> = Vec::new();
        loop {
            // An operand: prefix `!` and `(`, then a primitive or a group's end.
            loop {
                let at = self.pos;
                if self.eat('!') {
                    operators.push((Pending::Complement, at));
                } else if self.eat('(') {
                    operators.push((Pending::Group, at));
                } else {
                    break;
                }
            }
            operands.push(Operand::Shape(Deep {
                shape: self.primitive()?,
                depth: 1,
            }));
            // Then methods, `)` and binary operators until the next operand.
            loop {
                let at = self.pos;
                if self.eat('.') {
                    // Errors of a method name its name's column.
                    self.skip_space();
                    let at = self.pos;
                    let top = operands.pop().expect("an operand precedes a method");
                    operands.push(Operand::Shape(self.method(top.build(), at)?));
                } else if self.eat(')') {
                    loop {
                        match operators.pop() {
                            Some((Pending::Group, _)) => break,
                            Some((op, at)) => apply(&mut operands, op, at)?,
                            None => return Err(self.error_at(at, "unmatched `)`".into())),
                        }
                    }
                } else {
                    break;
                }
            }
            let next = match self.peek() {
                Some('+') => Pending::Binary(TypeCode::Union),
                Some('-') => Pending::Binary(TypeCode::Difference),
                Some('*') => Pending::Binary(TypeCode::Intersection),
                _ => break,
            };
            let at = self.pos;
            self.pos += 1;
            while let Some(&(top, top_at)) = operators.last() {
                if top.precedence() < next.precedence() {
                    break;
                }
                operators.pop();
                apply(&mut operands, top, top_at)?;
            }
            operators.push((next, at));
        }
        while let Some((op, at)) = operators.pop() {
            if op == Pending::Group {
                return Err(self.error(format!(
                    "expected `)` for the `(` at column {}, found `{}`",
                    at + 1,
                    self.rest_preview()
                )));
            }
            apply(&mut operands, op, at)?;
        }
        let shape = operands.pop().expect("one operand left").build();
        debug_assert!(operands.is_empty());
        Ok(shape.shape)
    }

    fn error_at(&self, offset: usize, message: String) -> ExprError {
        ExprError { offset, message }
    }

    /// The method after a `.` (at byte `at`) applied to `shape`; a placement of a placed
    /// shape composes the two transforms, so chains of methods stay one level deep.
    fn method(&mut self, operand: Deep, at: usize) -> Result<Deep, ExprError> {
        let Some(name) = self.identifier().map(str::to_string) else {
            return Err(self.error("expected a method name after `.`".into()));
        };
        let args = self.arguments()?;
        let want = |n: usize| -> Result<(), ExprError> {
            if args.len() == n {
                Ok(())
            } else {
                Err(ExprError {
                    offset: at,
                    message: format!("`{name}` takes {n} numbers, got {}", args.len()),
                })
            }
        };
        let transform = match name.as_str() {
            "translate" => {
                want(3)?;
                Transform64::translation([args[0], args[1], args[2]])
            }
            "rotate" => {
                want(4)?;
                let axis = [args[0], args[1], args[2]];
                if !axis.iter().any(|v| *v != 0.0) {
                    return Err(self.error_at(at, "rotate needs a non-zero axis".into()));
                }
                Transform64::rotation(axis, args[3].to_radians())
            }
            "scale" => {
                want(3)?;
                if !args.iter().all(|v| *v != 0.0) {
                    return Err(self.error_at(at, "scale factors must be non-zero".into()));
                }
                Transform64::scaling([args[0], args[1], args[2]])
            }
            other => {
                return Err(self.error_at(
                    at,
                    format!("unknown method `{other}` (translate, rotate, scale)"),
                ))
            }
        };
        Ok(match operand.shape {
            Shape::Placed(inner, s) => Deep {
                shape: Shape::Placed(transform.compose(&inner), s),
                depth: operand.depth,
            },
            s => {
                check_depth(operand.depth + 1, at)?;
                Deep {
                    shape: s.placed(transform),
                    depth: operand.depth + 1,
                }
            }
        })
    }

    fn primitive(&mut self) -> Result<Shape, ExprError> {
        let at = self.pos;
        let Some(name) = self.identifier().map(str::to_string) else {
            return Err(self.error(format!(
                "expected a primitive or `(`, found `{}`",
                self.rest_preview()
            )));
        };
        let a = self.arguments()?;
        let at_error = |message: String| ExprError {
            offset: at,
            message,
        };
        let want = |n: usize| -> Result<(), ExprError> {
            if a.len() == n {
                Ok(())
            } else {
                Err(at_error(format!(
                    "`{name}` takes {n} numbers, got {}",
                    a.len()
                )))
            }
        };
        let built: Result<Shape, CsgError> = match name.as_str() {
            "sphere" => want(1).map(|_| sphere(a[0]))?,
            "zsphere" => want(3).map(|_| zsphere(a[0], a[1], a[2]))?,
            "box" => want(3).map(|_| box3(a[0], a[1], a[2]))?,
            "cylinder" => want(3).map(|_| cylinder(a[0], a[1], a[2]))?,
            "tube" => want(4).map(|_| tube(a[0], a[1], a[2], a[3]))?,
            "cone" => want(4).map(|_| cone(a[0], a[1], a[2], a[3]))?,
            "hyperboloid" => want(4).map(|_| hyperboloid(a[0], a[1], a[2], a[3]))?,
            "torus" => want(3).map(|_| torus(a[0], a[1], a[2]))?,
            "paraboloid" => want(3).map(|_| paraboloid(a[0], a[1], a[2]))?,
            "halfspace" => want(4).map(|_| halfspace([a[0], a[1], a[2]], a[3]))?,
            "slab" => want(5).map(|_| slab([a[0], a[1], a[2]], a[3], a[4]))?,
            "phicut" => want(2).map(|_| phi_cut(a[0].to_radians(), a[1].to_radians()))?,
            "thetacut" => want(2).map(|_| theta_cut(a[0].to_radians(), a[1].to_radians()))?,
            "saddle" => want(1).map(|_| saddle(a[0]))?,
            "polyhedron" => {
                if a.is_empty() || a.len() % 4 != 0 {
                    return Err(at_error(format!(
                        "`polyhedron` takes four numbers per plane, got {}",
                        a.len()
                    )));
                }
                let planes: Vec<[f64; 4]> = a
                    .chunks_exact(4)
                    .map(|c| [c[0], c[1], c[2], c[3]])
                    .collect();
                polyhedron(&planes)
            }
            other => {
                return Err(at_error(format!(
                    "unknown primitive `{other}` (sphere, zsphere, box, cylinder, tube, cone, \
                     hyperboloid, torus, paraboloid, halfspace, slab, phicut, thetacut, \
                     saddle, polyhedron)"
                )))
            }
        };
        built.map_err(|e| at_error(e.to_string()))
    }

    fn arguments(&mut self) -> Result<Vec<f64>, ExprError> {
        self.expect('(')?;
        let mut out = Vec::new();
        if self.eat(')') {
            return Ok(out);
        }
        loop {
            out.push(self.number()?);
            if self.eat(')') {
                return Ok(out);
            }
            self.expect(',')?;
        }
    }

    fn number(&mut self) -> Result<f64, ExprError> {
        let mut value = self.factor()?;
        loop {
            if self.eat('*') {
                value *= self.factor()?;
            } else if self.eat('/') {
                value /= self.factor()?;
            } else {
                break;
            }
        }
        if !value.is_finite() {
            return Err(self.error(format!("number {value} is not finite")));
        }
        Ok(value)
    }

    fn factor(&mut self) -> Result<f64, ExprError> {
        // Any run of unary minuses, counted rather than recursed into.
        let mut negative = false;
        while self.eat('-') {
            negative = !negative;
        }
        let value = self.unsigned()?;
        Ok(if negative { -value } else { value })
    }

    fn unsigned(&mut self) -> Result<f64, ExprError> {
        self.skip_space();
        if self.text[self.pos..].starts_with("pi") {
            self.pos += 2;
            return Ok(std::f64::consts::PI);
        }
        let start = self.pos;
        let len = self.text[start..]
            .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == 'e' || c == 'E'))
            .unwrap_or(self.text.len() - start);
        // An exponent sign belongs to the literal.
        let mut end = start + len;
        if end > start
            && self.text[start..end].ends_with(['e', 'E'])
            && self.text[end..].starts_with(['-', '+'])
        {
            end += 1;
            end += self.text[end..]
                .find(|c: char| !c.is_ascii_digit())
                .unwrap_or(self.text.len() - end);
        }
        let literal = &self.text[start..end];
        let value = literal.parse::<f64>().map_err(|_| {
            self.error(format!(
                "expected a number, found `{}`",
                self.rest_preview()
            ))
        })?;
        self.pos = end;
        Ok(value)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hytrace_testkit::{Random, XorShift64};

    #[test]
    fn precedence_and_methods_build_the_same_shape_as_the_builder() {
        let parsed = parse_shape(
            "tube(10, 100, -50, 50) - sphere(30).translate(0, 0, 50) * !box(20, 20, 2e2)",
        )
        .unwrap();
        let built = tube(10.0, 100.0, -50.0, 50.0).unwrap()
            - (sphere(30.0).unwrap().translate(0.0, 0.0, 50.0) * !box3(20.0, 20.0, 200.0).unwrap());
        assert_eq!(parsed, built);
        let rotated = parse_shape("box(1,2,3).rotate(0, 0, 1, 90).scale(1, 1, 2)").unwrap();
        // Successive placements compose into one.
        let expected =
            box3(1.0, 2.0, 3.0)
                .unwrap()
                .placed(
                    Transform64::scaling([1.0, 1.0, 2.0]).compose(&Transform64::rotation(
                        [0.0, 0.0, 1.0],
                        std::f64::consts::FRAC_PI_2,
                    )),
                );
        assert_eq!(rotated, expected);
        assert_eq!(
            parse_shape("phicut(-2*pi/pi, 1e-1*10)").unwrap(),
            phi_cut((-2.0f64).to_radians(), 1f64.to_radians()).unwrap()
        );
    }

    #[test]
    fn errors_name_the_column_and_the_problem() {
        let cases = [
            ("sphere(1) + blob(2)", 13, "unknown primitive `blob`"),
            ("sphere(-1)", 1, "radius must be finite and > 0"),
            ("sphere(1, 2)", 1, "takes 1 numbers, got 2"),
            ("sphere(1) +", 12, "expected a primitive"),
            ("(sphere(1)", 11, "expected `)`"),
            ("sphere(1).spin(1)", 11, "unknown method `spin`"),
            ("sphere(1) sphere(2)", 11, "unexpected `sphere(2)`"),
            ("sphere(1/0)", 11, "not finite"),
            ("box(1,2,x)", 9, "expected a number"),
        ];
        for (text, column, needle) in cases {
            let e = parse_shape(text).unwrap_err();
            assert!(e.to_string().contains(needle), "{text}: {e}");
            assert_eq!(e.offset + 1, column, "{text}: {e}");
        }
    }

    /// Levels on the longest path of `shape` (a primitive is 1), counted without recursion.
    fn depth(shape: &Shape) -> u32 {
        let mut deepest = 0;
        let mut stack = vec![(shape, 1)];
        while let Some((s, d)) = stack.pop() {
            deepest = deepest.max(d);
            match s {
                Shape::Leaf(_) => {}
                Shape::Op(_, a, b) => stack.extend([(&**a, d + 1), (&**b, d + 1)]),
                Shape::Placed(_, c) | Shape::Complement(c) => stack.push((&**c, d + 1)),
            }
        }
        deepest
    }

    #[test]
    fn deep_nesting_parses_without_recursion() {
        let n = 100_000;
        // Parentheses, complements and unary minuses nested 10^5 deep.
        let text = format!("{}sphere(1){}", "(".repeat(n), ")".repeat(n));
        assert_eq!(parse_shape(&text).unwrap(), sphere(1.0).unwrap());
        let text = format!("{}sphere(1)", "!".repeat(n + 1));
        assert_eq!(parse_shape(&text).unwrap(), !sphere(1.0).unwrap());
        let text = format!("sphere({}2)", "-".repeat(n));
        assert_eq!(parse_shape(&text).unwrap(), sphere(2.0).unwrap());
        // 10^5 placements compose into one.
        let text = format!("sphere(1){}", ".translate(1, 0, 0)".repeat(n));
        match parse_shape(&text).unwrap() {
            Shape::Placed(t, _) => assert_eq!(t.rows[0][3], n as f64),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn long_chains_written_either_way_become_shallow_trees() {
        // 5000 unions nested to the right, to the left and flat: one balanced tree each,
        // 14 levels deep (a primitive is 1), which the tree builder turns into a list.
        let parts = 5000;
        let part = |i: usize| format!("sphere(1).translate({i}, 0, 0)");
        let mut right = part(parts - 1);
        for i in (0..parts - 1).rev() {
            right = format!("{} + ({right})", part(i));
        }
        let mut left = part(0);
        for i in 1..parts {
            left = format!("({left}) + {}", part(i));
        }
        let flat = (0..parts).map(part).collect::<Vec<_>>().join(" + ");
        for text in [right, left, flat] {
            let shape = parse_shape(&text).unwrap();
            assert_eq!(depth(&shape), 15, "{}", &text[..40]);
            let tree = crate::to_tree(&shape).unwrap();
            assert_eq!(tree.members.len(), parts);
        }
        // `a - b - c - ...` subtracts one union.
        let text = format!(
            "box(100, 100, 100) - {}",
            (0..parts).map(part).collect::<Vec<_>>().join(" - ")
        );
        assert_eq!(depth(&parse_shape(&text).unwrap()), 16);
    }

    #[test]
    fn nesting_no_tree_can_hold_is_a_clear_error() {
        // Differences nested to the right do not join: 5000 levels are refused by name.
        let mut text = String::from("sphere(1)");
        for _ in 0..5000 {
            text = format!("sphere(2) - ({text})");
        }
        let e = parse_shape(&text).unwrap_err();
        assert!(e.to_string().contains("more than 1000 levels"), "{e}");
        // Alternating complements and placements nest too.
        let text = format!(
            "{}sphere(1){}",
            "!(".repeat(3000),
            ").translate(1, 0, 0)".repeat(3000)
        );
        let e = parse_shape(&text).unwrap_err();
        assert!(e.to_string().contains("more than 1000 levels"), "{e}");
    }

    #[test]
    fn arbitrary_input_never_panics() {
        // Property test: every prefix and 10^5 byte-mutations of valid expressions parse or
        // error cleanly.
        let seeds = [
            "(tube(10, 100, -50, 50) - sphere(30).translate(0, 0, 50)) * !box(20, 20, 200)",
            "polyhedron(1,0,0,1, -1,0,0,1, 0,1,0,1, 0,-1,0,1, 0,0,1,1, 0,0,-1,1).rotate(1,1,0,-3e1)",
            "torus(0,1,5) + phicut(0, 90)*thetacut(10,80)",
        ];
        let alphabet = b"()+-*!.,0123456789e pi";
        let mut rng = XorShift64(0x9e3779b97f4a7c15);
        for s in seeds {
            for end in 0..=s.len() {
                let _ = parse_shape(&s[..end]);
            }
            for _ in 0..33_400 {
                let mut bytes = s.as_bytes().to_vec();
                for _ in 0..3 {
                    let state = rng.next_u64();
                    let i = (state % bytes.len() as u64) as usize;
                    bytes[i] = alphabet[(state >> 32) as usize % alphabet.len()];
                }
                let _ = parse_shape(&String::from_utf8(bytes).unwrap());
            }
        }
    }
}
