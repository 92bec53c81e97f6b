//! A detector view's legend as a picture (`IMAGE.legend.png` beside the image): a title
//! line (`color by KEY`), then one row per entry, a square swatch of its colour and its
//! name, in the 8x8 bitmap font of `font8x8` drawn at twice its size.

use font8x8::legacy::BASIC_LEGACY;

use super::detector::Legend;
use super::output::Image;

/// Pixels around the content.
const MARGIN: u32 = 8;
/// Glyph size in pixels (the 8x8 font doubled); also the swatch's side.
const GLYPH: u32 = 16;
/// Height of a row.
const ROW: u32 = 24;
/// Characters of a name drawn at most (longer ones end in `...`).
const MAX_CHARS: usize = 40;
/// Linear background and text colours.
const PAPER: [f32; 3] = [0.02, 0.02, 0.02];
const INK: [f32; 3] = [1.0, 1.0, 1.0];

/// `text` cut to [`MAX_CHARS`] characters, non-ASCII ones drawn as `?`.
fn printable(text: &str) -> Vec<u8> {
    let mut bytes: Vec<u8> = text
        .chars()
        .map(|c| {
            if c.is_ascii() && !c.is_ascii_control() {
                c as u8
            } else {
                b'?'
            }
        })
        .collect();
    if bytes.len() > MAX_CHARS {
        bytes.truncate(MAX_CHARS - 3);
        bytes.extend_from_slice(b"...");
    }
    bytes
}

impl Legend {
    /// The legend drawn as a linear image; its swatches hold the entries' colours exactly
    /// (so the PNG's are their sRGB encodings, as the JSON legend's `srgb8`).
    pub fn image(&self) -> Image {
        let title = printable(&format!("color by {}", self.color_by));
        let names: Vec<Vec<u8>> = self.entries.iter().map(|e| printable(&e.name)).collect();
        let text_x = MARGIN + GLYPH + MARGIN;
        let widest = names.iter().map(Vec::len).max().unwrap_or(0) as u32;
        let width = (text_x + widest * GLYPH).max(MARGIN + title.len() as u32 * GLYPH) + MARGIN;
        let height = 2 * MARGIN + ROW * (1 + names.len() as u32);
        let mut image = Image {
            width,
            height,
            pixels: vec![PAPER; (width * height) as usize],
        };
        let inset = (ROW - GLYPH) / 2;
        image.text(&title, MARGIN, MARGIN + inset);
        for (k, (entry, name)) in self.entries.iter().zip(&names).enumerate() {
            let top = MARGIN + ROW * (k as u32 + 1) + inset;
            let colour = entry.colour.map(|c| c as f32);
            for y in top..top + GLYPH {
                for x in MARGIN..MARGIN + GLYPH {
                    image.pixels[(y * width + x) as usize] = colour;
                }
            }
            image.text(name, text_x, top);
        }
        image
    }
}

impl Image {
    /// Draws ASCII `text` in [`INK`] with its top left corner at `(x, y)`.
    fn text(&mut self, text: &[u8], x: u32, y: u32) {
        let scale = GLYPH / 8;
        for (k, &c) in text.iter().enumerate() {
            let glyph = BASIC_LEGACY[usize::from(c & 0x7f)];
            let left = x + k as u32 * GLYPH;
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8u32 {
                    // Bit `col` of a row is its column `col` from the left.
                    if bits >> col & 1 == 0 {
                        continue;
                    }
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (px, py) = (left + col * scale + dx, y + row as u32 * scale + dy);
                            self.pixels[(py * self.width + px) as usize] = INK;
                        }
                    }
                }
            }
        }
    }
}
