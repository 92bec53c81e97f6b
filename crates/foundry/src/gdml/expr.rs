//! GDML arithmetic expressions, evaluated the way Geant4 evaluates them (CLHEP's
//! `HepTool::Evaluator` behind `G4GDMLEvaluator`).
//!
//! Grammar, from the loosest to the tightest binding (all binary operators are
//! left-associative except the power):
//!
//! | level | operators                 | result          |
//! |-------|---------------------------|-----------------|
//! | 1     | `\|\|`                    | 1.0 or 0.0      |
//! | 2     | `&&`                      | 1.0 or 0.0      |
//! | 3     | `==` `!=`                 | 1.0 or 0.0      |
//! | 4     | `<` `<=` `>` `>=`         | 1.0 or 0.0      |
//! | 5     | `+` `-`                   |                 |
//! | 6     | `*` `/`                   |                 |
//! | 7     | unary `+` `-`             |                 |
//! | 8     | `^` and `**`, right-assoc. | `-2^2` is -4, `2^3^2` is 512, `2^-1` is 0.5 |
//!
//! Operands are numbers (`1`, `1.5`, `.5`, `1e-3`, `2.E+4`), parenthesised
//! expressions, names (`[A-Za-z_][A-Za-z0-9_]*`), function calls `name(a, b)` and matrix
//! elements `name[i]` / `name[i, j]`. Blanks (C `isspace`) may separate any two tokens.
//!
//! A name is looked up in the [`Scope`] first, then among the built-in constants (`pi`,
//! `e`, `gamma`, `twopi`, `halfpi`, `pi2`, `PI`, `TWOPI`, `HALFPI` and CLHEP's
//! `PhysicalConstants.h`: `c_light`, `hbarc`, `electron_mass_c2`, ...), then among the
//! units ([`unit()`]), and last as a matrix element name (below).
//!
//! # Matrices
//!
//! Geant4 (`G4GDMLEvaluator::DefineMatrix`) stores the elements of a matrix `m` as
//! constants named with 0-based indices: `m_k` when the matrix has one row or one column,
//! `m_i_j` (row `i`, column `j`) otherwise. `G4GDMLEvaluator::SolveBrackets` rewrites
//! `m[i]` / `m[i,j]` in an expression into `m_(i-1)` / `m_(i-1)_(j-1)`: brackets are
//! 1-based and the indices must be integer-valued expressions. Both spellings work here,
//! on the matrices of [`Scope::matrix`].
//!
//! # Errors
//!
//! Nothing panics: syntax errors, unknown names or functions, wrong argument counts, a
//! division by zero, any non-finite intermediate value (`sqrt(-1)`, `1e308*10`) and
//! nesting deeper than 256 levels are [`ExprError`]s carrying the expression and the
//! 1-based byte column of the problem.
//!
//! The evaluator is a recursive-descent parser over the bytes of the text that computes
//! as it parses; it allocates only to report an error (and to rebuild the Geant4 element
//! name for `m[i]` when the scope has no matrix `m`). The deepest nesting allowed takes
//! about 100 KiB of stack when optimised, 400 KiB unoptimised.
//!
//! # Differences from CLHEP
//!
//! Besides CLHEP's functions (`abs min max sqrt pow sin cos tan asin acos atan atan2 sinh
//! cosh tanh exp log log10`) there are `fabs fmod floor ceil int` (`int` truncates).
//! Numbers are decimal only (CLHEP's `strtod` would also take `0x1F`); a number that
//! underflows is 0 rather than an error. Matrices are also reachable when the scope
//! defines them whole rather than element by element.

/// Values an expression may refer to.
pub trait Scope {
    /// The value of a named scalar (constant, variable, quantity, loop variable), if defined.
    fn scalar(&self, name: &str) -> Option<f64>;
    /// The elements of a named matrix in row-major order (element `(i, j)`, 0-based, at
    /// `i * columns + j`) and its (rows, columns), if the matrix exists.
    fn matrix(&self, name: &str) -> Option<(&[f64], usize, usize)>;
}

/// The empty scope: expressions made of numbers, constants and units only.
impl Scope for () {
    fn scalar(&self, _name: &str) -> Option<f64> {
        None
    }
    fn matrix(&self, _name: &str) -> Option<(&[f64], usize, usize)> {
        None
    }
}

/// Error with a message saying what is wrong and where in the text (byte column).
///
/// `message` starts with the expression (`cannot evaluate "2*(x+": unexpected end`);
/// `column` is the 1-based byte column of the problem (one past the end for a premature
/// end). Displayed as `cannot evaluate "2*(x+": unexpected end at column 6`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message} at column {column}")]
pub struct ExprError {
    /// What is wrong, after the quoted expression.
    pub message: String,
    /// 1-based byte column in the expression where the problem is.
    pub column: usize,
}

/// Evaluates `text` (a GDML expression) in `scope`.
///
/// The result is always finite. See the [module documentation](self) for the grammar,
/// the name lookup order and the matrix conventions.
pub fn evaluate(text: &str, scope: &dyn Scope) -> Result<f64, ExprError> {
    let mut parser = Parser {
        text,
        bytes: text.as_bytes(),
        pos: 0,
        depth: 0,
        scope,
    };
    parser.run().map_err(|fail| fail.into_error(text))
}

/// Nesting (parentheses, arguments, indices, exponents) allowed before giving up.
const MAX_DEPTH: usize = 256;

