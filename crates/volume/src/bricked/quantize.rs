//! One brick's encoding: its decode parameters, texels, measured error and a priori bound.
//!
//! Decode (shared by every format and by the GPU twin): `value = offset + t * scale` in f32
//! (a multiply then an add), `t` being the texel in code units:
//!
//! - unorm8 / unorm16: the stored integer `q`; `offset` = brick min, `scale` =
//!   `f32((max - min) / (2^n - 1))`, and `q = round((v - min) / scale)` (to nearest, where
//!   Falcor truncates);
//! - bc4: the palette value of the texel's index (see [`super::bc4`]), same offset and scale
//!   as unorm8;
//! - f16: the stored half; `scale` = 1 and `offset` = 0 (raw values) or the brick min (values
//!   relative to it), whichever gives the smaller bound;
//! - f32: the stored float; `offset` = 0, `scale` = 1 (exact).
//!
//! Encoding is done in f64, so `max - min` neither overflows nor loses the small differences
//! of values far from zero.

use half::f16;

use super::bc4;
use super::format::TexelFormat;

/// Values one brick's texel format cannot encode, in words; the caller adds the brick.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct EncodeError(String);

/// Voxels per brick.
pub const VOXELS: usize = 512;

/// Unit roundoff of f32.
const ROUNDOFF: f64 = 1.0 / (1u64 << 24) as f64;

/// Relative slack over the f64 arithmetic of the encoder.
const SLACK: f64 = 1.0 / (1u64 << 20) as f64;

/// Allowance for the f32 decode of a brick spanning `range` with values up to `magnitude`
/// through `codes` code steps: the rounded scale times up to `codes` and the product (2u R),
/// the sum (u M), doubled for a fused multiply-add or a palette division off by two ulps on
/// the GPU, plus subnormal steps.
fn decode_rounding(range: f64, magnitude: f64, codes: f64) -> f64 {
    let tiny = f64::from(f32::from_bits(1));
    4.0 * ROUNDOFF * range + 2.0 * ROUNDOFF * magnitude + (codes + 2.0) * tiny
}

/// The encoding of one brick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Encoded {
    /// Decode offset (the value of a constant brick).
    pub offset: f32,
    /// Decode scale (0 for a constant brick).
    pub scale: f32,
    /// Whether texels were appended (false: constant brick).
    pub texels: bool,
    /// Largest |decoded - source| over the brick's voxels.
    pub max_error: f64,
    /// The a priori bound on that error for the brick's value range.
    pub bound: f64,
}

/// Decodes texel `t` of a brick with `offset` and `scale`.
pub fn decode(offset: f32, scale: f32, t: f32) -> f32 {
    offset + t * scale
}

/// Code-unit value of voxel `i` (`x + 8 y + 64 z`) of a brick's `texels`.
pub fn texel(format: TexelFormat, texels: &[u8], i: usize) -> f32 {
    let bytes = |n: usize| &texels[n * i..n * i + n];
    match format {
        TexelFormat::Unorm8 => f32::from(texels[i]),
        TexelFormat::Unorm16 => f32::from(u16::from_le_bytes([texels[2 * i], texels[2 * i + 1]])),
        TexelFormat::F16 => f16::from_le_bytes([texels[2 * i], texels[2 * i + 1]]).to_f32(),
        TexelFormat::F32 => {
            let b = bytes(4);
            f32::from_le_bytes([b[0], b[1], b[2], b[3]])
        }
        TexelFormat::Bc4 => {
            let (x, y, z) = (i & 7, (i >> 3) & 7, i >> 6);
            // Per z-slice four blocks, by block row then block column.
            let start = bc4::BLOCK_BYTES * (4 * z + 2 * (y >> 2) + (x >> 2));
            let block = std::array::from_fn(|k| texels[start + k]);
            bc4::decode_texel(&block, 4 * (y & 3) + (x & 3))
        }
    }
}

