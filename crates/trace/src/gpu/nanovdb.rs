//! Raw NanoVDB grids on the GPU: the checks a grid passes before its buffer is uploaded, as
//! it is, for `shaders/volume/nanovdb.wgsl` (words of the volume atlas, byte offsets of
//! NanoVDB's layout read as u32), and a probe that reads voxels through that lookup. The
//! transmittance kernel reads the same buffers ([`super::GpuVolume::nanovdb`]).

use bytemuck::Zeroable;
use hytrace_volume::{NanoGrid, NanoGridType};

use super::context::{GpuContext, GpuError};
use super::oneshot::{run, Buffer};
use super::records::{VolumeParams, VOLUME_FORMAT_NANOVDB};

/// Grid types the WGSL lookup decodes (f32 values, and codes quantized per leaf).
pub const GPU_NANOVDB_TYPES: [NanoGridType; 5] = [
    NanoGridType::Float,
    NanoGridType::Fp4,
    NanoGridType::Fp8,
    NanoGridType::Fp16,
    NanoGridType::FpN,
];

/// Largest grid buffer the lookup addresses: its byte offsets are u32.
pub const MAX_GPU_NANOVDB_BYTES: u64 = 1 << 32;

/// Why a NanoVDB grid was not read on the GPU.
#[derive(Debug, thiserror::Error)]
pub enum NanoGpuError {
    /// The grid cannot be read by the lookup (its type, its size); nothing was uploaded.
    #[error("NanoVDB grid {number} '{name}' cannot be read on the GPU: {reason}")]
    Refused {
        /// The grid's position in its file.
        number: usize,
        /// The grid's name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// The GPU failed.
    #[error(transparent)]
    Gpu(#[from] GpuError),
}

/// The bytes of `grid` to upload for the lookup, after checking that it can read them: a
/// validated grid of a type in [`GPU_NANOVDB_TYPES`], a whole number of words, at most
/// [`MAX_GPU_NANOVDB_BYTES`] and at most `max_bytes` (what the device can bind for it: its
/// storage-buffer binding limit, or the capacity of the split volume atlas).
pub fn nanovdb_gpu_bytes(grid: &NanoGrid, max_bytes: u64) -> Result<&[u8], NanoGpuError> {
    let refuse = |reason: String| NanoGpuError::Refused {
        number: grid.number(),
        name: grid.name().to_string(),
        reason,
    };
    let grid_type = grid.grid_type();
    if !GPU_NANOVDB_TYPES.contains(&grid_type) || !grid.is_sampleable() {
        return Err(refuse(format!(
            "values of type {grid_type} (the GPU reads float, Fp4, Fp8, Fp16 and FpN grids)"
        )));
    }
    let bytes = grid.buffer();
    let len = bytes.len() as u64;
    if !len.is_multiple_of(4) {
        return Err(refuse(format!(
            "its buffer of {len} bytes is not a whole number of 4-byte words"
        )));
    }
    if len > MAX_GPU_NANOVDB_BYTES {
        return Err(refuse(format!(
            "its buffer of {len} bytes has offsets beyond 2^32 bytes, which the GPU lookup cannot address"
        )));
    }
    if len > max_bytes {
        return Err(refuse(format!(
            "its buffer of {len} bytes exceeds the {max_bytes} bytes the device can bind for it"
        )));
    }
    Ok(bytes)
}

/// Values of the voxels `points` of `grid` read on the GPU by `nanovdb_voxel` (kernel
/// `shaders/kernels/nanovdb_probe.wgsl`), in order; the grid is checked by
/// [`nanovdb_gpu_bytes`] against the device's limit before anything is uploaded.
pub fn probe_nanovdb(
    ctx: &GpuContext,
    grid: &NanoGrid,
    points: &[[i32; 3]],
) -> Result<Vec<f32>, NanoGpuError> {
    let bytes = nanovdb_gpu_bytes(grid, ctx.limits.max_storage_buffer_binding_size)?;
    let count = u32::try_from(points.len())
        .map_err(|_| GpuError::SceneTooBig(format!("{} probe points", points.len())))?;
    let items: Vec<i32> = points.iter().flat_map(|p| [p[0], p[1], p[2], 0]).collect();
    // The grid alone in the atlas, untranslated.
    let mut params = VolumeParams::zeroed();
    params.format = VOLUME_FORMAT_NANOVDB;
    params.nanovdb_words = (bytes.len() / 4) as u32;
    let out = run(
        ctx,
        "kernels/nanovdb_probe",
        "nanovdb_probe",
        count,
        &[
            vec![
                Buffer::Input(bytemuck::bytes_of(&params)),
                Buffer::Input(&[]),
                Buffer::Input(&[]),
                Buffer::Input(&[]),
                Buffer::Input(bytes),
            ],
            vec![
                Buffer::Input(bytemuck::cast_slice(&items)),
                Buffer::Output(4 * u64::from(count)),
            ],
        ],
    )?;
    Ok(bytemuck::cast_slice::<u8, u32>(&out[0])
        .iter()
        .map(|b| f32::from_bits(*b))
        .collect())
}
