//! The two codecs OpenVDB and NanoVDB compress data with: zlib and Blosc 1 (LZ4 with byte
//! shuffle). Each file format frames them its own way (`openvdb::codec`, `nanovdb::codec`);
//! this module decodes one zlib stream or one Blosc frame.
//!
//! Every stated size is checked against the bytes present and against the size the caller
//! expects, and against what the codec can produce from its input before anything is
//! allocated: corrupt data gives an error, never a panic, an out-of-bounds read or a huge
//! allocation. Messages say what is wrong with the data; the callers add which file, grid
//! and frame it is.

use crate::decode_error::DecodeError;

/// Upper bound of deflate's output per input byte (its format allows about 1032).
const ZLIB_MAX_RATIO: u64 = 1100;

/// Upper bound of LZ4's output per input byte (a length byte adds at most 255).
pub(crate) const LZ4_MAX_RATIO: u64 = 256;

/// Output a few bytes of input may always claim on top of the ratios above.
pub(crate) const RATIO_SLACK: u64 = 1024;

/// Decodes a zlib stream that must hold exactly `expected` bytes.
pub(crate) fn inflate_zlib(data: &[u8], expected: usize) -> Result<Vec<u8>, DecodeError> {
    if expected as u64 > ZLIB_MAX_RATIO * data.len() as u64 + RATIO_SLACK {
        return Err(DecodeError(format!(
            "{} bytes of zlib data cannot hold {expected} bytes",
            data.len()
        )));
    }
    // The output grows with the data actually decoded, up to `expected` bytes.
    let out =
        miniz_oxide::inflate::decompress_to_vec_zlib_with_limit(data, expected).map_err(|e| {
            DecodeError(format!(
                "zlib data is corrupt or exceeds {expected} bytes ({:?})",
                e.status
            ))
        })?;
    if out.len() != expected {
        return Err(DecodeError(format!(
            "zlib data holds {} bytes, expected {expected}",
            out.len()
        )));
    }
    Ok(out)
}

/// Blosc 1 header flags (c-blosc 1 blosc.h).
const DOSHUFFLE: u8 = 0x01;
const MEMCPYED: u8 = 0x02;
const DOBITSHUFFLE: u8 = 0x04;
const RESERVED: u8 = 0x08;
const DONT_SPLIT: u8 = 0x10;
/// Compressor code (top three flag bits) of LZ4 and LZ4HC.
const LZ4_CODE: u8 = 1;
const COMPRESSOR_NAMES: [&str; 5] = ["blosclz", "lz4", "snappy", "zlib", "zstd"];
/// Blosc splits a block into `typesize` streams only up to this type size ...
const MAX_SPLITS: usize = 16;
/// ... and when every stream gets at least this many bytes.
const MIN_SPLIT_BYTES: usize = 128;
const HEADER: usize = 16;

/// The little-endian 4 bytes at `off`, or `None` when they do not all lie in `b`.
fn le32(b: &[u8], off: usize) -> Option<[u8; 4]> {
    b.get(off..off.checked_add(4)?)?.try_into().ok()
}

