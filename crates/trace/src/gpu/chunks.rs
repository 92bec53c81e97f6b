//! Arrays above the device's storage-binding limit, split into the chunks that the WGSL
//! composer's `#chunked` declarations read ([`super::compose`]): the volume atlas, a mesh's
//! nodes and triangles.

use super::compose::{chunk_constant, CHUNKS};
use super::context::GpuError;

/// An array's bytes as the buffers a kernel binds for it: one buffer when it fits the
/// binding limit, else [`CHUNKS`] chunks of `len` elements (the last ones shorter, unused
/// ones one zeroed element).
pub(super) struct Chunked {
    /// The buffers' bytes, in binding order.
    pub buffers: Vec<Vec<u8>>,
    /// Elements per chunk, when the array is split.
    pub len: Option<u32>,
}

/// Elements of `element` bytes per chunk under binding limit `limit` (at most 2^30, so
/// that the elements of all chunks have u32 indices).
fn chunk_len(element: usize, limit: u64) -> u64 {
    (limit / element as u64).clamp(1, 1 << 30)
}

/// Bytes an array of `element`-byte elements may hold once split, on a device with binding
/// limit `limit`.
pub(super) fn chunked_capacity(element: usize, limit: u64) -> u64 {
    CHUNKS as u64 * element as u64 * chunk_len(element, limit)
}

/// The buffers of array `name` (`bytes`, elements of `element` bytes) under binding limit
/// `limit`; more than [`chunked_capacity`] is a [`GpuError::SceneTooBig`] naming it.
pub(super) fn chunk(
    name: &str,
    bytes: Vec<u8>,
    element: usize,
    limit: u64,
) -> Result<Chunked, GpuError> {
    if bytes.len() as u64 <= limit {
        return Ok(Chunked {
            buffers: vec![bytes],
            len: None,
        });
    }
    if bytes.len() as u64 > chunked_capacity(element, limit) {
        return Err(GpuError::SceneTooBig(format!(
            "array `{name}` has {} bytes, more than the {} bytes of the {CHUNKS} storage \
             buffers the device can bind for it",
            bytes.len(),
            chunked_capacity(element, limit)
        )));
    }
    let len = chunk_len(element, limit);
    let mut buffers: Vec<Vec<u8>> = bytes
        .chunks(element * len as usize)
        .map(<[u8]>::to_vec)
        .collect();
    buffers.resize(CHUNKS, vec![0; element.max(16)]);
    Ok(Chunked {
        buffers,
        len: Some(len as u32),
    })
}

impl Chunked {
    /// The pipeline constant of the array's `#chunked` line naming it `array`, when split.
    pub fn constant(&self, array: &str) -> Option<(String, f64)> {
        self.len.map(|l| (chunk_constant(array), f64::from(l)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arrays_split_only_above_the_limit_into_whole_elements() {
        let bytes: Vec<u8> = (0..=255).collect();
        let whole = chunk("a", bytes.clone(), 4, 256).unwrap();
        assert_eq!((whole.buffers.len(), whole.len), (1, None));
        // 48-byte elements under a 100-byte limit: chunks of 2 elements; 256 bytes need 3.
        let split = chunk("a", bytes.clone(), 48, 100).unwrap();
        assert_eq!(split.len, Some(2));
        assert_eq!(split.buffers.len(), CHUNKS);
        assert_eq!(split.buffers[..3].concat(), bytes);
        assert!(split.buffers[..2].iter().all(|b| b.len() == 96));
        assert_eq!(chunked_capacity(48, 100), 4 * 96);
        let err = chunk("big", vec![0; 4 * 96 + 1], 48, 100).err().unwrap();
        assert!(
            err.to_string().contains("array `big` has 385 bytes"),
            "{err}"
        );
    }
}