/// How much of the expression an error message quotes.
const MAX_QUOTED: usize = 160;

/// An error before the expression text is attached (boxed: the parser's results stay
/// two words wide, which keeps its recursion frames small).
struct Fail(Box<(usize, String)>);

impl Fail {
    #[cold]
    fn into_error(self, text: &str) -> ExprError {
        let (at, problem) = *self.0;
        let message = if text.len() <= MAX_QUOTED {
            format!("cannot evaluate {text:?}: {problem}")
        } else {
            let mut cut = MAX_QUOTED;
            while !text.is_char_boundary(cut) {
                cut -= 1;
            }
            format!(
                "cannot evaluate {:?}... ({} bytes): {problem}",
                &text[..cut],
                text.len()
            )
        };
        ExprError {
            message,
            column: at + 1,
        }
    }
}

#[cold]
#[inline(never)]
fn fail(at: usize, message: String) -> Fail {
    Fail(Box::new((at, message)))
}

type Parsed = Result<f64, Fail>;

#[derive(Clone, Copy)]
enum BinOp {
    Or,
    And,
    Eq,
    Ne,
    Lt,
    Le,
    Gt,
    Ge,
    Add,
    Sub,
    Mul,
    Div,
}

impl BinOp {
    fn precedence(self) -> u8 {
        match self {
            BinOp::Or => 1,
            BinOp::And => 2,
            BinOp::Eq | BinOp::Ne => 3,
            BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => 4,
            BinOp::Add | BinOp::Sub => 5,
            BinOp::Mul | BinOp::Div => 6,
        }
    }

    fn symbol(self) -> &'static str {
        match self {
            BinOp::Or => "||",
            BinOp::And => "&&",
            BinOp::Eq => "==",
            BinOp::Ne => "!=",
            BinOp::Lt => "<",
            BinOp::Le => "<=",
            BinOp::Gt => ">",
            BinOp::Ge => ">=",
            BinOp::Add => "+",
            BinOp::Sub => "-",
            BinOp::Mul => "*",
            BinOp::Div => "/",
        }
    }
}

