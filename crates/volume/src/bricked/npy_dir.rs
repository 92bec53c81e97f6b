//! Writing a [`BrickedGrid`] as a directory of `.npy` files and a `meta.json`.

use std::path::Path;

use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::{write_array, write_atomically, write_records};
use npyz::{DType, TypeStr, WriterBuilder};

use super::{BrickedGrid, TexelFormat, NO_BRICK, NO_SLOT};
use crate::dense::VolumeError;
use crate::ranges::RangeLevel;

fn volume_error(e: impl std::fmt::Display) -> VolumeError {
    VolumeError(e.to_string())
}

/// NumPy type string and per-slot shape of the atlas of `format`.
fn atlas_layout(format: TexelFormat) -> (&'static str, [u64; 3]) {
    match format {
        // One little-endian u64 per BC4 block: z-slice, then block (row-major 2x2).
        TexelFormat::Bc4 => ("<u8", [8, 4, 1]),
        TexelFormat::Unorm8 => ("|u1", [8, 8, 8]),
        TexelFormat::Unorm16 => ("<u2", [8, 8, 8]),
        TexelFormat::F16 => ("<f2", [8, 8, 8]),
        TexelFormat::F32 => ("<f4", [8, 8, 8]),
    }
}

/// The shape of the atlas array: `(slots, 8, 8, 8)` (z, y, x), or `(slots, 8, 4)` for BC4.
pub(crate) fn atlas_shape(g: &BrickedGrid) -> Vec<u64> {
    let (_, per_slot) = atlas_layout(g.format);
    let mut shape = vec![g.atlas_slots() as u64];
    shape.extend(per_slot.iter().filter(|n| **n > 1));
    shape
}

fn zyx(dims: [u32; 3]) -> [u64; 3] {
    [dims[2], dims[1], dims[0]].map(u64::from)
}

fn write_atlas(g: &BrickedGrid, path: &Path) -> Result<(), VolumeError> {
    let (descr, _) = atlas_layout(g.format);
    let dtype = DType::Plain(descr.parse::<TypeStr>().map_err(volume_error)?);
    let shape = atlas_shape(g);
    write_atomically(path, |w| {
        let w = npyz::WriteOptions::new_header_only()
            .dtype(dtype)
            .shape(&shape)
            .writer(w)
            .write_header_only()?;
        w.write_all(&g.atlas)
    })
    .map_err(volume_error)
}

fn write_level(level: &RangeLevel, path: &Path) -> Result<(), VolumeError> {
    let mut shape = zyx(level.dims).to_vec();
    shape.push(2);
    let pairs: Vec<[f32; 2]> = level.ranges.iter().map(|r| [r.min, r.max]).collect();
    write_array(path, Scalar::F32, &shape, bytemuck::cast_slice(&pairs)).map_err(volume_error)
}

fn meta(g: &BrickedGrid) -> serde_json::Value {
    let levels: Vec<serde_json::Value> = g
        .ranges
        .levels
        .iter()
        .map(|l| serde_json::json!({"side": l.side, "lo": l.lo, "dims": l.dims}))
        .collect();
    serde_json::json!({
        "format": g.format.name(),
        "bits_per_voxel": g.format.bits_per_voxel(),
        "brick_side": 8,
        "lo": g.lo,
        "dims": g.dims,
        "no_brick": NO_BRICK,
        "no_slot": NO_SLOT,
        "bricks": g.table.len(),
        "atlas_slots": g.atlas_slots(),
        "atlas_bytes_per_slot": g.format.bytes_per_brick(),
        "background": g.background,
        "error_bound": g.max_error,
        "analytic_error_bound": g.analytic_bound,
        "map": {"matrix": g.map.matrix, "translation": g.map.translation},
        "ranges": levels,
        "decode": "value = offset + t * scale (f32); t: unorm code, bc4 palette value (0..255), \
                   f16/f32 value; constant bricks (atlas_slot = no_slot) read offset",
    })
}

impl BrickedGrid {
    /// Writes the grid to directory `dir`:
    /// - `atlas.npy`: `(slots, 8, 8, 8)` (z, y, x) of `u1`/`<u2`/`<f2`/`<f4` for
    ///   unorm8/unorm16/f16/f32, `(slots, 8, 4)` `<u8` BC4 blocks (z-slice, block) for bc4;
    ///   the data bytes are the atlas bytes;
    /// - `indirection.npy`: `(dz, dy, dx)` `<u4`, brick-table indices or [`NO_BRICK`];
    /// - `bricks.npy`: the brick table, a structured array of [`super::BrickEntry`];
    /// - `ranges_l0.npy` .. `ranges_l3.npy`: `(dz, dy, dx, 2)` `<f4` (min, max) per block;
    /// - `meta.json`: format, indirection box (`lo`, `dims`, brick units, x y z), map,
    ///   background, error bounds, range boxes and the decode formula.
    ///
    /// Every file is written atomically (temporary file and rename). A new directory appears
    /// complete or not at all (it is assembled under a temporary name); into an existing
    /// directory `meta.json` is removed first and written last, so a directory holding a
    /// `meta.json` is complete.
    pub fn write_npy_dir(&self, dir: &Path) -> Result<(), VolumeError> {
        let io = |e: std::io::Error| VolumeError(format!("{}: {e}", dir.display()));
        if dir.exists() {
            if !dir.is_dir() {
                return Err(VolumeError(format!("{} is not a directory", dir.display())));
            }
            match std::fs::remove_file(dir.join("meta.json")) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(io(e)),
                _ => {}
            }
            return self.write_files(dir);
        }
        let parent = dir
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        std::fs::create_dir_all(parent).map_err(io)?;
        let staging = tempfile::Builder::new()
            .prefix(".hytrace-bricked-")
            .tempdir_in(parent)
            .map_err(io)?;
        // Listed for the interrupt handler, which runs no destructors.
        let _tracked = hytrace_foundry::npy::TrackedTemporary::new(staging.path());
        self.write_files(staging.path())?;
        std::fs::rename(staging.path(), dir).map_err(io)?;
        // The directory now lives under its final name; nothing is left to clean up.
        let _ = staging.keep();
        Ok(())
    }

    fn write_files(&self, dir: &Path) -> Result<(), VolumeError> {
        write_atlas(self, &dir.join("atlas.npy"))?;
        write_array(
            &dir.join("indirection.npy"),
            Scalar::U32,
            &zyx(self.dims),
            bytemuck::cast_slice(&self.indirection),
        )
        .map_err(volume_error)?;
        write_records(&dir.join("bricks.npy"), &self.table).map_err(volume_error)?;
        for (l, level) in self.ranges.levels.iter().enumerate() {
            write_level(level, &dir.join(format!("ranges_l{l}.npy")))?;
        }
        let text = serde_json::to_string_pretty(&meta(self)).map_err(volume_error)?;
        write_atomically(&dir.join("meta.json"), |w| w.write_all(text.as_bytes()))
            .map_err(volume_error)
    }
}
