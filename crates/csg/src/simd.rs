//! The instruction sets the f32 mesh kernel runs with, chosen once per process at run time.
//!
//! The kernel's node box test (8 children at once), packet slab test and triangle block test
//! are written once, generically over an instruction-set marker (`Isa`): `Portable`
//! uses `wide`'s vectors, whose form is fixed when this crate is compiled (two SSE halves
//! for 8 lanes in the default x86-64 build, NEON on AArch64, arrays elsewhere); on x86-64,
//! `Avx2` holds 8 lanes in one 256-bit register. A search (a `Kernel`) is compiled once per
//! path: for the portable one as it stands, and for each x86-64 path inside a function built
//! for that instruction set (`#[target_feature]`), into which the whole search is inlined,
//! so that the walk, the triangle tests and the scalar work around them all use it. The
//! AVX-512 path runs the AVX2 marker's code compiled with AVX-512 enabled (its compare masks
//! and 32 vector registers), the 8 lanes staying 256 bits wide.
//!
//! Every path performs the same IEEE operations in the same order, on the same operands
//! (no fused multiply-add: Rust never contracts `a * b + c` on its own, and the FMA feature
//! is not enabled), so their answers are bit for bit the same; the tests compare them.
//!
//! The path is the best one the CPU supports ([`SimdPath::detect`]), or the one the
//! environment variable `HYTRACE_SIMD` (`portable`, `avx2`, `avx512`) names; [`selected`]
//! reads it once. [`select`] changes it for the rest of the process (benchmarks compare
//! paths that way); `run_on` runs one search on a given path.

use std::fmt;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};
use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};

use wide::{f32x4, f32x8, u32x8};

/// An instruction-set path of the f32 mesh kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SimdPath {
    /// `wide`'s vectors as this crate was compiled (SSE2 in the default x86-64 build).
    Portable,
    /// AVX2 (with BMI1/2, LZCNT and POPCNT): 8 lanes in one 256-bit register.
    Avx2,
    /// The AVX2 path compiled with AVX-512 (F, VL, BW, DQ) enabled as well.
    Avx512,
}

/// The paths, in the order of [`SimdPath`]'s discriminants (the cached choice's encoding).
const PATHS: [SimdPath; 3] = [SimdPath::Portable, SimdPath::Avx2, SimdPath::Avx512];

/// The names `HYTRACE_SIMD` and [`SimdPath`]'s `FromStr` accept, in the order of [`PATHS`].
const NAMES: [&str; 3] = ["portable", "avx2", "avx512"];

/// A SIMD path that cannot be chosen.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SimdError {
    /// No path of that name.
    #[error("unknown SIMD path {0:?} (expected portable, avx2 or avx512)")]
    Unknown(String),
    /// The CPU (or the target this was built for) lacks the instructions of the path.
    #[error("this CPU does not support the {0} SIMD path (available: {1})")]
    Unsupported(SimdPath, String),
    /// `HYTRACE_SIMD` names a path that cannot be chosen.
    #[error("environment variable HYTRACE_SIMD: {0}")]
    Environment(Box<SimdError>),
}

impl fmt::Display for SimdPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(NAMES[*self as usize])
    }
}

impl FromStr for SimdPath {
    type Err = SimdError;

    fn from_str(s: &str) -> Result<Self, SimdError> {
        NAMES
            .iter()
            .position(|n| n.eq_ignore_ascii_case(s.trim()))
            .map(|i| PATHS[i])
            .ok_or_else(|| SimdError::Unknown(s.to_string()))
    }
}

