//! The texel formats a bricked grid can store its voxels in.

use std::fmt;
use std::str::FromStr;

use crate::dense::VolumeError;

/// How the texels of a brick are stored in the atlas.
///
/// Every format decodes a texel `t` (in "code units", see [`crate::BrickedGrid`]) as
/// `offset + t * scale` with the brick's own `offset` and `scale`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TexelFormat {
    /// BC4 (UNORM) blocks: 4x4 texels in 8 bytes, palette of 8 levels between two 8-bit
    /// endpoints, relative to the brick's `[min, max]`.
    Bc4,
    /// 8-bit unsigned normalized, relative to the brick's `[min, max]`.
    Unorm8,
    /// 16-bit unsigned normalized, relative to the brick's `[min, max]`.
    Unorm16,
    /// IEEE half precision, raw or relative to the brick's minimum (whichever is tighter).
    F16,
    /// IEEE single precision, raw (exact for f32 sources).
    F32,
}

impl TexelFormat {
    /// Every format, smallest first.
    pub const ALL: [TexelFormat; 5] = [
        TexelFormat::Bc4,
        TexelFormat::Unorm8,
        TexelFormat::Unorm16,
        TexelFormat::F16,
        TexelFormat::F32,
    ];

    /// Atlas bits per voxel.
    pub const fn bits_per_voxel(self) -> u32 {
        match self {
            TexelFormat::Bc4 => 4,
            TexelFormat::Unorm8 => 8,
            TexelFormat::Unorm16 | TexelFormat::F16 => 16,
            TexelFormat::F32 => 32,
        }
    }

    /// Atlas bytes of one 8^3 brick.
    pub const fn bytes_per_brick(self) -> usize {
        512 * self.bits_per_voxel() as usize / 8
    }

    /// The name used on the command line and in `meta.json`.
    pub const fn name(self) -> &'static str {
        match self {
            TexelFormat::Bc4 => "bc4",
            TexelFormat::Unorm8 => "unorm8",
            TexelFormat::Unorm16 => "unorm16",
            TexelFormat::F16 => "f16",
            TexelFormat::F32 => "f32",
        }
    }
}

impl fmt::Display for TexelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for TexelFormat {
    type Err = VolumeError;

    fn from_str(s: &str) -> Result<TexelFormat, VolumeError> {
        TexelFormat::ALL
            .into_iter()
            .find(|f| f.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = TexelFormat::ALL.iter().map(|f| f.name()).collect();
                VolumeError(format!(
                    "unknown texel format `{s}`; expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_sizes_add_up() {
        for f in TexelFormat::ALL {
            assert_eq!(f.to_string().parse::<TexelFormat>(), Ok(f));
            assert_eq!(f.bytes_per_brick() * 8, 512 * f.bits_per_voxel() as usize);
        }
        assert_eq!(TexelFormat::Bc4.bytes_per_brick(), 256);
        let err = "bc7".parse::<TexelFormat>().unwrap_err().to_string();
        assert!(err.contains("bc4, unorm8, unorm16, f16, f32"), "{err}");
    }
}