/// Appends the `expected` bytes of one Blosc 1 frame (format version 2) to `out`.
///
/// Frame: 16-byte header (version, compressor version, flags, type size, u32 uncompressed
/// size, u32 block size, u32 frame size), then either the raw bytes (memcpy flag) or one
/// u32 start offset per block followed by the blocks; each block is one or `typesize`
/// streams, each an i32 length and LZ4 data (or raw bytes when the length equals the
/// stream's size). With the shuffle flag a block's bytes are grouped by byte position
/// within the `typesize`-byte elements. Other compressors and bit shuffle give an error.
pub(crate) fn blosc_frame(
    frame: &[u8],
    expected: usize,
    out: &mut Vec<u8>,
) -> Result<(), DecodeError> {
    if frame.len() < HEADER {
        return Err(DecodeError(format!(
            "{} bytes, shorter than its {HEADER}-byte header",
            frame.len()
        )));
    }
    let (version, flags, typesize) = (frame[0], frame[2], frame[3] as usize);
    let header = |off| le32(frame, off).map_or(0, |v| u32::from_le_bytes(v) as usize);
    let (nbytes, blocksize, cbytes) = (header(4), header(8), header(12));
    if version != 2 {
        return Err(DecodeError(format!(
            "Blosc format version {version} is not supported (expected 2)"
        )));
    }
    if nbytes != expected {
        return Err(DecodeError(format!(
            "holds {nbytes} bytes, expected {expected}"
        )));
    }
    if cbytes != frame.len() {
        return Err(DecodeError(format!(
            "states {cbytes} bytes but has {}",
            frame.len()
        )));
    }
    if flags & RESERVED != 0 {
        return Err(DecodeError(format!(
            "reserved flag bit set (flags {flags:#x})"
        )));
    }
    if nbytes == 0 {
        return Ok(());
    }
    if flags & MEMCPYED != 0 {
        if frame.len() != HEADER + nbytes {
            return Err(DecodeError(format!(
                "stored frame of {} bytes for {nbytes} bytes",
                frame.len()
            )));
        }
        out.extend_from_slice(&frame[HEADER..]);
        return Ok(());
    }
    let compressor = flags >> 5;
    if compressor != LZ4_CODE {
        let name = COMPRESSOR_NAMES
            .get(compressor as usize)
            .map_or_else(|| format!("code {compressor}"), |n| n.to_string());
        return Err(DecodeError(format!(
            "Blosc compressor {name} is not supported (OpenVDB and NanoVDB write LZ4)"
        )));
    }
    if typesize == 0 || blocksize == 0 {
        return Err(DecodeError(format!(
            "corrupt header: type size {typesize}, block size {blocksize}"
        )));
    }
    if flags & DOBITSHUFFLE != 0 && blocksize >= typesize {
        return Err(DecodeError(
            "Blosc bit shuffle is not supported (OpenVDB and NanoVDB write byte shuffle)".into(),
        ));
    }
    if nbytes as u64 > LZ4_MAX_RATIO * cbytes as u64 + RATIO_SLACK {
        return Err(DecodeError(format!(
            "{cbytes} bytes cannot hold {nbytes} bytes"
        )));
    }
    let shuffle = flags & DOSHUFFLE != 0 && typesize > 1;
    let blocks = nbytes.div_ceil(blocksize);
    if blocks > (frame.len() - HEADER) / 4 {
        return Err(DecodeError(format!(
            "{blocks} blocks do not fit their start table"
        )));
    }
    let table_end = HEADER + 4 * blocks;
    let start = out.len();
    out.resize(start + nbytes, 0);
    let mut shuffled = if shuffle {
        vec![0u8; blocksize.min(nbytes)]
    } else {
        Vec::new()
    };
    for j in 0..blocks {
        let first = j * blocksize;
        let size = blocksize.min(nbytes - first);
        let leftover = size < blocksize;
        let splits = if flags & DONT_SPLIT == 0
            && typesize <= MAX_SPLITS
            && size / typesize >= MIN_SPLIT_BYTES
            && !leftover
        {
            typesize
        } else {
            1
        };
        let bstart = le32(frame, HEADER + 4 * j).map_or(-1, i32::from_le_bytes);
        let src = usize::try_from(bstart)
            .ok()
            .filter(|&s| s >= table_end)
            .ok_or_else(|| DecodeError(format!("block {j} starts at {bstart}")))?;
        let dest = &mut out[start + first..start + first + size];
        let target = if shuffle { &mut shuffled[..size] } else { dest };
        decode_block(frame, src, splits, target)
            .map_err(|e| DecodeError(format!("block {j}: {e}")))?;
        if shuffle {
            let dest = &mut out[start + first..start + first + size];
            unshuffle(&shuffled[..size], typesize, dest);
        }
    }
    Ok(())
}

/// Decodes the `splits` streams starting at `src` into `target`, one equal part each.
fn decode_block(
    frame: &[u8],
    mut src: usize,
    splits: usize,
    target: &mut [u8],
) -> Result<(), DecodeError> {
    let part = target.len() / splits;
    if part == 0 || part * splits != target.len() {
        return Err(DecodeError(format!(
            "{} bytes do not split into {splits} streams",
            target.len()
        )));
    }
    for (s, dest) in target.chunks_exact_mut(part).enumerate() {
        let length = le32(frame, src)
            .map(i32::from_le_bytes)
            .ok_or_else(|| DecodeError(format!("stream {s} length missing")))?;
        src += 4;
        let data = usize::try_from(length)
            .ok()
            .and_then(|n| frame.get(src..src.checked_add(n)?))
            .ok_or_else(|| {
                DecodeError(format!("stream {s} of {length} bytes overruns the frame"))
            })?;
        src += data.len();
        if data.len() == part {
            dest.copy_from_slice(data);
        } else {
            let n = lz4_flex::block::decompress_into(data, dest)
                .map_err(|e| DecodeError(format!("stream {s}: LZ4 data is corrupt: {e}")))?;
            if n != part {
                return Err(DecodeError(format!(
                    "stream {s}: LZ4 gave {n} bytes, expected {part}"
                )));
            }
        }
    }
    Ok(())
}

