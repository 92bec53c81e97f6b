//! Volumes larger than memory: an on-disk store of 16-bit 8^3 bricks grouped in superchunks
//! of 16^3 bricks (as BrickMap), empty bricks dropped, with halo-inclusive block ranges and
//! coarser levels of detail per brick; converted from raw files in bounded memory
//! ([`convert_raw`]) and read through a brick cache with a byte budget ([`BrickStore`]).
//!
//! The store's voxels are its decoded codes: a lookup through the cache answers exactly
//! what the same store held whole in memory answers, whatever the budget.

mod convert;
mod format;
mod streamed;

use std::path::{Path, PathBuf};

use crate::grid::GridMap;

pub use convert::{
    convert_grid, convert_raw, planned_memory, ConvertOptions, ConvertReport, Endian, RawSpec,
    RawType,
};
pub use format::{
    Quantization, StoreMeta, BRICK_BYTES, BRICK_VOXELS, LOD_VALUES, STORE_FORMAT, STORE_VERSION,
    SUPERCHUNK_BRICKS,
};
pub use streamed::{is_brick_store, BrickStore, CacheStats};

/// What went wrong with a brick store or its source, and in which file.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("{}: {problem}", path.display())]
pub struct StoreError {
    /// The file or directory.
    pub path: PathBuf,
    /// What is wrong.
    pub problem: String,
}

/// Bytes of the files in store directory `dir`.
pub fn store_bytes(dir: &Path) -> std::io::Result<u64> {
    let mut total = 0;
    for entry in std::fs::read_dir(dir)? {
        total += entry?.metadata()?.len();
    }
    Ok(total)
}

impl StoreError {
    /// An error about `path`.
    pub fn new(path: &Path, problem: String) -> StoreError {
        StoreError {
            path: path.to_path_buf(),
            problem,
        }
    }
}

impl StoreMeta {
    /// Metadata of an empty store of `dims` voxels (index space is world space, background
    /// 0).
    pub fn for_dims(dims: [u32; 3]) -> StoreMeta {
        StoreMeta {
            format: STORE_FORMAT.to_string(),
            version: STORE_VERSION,
            dims,
            index_origin: [0; 3],
            matrix: GridMap::IDENTITY.matrix,
            translation: [0.0; 3],
            background: 0.0,
            threshold: 0.0,
            quantization: Quantization { lo: 0.0, step: 0.0 },
            kept_bricks: 0,
            dropped_bricks: 0,
            source: String::new(),
        }
    }
}
