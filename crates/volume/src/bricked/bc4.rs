//! BC4 (UNORM) blocks: our own encoder and the exact float decoder.
//!
//! A block holds 4x4 texels in 8 bytes: endpoint `r0` (byte 0), endpoint `r1` (byte 1), then
//! sixteen 3-bit palette indices in the remaining 48 bits of the little-endian u64, texel
//! `i = 4 * row + column` at bits `16 + 3 i`. The palette, in code units 0..=255 (the D3D
//! and Vulkan BC4_UNORM palette times 255):
//!
//! - `r0 > r1` (8 levels): index 0 is `r0`, 1 is `r1`, index `j` in 2..=7 is
//!   `((8 - j) r0 + (j - 1) r1) / 7`;
//! - `r0 <= r1` (6 levels and the extremes): index 0 is `r0`, 1 is `r1`, `j` in 2..=5 is
//!   `((6 - j) r0 + (j - 1) r1) / 5`, index 6 is 0 and index 7 is 255.
//!
//! The decoder evaluates these in f32 (exact integer numerator, one rounded division), the
//! CPU twin of a software GPU decode; hardware BC4 units may differ by their stated tolerance.
//!
//! The encoder takes 16 targets in code units (reals in [0, 255]) and tries the 8-level mode
//! with endpoints at the rounded block minimum/maximum and their +-1 neighbours, and the
//! 6-level mode the same way over the texels not within half a code of 0 or 255 (which its
//! exact extremes serve), keeping the candidate with the least maximum error. Among the
//! candidates is the 8-level block with endpoints `round(min)`, `round(max)` (or a 6-level
//! block with equal endpoints), whose error is at most `max(0.5, 255 / 14)`: [`WORST_ERROR`]
//! code units bound every encoded block.

/// Bytes of one block.
pub const BLOCK_BYTES: usize = 8;

/// Largest error, in code units, of an encoded texel against its target: half the spacing of
/// an 8-level palette spanning all 255 codes.
pub const WORST_ERROR: f64 = 255.0 / 14.0;

/// Palette value (code units) of `index` (0..8) for endpoints `r0`, `r1`, in f32.
pub fn palette_value(r0: u8, r1: u8, index: u32) -> f32 {
    let (a, b) = (f32::from(r0), f32::from(r1));
    match index {
        0 => a,
        1 => b,
        _ if r0 > r1 => ((8 - index) as f32 * a + (index - 1) as f32 * b) / 7.0,
        6 => 0.0,
        7 => 255.0,
        _ => ((6 - index) as f32 * a + (index - 1) as f32 * b) / 5.0,
    }
}

/// Code-unit value of texel `i` (0..16, `4 * row + column`) of `block`.
pub fn decode_texel(block: &[u8; BLOCK_BYTES], i: usize) -> f32 {
    let bits = u64::from_le_bytes(*block) >> 16;
    let index = (bits >> (3 * i)) as u32 & 7;
    palette_value(block[0], block[1], index)
}

/// Candidate endpoints and the nearest palette index of each texel.
#[derive(Clone, Copy)]
struct Fit {
    r0: u8,
    r1: u8,
    indices: [u32; 16],
    max_error: f64,
}

/// The nearest palette entries for endpoints `r0`, `r1`, in exact (f64) arithmetic. The
/// interpolants are evenly spaced between the endpoints, so the nearest is found by rounding
/// the position on that grid rather than by a search.
#[derive(Clone, Copy)]
struct Palette {
    r0: u8,
    r1: u8,
    /// First grid value (r1 for 8 levels, r0 for 6).
    start: f64,
    /// Grid steps per code unit (0 when the endpoints are equal).
    per_code: f64,
    /// Grid value spacing.
    step: f64,
    /// Largest grid position: 7 or 5.
    last: u32,
}

impl Palette {
    fn new(r0: u8, r1: u8) -> Palette {
        let (a, b) = (f64::from(r0), f64::from(r1));
        let (start, span, last) = if r0 > r1 {
            (b, a - b, 7)
        } else {
            (a, b - a, 5)
        };
        let per_code = if span > 0.0 {
            f64::from(last) / span
        } else {
            0.0
        };
        Palette {
            r0,
            r1,
            start,
            per_code,
            step: span / f64::from(last),
            last,
        }
    }