/// What produced a non-finite value, for the error message.
#[derive(Clone, Copy)]
enum Source<'n> {
    Op(BinOp),
    Power,
    Call(&'n str),
    Name(&'n str),
    Element(&'n str),
}

fn truth(b: bool) -> f64 {
    if b {
        1.0
    } else {
        0.0
    }
}

/// C's `isspace` in the "C" locale.
fn is_blank(c: u8) -> bool {
    c == b' ' || (b'\t'..=b'\r').contains(&c)
}

fn is_name_byte(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

/// `value` if finite, else an error saying what made it.
#[inline]
fn finite(value: f64, at: usize, source: Source) -> Parsed {
    if value.is_finite() {
        Ok(value)
    } else {
        Err(not_finite(value, at, source))
    }
}

#[cold]
#[inline(never)]
fn not_finite(value: f64, at: usize, source: Source) -> Fail {
    let what = match source {
        Source::Op(op) => format!("\"{}\"", op.symbol()),
        Source::Power => "power".to_string(),
        Source::Call(name) => format!("{name}()"),
        Source::Name(name) => format!("{name:?}"),
        Source::Element(name) => format!("element of {name:?}"),
    };
    fail(at, format!("{what} evaluates to {value}"))
}

/// The built-in functions: number of arguments.
fn arity(name: &str) -> Option<usize> {
    Some(match name {
        "abs" | "fabs" | "sqrt" | "sin" | "cos" | "tan" | "asin" | "acos" | "atan" | "sinh"
        | "cosh" | "tanh" | "exp" | "log" | "log10" | "floor" | "ceil" | "int" => 1,
        "min" | "max" | "pow" | "atan2" | "fmod" => 2,
        _ => return None,
    })
}

/// The built-in functions: value (`b` is ignored by one-argument functions).
#[inline(never)]
fn call_function(name: &str, a: f64, b: f64) -> Option<f64> {
    Some(match name {
        "abs" | "fabs" => a.abs(),
        "min" => {
            if a < b {
                a
            } else {
                b
            }
        }
        "max" => {
            if a > b {
                a
            } else {
                b
            }
        }
        "sqrt" => a.sqrt(),
        "pow" => a.powf(b),
        "sin" => a.sin(),
        "cos" => a.cos(),
        "tan" => a.tan(),
        "asin" => a.asin(),
        "acos" => a.acos(),
        "atan" => a.atan(),
        "atan2" => a.atan2(b),
        "sinh" => a.sinh(),
        "cosh" => a.cosh(),
        "tanh" => a.tanh(),
        "exp" => a.exp(),
        "log" => a.ln(),
        "log10" => a.log10(),
        "fmod" => a % b,
        "floor" => a.floor(),
        "ceil" => a.ceil(),
        "int" => a.trunc(),
        _ => return None,
    })
}

/// Up to two parsed indices of `name[...]` (1-based values and their byte offsets) and
/// how many there were.
#[derive(Clone, Copy)]
struct Indices {
    values: [usize; 2],
    offsets: [usize; 2],
    count: usize,
}

struct Parser<'a> {
    text: &'a str,
    bytes: &'a [u8],
    pos: usize,
    depth: usize,
    scope: &'a dyn Scope,
}

// The functions on the recursion (binary, unary, power, primary, name, call, element)
// leave all formatting to out-of-line cold functions, so that even unoptimised builds
// use little stack per nesting level.
impl<'a> Parser<'a> {
    fn run(&mut self) -> Parsed {
        self.skip_blanks();
        if self.pos == self.bytes.len() {
            return Err(fail(0, "empty expression".to_string()));
        }
        let value = self.binary(1)?;
        self.skip_blanks();
        match self.peek() {
            None => Ok(value),
            Some(b')') => Err(fail(self.pos, "unmatched \")\"".to_string())),
            Some(_) => Err(self.unexpected()),
        }
    }

    fn peek(&self) -> Option<u8> {
        self.bytes.get(self.pos).copied()
    }

    fn peek_at(&self, offset: usize) -> Option<u8> {
        self.bytes.get(self.pos + offset).copied()
    }

    fn skip_blanks(&mut self) {
        while self.peek().is_some_and(is_blank) {
            self.pos += 1;
        }
    }

    /// "unexpected X" for what is at the current position.
    #[cold]
    #[inline(never)]
    fn unexpected(&self) -> Fail {
        fail(self.pos, format!("unexpected {}", self.found()))
    }

    /// "expected WHAT but found X" at the current position.
    #[cold]
    #[inline(never)]
    fn expected(&self, what: &str) -> Fail {
        fail(
            self.pos,
            format!("expected {what} but found {}", self.found()),
        )
    }

    #[cold]
    #[inline(never)]
    fn unclosed(&self, open: usize) -> Fail {
        self.expected(&format!("\")\" to close \"(\" at column {}", open + 1))
    }

    #[cold]
    #[inline(never)]
    fn unknown(&self, what: &str, name: &str, at: usize) -> Fail {
        fail(at, format!("unknown {what} {name:?}"))
    }

    #[cold]
    fn found(&self) -> String {
        // `pos` only ever advances over ASCII bytes, so it is on a char boundary.
        match self
            .text
            .get(self.pos..)
            .and_then(|rest| rest.chars().next())
        {
            None => "end".to_string(),
            Some(c) => format!("{:?}", c.to_string()),
        }
    }

    /// Precedence climbing over the left-associative binary operators.
    fn binary(&mut self, min_precedence: u8) -> Parsed {
        let mut lhs = self.unary()?;
        loop {
            self.skip_blanks();
            let Some((op, len)) = self.peek_binop() else {
                return Ok(lhs);
            };
            let precedence = op.precedence();
            if precedence < min_precedence {
                return Ok(lhs);
            }
            let at = self.pos;
            self.pos += len;
            let rhs = self.binary(precedence + 1)?;
            lhs = apply(op, lhs, rhs, at)?;
        }
    }

    fn peek_binop(&self) -> Option<(BinOp, usize)> {
        let next = self.peek_at(1);
        Some(match (self.peek()?, next) {
            (b'|', Some(b'|')) => (BinOp::Or, 2),
            (b'&', Some(b'&')) => (BinOp::And, 2),
            (b'=', Some(b'=')) => (BinOp::Eq, 2),
            (b'!', Some(b'=')) => (BinOp::Ne, 2),
            (b'<', Some(b'=')) => (BinOp::Le, 2),
            (b'<', _) => (BinOp::Lt, 1),
            (b'>', Some(b'=')) => (BinOp::Ge, 2),
            (b'>', _) => (BinOp::Gt, 1),
            (b'+', _) => (BinOp::Add, 1),
            (b'-', _) => (BinOp::Sub, 1),
            (b'*', Some(b'*')) => return None,
            (b'*', _) => (BinOp::Mul, 1),
            (b'/', _) => (BinOp::Div, 1),
            _ => return None,
        })
    }

    /// Unary signs, then a power. Every nested expression passes through here, so this
    /// is where the depth is bounded.
    fn unary(&mut self) -> Parsed {
        if self.depth >= MAX_DEPTH {
            return Err(too_deep(self.pos));
        }
        self.depth += 1;
        let (mut signs, mut minuses, mut last_minus) = (0usize, 0usize, false);
        loop {
            self.skip_blanks();
            match self.peek() {
                Some(b'+') => last_minus = false,
                Some(b'-') => {
                    last_minus = true;
                    minuses += 1;
                }
                _ => break,
            }
            signs += 1;
            self.pos += 1;
        }
        let value = self.power();
        self.depth -= 1;
        let value = value?;
        if signs == 0 {
            return Ok(value);
        }
        // CLHEP computes a unary sign as `0 + x` / `0 - x`: the innermost one decides the
        // sign of a zero, the others can only negate (and never produce -0).
        let mut result = if last_minus { 0.0 - value } else { 0.0 + value };
        if (minuses - usize::from(last_minus)) % 2 == 1 {
            result = 0.0 - result;
        }
        Ok(result)
    }

    /// An operand, optionally raised to a (right-associative, possibly signed) power.
    fn power(&mut self) -> Parsed {
        let base = self.primary()?;
        self.skip_blanks();
        let at = self.pos;
        let len = match (self.peek(), self.peek_at(1)) {
            (Some(b'^'), _) => 1,
            (Some(b'*'), Some(b'*')) => 2,
            _ => return Ok(base),
        };
        self.pos += len;
        let exponent = self.unary()?;
        finite(base.powf(exponent), at, Source::Power)
    }

    fn primary(&mut self) -> Parsed {
        self.skip_blanks();
        let start = self.pos;
        match self.peek() {
            None => Err(fail(start, "unexpected end".to_string())),
            Some(b'(') => {
                self.pos += 1;
                let value = self.binary(1)?;
                self.skip_blanks();
                if self.peek() != Some(b')') {
                    return Err(self.unclosed(start));
                }
                self.pos += 1;
                Ok(value)
            }
            Some(c) if c.is_ascii_digit() || c == b'.' => self.number(),
            Some(c) if c.is_ascii_alphabetic() || c == b'_' => self.name(),
            Some(_) => Err(self.unexpected()),
        }
    }

    fn number(&mut self) -> Parsed {
        let bytes = self.bytes;
        let start = self.pos;
        let digits_from = |mut i: usize| {
            while bytes.get(i).is_some_and(u8::is_ascii_digit) {
                i += 1;
            }
            i
        };
        let mut end = digits_from(start);
        let mut digits = end - start;
        if bytes.get(end) == Some(&b'.') {
            let after = digits_from(end + 1);
            digits += after - end - 1;
            end = after;
        }
        if digits == 0 {
            return Err(fail(start, "bad number \".\"".to_string()));
        }
        if matches!(bytes.get(end), Some(b'e' | b'E')) {
            let mut i = end + 1;
            if matches!(bytes.get(i), Some(b'+' | b'-')) {
                i += 1;
            }
            let after = digits_from(i);
            if after == i {
                return Err(bad_number(
                    &self.text[start..i],
                    start,
                    "exponent without digits",
                ));
            }
            end = after;
        }
        let literal = &self.text[start..end];
        match literal.parse::<f64>() {
            Ok(value) if value.is_finite() => {
                self.pos = end;
                Ok(value)
            }
            Ok(_) => Err(bad_number(literal, start, "out of range")),
            Err(_) => Err(bad_number(literal, start, "not a number")),
        }
    }

    fn name(&mut self) -> Parsed {
        let start = self.pos;
        let mut end = start;
        while self.bytes.get(end).copied().is_some_and(is_name_byte) {
            end += 1;
        }
        let name = &self.text[start..end];
        self.pos = end;
        self.skip_blanks();
        match self.peek() {
            Some(b'(') => self.call(name, start),
            Some(b'[') => self.element(name, start),
            _ => self.variable(name, start),
        }
    }

    fn variable(&self, name: &str, at: usize) -> Parsed {
        match self.lookup(name) {
            Some(value) => finite(value, at, Source::Name(name)),
            None => Err(self.unknown("name", name, at)),
        }
    }

    fn lookup(&self, name: &str) -> Option<f64> {
        self.scope
            .scalar(name)
            .or_else(|| constant(name))
            .or_else(|| unit(name))
            .or_else(|| matrix_element(self.scope, name))
    }

    /// `name(args)`; the current byte is the `(`.
    fn call(&mut self, name: &str, at: usize) -> Parsed {
        let Some(arity) = arity(name) else {
            return Err(self.unknown("function", name, at));
        };
        self.pos += 1;
        let mut args = [0.0; 2];
        let mut count = 0usize;
        self.skip_blanks();
        if self.peek() == Some(b')') {
            self.pos += 1;
        } else {
            loop {
                let value = self.binary(1)?;
                if let Some(slot) = args.get_mut(count) {
                    *slot = value;
                }
                count += 1;
                self.skip_blanks();
                match self.peek() {
                    Some(b',') => self.pos += 1,
                    Some(b')') => {
                        self.pos += 1;
                        break;
                    }
                    _ => return Err(self.expected("\",\" or \")\"")),
                }
            }
        }
        if count != arity {
            return Err(wrong_arity(name, arity, count, at));
        }
        match call_function(name, args[0], args[1]) {
            Some(value) => finite(value, at, Source::Call(name)),
            None => Err(self.unknown("function", name, at)),
        }
    }

    /// `name[i]` or `name[i, j]` with 1-based indices; the current byte is the `[`.
    fn element(&mut self, name: &str, at: usize) -> Parsed {
        self.pos += 1;
        let mut indices = Indices {
            values: [0; 2],
            offsets: [0; 2],
            count: 0,
        };
        loop {
            self.skip_blanks();
            let offset = self.pos;
            let value = self.binary(1)?;
            if value < 1.0 || value.fract() != 0.0 {
                return Err(bad_index(value, offset));
            }
            if indices.count < 2 {
                // Saturates for huge values, which are then out of range.
                indices.values[indices.count] = value as usize;
                indices.offsets[indices.count] = offset;
            }
            indices.count += 1;
            self.skip_blanks();
            match self.peek() {
                Some(b',') => self.pos += 1,
                Some(b']') => {
                    self.pos += 1;
                    break;
                }
                _ => return Err(self.expected("\",\" or \"]\"")),
            }
        }
        self.resolve_element(name, at, indices)
    }

    #[inline(never)]
    fn resolve_element(&self, name: &str, at: usize, indices: Indices) -> Parsed {
        let Some((data, rows, columns)) = self.scope.matrix(name) else {
            return self.element_by_name(name, at, indices);
        };
        let vector = rows == 1 || columns == 1;
        if indices.count != if vector { 1 } else { 2 } {
            return Err(wrong_index_count(name, rows, columns, indices.count, at));
        }
        let [i, j] = indices.values;
        let flat = if vector {
            let size = rows.saturating_mul(columns);
            if i > size {
                return Err(out_of_range(name, i, size, indices.offsets[0]));
            }
            i - 1
        } else {
            if i > rows {
                return Err(out_of_range(name, i, rows, indices.offsets[0]));
            }
            if j > columns {
                return Err(out_of_range(name, j, columns, indices.offsets[1]));
            }
            (i - 1).saturating_mul(columns).saturating_add(j - 1)
        };
        match data.get(flat) {
            Some(&value) => finite(value, at, Source::Element(name)),
            None => Err(short_matrix(name, data.len(), rows, columns, at)),
        }
    }

    /// `name[i,j]` when the scope has no matrix `name`: Geant4 rewrites it into the
    /// variable `name_(i-1)_(j-1)` whatever defined it, so look that name up.
    #[cold]
    #[inline(never)]
    fn element_by_name(&self, name: &str, at: usize, indices: Indices) -> Parsed {
        if self.lookup(name).is_some() {
            return Err(fail(at, format!("{name:?} is not a matrix")));
        }
        if indices.count <= 2 {
            let mut flat = name.to_string();
            for &index in &indices.values[..indices.count] {
                flat.push_str(&format!("_{}", index - 1));
            }
            if let Some(value) = self.lookup(&flat) {
                return finite(value, at, Source::Name(&flat));
            }
        }
        Err(self.unknown("matrix", name, at))
    }
}

fn apply(op: BinOp, l: f64, r: f64, at: usize) -> Parsed {
    let value = match op {
        BinOp::Or => truth(l != 0.0 || r != 0.0),
        BinOp::And => truth(l != 0.0 && r != 0.0),
        BinOp::Eq => truth(l == r),
        BinOp::Ne => truth(l != r),
        BinOp::Lt => truth(l < r),
        BinOp::Le => truth(l <= r),
        BinOp::Gt => truth(l > r),
        BinOp::Ge => truth(l >= r),
        BinOp::Add => l + r,
        BinOp::Sub => l - r,
        BinOp::Mul => l * r,
        BinOp::Div => {
            if r == 0.0 {
                return Err(fail(at, "division by zero".to_string()));
            }
            l / r
        }
    };
    finite(value, at, Source::Op(op))
}

#[cold]
#[inline(never)]
fn too_deep(at: usize) -> Fail {
    fail(at, format!("nesting deeper than {MAX_DEPTH} levels"))
}

#[cold]
#[inline(never)]
fn bad_number(literal: &str, at: usize, why: &str) -> Fail {
    fail(at, format!("bad number {literal:?} ({why})"))
}

#[cold]
#[inline(never)]
fn wrong_arity(name: &str, arity: usize, count: usize, at: usize) -> Fail {
    let plural = if arity == 1 { "" } else { "s" };
    fail(
        at,
        format!("{name}() takes {arity} argument{plural} but {count} given"),
    )
}

#[cold]
#[inline(never)]
fn bad_index(value: f64, at: usize) -> Fail {
    fail(
        at,
        format!("matrix index {value} is not a positive integer (GDML indices start at 1)"),
    )
}

#[cold]
#[inline(never)]
fn wrong_index_count(name: &str, rows: usize, columns: usize, count: usize, at: usize) -> Fail {
    let what = if rows == 1 || columns == 1 {
        "1 index"
    } else {
        "2 indices"
    };
    fail(
        at,
        format!("matrix {name:?} is {rows}x{columns} and takes {what}, not {count}"),
    )
}

#[cold]
#[inline(never)]
fn out_of_range(name: &str, index: usize, size: usize, at: usize) -> Fail {
    fail(
        at,
        format!("index {index} is out of range 1..={size} of matrix {name:?}"),
    )
}

#[cold]
#[inline(never)]
fn short_matrix(name: &str, len: usize, rows: usize, columns: usize, at: usize) -> Fail {
    fail(
        at,
        format!("matrix {name:?} has {len} elements, fewer than {rows}x{columns}"),
    )
}

/// `prefix_k` with `k` a canonical decimal (as Geant4 prints it) into (`prefix`, `k`).
fn split_index(name: &str) -> Option<(&str, usize)> {
    let underscore = name.rfind('_')?;
    let (prefix, digits) = (&name[..underscore], &name[underscore + 1..]);
    if prefix.is_empty()
        || digits.is_empty()
        || !digits.bytes().all(|c| c.is_ascii_digit())
        || (digits.len() > 1 && digits.starts_with('0'))
    {
        return None;
    }
    Some((prefix, digits.parse().ok()?))
}

/// A matrix element by the name Geant4 gives it: `m_i_j` (0-based) for a matrix with
/// several rows and columns, `m_k` for one with a single row or column.
fn matrix_element(scope: &dyn Scope, name: &str) -> Option<f64> {
    let (head, last) = split_index(name)?;
    if let Some((matrix, row)) = split_index(head) {
        if let Some((data, rows, columns)) = scope.matrix(matrix) {
            if rows > 1 && columns > 1 && row < rows && last < columns {
                return data
                    .get(row.checked_mul(columns)?.checked_add(last)?)
                    .copied();
            }
        }
    }
    let (data, rows, columns) = scope.matrix(head)?;
    if (rows == 1 || columns == 1) && last < rows.saturating_mul(columns) {
        return data.get(last).copied();
    }
    None
}

// ---------------------------------------------------------------------------------------
// CLHEP's SystemOfUnits.h (HEP units: mm, ns, MeV, eplus, kelvin, mole, candela, rad, sr)
// ---------------------------------------------------------------------------------------

const PI: f64 = std::f64::consts::PI;

const MILLIMETER: f64 = 1.0;
const CENTIMETER: f64 = 10.0 * MILLIMETER;
const METER: f64 = 1000.0 * MILLIMETER;
const KILOMETER: f64 = 1000.0 * METER;
const METER2: f64 = METER * METER;
const CENTIMETER3: f64 = CENTIMETER * CENTIMETER * CENTIMETER;
const PARSEC: f64 = 3.0856775807e+16 * METER;
const MICROMETER: f64 = 1.0e-6 * METER;
const NANOMETER: f64 = 1.0e-9 * METER;
const ANGSTROM: f64 = 1.0e-10 * METER;
const FERMI: f64 = 1.0e-15 * METER;
const BARN: f64 = 1.0e-28 * METER2;
const LITER: f64 = 1.0e+3 * CENTIMETER3;

const RADIAN: f64 = 1.0;
const MILLIRADIAN: f64 = 1.0e-3 * RADIAN;
const DEGREE: f64 = (PI / 180.0) * RADIAN;
const STERADIAN: f64 = 1.0;

const NANOSECOND: f64 = 1.0;
const SECOND: f64 = 1.0e+9 * NANOSECOND;
const MILLISECOND: f64 = 1.0e-3 * SECOND;
const MICROSECOND: f64 = 1.0e-6 * SECOND;
const PICOSECOND: f64 = 1.0e-12 * SECOND;
const MINUTE: f64 = 60.0 * SECOND;
const HOUR: f64 = 60.0 * MINUTE;
const DAY: f64 = 24.0 * HOUR;
const YEAR: f64 = 365.0 * DAY;
const HERTZ: f64 = 1.0 / SECOND;

const EPLUS: f64 = 1.0;
const E_SI: f64 = 1.602176634e-19;
const COULOMB: f64 = EPLUS / E_SI;

const MEGAELECTRONVOLT: f64 = 1.0;
const ELECTRONVOLT: f64 = 1.0e-6 * MEGAELECTRONVOLT;
const JOULE: f64 = ELECTRONVOLT / E_SI;

const KILOGRAM: f64 = JOULE * SECOND * SECOND / (METER * METER);
const GRAM: f64 = 1.0e-3 * KILOGRAM;
const MILLIGRAM: f64 = 1.0e-3 * GRAM;

const WATT: f64 = JOULE / SECOND;
const NEWTON: f64 = JOULE / METER;
const HEP_PASCAL: f64 = NEWTON / METER2;
const BAR: f64 = 100000.0 * HEP_PASCAL;
const ATMOSPHERE: f64 = 101325.0 * HEP_PASCAL;

const AMPERE: f64 = COULOMB / SECOND;
const MEGAVOLT: f64 = MEGAELECTRONVOLT / EPLUS;
const KILOVOLT: f64 = 1.0e-3 * MEGAVOLT;
const VOLT: f64 = 1.0e-6 * MEGAVOLT;
const OHM: f64 = VOLT / AMPERE;
const FARAD: f64 = COULOMB / VOLT;
const WEBER: f64 = VOLT * SECOND;
const TESLA: f64 = VOLT * SECOND / METER2;
const GAUSS: f64 = 1.0e-4 * TESLA;
const KILOGAUSS: f64 = 1.0e-1 * TESLA;
const HENRY: f64 = WEBER / AMPERE;

const KELVIN: f64 = 1.0;
const MOLE: f64 = 1.0;

const BECQUEREL: f64 = 1.0 / SECOND;
const CURIE: f64 = 3.7e+10 * BECQUEREL;
const GRAY: f64 = JOULE / KILOGRAM;
const SIEVERT: f64 = JOULE / KILOGRAM;

const CANDELA: f64 = 1.0;
const LUMEN: f64 = CANDELA * STERADIAN;
const LUX: f64 = LUMEN / METER2;

/// The value of a CLHEP unit name (mm, cm, deg, ...), if it is one.
///
/// Covers every name of CLHEP's `SystemOfUnits.h` (values in its HEP system: mm, ns,
/// MeV, eplus, kelvin, mole, candela, rad, sr are 1; `e_SI` = 1.602176634e-19), the
/// extra names CLHEP's `Evaluator::setSystemOfUnits` defines for expressions (`metre`,
/// `A`, `N`, `Pa`, `J`, `W`, `V`, `T`, `Hz`, `cc`, `micron`, `kJ`, ...) with the same
/// values, and the symbols of Geant4's units table that are plain names (`Ang`, `fm`,
/// `mubarn`, `meV`, `muA`, `kG`, ...).
pub fn unit(name: &str) -> Option<f64> {
    Some(match name {
        // Length, area, volume
        "millimeter" | "mm" => MILLIMETER,
        "millimeter2" | "mm2" => MILLIMETER * MILLIMETER,
        "millimeter3" | "mm3" => MILLIMETER * MILLIMETER * MILLIMETER,
        "centimeter" | "cm" => CENTIMETER,
        "centimeter2" | "cm2" => CENTIMETER * CENTIMETER,
        "centimeter3" | "cm3" | "cc" => CENTIMETER3,
        "decimeter" => 0.1 * METER,
        "meter" | "metre" | "m" => METER,
        "meter2" | "m2" => METER2,
        "meter3" | "m3" => METER * METER * METER,
        "kilometer" | "km" => KILOMETER,
        "kilometer2" | "km2" => KILOMETER * KILOMETER,
        "kilometer3" | "km3" => KILOMETER * KILOMETER * KILOMETER,
        "parsec" | "pc" => PARSEC,
        "micrometer" | "um" | "micron" => MICROMETER,
        "nanometer" | "nm" => NANOMETER,
        "angstrom" | "Ang" => ANGSTROM,
        "fermi" | "fm" => FERMI,
        "barn" => BARN,
        "millibarn" | "mbarn" => 1.0e-3 * BARN,
        "microbarn" | "mubarn" => 1.0e-6 * BARN,
        "nanobarn" | "nbarn" => 1.0e-9 * BARN,
        "picobarn" | "pbarn" => 1.0e-12 * BARN,
        "liter" | "litre" | "L" => LITER,
        "dL" => 1.0e-1 * LITER,
        "centiliter" | "cL" => 1.0e-2 * LITER,
        "milliliter" | "mL" => 1.0e-3 * LITER,
        "diopter" | "dioptre" | "dpt" => 1.0 / METER,
        // Angle, solid angle
        "radian" | "rad" => RADIAN,
        "milliradian" | "mrad" => MILLIRADIAN,
        "degree" | "deg" => DEGREE,
        "steradian" | "sr" => STERADIAN,
        "millisteradian" | "msr" => STERADIAN * 0.001,
        // Time, frequency
        "nanosecond" | "ns" => NANOSECOND,
        "second" | "s" => SECOND,
        "millisecond" | "ms" => MILLISECOND,
        "microsecond" | "us" => MICROSECOND,
        "picosecond" | "ps" => PICOSECOND,
        "minute" => MINUTE,
        "hour" => HOUR,
        "day" => DAY,
        "year" => YEAR,
        "hertz" | "Hz" => HERTZ,
        "kilohertz" | "kHz" => 1.0e+3 * HERTZ,
        "megahertz" | "MHz" => 1.0e+6 * HERTZ,
        // Charge
        "eplus" => EPLUS,
        "e_SI" => E_SI,
        "coulomb" | "C" => COULOMB,
        // Energy
        "electronvolt" | "eV" => ELECTRONVOLT,
        "kiloelectronvolt" | "keV" => 1.0e-3 * MEGAELECTRONVOLT,
        "megaelectronvolt" | "MeV" => MEGAELECTRONVOLT,
        "gigaelectronvolt" | "GeV" => 1.0e+3 * MEGAELECTRONVOLT,
        "teraelectronvolt" | "TeV" => 1.0e+6 * MEGAELECTRONVOLT,
        "petaelectronvolt" | "PeV" => 1.0e+9 * MEGAELECTRONVOLT,
        "millielectronvolt" | "millielectronVolt" | "meV" => 1.0e-9 * MEGAELECTRONVOLT,
        "joule" | "J" => JOULE,
        "kilojoule" | "kJ" => 1.0e+3 * JOULE,
        "megajoule" | "MJ" => 1.0e+6 * JOULE,
        "gigajoule" | "GJ" => 1.0e+9 * JOULE,
        // Mass
        "kilogram" | "kg" => KILOGRAM,
        "gram" | "g" => GRAM,
        "milligram" | "mg" => MILLIGRAM,
        // Power, force, pressure
        "watt" | "W" => WATT,
        "kilowatt" | "kW" => 1.0e+3 * WATT,
        "megawatt" | "MW" => 1.0e+6 * WATT,
        "gigawatt" | "GW" => 1.0e+9 * WATT,
        "newton" | "N" => NEWTON,
        "kilonewton" | "kN" => 1.0e+3 * NEWTON,
        "hep_pascal" | "pascal" | "Pa" => HEP_PASCAL,
        "bar" => BAR,
        "kilobar" | "kbar" => 1.0e+3 * BAR,
        "millibar" | "mbar" => 1.0e-3 * BAR,
        "atmosphere" | "atm" => ATMOSPHERE,
        // Current, potential, resistance, capacitance
        "ampere" | "amp" | "A" => AMPERE,
        "milliampere" | "mA" => 1.0e-3 * AMPERE,
        "microampere" | "muA" => 1.0e-6 * AMPERE,
        "nanoampere" | "nA" => 1.0e-9 * AMPERE,
        "megavolt" | "MV" => MEGAVOLT,
        "kilovolt" | "kV" => KILOVOLT,
        "volt" | "V" => VOLT,
        "ohm" => OHM,
        "siemens" | "S" => 1.0 / OHM,
        "farad" | "F" => FARAD,
        "millifarad" | "mF" => 1.0e-3 * FARAD,
        "microfarad" | "uF" => 1.0e-6 * FARAD,
        "nanofarad" | "nF" => 1.0e-9 * FARAD,
        "picofarad" | "pF" => 1.0e-12 * FARAD,
        // Magnetism
        "weber" | "Wb" => WEBER,
        "tesla" | "T" => TESLA,
        "gauss" | "Gs" => GAUSS,
        "kilogauss" | "kGs" | "kG" => KILOGAUSS,
        "henry" | "H" => HENRY,
        // Temperature, amount of substance
        "kelvin" | "K" => KELVIN,
        "mole" | "mol" => MOLE,
        // Activity
        "becquerel" | "Bq" => BECQUEREL,
        "kilobecquerel" | "kBq" => 1.0e+3 * BECQUEREL,
        "megabecquerel" | "MBq" => 1.0e+6 * BECQUEREL,
        "gigabecquerel" | "GBq" => 1.0e+9 * BECQUEREL,
        "curie" | "Ci" => CURIE,
        "millicurie" | "mCi" => 1.0e-3 * CURIE,
        "microcurie" | "uCi" => 1.0e-6 * CURIE,
        // Dose
        "gray" | "Gy" => GRAY,
        "kilogray" => 1.0e+3 * GRAY,
        "milligray" => 1.0e-3 * GRAY,
        "microgray" => 1.0e-6 * GRAY,
        "sievert" | "Sv" => SIEVERT,
        "millisievert" => 1.0e-3 * SIEVERT,
        "microsievert" => 1.0e-6 * SIEVERT,
        // Light
        "candela" | "cd" => CANDELA,
        "lumen" | "lm" => LUMEN,
        "lux" | "lx" => LUX,
        // Ratios
        "perCent" => 0.01,
        "perThousand" => 0.001,
        "perMillion" => 0.000001,
        _ => return None,
    })
}

// CLHEP's PhysicalConstants.h (PDG 2019 defining constants), in the same units.
const C_LIGHT: f64 = 2.99792458e+8 * METER / SECOND;
const C_SQUARED: f64 = C_LIGHT * C_LIGHT;
const H_PLANCK: f64 = 6.62607015e-34 * JOULE * SECOND;
const HBAR_PLANCK: f64 = H_PLANCK / (2.0 * PI);
const HBARC: f64 = HBAR_PLANCK * C_LIGHT;
const E_SQUARED: f64 = EPLUS * EPLUS;
const ELECTRON_MASS_C2: f64 = 0.510998910 * MEGAELECTRONVOLT;
const PROTON_MASS_C2: f64 = 938.272013 * MEGAELECTRONVOLT;
const AMU_C2: f64 = 931.494028 * MEGAELECTRONVOLT;
const MU0: f64 = 4.0 * PI * 1.0e-7 * HENRY / METER;
const EPSILON0: f64 = 1.0 / (C_SQUARED * MU0);
const ELM_COUPLING: f64 = E_SQUARED / (4.0 * PI * EPSILON0);
const FINE_STRUCTURE_CONST: f64 = ELM_COUPLING / HBARC;
const CLASSIC_ELECTR_RADIUS: f64 = ELM_COUPLING / ELECTRON_MASS_C2;
const ELECTRON_COMPTON_LENGTH: f64 = HBARC / ELECTRON_MASS_C2;

/// Built-in constants: CLHEP's `Evaluator::setStdMath` (`pi`, `e`, `gamma`), the
/// upper-case spellings GDML files use, and CLHEP's `PhysicalConstants.h`.
fn constant(name: &str) -> Option<f64> {
    Some(match name {
        "pi" | "PI" => PI,
        "twopi" | "TWOPI" => 2.0 * PI,
        "halfpi" | "HALFPI" => PI / 2.0,
        "pi2" => PI * PI,
        "e" => std::f64::consts::E,
        "gamma" => 0.577_215_664_901_532_9,
        "Avogadro" => 6.02214076e+23 / MOLE,
        "c_light" => C_LIGHT,
        "c_squared" => C_SQUARED,
        "h_Planck" => H_PLANCK,
        "hbar_Planck" => HBAR_PLANCK,
        "hbarc" => HBARC,
        "hbarc_squared" => HBARC * HBARC,
        "electron_charge" => -EPLUS,
        "e_squared" => E_SQUARED,
        "electron_mass_c2" => ELECTRON_MASS_C2,
        "proton_mass_c2" => PROTON_MASS_C2,
        "neutron_mass_c2" => 939.56536 * MEGAELECTRONVOLT,
        "amu_c2" => AMU_C2,
        "amu" => AMU_C2 / C_SQUARED,
        "mu0" => MU0,
        "epsilon0" => EPSILON0,
        "elm_coupling" => ELM_COUPLING,
        "fine_structure_const" => FINE_STRUCTURE_CONST,
        "classic_electr_radius" => CLASSIC_ELECTR_RADIUS,
        "electron_Compton_length" => ELECTRON_COMPTON_LENGTH,
        "Bohr_radius" => ELECTRON_COMPTON_LENGTH / FINE_STRUCTURE_CONST,
        "alpha_rcl2" => FINE_STRUCTURE_CONST * CLASSIC_ELECTR_RADIUS * CLASSIC_ELECTR_RADIUS,
        "twopi_mc2_rcl2" => {
            2.0 * PI * ELECTRON_MASS_C2 * CLASSIC_ELECTR_RADIUS * CLASSIC_ELECTR_RADIUS
        }
        "Bohr_magneton" => (EPLUS * HBARC * C_LIGHT) / (2.0 * ELECTRON_MASS_C2),
        "nuclear_magneton" => (EPLUS * HBARC * C_LIGHT) / (2.0 * PROTON_MASS_C2),
        "k_Boltzmann" => 8.617333e-11 * MEGAELECTRONVOLT / KELVIN,
        "STP_Temperature" => 273.15 * KELVIN,
        "STP_Pressure" => 1.0 * ATMOSPHERE,
        "kGasThreshold" => 10.0 * MILLIGRAM / CENTIMETER3,
        "universe_mean_density" => 1.0e-25 * GRAM / CENTIMETER3,
        _ => return None,
    })
}

#[cfg(test)]
mod tests;
