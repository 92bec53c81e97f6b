//! The floating-point types the intersection kernels are generic over (f32 and f64), a
//! small 3-vector over them, and error-free products and sums. The WGSL twin is
//! `shaders/real.wgsl`.

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// A floating-point scalar: `f32` (what the GPU runs) or `f64` (the reference precision).
pub trait Real:
    Copy
    + Debug
    + PartialOrd
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// 1/2.
    const HALF: Self;
    /// Positive infinity (a miss).
    const INFINITY: Self;
    /// Pi.
    const PI: Self;
    /// Machine epsilon (the gap between 1 and the next representable value).
    const EPSILON: Self;
    /// Relative surface tolerance: crossings closer than this times the solid's size to the
    /// start of a query are the surface the query starts on, and two crossings closer than
    /// this are one (coincident faces).
    const SURFACE_TOLERANCE: Self;
    /// The precision's name (`"f32"` or `"f64"`).
    const NAME: &'static str;

    /// Conversion from f64 (rounding to nearest).
    fn from_f64(v: f64) -> Self;
    /// Conversion to f64 (exact).
    fn to_f64(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Cube root.
    fn cbrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Smaller of two values (the non-NaN one if one is NaN).
    fn min(self, other: Self) -> Self;
    /// Larger of two values (the non-NaN one if one is NaN).
    fn max(self, other: Self) -> Self;
    /// `self` with the sign of `sign`.
    fn copysign(self, sign: Self) -> Self;
    /// Four-quadrant arctangent of `self / x`.
    fn atan2(self, x: Self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Sine.
    fn sin(self) -> Self;
    /// Whether the value is neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// The least value greater than `self` (`t < x.next_up()` is `t <= x`).
    fn next_up(self) -> Self;

    /// Conversion from f32 (exact).
    fn from_f32(v: f32) -> Self {
        Self::from_f64(v as f64)
    }
}

macro_rules! impl_real {
    ($t:ident, $tol:expr) => {
        impl Real for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const HALF: Self = 0.5;
            const INFINITY: Self = $t::INFINITY;
            const PI: Self = std::$t::consts::PI;
            const EPSILON: Self = $t::EPSILON;
            const SURFACE_TOLERANCE: Self = $tol;
            const NAME: &'static str = stringify!($t);

            fn from_f64(v: f64) -> Self {
                v as $t
            }
            fn to_f64(self) -> f64 {
                self as f64
            }
            fn sqrt(self) -> Self {
                $t::sqrt(self)
            }
            fn cbrt(self) -> Self {
                $t::cbrt(self)
            }
            fn abs(self) -> Self {
                $t::abs(self)
            }
            fn min(self, other: Self) -> Self {
                $t::min(self, other)
            }
            fn max(self, other: Self) -> Self {
                $t::max(self, other)
            }
            fn copysign(self, sign: Self) -> Self {
                $t::copysign(self, sign)
            }
            fn next_up(self) -> Self {
                $t::next_up(self)
            }
            fn atan2(self, x: Self) -> Self {
                $t::atan2(self, x)
            }
            fn cos(self) -> Self {
                $t::cos(self)
            }
            fn sin(self) -> Self {
                $t::sin(self)
            }
            fn is_finite(self) -> bool {
                $t::is_finite(self)
            }
        }
    };
}

// f32: about 17 ulps (below the 2e-6 agreement band asked of f32); f64: far above rounding,
// far below Geant4's 1e-9 mm at metre scales.
impl_real!(f32, 2.0e-6);
impl_real!(f64, 1.0e-11);