impl SimdPath {
    /// Whether this CPU runs the path.
    pub fn supported(self) -> bool {
        match self {
            SimdPath::Portable => true,
            #[cfg(target_arch = "x86_64")]
            SimdPath::Avx2 => {
                is_x86_feature_detected!("avx2")
                    && is_x86_feature_detected!("bmi1")
                    && is_x86_feature_detected!("bmi2")
                    && is_x86_feature_detected!("lzcnt")
                    && is_x86_feature_detected!("popcnt")
            }
            #[cfg(target_arch = "x86_64")]
            SimdPath::Avx512 => {
                SimdPath::Avx2.supported()
                    && is_x86_feature_detected!("avx512f")
                    && is_x86_feature_detected!("avx512vl")
                    && is_x86_feature_detected!("avx512bw")
                    && is_x86_feature_detected!("avx512dq")
            }
            #[cfg(not(target_arch = "x86_64"))]
            _ => false,
        }
    }

    /// The paths this CPU runs, portable first.
    pub fn available() -> Vec<SimdPath> {
        PATHS.into_iter().filter(|p| p.supported()).collect()
    }

    /// The fastest path this CPU runs (measured: BENCHMARKS.md, issue 36).
    pub fn detect() -> SimdPath {
        // AVX2 before AVX-512: see `docs/bench-log.md`, "Issue 36: runtime dispatch".
        [SimdPath::Avx2, SimdPath::Portable]
            .into_iter()
            .find(|p| p.supported())
            .unwrap_or(SimdPath::Portable)
    }

    /// The path `HYTRACE_SIMD` names (if set and not empty), checked against this CPU.
    pub fn from_env() -> Result<Option<SimdPath>, SimdError> {
        let Ok(name) = std::env::var("HYTRACE_SIMD") else {
            return Ok(None);
        };
        if name.trim().is_empty() {
            return Ok(None);
        }
        let check = || -> Result<SimdPath, SimdError> {
            let path: SimdPath = name.parse()?;
            path.check()?;
            Ok(path)
        };
        check()
            .map(Some)
            .map_err(|e| SimdError::Environment(Box::new(e)))
    }

    /// The path itself when this CPU runs it; an error naming the ones it does run.
    pub fn check(self) -> Result<SimdPath, SimdError> {
        if self.supported() {
            return Ok(self);
        }
        let names: Vec<String> = SimdPath::available()
            .iter()
            .map(|p| p.to_string())
            .collect();
        Err(SimdError::Unsupported(self, names.join(", ")))
    }
}

/// The chosen path's index in [`PATHS`], or `UNSET` before the first [`selected`].
static CHOSEN: AtomicU8 = AtomicU8::new(UNSET);
const UNSET: u8 = u8::MAX;

/// The path searches run on: on first use, the one `HYTRACE_SIMD` names, else
/// [`SimdPath::detect`]'s. A `HYTRACE_SIMD` that names no path, or one this CPU lacks, is
/// reported once on standard error and the detected path used (the `hytrace` command
/// refuses it before any work, through [`SimdPath::from_env`]).
pub fn selected() -> SimdPath {
    match CHOSEN.load(Ordering::Relaxed) {
        UNSET => {
            let path = SimdPath::from_env().unwrap_or_else(|e| {
                eprintln!("hytrace: warning: {e}; using the detected path");
                None
            });
            let path = path.unwrap_or_else(SimdPath::detect);
            // Another thread may have chosen meanwhile: keep the first choice.
            match CHOSEN.compare_exchange(UNSET, path as u8, Ordering::Relaxed, Ordering::Relaxed) {
                Ok(_) => path,
                Err(first) => PATHS[first as usize],
            }
        }
        i => PATHS[i as usize],
    }
}

/// Makes `path` the one searches run on from now on, in every thread; an error when this
/// CPU does not run it.
pub fn select(path: SimdPath) -> Result<(), SimdError> {
    path.check()?;
    CHOSEN.store(path as u8, Ordering::Relaxed);
    Ok(())
}

/// A search of the f32 mesh kernel, compiled for each path ([`run_on`]).
pub(crate) trait Kernel {
    /// What the search returns.
    type Output;

    /// The search with the vectors of `S`. Implementations are `#[inline(always)]`, so the
    /// search is compiled into each path's entry function, for its instruction set.
    fn run<S: Isa>(self) -> Self::Output;
}

