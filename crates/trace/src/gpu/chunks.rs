//! Arrays above the device's storage-binding limit, split into the chunks that the WGSL
//! composer's `#chunked` declarations read ([`super::compose::ChunkedArray`]): the volume
//! atlas and every array of a scene.

use super::compose::{chunk_constant, ChunkedArray, CHUNKS};
use super::context::{GpuContext, GpuError};

/// One array a kernel reads through its `#chunked` declaration: the declared name, the
/// feature that splits it, the size of its elements and its bytes.
pub(super) struct NamedArray {
    /// The name in its `#chunked` line.
    pub name: &'static str,
    /// `chunked_` and the name.
    pub feature: &'static str,
    /// Bytes per element.
    pub element: usize,
    /// The array's bytes (at least one element: a binding cannot be empty).
    pub bytes: Vec<u8>,
}

/// The size of one element of `items` (which may be empty).
pub(super) fn element_size<T>(_: &[T]) -> usize {
    size_of::<T>()
}

/// The [`NamedArray`] of `items` (a slice of POD records) declared as `#chunked $name`.
macro_rules! named_array {
    ($name:literal, $items:expr) => {{
        let items = $items;
        $crate::gpu::chunks::NamedArray {
            name: $name,
            feature: concat!("chunked_", $name),
            element: $crate::gpu::chunks::element_size(items),
            bytes: $crate::gpu::tracer::binding_bytes(items),
        }
    }};
}
pub(super) use named_array;

/// Arrays uploaded to the bindings their `#chunked` lines declare, each split over four
/// buffers above the device's binding limit (or when [`GpuContext::split_arrays`] names it).
pub(super) struct ChunkedUpload {
    /// The buffers, in the order of `bindings`.
    pub buffers: Vec<wgpu::Buffer>,
    /// The binding of each buffer.
    pub bindings: Vec<u32>,
    /// `chunked_ARRAY` for each array split.
    pub features: Vec<&'static str>,
    /// The chunk-length constants of the arrays split.
    pub constants: Vec<(String, f64)>,
}

impl ChunkedUpload {
    /// Uploads `arrays`; one without a `#chunked` declaration is a [`GpuError::Shader`], one
    /// beyond four buffers a [`GpuError::SceneTooBig`] naming it.
    pub fn new(ctx: &GpuContext, arrays: Vec<NamedArray>) -> Result<ChunkedUpload, GpuError> {
        let limit = ctx.limits.max_storage_buffer_binding_size;
        let mut upload = ChunkedUpload {
            buffers: Vec::new(),
            bindings: Vec::new(),
            features: Vec::new(),
            constants: Vec::new(),
        };
        let mut bytes = Vec::new();
        for a in arrays {
            let declared = ChunkedArray::declared(a.name).ok_or_else(|| GpuError::Shader {
                name: a.name.to_string(),
                problem: format!("no `#chunked` declaration of the array `{}`", a.name),
            })?;
            let always = ctx.split_arrays.iter().any(|s| s == a.name);
            let split = chunk(a.name, a.bytes, a.element, limit, always)?;
            if let Some(c) = split.constant(a.name) {
                upload.features.push(a.feature);
                upload.constants.push(c);
            }
            upload
                .bindings
                .extend(declared.bindings(split.buffers.len()));
            bytes.extend(split.buffers.into_iter().map(|b| (a.name, b)));
        }
        upload.buffers = ctx.storage_buffers(&bytes)?;
        Ok(upload)
    }

    /// The bind group entries of the buffers.
    pub fn entries(&self) -> Vec<wgpu::BindGroupEntry<'_>> {
        (self.bindings.iter().zip(&self.buffers))
            .map(|(&binding, b)| wgpu::BindGroupEntry {
                binding,
                resource: b.as_entire_binding(),
            })
            .collect()
    }
}

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
/// `limit`, split only above it unless `always` (then an array within the limit is split in
/// [`CHUNKS`] nearly equal chunks); more than [`chunked_capacity`] is a
/// [`GpuError::SceneTooBig`] naming it.
pub(super) fn chunk(
    name: &str,
    bytes: Vec<u8>,
    element: usize,
    limit: u64,
    always: bool,
) -> Result<Chunked, GpuError> {
    let within = bytes.len() as u64 <= limit;
    if within && !always {
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
    let len = if within {
        (bytes.len().div_ceil(element) as u64).div_ceil(CHUNKS as u64)
    } else {
        chunk_len(element, limit)
    };
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
        let whole = chunk("a", bytes.clone(), 4, 256, false).unwrap();
        assert_eq!((whole.buffers.len(), whole.len), (1, None));
        // Split although within the limit: 64 elements in four chunks of 16.
        let forced = chunk("a", bytes.clone(), 4, 256, true).unwrap();
        assert_eq!(forced.len, Some(16));
        assert_eq!(forced.buffers.concat(), bytes);
        // 3 elements in chunks of 1: the fourth chunk is one unused element.
        let few = chunk("a", vec![7; 12], 4, 256, true).unwrap();
        assert_eq!(few.len, Some(1));
        assert_eq!(few.buffers.concat()[..12], [7; 12]);
        // 48-byte elements under a 100-byte limit: chunks of 2 elements; 256 bytes need 3.
        let split = chunk("a", bytes.clone(), 48, 100, false).unwrap();
        assert_eq!(split.len, Some(2));
        assert_eq!(split.buffers.len(), CHUNKS);
        assert_eq!(split.buffers[..3].concat(), bytes);
        assert!(split.buffers[..2].iter().all(|b| b.len() == 96));
        assert_eq!(chunked_capacity(48, 100), 4 * 96);
        let err = chunk("big", vec![0; 4 * 96 + 1], 48, 100, true)
            .err()
            .unwrap();
        assert!(
            err.to_string().contains("array `big` has 385 bytes"),
            "{err}"
        );
    }
}