    /// `(index, |x - value|)` of the entry nearest to `x` (in [0, 255]).
    fn nearest(&self, x: f64) -> (u32, f64) {
        // The nearest grid position: clamped below at 0, +0.5 and truncation rounds.
        let k = (((x - self.start) * self.per_code).max(0.0) + 0.5) as u32;
        let k = k.min(self.last);
        let value = self.start + f64::from(k) * self.step;
        let error = (x - value).abs();
        if self.last == 7 {
            // Grid position k from r1 (index 1) to r0 (index 0); interpolants 8 - k.
            let index = match k {
                0 => 1,
                7 => 0,
                k => 8 - k,
            };
            return (index, error);
        }
        // Grid position k from r0 (index 0) to r1 (index 1); interpolants k + 1; then the
        // extremes 0 (index 6) and 255 (index 7).
        let index = match k {
            0 => 0,
            5 => 1,
            k => k + 1,
        };
        let mut best = (index, error);
        if x < best.1 {
            best = (6, x);
        }
        if 255.0 - x < best.1 {
            best = (7, 255.0 - x);
        }
        best
    }
}

/// The nearest palette index of every target for endpoints `r0`, `r1`.
fn fit(r0: u8, r1: u8, x: &[f64; 16]) -> Fit {
    let palette = Palette::new(r0, r1);
    let mut indices = [0u32; 16];
    let mut max_error = 0.0f64;
    for (t, v) in x.iter().enumerate() {
        let (index, error) = palette.nearest(*v);
        indices[t] = index;
        max_error = max_error.max(error);
    }
    Fit {
        r0: palette.r0,
        r1: palette.r1,
        indices,
        max_error,
    }
}

/// The rounded value and its +-1 neighbours, within 0..=255.
fn around(v: f64) -> impl Iterator<Item = u8> {
    let r = v.round().clamp(0.0, 255.0) as i32;
    (r - 1..=r + 1)
        .filter(|c| (0..=255).contains(c))
        .map(|c| c as u8)
}