/// Runs `kernel` on `path`, which must be one this CPU supports (the portable path where it
/// is not: a caller that skipped [`SimdPath::check`] gets the same answers, slower).
#[inline(always)]
pub(crate) fn run_on<K: Kernel>(path: SimdPath, kernel: K) -> K::Output {
    match path {
        #[cfg(target_arch = "x86_64")]
        SimdPath::Avx2 if path.supported() => {
            // SAFETY: the CPU has AVX2, BMI1/2, LZCNT and POPCNT (checked just above).
            unsafe { x86::run_avx2(kernel) }
        }
        #[cfg(target_arch = "x86_64")]
        SimdPath::Avx512 if path.supported() => {
            // SAFETY: the CPU has those and AVX-512 F, VL, BW and DQ (checked just above).
            unsafe { x86::run_avx512(kernel) }
        }
        _ => kernel.run::<Portable>(),
    }
}

/// Lanes of f32 of one instruction set, with the operations the kernel's tests use. The
/// comparisons return masks of all ones or all zeros per lane, as `wide`'s do.
pub(crate) trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Not<Output = Self>
{
    /// The lanes as an array.
    type Array;
    /// Every lane `x`.
    fn splat(x: f32) -> Self;
    /// The lanes of `a`.
    fn load(a: &Self::Array) -> Self;
    /// The lanes as an array.
    fn to_array(self) -> Self::Array;
    /// Per lane, the larger of `self` and `other` (`other` when either is NaN: SSE's
    /// `maxps` operand order, which `wide`'s `fast_max` keeps).
    fn max(self, other: Self) -> Self;
    /// Per lane, the smaller (`other` when either is NaN).
    fn min(self, other: Self) -> Self;
    /// The mask of `self < other` (false with a NaN, as the next three).
    fn lt(self, other: Self) -> Self;
    /// The mask of `self <= other`.
    fn le(self, other: Self) -> Self;
    /// The mask of `self > other`.
    fn gt(self, other: Self) -> Self;
    /// The mask of `self == other`.
    fn eq(self, other: Self) -> Self;
    /// The mask of `self != other` (true with a NaN).
    fn ne(self, other: Self) -> Self;
    /// Per lane, `if_one` where the mask `self` is set, else `if_zero`.
    fn select(self, if_one: Self, if_zero: Self) -> Self;
    /// The mask's lanes, one bit each, lane 0 lowest.
    fn bitmask(self) -> u32;
}

/// An instruction set's vectors: 8 lanes (a node's children, a packet's rays) and 4 (a
/// triangle block).
pub(crate) trait Isa {
    /// 8 lanes of f32.
    type F8: Lanes<Array = [f32; 8]>;
    /// 4 lanes of f32.
    type F4: Lanes<Array = [f32; 4]>;
    /// The lanes of `a` that are not 0, one bit each.
    fn nonzero(a: &[u32; 8]) -> u32;
}

/// `wide`'s vectors, in the form this crate was compiled for.
pub(crate) struct Portable;

impl Isa for Portable {
    type F8 = f32x8;
    type F4 = f32x4;

    #[inline(always)]
    fn nonzero(a: &[u32; 8]) -> u32 {
        !u32x8::from(*a).simd_eq(u32x8::ZERO).to_bitmask() & 0xff
    }
}

