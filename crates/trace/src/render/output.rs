//! Rendered images and their files: PNG (sRGB, 8 bits, clamped), NumPy (float32
//! `(height, width, 3)` linear radiance) or OpenEXR (linear RGB, half or float), written
//! atomically.

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

/// The sample type of an OpenEXR image.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ExrPrecision {
    /// 32-bit float: the radiance exactly as rendered.
    #[default]
    Float,
    /// 16-bit half float (rounded to nearest; values beyond 65504 become infinite).
    Half,
}

crate::choice::named!(ExrPrecision {
    (ExrPrecision::Float, "float", [], "32-bit float: the radiance exactly as rendered"),
    (ExrPrecision::Half, "half", [], "16-bit half float, rounded to nearest"),
});

impl Image {
    /// The OpenEXR file's bytes: one scan-line part with linear R, G and B channels of
    /// `precision`, ZIP-compressed in blocks of 16 lines.
    pub fn exr_bytes(&self, precision: ExrPrecision) -> crate::Result<Vec<u8>> {
        use exr::prelude::{Encoding, Image as ExrImage, SpecificChannels, Vec2, WritableImage};
        let (w, h) = (self.width as usize, self.height as usize);
        let at = |x: usize, y: usize| self.pixels[y * w + x];
        let mut cursor = std::io::Cursor::new(Vec::new());
        let encoding = Encoding::SMALL_LOSSLESS;
        match precision {
            ExrPrecision::Float => {
                let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                    let [r, g, b] = at(x, y);
                    (r, g, b)
                });
                ExrImage::from_encoded_channels((w, h), encoding, channels)
                    .write()
                    .to_buffered(&mut cursor)?;
            }
            ExrPrecision::Half => {
                let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                    let [r, g, b] = at(x, y).map(exr::prelude::f16::from_f32);
                    (r, g, b)
                });
                ExrImage::from_encoded_channels((w, h), encoding, channels)
                    .write()
                    .to_buffered(&mut cursor)?;
            }
        }
        Ok(cursor.into_inner())
    }

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

/// The image file extensions [`write_image`] writes.
pub const IMAGE_EXTENSIONS: &str = ".png, .npy or .exr";

/// Writes `image` to `path` as PNG (`.png`), NumPy (`.npy`, float32 `(height, width, 3)`)
/// or OpenEXR (`.exr`, of `exr` precision), through a temporary file in the same folder
/// renamed into place, so no partial file is ever left.
pub fn write_image(image: &Image, path: &Path, exr: ExrPrecision) -> crate::Result<()> {
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
        Some("exr") => {
            let bytes = image.exr_bytes(exr)?;
            write_atomically(path, |w| w.write_all(&bytes))?;
        }
        _ => bail!(
            "{}: the image must be a {IMAGE_EXTENSIONS} file",
            path.display()
        ),
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