/// Encodes the finite `values` (x fastest) of one brick, appending its texels (if any) to
/// `out`. Errors name the problem; the caller adds the brick.
pub fn encode(
    format: TexelFormat,
    values: &[f32; VOXELS],
    out: &mut Vec<u8>,
) -> Result<Encoded, EncodeError> {
    let min = values.iter().copied().fold(f32::INFINITY, f32::min);
    let max = values.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    if min == max {
        return Ok(Encoded {
            offset: min,
            scale: 0.0,
            texels: false,
            max_error: 0.0,
            bound: 0.0,
        });
    }
    let span = Span {
        min,
        max,
        range: f64::from(max) - f64::from(min),
        magnitude: f64::from(min).abs().max(f64::from(max).abs()),
    };
    let start = out.len();
    let (offset, scale, bound) = match format {
        TexelFormat::F32 => {
            out.extend(values.iter().flat_map(|v| v.to_le_bytes()));
            (0.0, 1.0, 0.0)
        }
        TexelFormat::F16 => encode_f16(values, &span, out)?,
        TexelFormat::Unorm8 => encode_unorm(values, &span, format, out)?,
        TexelFormat::Unorm16 => encode_unorm(values, &span, format, out)?,
        TexelFormat::Bc4 => encode_bc4(values, &span, out)?,
    };
    // The error measured with the decoder every lookup uses.
    let texels = &out[start..];
    let mut max_error = 0.0f64;
    for (i, v) in values.iter().enumerate() {
        let d = decode(offset, scale, texel(format, texels, i));
        let e = (f64::from(d) - f64::from(*v)).abs();
        if !e.is_finite() {
            return Err(EncodeError(format!(
                "voxel {v} decodes to {d} (values span [{min}, {max}])"
            )));
        }
        max_error = max_error.max(e);
    }
    Ok(Encoded {
        offset,
        scale,
        texels: true,
        max_error,
        bound,
    })
}

/// A brick's value range.
struct Span {
    min: f32,
    max: f32,
    /// `max - min` in f64.
    range: f64,
    /// `max(|min|, |max|)`.
    magnitude: f64,
}

impl Span {
    /// The decode scale for `codes` steps over the range; errors where `offset + t * scale`
    /// could overflow f32.
    fn scale(&self, codes: f64, format: TexelFormat) -> Result<f32, EncodeError> {
        if self.range * (1.0 + SLACK) > f64::from(f32::MAX) {
            return Err(EncodeError(format!(
                "values span [{}, {}], wider than the largest f32: {format} decodes \
                 `min + t * scale` in f32, which would overflow; use the f32 format",
                self.min, self.max
            )));
        }
        Ok((self.range / codes) as f32)
    }

    /// `(v - min) / scale` in f64: the target in code units.
    fn code(&self, v: f32, scale: f32, codes: f64) -> f64 {
        if scale > 0.0 {
            ((f64::from(v) - f64::from(self.min)) / f64::from(scale)).clamp(0.0, codes)
        } else {
            // A range below codes * 2^-150: every voxel decodes to the minimum.
            0.0
        }
    }
}

fn encode_unorm(
    values: &[f32; VOXELS],
    span: &Span,
    format: TexelFormat,
    out: &mut Vec<u8>,
) -> Result<(f32, f32, f64), EncodeError> {
    let codes = if format == TexelFormat::Unorm8 {
        255.0
    } else {
        65535.0
    };
    let scale = span.scale(codes, format)?;
    for v in values {
        let q = span.code(*v, scale, codes).round();
        if format == TexelFormat::Unorm8 {
            out.push(q as u8);
        } else {
            out.extend((q as u16).to_le_bytes());
        }
    }
    // Half a quantum, then the f32 decode.
    let bound = span.range / (2.0 * codes) * (1.0 + SLACK)
        + decode_rounding(span.range, span.magnitude, codes);
    Ok((span.min, scale, bound))
}

fn encode_bc4(
    values: &[f32; VOXELS],
    span: &Span,
    out: &mut Vec<u8>,
) -> Result<(f32, f32, f64), EncodeError> {
    let scale = span.scale(255.0, TexelFormat::Bc4)?;
    for z in 0..8 {
        for by in 0..2 {
            for bx in 0..2 {
                let targets = std::array::from_fn(|t| {
                    let (x, y) = (4 * bx + (t & 3), 4 * by + (t >> 2));
                    span.code(values[x + 8 * y + 64 * z], scale, 255.0)
                });
                out.extend(bc4::encode_block(&targets).0);
            }
        }
    }
    // At most WORST_ERROR codes of R/255 each, then the f32 decode.
    let bound = bc4::WORST_ERROR * span.range / 255.0 * (1.0 + SLACK)
        + decode_rounding(span.range, span.magnitude, 255.0);
    Ok((span.min, scale, bound))
}