/// [`Lanes`] of a `wide` vector type, by its own operations.
macro_rules! wide_lanes {
    ($t:ty, $n:literal) => {
        impl Lanes for $t {
            type Array = [f32; $n];
            #[inline(always)]
            fn splat(x: f32) -> Self {
                <$t>::splat(x)
            }
            #[inline(always)]
            fn load(a: &[f32; $n]) -> Self {
                <$t>::from(*a)
            }
            #[inline(always)]
            fn to_array(self) -> [f32; $n] {
                <$t>::to_array(self)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                self.fast_max(other)
            }
            #[inline(always)]
            fn min(self, other: Self) -> Self {
                self.fast_min(other)
            }
            #[inline(always)]
            fn lt(self, other: Self) -> Self {
                self.simd_lt(other)
            }
            #[inline(always)]
            fn le(self, other: Self) -> Self {
                self.simd_le(other)
            }
            #[inline(always)]
            fn gt(self, other: Self) -> Self {
                self.simd_gt(other)
            }
            #[inline(always)]
            fn eq(self, other: Self) -> Self {
                self.simd_eq(other)
            }
            #[inline(always)]
            fn ne(self, other: Self) -> Self {
                self.simd_ne(other)
            }
            #[inline(always)]
            fn select(self, if_one: Self, if_zero: Self) -> Self {
                self.bitselect(if_one, if_zero)
            }
            #[inline(always)]
            fn bitmask(self) -> u32 {
                self.to_bitmask()
            }
        }
    };
}

wide_lanes!(f32x8, 8);
wide_lanes!(f32x4, 4);

