//! Rendered images and their files: PNG (sRGB, 8 bits, clamped) or NumPy (float32
//! `(height, width, 3)` linear radiance), written atomically.

use std::path::Path;

use crate::error::bail;
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{write_array, write_atomically};

/// A linear-radiance RGB image, rows from the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width * height` pixels, row by row from the top.
    pub pixels: Vec<[f32; 3]>,
}

/// The sRGB encoding of a linear value clamped to [0, 1], as 8 bits.
pub fn srgb8(linear: f32) -> u8 {
    let x = if linear.is_finite() {
        linear.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let encoded = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (encoded * 255.0 + 0.5) as u8
}

impl Image {
    /// The PNG file's bytes: 8-bit sRGB.
    pub fn png_bytes(&self) -> crate::Result<Vec<u8>> {
        let mut bytes = Vec::new();
        {
            let mut encoder = png::Encoder::new(&mut bytes, self.width, self.height);
            encoder.set_color(png::ColorType::Rgb);
            encoder.set_depth(png::BitDepth::Eight);
            encoder.set_source_srgb(png::SrgbRenderingIntent::Perceptual);
            let mut writer = encoder.write_header()?;
            let data: Vec<u8> = self.pixels.iter().flat_map(|p| p.map(srgb8)).collect();
            writer.write_image_data(&data)?;
        }
        Ok(bytes)
    }
}

/// Writes `image` to `path` as PNG (`.png`) or NumPy (`.npy`, float32
/// `(height, width, 3)`), through a temporary file in the same folder renamed into place,
/// so no partial file is ever left.
pub fn write_image(image: &Image, path: &Path) -> crate::Result<()> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("png") => {
            let bytes = image.png_bytes()?;
            write_atomically(path, |w| w.write_all(&bytes))?;
        }
        Some("npy") => {
            let shape = [image.height as u64, image.width as u64, 3];
            write_array(
                path,
                Scalar::F32,
                &shape,
                bytemuck::cast_slice(&image.pixels),
            )?;
        }
        _ => bail!("{}: the image must be a .png or .npy file", path.display()),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_encoding_is_monotonic_and_clamped() {
        assert_eq!(srgb8(0.0), 0);
        assert_eq!(srgb8(1.0), 255);
        assert_eq!(srgb8(7.0), 255);
        assert_eq!(srgb8(-1.0), 0);
        assert_eq!(srgb8(f32::NAN), 0);
        // Middle grey (18%) encodes near 118.
        assert!((srgb8(0.18) as i32 - 118).abs() <= 1);
        let mut last = 0;
        for k in 0..=1000 {
            let v = srgb8(k as f32 / 1000.0);
            assert!(v >= last);
            last = v;
        }
    }
}
