//! The file container: segments with metadata and compressed grids, or a raw grid buffer.
//!
//! A segment file is one or more segments, each a 16-byte header (u64 magic, u32 version,
//! u16 grid count, u16 codec), then per grid 176 bytes of metadata and its NUL-terminated
//! name, then the grids' payloads in the same order. A raw file (written by NanoVDB 32.6 and
//! later) is one or more grid buffers back to back, each starting with its grid header.

use super::bytes::{c_string, u16_at, u32_at, u64_at};
use super::codec::decode;
use super::layout::{
    grid, NanoCodec, NanoVersion, MAGIC_FILE, MAGIC_GRID, MAGIC_NUMB, MAJOR, OPENVDB_MAGIC_LOW,
};
use crate::decode_error::DecodeError;

/// A grid's decoded buffer and what the container says about it.
pub(crate) struct RawGrid {
    pub buffer: Vec<u8>,
    /// The metadata's name (segment files only).
    pub name: Option<String>,
    pub codec: NanoCodec,
}

/// Segment header size.
const HEADER_SIZE: usize = 16;

/// Per-grid metadata (FileMetaData) fields used here.
mod meta {
    pub const SIZE: usize = 176;
    pub const GRID_SIZE: usize = 0;
    pub const FILE_SIZE: usize = 8;
    pub const NAME_SIZE: usize = 136;
}

/// Splits a file into its grids' decoded buffers.
pub(crate) fn split(bytes: &[u8]) -> Result<Vec<RawGrid>, DecodeError> {
    let Some(magic) = u64_at(bytes, 0) else {
        return Err(DecodeError(format!(
            "{} bytes are too few for a NanoVDB file",
            bytes.len()
        )));
    };
    match magic {
        MAGIC_FILE => segments(bytes),
        MAGIC_GRID => raw_grids(bytes),
        MAGIC_NUMB => {
            // "NanoVDB0" opens both segment headers and (until 32.6) grids. A segment
            // header has its version at byte 8, a grid at byte 16; 32.6 grids also keep
            // "NanoVDB1" in their last header word.
            let major = |off| u32_at(bytes, off).map(|w| NanoVersion::from_packed(w).major);
            let grid_version = major(grid::VERSION) == Some(MAJOR);
            let grid_magic = u64_at(bytes, grid::DATA2) == Some(MAGIC_GRID);
            if grid_version && (grid_magic || major(8) != Some(MAJOR)) {
                raw_grids(bytes)
            } else {
                segments(bytes)
            }
        }
        m if [MAGIC_NUMB, MAGIC_GRID, MAGIC_FILE].contains(&m.swap_bytes()) => Err(DecodeError(
            "big-endian NanoVDB files are not supported".into(),
        )),
        m if m as u32 == OPENVDB_MAGIC_LOW => Err(DecodeError(
            "this is an OpenVDB file, not a NanoVDB file".into(),
        )),
        m => Err(DecodeError(format!(
            "not a NanoVDB file (starts with {:?})",
            String::from_utf8_lossy(&m.to_le_bytes())
        ))),
    }
}

/// The metadata of one grid in a segment.
struct Meta {
    grid_size: u64,
    file_size: u64,
    name: String,
}

fn segments(bytes: &[u8]) -> Result<Vec<RawGrid>, DecodeError> {
    let mut grids = Vec::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        let at = pos;
        if bytes.len() - pos < HEADER_SIZE {
            return Err(DecodeError(format!(
                "segment header at byte {at} truncated ({} of {HEADER_SIZE} bytes)",
                bytes.len() - pos
            )));
        }
        let magic = u64_at(bytes, pos).unwrap_or(0);
        if magic != MAGIC_NUMB && magic != MAGIC_FILE {
            return Err(DecodeError(format!(
                "segment at byte {at} has bad magic {magic:#018x}"
            )));
        }
        let version = NanoVersion::from_packed(u32_at(bytes, pos + 8).unwrap_or(0));
        if !version.is_supported() {
            return Err(DecodeError(format!(
                "segment at byte {at}: NanoVDB version {version} is not supported (this reader reads 32.3 and later 32.x)"
            )));
        }
        let count = u16_at(bytes, pos + 12).unwrap_or(0);
        let code = u16_at(bytes, pos + 14).unwrap_or(0);
        let codec = NanoCodec::from_code(code)
            .ok_or_else(|| DecodeError(format!("segment at byte {at} has unknown codec {code}")))?;
        if count == 0 {
            return Err(DecodeError(format!("segment at byte {at} holds no grids")));
        }
        pos += HEADER_SIZE;

        let mut metas = Vec::new();
        for g in 0..count {
            let number = grids.len() + g as usize;
            let field = |off| u64_at(bytes, pos + off);
            let (Some(grid_size), Some(file_size), Some(name_size)) = (
                field(meta::GRID_SIZE),
                field(meta::FILE_SIZE),
                u32_at(bytes, pos + meta::NAME_SIZE).filter(|_| pos + meta::SIZE <= bytes.len()),
            ) else {
                return Err(DecodeError(format!(
                    "grid {number}: metadata at byte {pos} truncated (file of {} bytes)",
                    bytes.len()
                )));
            };
            let name_at = pos + meta::SIZE;
            let name = bytes
                .get(name_at..name_at.saturating_add(name_size as usize))
                .ok_or_else(|| {
                    DecodeError(format!(
                        "grid {number}: name of {name_size} bytes at byte {name_at} beyond the file ({} bytes)",
                        bytes.len()
                    ))
                })?;
            metas.push(Meta {
                grid_size,
                file_size,
                name: c_string(name),
            });
            pos = name_at + name.len();
        }
        for m in metas {
            let number = grids.len();
            let label = format!("grid {number} '{}'", m.name);
            let payload = usize::try_from(m.file_size)
                .ok()
                .and_then(|n| bytes.get(pos..pos.checked_add(n)?))
                .ok_or_else(|| {
                    DecodeError(format!(
                        "{label}: {} bytes of {codec} data at byte {pos} beyond the file ({} bytes)",
                        m.file_size,
                        bytes.len()
                    ))
                })?;
            pos += payload.len();
            let buffer = decode(codec, payload, m.grid_size)
                .map_err(|e| DecodeError(format!("{label}: {e}")))?;
            grids.push(RawGrid {
                buffer,
                name: Some(m.name),
                codec,
            });
        }
    }
    Ok(grids)
}

fn raw_grids(bytes: &[u8]) -> Result<Vec<RawGrid>, DecodeError> {
    let mut grids = Vec::new();
    let mut pos = 0usize;
    while pos < bytes.len() {
        let number = grids.len();
        let rest = &bytes[pos..];
        let magic = u64_at(rest, 0).unwrap_or(0);
        if rest.len() < grid::SIZE || (magic != MAGIC_NUMB && magic != MAGIC_GRID) {
            return Err(DecodeError(format!(
                "grid {number}: no grid header at byte {pos} ({} bytes left)",
                rest.len()
            )));
        }
        let size = u64_at(rest, grid::GRID_SIZE).unwrap_or(0);
        let buffer = usize::try_from(size)
            .ok()
            .filter(|s| *s >= grid::SIZE)
            .and_then(|s| rest.get(..s))
            .ok_or_else(|| {
                DecodeError(format!(
                    "grid {number}: grid size {size} at byte {pos} does not fit the {} bytes left",
                    rest.len()
                ))
            })?;
        pos += buffer.len();
        grids.push(RawGrid {
            buffer: buffer.to_vec(),
            name: None,
            codec: NanoCodec::None,
        });
    }
    Ok(grids)
}
