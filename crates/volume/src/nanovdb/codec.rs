//! Decoding a grid's payload: NONE (raw bytes), ZIP (one zlib stream after its u64 size) and
//! BLOSC (Blosc 1 frames of at most 1 GiB of grid bytes, each after its u64 size).
//!
//! Stated sizes are checked against the bytes present before anything is allocated: a
//! payload cannot claim more output than its codec can produce from its length. The zlib
//! streams and Blosc frames themselves are decoded by [`crate::codec`].

use crate::codec::{blosc_frame, inflate_zlib, LZ4_MAX_RATIO, RATIO_SLACK};
use crate::decode_error::DecodeError;

use super::bytes::u64_at;
use super::layout::NanoCodec;

/// Largest grid this reader decompresses into memory.
pub(crate) const MAX_GRID_BYTES: u64 = 1 << 36;

/// Most bytes NanoVDB puts in one Blosc frame.
const BLOSC_CHUNK: u64 = 1 << 30;

/// Largest allocation made before the data proves it is there.
const INITIAL_CAPACITY: u64 = 1 << 26;

/// Decodes `payload` (exactly the bytes the file gives the grid) into `grid_size` bytes.
pub(crate) fn decode(
    codec: NanoCodec,
    payload: &[u8],
    grid_size: u64,
) -> Result<Vec<u8>, DecodeError> {
    if grid_size > MAX_GRID_BYTES {
        return Err(DecodeError(format!(
            "grid size {grid_size} bytes exceeds the reader's limit of {MAX_GRID_BYTES}"
        )));
    }
    match codec {
        NanoCodec::None => {
            if payload.len() as u64 != grid_size {
                return Err(DecodeError(format!(
                    "uncompressed grid of {grid_size} bytes stored in {} bytes",
                    payload.len()
                )));
            }
            Ok(payload.to_vec())
        }
        NanoCodec::Zip => unzip(payload, grid_size),
        NanoCodec::Blosc => unblosc(payload, grid_size),
    }
}

fn unzip(payload: &[u8], grid_size: u64) -> Result<Vec<u8>, DecodeError> {
    let size = u64_at(payload, 0)
        .ok_or_else(|| DecodeError("ZIP payload shorter than its 8-byte size".into()))?;
    let data = &payload[8..];
    if size != data.len() as u64 {
        return Err(DecodeError(format!(
            "ZIP payload states {size} compressed bytes but holds {}",
            data.len()
        )));
    }
    let expected = usize::try_from(grid_size).map_err(|_| {
        DecodeError(format!(
            "grid size {grid_size} bytes does not fit in memory"
        ))
    })?;
    inflate_zlib(data, expected).map_err(|e| DecodeError(format!("ZIP payload: {e}")))
}

