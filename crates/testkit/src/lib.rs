//! Helpers shared by the tests of every hytrace crate (a dev-dependency only): seeded,
//! dependency-free random generators, so a failure reproduces from its seed; arithmetic on
//! `[f64; 3]`; and the ray families the tests draw.
//!
//! The library's own generator (`hytrace_volume::Rng`, a counter-based stream the kernels
//! share with the GPU) is not here: tests that compare against kernels use it directly.

pub mod files;
pub mod torus;
pub mod vec3;

/// How many inputs a fuzz or property test tries: `default` (sized for CI's time), or the
/// count in `HYTRACE_FUZZ_CASES` (`scripts/fuzz_all.sh` sets 100000 for the recorded run).
pub fn fuzz_cases(default: usize) -> usize {
    match std::env::var("HYTRACE_FUZZ_CASES") {
        Ok(v) => v
            .parse()
            .unwrap_or_else(|_| panic!("HYTRACE_FUZZ_CASES={v:?} is not a count")),
        Err(_) => default,
    }
}

/// A source of 64 random bits, and what the tests draw from it.
pub trait Random {
    /// The next 64 random bits.
    fn next_u64(&mut self) -> u64;

    /// Uniform in `[0, 1)` (the top 53 bits).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// An index below `n` (`next_u64() % n`; `n > 0`).
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// One of `items`, uniformly (`items` not empty).
    fn pick<T: Copy>(&mut self, items: &[T]) -> T
    where
        Self: Sized,
    {
        items[self.below(items.len())]
    }

    /// A uniformly distributed unit vector (rejection sampling in the cube `[-1, 1)^3`).
    fn direction(&mut self) -> [f64; 3] {
        loop {
            let v = [0, 1, 2].map(|_| self.range(-1., 1.));
            let l = vec3::length(v);
            if l > 0.1 && l <= 1.0 {
                return v.map(|c| c / l);
            }
        }
    }

    /// A point uniform in the cube of half side `half` centred on the origin.
    fn in_cube(&mut self, half: f64) -> [f64; 3] {
        [0, 1, 2].map(|_| self.range(-half, half))
    }

    /// A ray from a uniform point of the cube of half side `origin_half` aimed at a uniform
    /// point of the cube of half side `target_half` (both centred on the origin): origin
    /// and unit direction.
    fn aimed(&mut self, origin_half: f64, target_half: f64) -> ([f64; 3], [f64; 3]) {
        let o = self.in_cube(origin_half);
        let t = self.in_cube(target_half);
        (o, vec3::normalized(vec3::sub(t, o)))
    }
}

/// xorshift64 (Marsaglia's 13, 7, 17 triple): 64 bits of state, any non-zero seed.
#[derive(Clone, Debug)]
pub struct XorShift64(pub u64);

impl Random for XorShift64 {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// xorshift64* (Vigna): 64 bits of state, any non-zero seed.
#[derive(Clone, Debug)]
pub struct XorShift64Star(pub u64);

impl Random for XorShift64Star {
    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

/// SplitMix64 (Steele, Lea and Flood): 64 bits of state, any seed.
#[derive(Clone, Debug)]
pub struct SplitMix64(pub u64);

impl Random for SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generators_give_their_reference_sequences() {
        // SplitMix64 from seed 0 (the reference implementation's first output).
        assert_eq!(SplitMix64(0).next_u64(), 0xe220_a839_7b1d_cdaf);
        // xorshift64 from state 1: 1 ^ 1 << 13 = 0x2001, ^ 0x2001 >> 7 = 0x2041, then
        // ^ 0x2041 << 17.
        assert_eq!(XorShift64(1).next_u64(), 0x4082_2041);
        // xorshift64* from state 1: 1 ^ 1 << 25, times the multiplier.
        assert_eq!(XorShift64Star(1).next_u64(), 0x47e4_ce4b_896c_dd1d);
        let u = SplitMix64(7).uniform();
        assert!((0.0..1.0).contains(&u));
    }

    #[test]
    fn directions_are_unit_and_aimed_rays_hit_their_cube() {
        let mut r = XorShift64Star(0x2545_f491_4f6c_dd1d);
        for _ in 0..1000 {
            assert!((vec3::length(r.direction()) - 1.0).abs() < 1e-12);
            let (o, d) = r.aimed(10.0, 1.0);
            assert!((vec3::length(d) - 1.0).abs() < 1e-12);
            assert!(o.iter().all(|c| c.abs() <= 10.0));
        }
    }
}
