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
//!   `polyhedron(nx, ny, nz, d, ...)` (four numbers per plane).
//! - Numbers: decimal literals, `pi`, unary minus, and `*` `/` between them
//!   (`-2*pi/3`).

use crate::shape::{
    box3, cone, cylinder, halfspace, hyperboloid, paraboloid, phi_cut, polyhedron, slab, sphere,
    theta_cut, torus, tube, zsphere, CsgError, Shape,
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

    fn expression(&mut self) -> Result<Shape, ExprError> {
        let mut left = self.term()?;
        loop {
            if self.eat('+') {
                left = left + self.term()?;
            } else if self.eat('-') {
                left = left - self.term()?;
            } else {
                return Ok(left);
            }
        }
    }

    fn term(&mut self) -> Result<Shape, ExprError> {
        let mut left = self.unary()?;
        while self.eat('*') {
            left = left * self.unary()?;
        }
        Ok(left)
    }

    fn unary(&mut self) -> Result<Shape, ExprError> {
        if self.eat('!') {
            return Ok(!self.unary()?);
        }
        let mut shape = if self.eat('(') {
            let s = self.expression()?;
            self.expect(')')?;
            s
        } else {
            self.primitive()?
        };
        while self.eat('.') {
            let at = self.pos;
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
            shape = match name.as_str() {
                "translate" => {
                    want(3)?;
                    shape.translate(args[0], args[1], args[2])
                }
                "rotate" => {
                    want(4)?;
                    let axis = [args[0], args[1], args[2]];
                    if !axis.iter().any(|v| *v != 0.0) {
                        return Err(ExprError {
                            offset: at,
                            message: "rotate needs a non-zero axis".into(),
                        });
                    }
                    shape.rotate(axis, args[3].to_radians())
                }
                "scale" => {
                    want(3)?;
                    if !args.iter().all(|v| *v != 0.0) {
                        return Err(ExprError {
                            offset: at,
                            message: "scale factors must be non-zero".into(),
                        });
                    }
                    shape.scale(args[0], args[1], args[2])
                }
                other => {
                    return Err(ExprError {
                        offset: at,
                        message: format!("unknown method `{other}` (translate, rotate, scale)"),
                    })
                }
            };
        }
        Ok(shape)
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
                     polyhedron)"
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
        if self.eat('-') {
            return Ok(-self.factor()?);
        }
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
        let expected = box3(1.0, 2.0, 3.0)
            .unwrap()
            .rotate([0.0, 0.0, 1.0], std::f64::consts::FRAC_PI_2)
            .scale(1.0, 1.0, 2.0);
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

    #[test]
    fn arbitrary_input_never_panics() {
        // Property test: every prefix and byte-mutation of valid expressions parses or
        // errors cleanly.
        let seeds = [
            "(tube(10, 100, -50, 50) - sphere(30).translate(0, 0, 50)) * !box(20, 20, 200)",
            "polyhedron(1,0,0,1, -1,0,0,1, 0,1,0,1, 0,-1,0,1, 0,0,1,1, 0,0,-1,1).rotate(1,1,0,-3e1)",
            "torus(0,1,5) + phicut(0, 90)*thetacut(10,80)",
        ];
        let alphabet = b"()+-*!.,0123456789e pi";
        let mut state = 0x9e3779b97f4a7c15u64;
        for s in seeds {
            for end in 0..=s.len() {
                let _ = parse_shape(&s[..end]);
            }
            for _ in 0..2000 {
                let mut bytes = s.as_bytes().to_vec();
                for _ in 0..3 {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    let i = (state % bytes.len() as u64) as usize;
                    bytes[i] = alphabet[(state >> 32) as usize % alphabet.len()];
                }
                let _ = parse_shape(&String::from_utf8(bytes).unwrap());
            }
        }
    }
}
