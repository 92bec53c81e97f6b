//! Reading NanoVDB files (`.nvdb`) of NanoVDB 32.3 to 32.x: segment files with NONE, ZIP
//! or BLOSC (LZ4) payloads and any number of grids and segments, and raw grid buffers
//! (NanoVDB 32.6 and later). Every grid keeps its raw NanoVDB buffer; Float, Double, Fp4,
//! Fp8, Fp16 and FpN grids are validated once at load (every node inside the buffer, counts
//! consistent) and then sampled through [`crate::VoxelGrid`] straight from that buffer.
//! Grids of other value types are listed with their facts but cannot be sampled.
//!
//! A truncated or corrupt file is a [`NanoError`] naming the file and what is wrong; no
//! input makes the reader panic or allocate more than its bytes can justify.

mod bytes;
mod codec;
mod error;
mod file;
mod grid;
mod layout;
mod tree;

use std::path::Path;

pub use error::NanoError;
pub use grid::{NanoGrid, NodeCounts, TileCounts};
pub use layout::{NanoCodec, NanoGridClass, NanoGridType, NanoVersion};

/// The grids of a NanoVDB file, in file order.
#[derive(Debug)]
pub struct NanoFile {
    /// Every grid of every segment.
    pub grids: Vec<NanoGrid>,
}

impl NanoFile {
    /// The first grid named `name`.
    pub fn grid(&self, name: &str) -> Option<&NanoGrid> {
        self.grids.iter().find(|g| g.name() == name)
    }
}

/// Reads the NanoVDB file at `path` (errors name it as given).
pub fn read_nanovdb(path: &Path) -> Result<NanoFile, NanoError> {
    let label = path.display().to_string();
    let bytes = std::fs::read(path)
        .map_err(|e| NanoError::new(&label, format!("cannot read the file: {e}")))?;
    parse_nanovdb(&bytes, &label)
}

/// Parses the bytes of a NanoVDB file; `source` names it in errors.
pub fn parse_nanovdb(bytes: &[u8], source: &str) -> Result<NanoFile, NanoError> {
    let raw = file::split(bytes).map_err(|m| NanoError::new(source, m.0))?;
    let grids = raw
        .into_iter()
        .enumerate()
        .map(|(number, g)| NanoGrid::parse(g.buffer, g.name, g.codec, source, number))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(NanoFile { grids })
}