/// Half the spacing of f16 values at magnitude `x` (<= 65504).
fn half_ulp_f16(x: f64) -> f64 {
    if x < 2f64.powi(-14) {
        return 2f64.powi(-25);
    }
    let exponent = ((x.to_bits() >> 52) & 0x7ff) as i32 - 1023;
    2f64.powi(exponent - 11)
}

/// The f16 nearest to `x` (|x| <= 65504): half's conversion, checked against its neighbours
/// (half drops the low mantissa bits of an f64 before rounding).
fn round_f16(x: f64) -> f16 {
    let first = f16::from_f64(x);
    let (sign, magnitude) = (first.to_bits() & 0x8000, first.to_bits() & 0x7fff);
    let mut best = first;
    for m in [magnitude.wrapping_sub(1), magnitude + 1] {
        if m <= f16::MAX.to_bits() {
            let c = f16::from_bits(sign | m);
            if (c.to_f64() - x).abs() < (best.to_f64() - x).abs() {
                best = c;
            }
        }
    }
    best
}

fn encode_f16(
    values: &[f32; VOXELS],
    span: &Span,
    out: &mut Vec<u8>,
) -> Result<(f32, f32, f64), EncodeError> {
    let largest = f16::MAX.to_f64();
    // Raw values decode exactly in f32 (0 + t * 1); values relative to the minimum pay the
    // f32 sum.
    let raw = (span.magnitude <= largest).then(|| half_ulp_f16(span.magnitude));
    let relative = (span.range * (1.0 + SLACK) <= largest).then(|| {
        half_ulp_f16(span.range * (1.0 + SLACK)) + decode_rounding(span.range, span.magnitude, 1.0)
    });
    let (offset, bound) = match (raw, relative) {
        (Some(r), Some(d)) if d < r => (span.min, d),
        (Some(r), _) => (0.0, r),
        (None, Some(d)) => (span.min, d),
        (None, None) => {
            return Err(EncodeError(format!(
                "values span [{}, {}]: beyond the f16 range (|t| <= 65504) both raw and \
                 relative to the brick minimum; use the f32 format",
                span.min, span.max
            )))
        }
    };
    for v in values {
        let t = round_f16(f64::from(*v) - f64::from(offset));
        out.extend(t.to_le_bytes());
    }
    Ok((offset, 1.0, bound))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn f16_rounding_is_to_nearest() {
        // 1 + 2^-11 + 2^-40: just above the midpoint of 1 and 1 + 2^-10, in bits half drops.
        let x = 1.0 + 2f64.powi(-11) + 2f64.powi(-40);
        assert_eq!(round_f16(x).to_f64(), 1.0 + 2f64.powi(-10));
        assert_eq!(round_f16(65504.0).to_f64(), 65504.0);
        assert_eq!(round_f16(-2.9e-8).to_f64(), -0.0);
        assert_eq!(half_ulp_f16(1.0), 2f64.powi(-11));
        assert_eq!(half_ulp_f16(65504.0), 16.0);
    }

    #[test]
    fn f16_picks_the_tighter_offset() {
        let mut v = [1000.0f32; VOXELS];
        v[3] = 1000.25;
        let mut out = Vec::new();
        let e = encode(TexelFormat::F16, &v, &mut out).unwrap();
        // Relative to 1000 the step 0.25 is exact; raw f16 has a spacing of 0.5 there.
        assert_eq!((e.offset, e.scale, e.max_error), (1000.0, 1.0, 0.0));
        let mut v = [0.001f32; VOXELS];
        v[0] = -1.0;
        let e = encode(TexelFormat::F16, &v, &mut Vec::new()).unwrap();
        assert_eq!(e.offset, 0.0);
        assert!(e.max_error <= e.bound);
    }
}
