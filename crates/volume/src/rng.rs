//! Counter-based random numbers in u32 arithmetic only, so a WGSL shader (which has no
//! 64-bit integers) can reproduce the same streams bit for bit.
//!
//! Every number is a hash of `(seed, stream, sample, counter)` by the `pcg4d` permutation of
//! Jarzynski and Olano ("Hash Functions for GPU Rendering", JCGT 2020): no state but the
//! counter, so any draw of any stream can be recomputed independently. Uniform numbers keep
//! the top 24 bits, which f32 and f64 both represent exactly: the CPU's f64 and the GPU's
//! f32 uniforms are the same numbers.

/// 2^-24: the spacing of the uniform numbers.
const UNIT: f64 = 1.0 / 16_777_216.0;

/// The `pcg4d` hash: four u32 in, four well-mixed u32 out.
pub fn pcg4d(v: [u32; 4]) -> [u32; 4] {
    let mut v = v.map(|x| x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223));
    let mix = |v: &mut [u32; 4]| {
        v[0] = v[0].wrapping_add(v[1].wrapping_mul(v[3]));
        v[1] = v[1].wrapping_add(v[2].wrapping_mul(v[0]));
        v[2] = v[2].wrapping_add(v[0].wrapping_mul(v[1]));
        v[3] = v[3].wrapping_add(v[1].wrapping_mul(v[2]));
    };
    mix(&mut v);
    v = v.map(|x| x ^ (x >> 16));
    mix(&mut v);
    v
}

/// One stream of random numbers: draw `n` of stream `(seed, stream, sample)` is
/// `pcg4d([seed, stream, sample, n])[0]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rng {
    key: [u32; 3],
    counter: u32,
}

impl Rng {
    /// The stream of sample `sample` of ray `stream` under `seed`, at its first draw.
    pub fn new(seed: u32, stream: u32, sample: u32) -> Rng {
        Rng {
            key: [seed, stream, sample],
            counter: 0,
        }
    }

    /// The next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let [a, b, c] = self.key;
        let h = pcg4d([a, b, c, self.counter]);
        self.counter = self.counter.wrapping_add(1);
        h[0]
    }

    /// The next uniform number in [0, 1), a multiple of 2^-24.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u32() >> 8) as f64 * UNIT
    }

    /// The same number as [`Rng::next_f64`] would give, in f32 (exactly representable).
    pub fn next_f32(&mut self) -> f32 {
        self.next_f64() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let draw = |seed, stream, sample| {
            let mut r = Rng::new(seed, stream, sample);
            (0..4).map(|_| r.next_u32()).collect::<Vec<_>>()
        };
        assert_eq!(draw(1, 2, 3), draw(1, 2, 3));
        assert_ne!(draw(1, 2, 3), draw(1, 2, 4));
        assert_ne!(draw(1, 2, 3), draw(1, 3, 3));
        assert_ne!(draw(1, 2, 3), draw(2, 2, 3));
        let mut r = Rng::new(9, 9, 9);
        let mut copy = r;
        let (a, b) = (copy.next_f64(), r.next_f32());
        assert_eq!(a as f32, b);
        assert_eq!(a, b as f64);
    }

    #[test]
    fn uniforms_look_uniform_and_uncorrelated() {
        // Consecutive draws of one stream and first draws of neighbouring streams.
        let n = 200_000;
        let mut r = Rng::new(7, 0, 0);
        let seq: Vec<f64> = (0..n).map(|_| r.next_f64()).collect();
        let across: Vec<f64> = (0..n as u32)
            .map(|s| Rng::new(7, s / 64, s % 64).next_f64())
            .collect();
        for xs in [&seq, &across] {
            let mean = xs.iter().sum::<f64>() / n as f64;
            let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
            let lag: f64 = xs
                .windows(2)
                .map(|w| (w[0] - mean) * (w[1] - mean))
                .sum::<f64>()
                / (n as f64 * var);
            assert!((mean - 0.5).abs() < 0.005, "{mean}");
            assert!((var - 1.0 / 12.0).abs() < 0.002, "{var}");
            assert!(lag.abs() < 0.01, "{lag}");
            // Chi-square over 64 bins (63 degrees of freedom; 120 is far in the tail).
            let mut bins = [0f64; 64];
            for x in xs.iter() {
                bins[(x * 64.0) as usize] += 1.0;
            }
            let e = n as f64 / 64.0;
            let chi2: f64 = bins.iter().map(|b| (b - e).powi(2) / e).sum();
            assert!(chi2 < 120.0, "{chi2}");
            assert!(xs.iter().all(|x| (0.0..1.0).contains(x)));
        }
    }
}