fn unblosc(payload: &[u8], grid_size: u64) -> Result<Vec<u8>, DecodeError> {
    if grid_size > LZ4_MAX_RATIO * payload.len() as u64 + RATIO_SLACK {
        return Err(DecodeError(format!(
            "BLOSC payload of {} bytes cannot hold a grid of {grid_size} bytes",
            payload.len()
        )));
    }
    let mut out = Vec::with_capacity(grid_size.min(INITIAL_CAPACITY) as usize);
    let mut pos = 0usize;
    let mut residual = grid_size;
    let mut frame_index = 0;
    // NanoVDB writes one frame per started GiB of grid bytes.
    loop {
        let chunk = residual.min(BLOSC_CHUNK);
        let size = u64_at(payload, pos).ok_or_else(|| {
            DecodeError(format!(
                "BLOSC frame {frame_index}: size missing at byte {pos}"
            ))
        })?;
        pos += 8;
        let frame = usize::try_from(size)
            .ok()
            .and_then(|s| payload.get(pos..pos.checked_add(s)?))
            .ok_or_else(|| {
                DecodeError(format!(
                    "BLOSC frame {frame_index}: {size} bytes stated, {} left",
                    payload.len() - pos
                ))
            })?;
        pos += frame.len();
        blosc_frame(frame, chunk as usize, &mut out)
            .map_err(|e| DecodeError(format!("BLOSC frame {frame_index}: {e}")))?;
        residual -= chunk;
        frame_index += 1;
        if residual == 0 {
            break;
        }
    }
    if pos != payload.len() {
        return Err(DecodeError(format!(
            "BLOSC payload has {} bytes after its last frame",
            payload.len() - pos
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::tests::{blosc_encode, sample_data};

    /// A NanoVDB BLOSC payload of one frame.
    fn blosc_payload(frame: &[u8]) -> Vec<u8> {
        let mut p = (frame.len() as u64).to_le_bytes().to_vec();
        p.extend_from_slice(frame);
        p
    }

    /// A NanoVDB ZIP payload.
    fn zip_payload(data: &[u8]) -> Vec<u8> {
        let packed = miniz_oxide::deflate::compress_to_vec_zlib(data, 6);
        let mut p = (packed.len() as u64).to_le_bytes().to_vec();
        p.extend_from_slice(&packed);
        p
    }

    /// Decoding fails with a message naming every one of `parts`.
    fn expect_error(codec: NanoCodec, payload: &[u8], grid_size: u64, parts: &[&str]) {
        let err = decode(codec, payload, grid_size).unwrap_err().0;
        assert!(
            parts.iter().all(|p| err.contains(p)),
            "{parts:?} not in {err}"
        );
    }

    #[test]
    fn every_codec_decodes_its_payload() {
        let data = sample_data(5000);
        let n = data.len() as u64;
        assert_eq!(decode(NanoCodec::None, &data, n).unwrap(), data);
        assert_eq!(
            decode(NanoCodec::Zip, &zip_payload(&data), n).unwrap(),
            data
        );
        for (typesize, blocksize, compress, memcpy) in [
            (4, 1024, true, false),
            (3, 333, false, false),
            (4, 1024, false, true),
        ] {
            let frame = blosc_encode(&data, typesize, blocksize, compress, memcpy);
            let out = decode(NanoCodec::Blosc, &blosc_payload(&frame), n)
                .unwrap_or_else(|e| panic!("{typesize} {blocksize} {compress} {memcpy}: {e}"));
            assert_eq!(out, data);
        }
    }

    #[test]
    fn corrupt_payloads_are_errors() {
        let data = sample_data(3000);
        let frame = blosc_encode(&data, 4, 1024, true, false);
        let payload = blosc_payload(&frame);
        expect_error(
            NanoCodec::Blosc,
            &payload,
            2999,
            &["BLOSC frame 0", "expected 2999"],
        );
        assert!(decode(NanoCodec::Blosc, &payload[..payload.len() - 1], 3000).is_err());
        assert!(decode(NanoCodec::Blosc, &payload[..4], 3000).is_err());
        let mut trailing = payload.clone();
        trailing.push(0);
        expect_error(NanoCodec::Blosc, &trailing, 3000, &["after its last frame"]);
        let mut zstd = frame.clone();
        zstd[2] = (4 << 5) | 1;
        expect_error(
            NanoCodec::Blosc,
            &blosc_payload(&zstd),
            3000,
            &["BLOSC frame 0", "zstd"],
        );
        for pos in 0..payload.len() {
            let mut bad = payload.clone();
            bad[pos] ^= 0x5a;
            // Must not panic; may decode (to wrong bytes) or fail.
            let _ = decode(NanoCodec::Blosc, &bad, 3000);
        }
        let zip = zip_payload(&data);
        expect_error(
            NanoCodec::Zip,
            &zip,
            3001,
            &["ZIP payload", "expected 3001"],
        );
        assert!(decode(NanoCodec::Zip, &zip[..zip.len() - 1], 3000).is_err());
        assert!(decode(NanoCodec::Zip, &[1, 0, 0, 0, 0, 0, 0, 0, 0], 10).is_err());
        assert!(decode(NanoCodec::Zip, &[0; 4], 10).is_err());
        assert!(decode(NanoCodec::None, &[0; 4], 5).is_err());
        assert!(decode(NanoCodec::None, &[0; 4], MAX_GRID_BYTES + 1).is_err());
        // A tiny payload claiming a huge grid is refused before any allocation.
        let mut zip = 10u64.to_le_bytes().to_vec();
        zip.extend_from_slice(&[0x78, 0x9c, 3, 0, 0, 0, 0, 1, 0, 0]);
        expect_error(NanoCodec::Zip, &zip, 1 << 30, &["cannot hold"]);
        expect_error(NanoCodec::Blosc, &payload, 1 << 30, &["cannot hold"]);
    }
}
