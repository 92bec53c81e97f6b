//! Double-double arithmetic (about 106 significant bits): the high-precision references of
//! the geometry rows, computed independently of the f32 and f64 kernels they judge.
//!
//! A value is the unevaluated sum `hi + lo` with `|lo| <= ulp(hi) / 2`. Sums use Knuth's
//! two-sum and products the exact fused-multiply-add residual, so each operation is
//! accurate to a few units of 2^-104 relative.

use std::ops::{Add, Mul, Neg, Sub};

/// A double-double number `hi + lo`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dd {
    hi: f64,
    lo: f64,
}

/// `a + b` as an exact pair (sum rounded, rounding error).
fn two_sum(a: f64, b: f64) -> Dd {
    let s = a + b;
    let bb = s - a;
    let err = (a - (s - bb)) + (b - bb);
    Dd { hi: s, lo: err }
}

/// Renormalises `hi + lo` so `lo` is below half an ulp of `hi`.
fn quick(hi: f64, lo: f64) -> Dd {
    let s = hi + lo;
    Dd {
        hi: s,
        lo: lo - (s - hi),
    }
}

impl Dd {
    /// The exact value of an f64.
    pub fn new(v: f64) -> Dd {
        Dd { hi: v, lo: 0.0 }
    }

    /// The nearest f64.
    pub fn to_f64(self) -> f64 {
        self.hi + self.lo
    }

    /// Square root by one Newton step on the f64 root (enough for full precision).
    pub fn sqrt(self) -> Dd {
        if self.hi <= 0.0 {
            return Dd::new(0.0);
        }
        let x = self.hi.sqrt();
        // sqrt(a) ~ x + (a - x^2) / (2x), with a - x^2 evaluated in double-double.
        let residual = self - Dd::new(x) * Dd::new(x);
        quick(x, residual.to_f64() / (2.0 * x))
    }

    /// Quotient, by a long division of two f64 steps.
    pub fn div(self, other: Dd) -> Dd {
        let q1 = self.hi / other.hi;
        let r = self - other * Dd::new(q1);
        let q2 = r.hi / other.hi;
        let r = r - other * Dd::new(q2);
        let q3 = r.hi / other.hi;
        quick(q1, q2) + Dd::new(q3)
    }

    /// Whether the value is below zero.
    pub fn is_negative(self) -> bool {
        self.hi < 0.0 || (self.hi == 0.0 && self.lo < 0.0)
    }
}

impl Add for Dd {
    type Output = Dd;
    fn add(self, o: Dd) -> Dd {
        let s = two_sum(self.hi, o.hi);
        let t = two_sum(self.lo, o.lo);
        let s = quick(s.hi, s.lo + t.hi);
        quick(s.hi, s.lo + t.lo)
    }
}

impl Neg for Dd {
    type Output = Dd;
    fn neg(self) -> Dd {
        Dd {
            hi: -self.hi,
            lo: -self.lo,
        }
    }
}

impl Sub for Dd {
    type Output = Dd;
    fn sub(self, o: Dd) -> Dd {
        self + -o
    }
}

impl Mul for Dd {
    type Output = Dd;
    fn mul(self, o: Dd) -> Dd {
        let p = self.hi * o.hi;
        // The exact rounding error of the leading product, by a fused multiply-add.
        let err = self.hi.mul_add(o.hi, -p);
        quick(p, err + (self.hi * o.lo + self.lo * o.hi))
    }
}

/// A 3-vector of double-doubles.
pub type DdVec = [Dd; 3];

/// The exact values of an f64 vector.
pub fn vec(v: [f64; 3]) -> DdVec {
    v.map(Dd::new)
}

/// Dot product.
pub fn dot(a: DdVec, b: DdVec) -> Dd {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a - b`.
pub fn sub(a: DdVec, b: DdVec) -> DdVec {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `o + t d`.
pub fn at(o: DdVec, d: DdVec, t: Dd) -> DdVec {
    [o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_and_products_keep_what_f64_rounds_away() {
        // (1 + 2^-60)^2 - 1 = 2^-59 + 2^-120: f64 gives 0.
        let x = Dd::new(1.0) + Dd::new(2f64.powi(-60));
        let y = x * x - Dd::new(1.0);
        assert_eq!(y.to_f64(), 2f64.powi(-59) + 2f64.powi(-120));
        // sqrt(2)^2 = 2 to double-double precision.
        let r = Dd::new(2.0).sqrt();
        let e = (r * r - Dd::new(2.0)).to_f64().abs();
        assert!(e < 1e-30, "sqrt(2)^2 - 2 = {e}");
        // 1 / 3 * 3 = 1 to double-double precision.
        let third = Dd::new(1.0).div(Dd::new(3.0));
        let e = (third * Dd::new(3.0) - Dd::new(1.0)).to_f64().abs();
        assert!(e < 1e-30, "3 * (1/3) - 1 = {e}");
    }
}
