//! OpenVDB's framing of a compressed buffer (io/Compression.cc, io::readData).
//!
//! With the grid's ZIP or BLOSC flag each buffer is an i64 byte count and that many bytes of
//! one zlib stream or one c-blosc 1 frame (OpenVDB compresses with LZ4 and byte shuffle of
//! 4-byte items); a count <= 0 means `-count` raw bytes follow (the codec did not shrink
//! them). Without either flag the buffer is its raw bytes. The streams and frames are
//! decoded by [`crate::codec`], which checks every length against the bytes that are there
//! and against the size expected, so a corrupt file gives an error, never a panic.

use crate::codec::{blosc_frame, inflate_zlib};
use crate::decode_error::DecodeError;

use super::format::{Cursor, COMPRESS_BLOSC, COMPRESS_ZIP};

/// Reads one buffer of `len` bytes stored with the grid's `compression` flags.
pub(super) fn read_data(
    cur: &mut Cursor,
    compression: u32,
    len: usize,
) -> Result<Vec<u8>, DecodeError> {
    if compression & (COMPRESS_BLOSC | COMPRESS_ZIP) == 0 {
        return Ok(cur.take(len)?.to_vec());
    }
    let n = cur.i64()?;
    if n <= 0 {
        if n.unsigned_abs() != len as u64 {
            return Err(DecodeError(format!(
                "expected a {len}-byte uncompressed chunk, got {}",
                n.unsigned_abs()
            )));
        }
        return Ok(cur.take(len)?.to_vec());
    }
    let src =
        cur.take(usize::try_from(n).map_err(|_| DecodeError(format!("chunk of {n} bytes")))?)?;
    if compression & COMPRESS_BLOSC != 0 {
        let mut out = Vec::new();
        blosc_frame(src, len, &mut out).map_err(|e| DecodeError(format!("Blosc frame: {e}")))?;
        Ok(out)
    } else {
        inflate_zlib(src, len)
    }
}