/// Undoes Blosc's byte shuffle: byte `b` of element `i` sits at `b * elements + i`; the bytes
/// after the last whole element are stored as they are.
fn unshuffle(src: &[u8], typesize: usize, dest: &mut [u8]) {
    let elements = src.len() / typesize;
    let tail = elements * typesize;
    if typesize == 4 && elements > 0 {
        // The type size of a float, which both formats shuffle with: one pass over whole
        // elements.
        let mut planes = src[..tail].chunks_exact(elements);
        let (p0, p1, p2, p3) = match (planes.next(), planes.next(), planes.next(), planes.next()) {
            (Some(a), Some(b), Some(c), Some(d)) => (a, b, c, d),
            _ => return,
        };
        let bytes = p0.iter().zip(p1).zip(p2).zip(p3);
        for (element, (((a, b), c), d)) in dest[..tail].chunks_exact_mut(4).zip(bytes) {
            element.copy_from_slice(&[*a, *b, *c, *d]);
        }
    } else if elements > 0 {
        for (b, plane) in src[..tail].chunks_exact(elements).enumerate() {
            for (byte, value) in dest[b..tail].iter_mut().step_by(typesize).zip(plane) {
                *byte = *value;
            }
        }
    }
    dest[tail..].copy_from_slice(&src[tail..]);
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Byte shuffle (the inverse of [`unshuffle`]).
    fn shuffle(src: &[u8], typesize: usize) -> Vec<u8> {
        let elements = src.len() / typesize;
        let mut out = src.to_vec();
        for i in 0..elements {
            for b in 0..typesize {
                out[b * elements + i] = src[i * typesize + b];
            }
        }
        out
    }

    /// A Blosc 1 frame of `data` as c-blosc lays it out: byte shuffle with `typesize`,
    /// blocks of `blocksize`, streams split per c-blosc's rule; `compress` chooses LZ4
    /// streams (kept raw when LZ4 does not shrink them) or raw streams; `memcpy` stores
    /// the bytes after the header only.
    pub(crate) fn blosc_encode(
        data: &[u8],
        typesize: usize,
        blocksize: usize,
        compress: bool,
        memcpy: bool,
    ) -> Vec<u8> {
        encode(data, typesize, blocksize, compress, memcpy, false)
    }

    /// [`blosc_encode`], with the choice of c-blosc's flag that keeps every block whole.
    fn encode(
        data: &[u8],
        typesize: usize,
        blocksize: usize,
        compress: bool,
        memcpy: bool,
        dont_split: bool,
    ) -> Vec<u8> {
        let mut flags = (LZ4_CODE << 5) | DOSHUFFLE;
        if dont_split {
            flags |= DONT_SPLIT;
        }
        let mut body = Vec::new();
        if memcpy {
            flags |= MEMCPYED;
            body.extend_from_slice(data);
        } else {
            let blocks = data.len().div_ceil(blocksize);
            let mut streams = Vec::new();
            let table = HEADER + 4 * blocks;
            for j in 0..blocks {
                body.extend_from_slice(&((table + streams.len()) as i32).to_le_bytes());
                let block = &data[j * blocksize..(j * blocksize + blocksize).min(data.len())];
                let leftover = block.len() < blocksize;
                let splits = if !dont_split
                    && typesize <= MAX_SPLITS
                    && block.len() / typesize >= MIN_SPLIT_BYTES
                    && !leftover
                {
                    typesize
                } else {
                    1
                };
                let shuffled = shuffle(block, typesize);
                for part in shuffled.chunks_exact(block.len() / splits) {
                    let packed = lz4_flex::block::compress(part);
                    let stored = if compress && packed.len() < part.len() {
                        &packed[..]
                    } else {
                        part
                    };
                    streams.extend_from_slice(&(stored.len() as i32).to_le_bytes());
                    streams.extend_from_slice(stored);
                }
            }
            body.extend_from_slice(&streams);
        }
        let mut frame = vec![2, 1, flags, typesize as u8];
        frame.extend_from_slice(&(data.len() as u32).to_le_bytes());
        frame.extend_from_slice(&(blocksize as u32).to_le_bytes());
        frame.extend_from_slice(&((HEADER + body.len()) as u32).to_le_bytes());
        frame.extend_from_slice(&body);
        frame
    }

    /// Bytes with runs and repeats, so that LZ4 shrinks some streams and not others.
    pub(crate) fn sample_data(n: usize) -> Vec<u8> {
        (0..n).map(|i| ((i / 7) % 5 * 50 + i % 3) as u8).collect()
    }

    /// The bytes of one Blosc frame, decoded on their own.
    fn unblosc(frame: &[u8], expected: usize) -> Result<Vec<u8>, DecodeError> {
        let mut out = Vec::new();
        blosc_frame(frame, expected, &mut out)?;
        Ok(out)
    }

    #[test]
    fn memcpyed_frames_and_bad_headers() {
        let mut frame = vec![2, 1, MEMCPYED | DOSHUFFLE, 4];
        frame.extend_from_slice(&5u32.to_le_bytes());
        frame.extend_from_slice(&5u32.to_le_bytes());
        frame.extend_from_slice(&21u32.to_le_bytes());
        frame.extend_from_slice(b"hello");
        assert_eq!(unblosc(&frame, 5).unwrap(), b"hello");
        // Frames append to what is already decoded.
        let mut out = b"say ".to_vec();
        blosc_frame(&frame, 5, &mut out).unwrap();
        assert_eq!(out, b"say hello");
        assert!(unblosc(&frame, 6).unwrap_err().0.contains("expected 6"));
        assert!(unblosc(&frame[..20], 5)
            .unwrap_err()
            .0
            .contains("states 21 bytes"));
        assert!(unblosc(&frame[..10], 5).unwrap_err().0.contains("header"));
        let mut future = frame.clone();
        future[0] = 3;
        assert!(unblosc(&future, 5).unwrap_err().0.contains("version 3"));
        let mut reserved = frame.clone();
        reserved[2] |= RESERVED;
        assert!(unblosc(&reserved, 5).unwrap_err().0.contains("reserved"));
        // A stored frame whose stated size does not match its bytes.
        let mut short = frame.clone();
        short[12..16].copy_from_slice(&20u32.to_le_bytes());
        short.pop();
        assert!(unblosc(&short, 5).unwrap_err().0.contains("stored frame"));
        // An empty frame decodes to nothing whatever its flags.
        let mut empty = vec![2, 1, !RESERVED, 0];
        empty.extend_from_slice(&[0; 8]);
        empty.extend_from_slice(&16u32.to_le_bytes());
        assert_eq!(unblosc(&empty, 0).unwrap(), b"");
    }

    #[test]
    fn unshuffle_restores_items_and_tail() {
        // Two 4-byte items and a 1-byte tail (the float path).
        let src = [1, 5, 2, 6, 3, 7, 4, 8, 9];
        let mut dest = [0; 9];
        unshuffle(&src, 4, &mut dest);
        assert_eq!(dest, [1, 2, 3, 4, 5, 6, 7, 8, 9]);
        // Three 3-byte items and a 2-byte tail (the general path).
        let src = [1, 4, 7, 2, 5, 8, 3, 6, 9, 10, 11];
        let mut dest = [0; 11];
        unshuffle(&src, 3, &mut dest);
        assert_eq!(dest, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11]);
        // Fewer bytes than one item: all tail.
        let mut dest = [0; 3];
        unshuffle(&[7, 8, 9], 4, &mut dest);
        assert_eq!(dest, [7, 8, 9]);
        // The inverse of the test encoder's shuffle, for both paths.
        let data = sample_data(1001);
        for typesize in [2, 4, 8] {
            let mut dest = vec![0; data.len()];
            unshuffle(&shuffle(&data, typesize), typesize, &mut dest);
            assert_eq!(dest, data, "type size {typesize}");
        }
    }

    #[test]
    fn blosc_frames_decode_in_every_layout() {
        let data = sample_data(5000);
        for typesize in [4, 3] {
            // c-blosc keeps block sizes a multiple of the type size.
            for (compress, memcpy, elements) in [
                (true, false, 256),
                (false, false, 256),
                (true, false, 1250),
                (true, false, 111),
                (false, true, 256),
            ] {
                let blocksize = elements * typesize;
                let frame = blosc_encode(&data, typesize, blocksize, compress, memcpy);
                let out = unblosc(&frame, data.len())
                    .unwrap_or_else(|e| panic!("{typesize} {compress} {memcpy} {blocksize}: {e}"));
                assert_eq!(out, data);
            }
        }
        // Blocks kept whole although c-blosc's rule would split them.
        for compress in [true, false] {
            let frame = encode(&data, 4, 1024, compress, false, true);
            assert_eq!(unblosc(&frame, data.len()).unwrap(), data);
        }
        // The flag is honoured: the same streams read as split are wrong.
        let mut frame = blosc_encode(&data, 4, 1024, true, false);
        frame[2] |= DONT_SPLIT;
        assert!(unblosc(&frame, data.len()).is_err());
        // Without the shuffle flag (or with one-byte types) the bytes stay as stored.
        let mut frame = blosc_encode(&data, 4, 1024, true, false);
        frame[2] &= !DOSHUFFLE;
        let stored: Vec<u8> = data.chunks(1024).flat_map(|b| shuffle(b, 4)).collect();
        assert_eq!(unblosc(&frame, data.len()).unwrap(), stored);
        let frame = blosc_encode(&data, 1, 1024, true, false);
        assert_eq!(unblosc(&frame, data.len()).unwrap(), data);
    }

    #[test]
    fn corrupt_frames_are_errors() {
        let data = sample_data(3000);
        let frame = blosc_encode(&data, 4, 1024, true, false);
        assert_eq!(unblosc(&frame, 3000).unwrap(), data);
        assert!(unblosc(&frame, 2999).is_err());
        assert!(unblosc(&frame[..frame.len() - 1], 3000).is_err());
        let mut zstd = frame.clone();
        zstd[2] = (4 << 5) | DOSHUFFLE;
        let err = unblosc(&zstd, 3000).unwrap_err().0;
        assert!(err.contains("zstd") && err.contains("LZ4"), "{err}");
        zstd[2] = (6 << 5) | DOSHUFFLE;
        assert!(unblosc(&zstd, 3000).unwrap_err().0.contains("code 6"));
        let mut bits = frame.clone();
        bits[2] |= DOBITSHUFFLE;
        assert!(unblosc(&bits, 3000).unwrap_err().0.contains("bit shuffle"));
        let mut typeless = frame.clone();
        typeless[3] = 0;
        assert!(unblosc(&typeless, 3000)
            .unwrap_err()
            .0
            .contains("type size 0"));
        // A block starting inside the start table, or before the frame.
        for start in [4i32, -4] {
            let mut bad = frame.clone();
            bad[20..24].copy_from_slice(&start.to_le_bytes());
            let err = unblosc(&bad, 3000).unwrap_err().0;
            assert!(err.contains(&format!("block 1 starts at {start}")), "{err}");
        }
        // More blocks than the frame has room to list.
        let mut tiny = frame.clone();
        tiny[8..12].copy_from_slice(&1u32.to_le_bytes());
        assert!(unblosc(&tiny, 3000).unwrap_err().0.contains("start table"));
        // A frame too small for the bytes it claims is refused before allocating them.
        let mut huge = frame[..64].to_vec();
        huge[4..8].copy_from_slice(&u32::MAX.to_le_bytes());
        huge[12..16].copy_from_slice(&64u32.to_le_bytes());
        let err = unblosc(&huge, u32::MAX as usize).unwrap_err().0;
        assert!(err.contains("cannot hold"), "{err}");
        for pos in 0..frame.len() {
            let mut bad = frame.clone();
            bad[pos] ^= 0x5a;
            // Must not panic; may decode (to wrong bytes) or fail.
            let _ = unblosc(&bad, 3000);
        }
    }

    #[test]
    fn zlib_streams_decode_to_their_exact_size() {
        let data = sample_data(10_000);
        let packed = miniz_oxide::deflate::compress_to_vec_zlib(&data, 6);
        assert_eq!(inflate_zlib(&packed, data.len()).unwrap(), data);
        let err = inflate_zlib(&packed, data.len() + 1).unwrap_err().0;
        assert!(err.contains("holds 10000 bytes, expected 10001"), "{err}");
        let err = inflate_zlib(&packed, data.len() - 1).unwrap_err().0;
        assert!(err.contains("exceeds 9999 bytes"), "{err}");
        assert!(inflate_zlib(&packed[..packed.len() / 2], data.len()).is_err());
        assert!(inflate_zlib(&[0; 4], 10).is_err());
        // Zeros compress past 1000:1 and still decode.
        let zeros = vec![0u8; 1 << 20];
        let packed = miniz_oxide::deflate::compress_to_vec_zlib(&zeros, 9);
        assert_eq!(inflate_zlib(&packed, zeros.len()).unwrap(), zeros);
        // A tiny stream claiming a huge output is refused before any allocation.
        let err = inflate_zlib(&[0x78, 0x9c, 3, 0, 0, 0, 0, 1, 0, 0], 1 << 30)
            .unwrap_err()
            .0;
        assert!(err.contains("cannot hold"), "{err}");
    }
}