/// `a * b` as an unevaluated sum `hi + lo` (Dekker's product with Veltkamp's split: exact in
/// round-to-nearest binary arithmetic barring overflow, and needs no fused multiply-add).
pub fn two_product<T: Real>(a: T, b: T) -> (T, T) {
    // 2^ceil(p/2) + 1 for the p-bit significand of T.
    let splitter = if T::EPSILON < T::from_f64(1e-10) {
        T::from_f64(134_217_729.0)
    } else {
        T::from_f64(4097.0)
    };
    let split = |x: T| {
        let k = splitter * x;
        let hi = k - (k - x);
        (hi, x - hi)
    };
    let ((ah, al), (bh, bl)) = (split(a), split(b));
    let p = a * b;
    (p, ((ah * bh - p) + ah * bl + al * bh) + al * bl)
}

/// `a + b` as an unevaluated sum `hi + lo` (Knuth's two-sum, exact).
///
/// The WGSL twins (`shaders/real.wgsl`) split products on the bits and take a run-time 1
/// that keeps shader compilers from simplifying the error terms away; their values are the
/// same.
pub fn two_sum<T: Real>(a: T, b: T) -> (T, T) {
    let s = a + b;
    let bb = s - a;
    (s, (a - (s - bb)) + (b - bb))
}

/// A 3-vector of [`Real`]s.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct V3<T> {
    /// x.
    pub x: T,
    /// y.
    pub y: T,
    /// z.
    pub z: T,
}

impl<T: Real> V3<T> {
    /// The vector (x, y, z).
    pub fn new(x: T, y: T, z: T) -> Self {
        V3 { x, y, z }
    }

    /// The zero vector.
    pub fn zero() -> Self {
        V3::new(T::ZERO, T::ZERO, T::ZERO)
    }

    /// From an f64 array (rounded to `T`).
    pub fn from_f64(a: [f64; 3]) -> Self {
        V3::new(T::from_f64(a[0]), T::from_f64(a[1]), T::from_f64(a[2]))
    }

    /// To an f64 array.
    pub fn to_f64(self) -> [f64; 3] {
        [self.x.to_f64(), self.y.to_f64(), self.z.to_f64()]
    }

    /// Dot product.
    pub fn dot(self, o: Self) -> T {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// Cross product.
    pub fn cross(self, o: Self) -> Self {
        V3::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }

    /// Squared length.
    pub fn length_squared(self) -> T {
        self.dot(self)
    }

    /// Length.
    pub fn length(self) -> T {
        self.dot(self).sqrt()
    }

    /// Unit vector in the same direction (unchanged if zero).
    pub fn normalized(self) -> Self {
        let l = self.length();
        if l > T::ZERO {
            self * (T::ONE / l)
        } else {
            self
        }
    }

    /// Largest absolute component.
    pub fn max_abs(self) -> T {
        self.x.abs().max(self.y.abs()).max(self.z.abs())
    }

    /// Component `k` (0, 1 or 2).
    pub fn get(self, k: usize) -> T {
        match k {
            0 => self.x,
            1 => self.y,
            _ => self.z,
        }
    }

    /// `self + d * t`.
    pub fn at(self, d: Self, t: T) -> Self {
        self + d * t
    }
}

impl<T: Real> Add for V3<T> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl<T: Real> Sub for V3<T> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        V3::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl<T: Real> Mul<T> for V3<T> {
    type Output = Self;
    fn mul(self, s: T) -> Self {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
}

impl<T: Real> Neg for V3<T> {
    type Output = Self;
    fn neg(self) -> Self {
        V3::new(-self.x, -self.y, -self.z)
    }
}

/// A ray `origin + t * direction`; the direction need not be unit length (it is scaled by
/// non-uniform transforms, which keeps `t` the same in every frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray<T> {
    /// Origin.
    pub origin: V3<T>,
    /// Direction.
    pub direction: V3<T>,
}

impl<T: Real> Ray<T> {
    /// A ray from f64 coordinates, each rounded to `T`.
    pub fn from_f64(origin: [f64; 3], direction: [f64; 3]) -> Self {
        Ray {
            origin: V3::from_f64(origin),
            direction: V3::from_f64(direction),
        }
    }
}