/// The x86-64 paths: the AVX2 marker's 256-bit lanes and the entry functions compiled for
/// AVX2 and AVX-512.
#[cfg(target_arch = "x86_64")]
mod x86 {
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Not, Sub};

    use wide::f32x4;

    use super::{Isa, Kernel, Lanes};

    /// 8 lanes in one AVX register. Values exist only inside searches run by
    /// [`run_avx2`] and [`run_avx512`], which are called only on CPUs with AVX2: that is
    /// what makes the intrinsics' `unsafe` blocks below sound.
    #[derive(Clone, Copy)]
    pub(crate) struct M256(__m256);

    /// AVX2: 8 lanes in one register; 4 lanes as `wide`'s SSE form, which AVX's encoding
    /// of the same operations compiles it to inside the entry functions.
    pub(crate) struct Avx2;

    impl Isa for Avx2 {
        type F8 = M256;
        type F4 = f32x4;

        #[inline(always)]
        fn nonzero(a: &[u32; 8]) -> u32 {
            // SAFETY: see `M256`; the load reads the 32 bytes of `a`, unaligned.
            unsafe {
                let v = _mm256_loadu_si256(a.as_ptr().cast());
                let zero = _mm256_cmpeq_epi32(v, _mm256_setzero_si256());
                !(_mm256_movemask_ps(_mm256_castsi256_ps(zero)) as u32) & 0xff
            }
        }
    }

    /// Runs `kernel` with [`Avx2`] compiled for AVX2.
    ///
    /// # Safety
    /// The CPU must have AVX2, BMI1, BMI2, LZCNT and POPCNT.
    #[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt")]
    pub(super) unsafe fn run_avx2<K: Kernel>(kernel: K) -> K::Output {
        kernel.run::<Avx2>()
    }

    /// Runs `kernel` with [`Avx2`] compiled for AVX-512 as well.
    ///
    /// # Safety
    /// The CPU must have what [`run_avx2`] needs and AVX-512 F, VL, BW and DQ.
    #[target_feature(enable = "avx2,bmi1,bmi2,lzcnt,popcnt,avx512f,avx512vl,avx512bw,avx512dq")]
    pub(super) unsafe fn run_avx512<K: Kernel>(kernel: K) -> K::Output {
        kernel.run::<Avx2>()
    }

    /// A binary operator of [`M256`] by one intrinsic.
    macro_rules! binary {
        ($trait:ident, $method:ident, $intrinsic:ident) => {
            impl $trait for M256 {
                type Output = M256;
                #[inline(always)]
                fn $method(self, rhs: M256) -> M256 {
                    // SAFETY: see `M256`.
                    M256(unsafe { $intrinsic(self.0, rhs.0) })
                }
            }
        };
    }

    binary!(Add, add, _mm256_add_ps);
    binary!(Sub, sub, _mm256_sub_ps);
    binary!(Mul, mul, _mm256_mul_ps);
    binary!(Div, div, _mm256_div_ps);
    binary!(BitAnd, bitand, _mm256_and_ps);
    binary!(BitOr, bitor, _mm256_or_ps);

    impl Not for M256 {
        type Output = M256;
        #[inline(always)]
        fn not(self) -> M256 {
            self ^ M256::splat(f32::from_bits(u32::MAX))
        }
    }

    impl std::ops::BitXor for M256 {
        type Output = M256;
        #[inline(always)]
        fn bitxor(self, rhs: M256) -> M256 {
            // SAFETY: see `M256`.
            M256(unsafe { _mm256_xor_ps(self.0, rhs.0) })
        }
    }

    impl M256 {
        /// The mask of the comparison `P` (an `_CMP_*` predicate).
        #[inline(always)]
        fn compare<const P: i32>(self, other: M256) -> M256 {
            // SAFETY: see `M256`.
            M256(unsafe { _mm256_cmp_ps::<P>(self.0, other.0) })
        }
    }

    impl Lanes for M256 {
        type Array = [f32; 8];
        #[inline(always)]
        fn splat(x: f32) -> Self {
            // SAFETY: see `M256`.
            M256(unsafe { _mm256_set1_ps(x) })
        }
        #[inline(always)]
        fn load(a: &[f32; 8]) -> Self {
            // SAFETY: see `M256`; the load reads the 32 bytes of `a`, unaligned.
            M256(unsafe { _mm256_loadu_ps(a.as_ptr()) })
        }
        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            let mut out = [0.0; 8];
            // SAFETY: see `M256`; the store writes the 32 bytes of `out`.
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
        #[inline(always)]
        fn max(self, other: Self) -> Self {
            // SAFETY: see `M256`. `vmaxps` returns its second operand when either is NaN,
            // as SSE's `maxps` does for `wide`.
            M256(unsafe { _mm256_max_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn min(self, other: Self) -> Self {
            // SAFETY: see `M256` (NaN: as `max`).
            M256(unsafe { _mm256_min_ps(self.0, other.0) })
        }
        #[inline(always)]
        fn lt(self, other: Self) -> Self {
            self.compare::<_CMP_LT_OQ>(other)
        }
        #[inline(always)]
        fn le(self, other: Self) -> Self {
            self.compare::<_CMP_LE_OQ>(other)
        }
        #[inline(always)]
        fn gt(self, other: Self) -> Self {
            self.compare::<_CMP_GT_OQ>(other)
        }
        #[inline(always)]
        fn eq(self, other: Self) -> Self {
            self.compare::<_CMP_EQ_OQ>(other)
        }
        #[inline(always)]
        fn ne(self, other: Self) -> Self {
            self.compare::<_CMP_NEQ_UQ>(other)
        }
        #[inline(always)]
        fn select(self, if_one: Self, if_zero: Self) -> Self {
            // SAFETY: see `M256`. `wide`'s bit select: (if_one & mask) | (if_zero & !mask).
            M256(unsafe {
                _mm256_or_ps(
                    _mm256_and_ps(if_one.0, self.0),
                    _mm256_andnot_ps(self.0, if_zero.0),
                )
            })
        }
        #[inline(always)]
        fn bitmask(self) -> u32 {
            // SAFETY: see `M256`.
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_parse_print_and_check() {
        for path in PATHS {
            assert_eq!(path.to_string().parse::<SimdPath>(), Ok(path));
        }
        assert_eq!(" AVX2 ".parse::<SimdPath>(), Ok(SimdPath::Avx2));
        let err = "sse9".parse::<SimdPath>().unwrap_err();
        assert!(
            err.to_string().contains("unknown SIMD path \"sse9\""),
            "{err}"
        );
        assert!(SimdPath::Portable.supported());
        assert_eq!(SimdPath::available()[0], SimdPath::Portable);
        assert!(SimdPath::detect().supported());
        for path in PATHS {
            match path.check() {
                Ok(p) => assert!(p.supported()),
                Err(e) => {
                    assert!(!path.supported());
                    assert!(e.to_string().contains("available: portable"), "{e}");
                }
            }
        }
    }

    /// `Lanes` of every available path against f64 arithmetic rounded once (exact for
    /// one IEEE operation), and the masks and selections against scalar comparisons, on
    /// values with NaNs, infinities, signed zeros and subnormals.
    #[test]
    fn lanes_of_every_path_compute_ieee_results_lane_by_lane() {
        struct Check([f32; 8], [f32; 8]);
        impl Kernel for Check {
            type Output = ();
            #[inline(always)]
            fn run<S: Isa>(self) {
                let (a, b) = (S::F8::load(&self.0), S::F8::load(&self.1));
                let bits = |v: S::F8| v.to_array().map(f32::to_bits);
                let exact = |f: fn(f64, f64) -> f64| {
                    std::array::from_fn::<u32, 8, _>(|i| {
                        (f(self.0[i] as f64, self.1[i] as f64) as f32).to_bits()
                    })
                };
                let same = |got: [u32; 8], want: [u32; 8]| {
                    for i in 0..8 {
                        let (g, w) = (f32::from_bits(got[i]), f32::from_bits(want[i]));
                        assert!(
                            got[i] == want[i] || (g.is_nan() && w.is_nan()),
                            "lane {i}: {g} against {w}"
                        );
                    }
                };
                same(bits(a + b), exact(|x, y| x + y));
                same(bits(a - b), exact(|x, y| x - y));
                same(bits(a * b), exact(|x, y| x * y));
                same(bits(a / b), exact(|x, y| x / y));
                // maxps: `b` unless `a > b`; minps: `b` unless `a < b`.
                let pick = |f: fn(f32, f32) -> bool| {
                    std::array::from_fn::<u32, 8, _>(|i| {
                        let (x, y) = (self.0[i], self.1[i]);
                        if f(x, y) { x } else { y }.to_bits()
                    })
                };
                same(bits(a.max(b)), pick(|x, y| x > y));
                same(bits(a.min(b)), pick(|x, y| x < y));
                let mask = |f: fn(f32, f32) -> bool| {
                    (0..8).fold(0, |m, i| m | (u32::from(f(self.0[i], self.1[i])) << i))
                };
                assert_eq!(a.lt(b).bitmask(), mask(|x, y| x < y));
                assert_eq!(a.le(b).bitmask(), mask(|x, y| x <= y));
                assert_eq!(a.gt(b).bitmask(), mask(|x, y| x > y));
                assert_eq!(a.eq(b).bitmask(), mask(|x, y| x == y));
                assert_eq!(a.ne(b).bitmask(), mask(|x, y| x != y));
                assert_eq!((!a.lt(b)).bitmask(), !mask(|x, y| x < y) & 0xff);
                assert_eq!((a.lt(b) | a.eq(b)).bitmask(), mask(|x, y| x <= y));
                assert_eq!((a.le(b) & !a.lt(b)).bitmask(), mask(|x, y| x == y));
                let chosen = a.lt(b).select(a, b).to_array().map(f32::to_bits);
                same(chosen, pick(|x, y| x < y));
                let counts = self.0.map(f32::to_bits);
                let nonzero = (0..8).fold(0, |m, i| m | (u32::from(counts[i] != 0) << i));
                assert_eq!(S::nonzero(&counts), nonzero);
            }
        }
        let tiny = f32::from_bits(1);
        let a = [1.5, -0.0, f32::NAN, f32::INFINITY, tiny, 3.0e38, -2.0, 0.0];
        let b = [0.1, 0.0, 1.0, f32::INFINITY, -tiny, 3.0e38, f32::NAN, 7.0];
        for path in SimdPath::available() {
            run_on(path, Check(a, b));
            run_on(path, Check(b, a));
        }
    }
}