/// Encodes 16 targets in code units (clamped to [0, 255]) as a BC4 block; also returns the
/// largest error of the exact palette against the clamped targets.
pub fn encode_block(targets: &[f64; 16]) -> ([u8; BLOCK_BYTES], f64) {
    let x = targets.map(|v| v.clamp(0.0, 255.0));
    let lo = x.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = x.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // The candidate that carries the guarantee: endpoints at the rounded extremes, 8 levels
    // when they differ (r0 > r1), else the 6-level mode with equal endpoints.
    let (a, b) = (lo.round() as u8, hi.round() as u8);
    let mut best = if b > a { fit(b, a, &x) } else { fit(a, b, &x) };
    let mut consider = |r0: u8, r1: u8| {
        if best.max_error == 0.0 {
            return;
        }
        let f = fit(r0, r1, &x);
        if f.max_error < best.max_error {
            best = f;
        }
    };
    // Over the whole block 8 levels beat 6 (the extremes 0 and 255 lie outside it).
    for a in around(lo) {
        for b in around(hi).filter(|b| *b > a) {
            consider(b, a);
        }
    }
    // Texels within half a code of 0 or 255 are served exactly by the 6-level mode's
    // extremes, so its endpoints may span only the others.
    let inner = x.iter().copied().filter(|v| *v > 0.5 && *v < 254.5);
    let a_in = inner.clone().fold(f64::INFINITY, f64::min);
    let b_in = inner.fold(f64::NEG_INFINITY, f64::max);
    if a_in <= b_in && (a_in, b_in) != (lo, hi) {
        for a in around(a_in) {
            for b in around(b_in).filter(|b| *b >= a) {
                consider(a, b);
            }
        }
    }
    let mut bits = 0u64;
    for (t, index) in best.indices.iter().enumerate() {
        bits |= u64::from(*index) << (3 * t);
    }
    let word = u64::from(best.r0) | u64::from(best.r1) << 8 | bits << 16;
    (word.to_le_bytes(), best.max_error)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hytrace_testkit::{Random, SplitMix64};

    /// The sixteen texels of `block`, in code units.
    fn decode_block(block: &[u8; BLOCK_BYTES]) -> [f32; 16] {
        std::array::from_fn(|i| decode_texel(block, i))
    }

    /// Largest error of the f32 decode of `block` against `x`.
    fn decoded_error(block: &[u8; 8], x: &[f64; 16]) -> f64 {
        let d = decode_block(block);
        (0..16)
            .map(|i| (f64::from(d[i]) - x[i]).abs())
            .fold(0.0, f64::max)
    }

    #[test]
    fn palettes_follow_the_spec() {
        // 8-level mode: endpoints then six interpolants from r0 towards r1.
        let p: Vec<f32> = (0..8).map(|j| palette_value(140, 0, j)).collect();
        assert_eq!(p, [140.0, 0.0, 120.0, 100.0, 80.0, 60.0, 40.0, 20.0]);
        // 6-level mode: endpoints, four interpolants, then 0 and 255.
        let p: Vec<f32> = (0..8).map(|j| palette_value(10, 60, j)).collect();
        assert_eq!(p, [10.0, 60.0, 20.0, 30.0, 40.0, 50.0, 0.0, 255.0]);
        // Texel i sits at bits 16 + 3 i: texel 0 index 2, texel 1 index 7, texel 15 index 1.
        let word = 140u64 | 2 << 16 | 7 << 19 | 1 << (16 + 45);
        let d = decode_block(&word.to_le_bytes());
        assert_eq!((d[0], d[1], d[2], d[15]), (120.0, 20.0, 140.0, 0.0));
    }

    #[test]
    fn constant_and_two_valued_blocks_are_exact() {
        for c in [0.0, 17.0, 255.0] {
            let x = [c; 16];
            let (block, err) = encode_block(&x);
            assert_eq!(err, 0.0);
            assert_eq!(decoded_error(&block, &x), 0.0);
        }
        // A non-integer constant lands on an interpolant of neighbouring endpoints
        // (100 + 2/7), closer than the nearest code.
        let (block, err) = encode_block(&[100.3; 16]);
        assert!((err - (100.3 - (100.0 + 2.0 / 7.0))).abs() < 1e-9, "{err}");
        assert!(decoded_error(&block, &[100.3; 16]) < 0.015);
        let x: [f64; 16] = std::array::from_fn(|i| if i % 3 == 0 { 10.0 } else { 200.0 });
        let (block, err) = encode_block(&x);
        assert_eq!((err, decoded_error(&block, &x)), (0.0, 0.0));
    }

    #[test]
    fn ramps_stay_within_the_palette_spacing() {
        // A full ramp 0..255: the worst case of the 8-level palette.
        let x: [f64; 16] = std::array::from_fn(|i| 17.0 * i as f64);
        let (block, err) = encode_block(&x);
        assert!(err <= WORST_ERROR, "{err}");
        assert!(decoded_error(&block, &x) <= WORST_ERROR + 1e-4);
        // A narrow ramp: spacing 1/7 of its span.
        let x: [f64; 16] = std::array::from_fn(|i| 100.0 + 1.5 * i as f64);
        let (block, err) = encode_block(&x);
        assert!(err <= 22.5 / 14.0 + 0.5, "{err}");
        assert!(decoded_error(&block, &x) <= err + 1e-4);
        // Brick extremes in a block of mid values: the 6-level mode keeps 0 and 255 exact.
        let mut x: [f64; 16] = std::array::from_fn(|i| 120.0 + i as f64);
        (x[0], x[15]) = (0.0, 255.0);
        let (block, err) = encode_block(&x);
        assert!(err <= 2.0, "{err}");
        let d = decode_block(&block);
        assert_eq!((d[0], d[15]), (0.0, 255.0));
    }

    #[test]
    fn nearest_agrees_with_a_search_of_the_palette() {
        for (r0, r1) in [(200, 13), (13, 200), (77, 77), (255, 0), (0, 255), (1, 0)] {
            for i in 0..=2550 {
                let x = i as f64 / 10.0;
                let (index, error) = Palette::new(r0, r1).nearest(x);
                let best = (0..8)
                    .map(|j| (x - f64::from(palette_value(r0, r1, j))).abs())
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (error - best).abs() < 1e-4,
                    "{r0} {r1} {x}: {error} vs {best}"
                );
                let value = f64::from(palette_value(r0, r1, index));
                assert!(((x - value).abs() - error).abs() < 1e-4, "{r0} {r1} {x}");
            }
        }
    }

    #[test]
    fn random_blocks_respect_the_worst_case() {
        let mut rng = SplitMix64(1);
        for _ in 0..2000 {
            let x: [f64; 16] = std::array::from_fn(|_| rng.uniform() * 255.0);
            let (block, err) = encode_block(&x);
            assert!(err <= WORST_ERROR);
            assert!((decoded_error(&block, &x) - err).abs() < 1e-4);
        }
    }
}
