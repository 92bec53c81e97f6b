//! A bricked grid's atlas as a 3D texture, the other place the volume kernels read texels
//! from (composition feature `atlas_texture`, `shaders/volume/grid.wgsl`): one 8^3 block of
//! texels per atlas slot, the slots laid out x fastest in a box of bricks, read with
//! `textureLoad` (never filtered, as the CPU reads them). Formats: R8Unorm and R16Unorm
//! (the code read back exactly as `round(value * (2^bits - 1))`), R16Float, R32Float, and
//! BC4 (`Bc4RUnorm`, sliced 3D), which the device decodes itself: its palette may round
//! differently from the CPU's (within one code unit), the accuracy this path trades.

use hytrace_volume::{BrickedGrid, TexelFormat};

use super::context::{GpuContext, GpuError};

/// Where the volume kernels read a bricked grid's texels from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TexelStore {
    /// A storage buffer of words, decoded by the kernel (every format, bit for bit the
    /// CPU's).
    #[default]
    Storage,
    /// A 3D texture of the format's own texture format.
    Texture,
}

crate::choice::named!(TexelStore {
    (TexelStore::Storage, "storage", [], "A storage buffer of words, decoded by the kernel (every format, bit for bit the CPU's)"),
    (TexelStore::Texture, "texture", [], "A 3D texture of the format's own texture format"),
});

/// Binding (group 0) of the texels' 3D texture (`shaders/volume/bindings.wgsl`).
pub(super) const ATLAS_TEXTURE_BINDING: u32 = 8;

/// The layout entry of a 3D texture of floats read with `textureLoad` at `binding`.
pub(super) fn texture_layout_entry(binding: u32) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable: false },
            view_dimension: wgpu::TextureViewDimension::D3,
            multisampled: false,
        },
        count: None,
    }
}

/// The texture format holding `format`'s texels, and the device features it needs.
pub fn texture_format(format: TexelFormat) -> (wgpu::TextureFormat, wgpu::Features) {
    match format {
        TexelFormat::Bc4 => (
            wgpu::TextureFormat::Bc4RUnorm,
            wgpu::Features::TEXTURE_COMPRESSION_BC
                | wgpu::Features::TEXTURE_COMPRESSION_BC_SLICED_3D,
        ),
        TexelFormat::Unorm8 => (wgpu::TextureFormat::R8Unorm, wgpu::Features::empty()),
        TexelFormat::Unorm16 => (
            wgpu::TextureFormat::R16Unorm,
            wgpu::Features::TEXTURE_FORMAT_16BIT_NORM,
        ),
        TexelFormat::F16 => (wgpu::TextureFormat::R16Float, wgpu::Features::empty()),
        TexelFormat::F32 => (wgpu::TextureFormat::R32Float, wgpu::Features::empty()),
    }
}

/// Bricks along x, y and z of a texture holding `slots` bricks when a side may hold at most
/// `max_bricks`; `None` when they do not fit.
fn brick_box(slots: usize, max_bricks: usize) -> Option<[usize; 3]> {
    let slots = slots.max(1);
    let x = slots.min(max_bricks);
    let y = slots.div_ceil(x).min(max_bricks);
    let z = slots.div_ceil(x * y);
    (z <= max_bricks).then_some([x, y, z])
}

/// The atlases of `grids` (one format), slot after slot, rearranged in texture order for a
/// box of `bricks`: for uncompressed formats rows of texels; for BC4 rows of 4x4 blocks (the
/// atlas keeps each brick's slice as four blocks, by block row then column). Returns the
/// bytes, the bytes per row and the rows per z slice.
fn texture_bytes(grids: &[&BrickedGrid], bricks: [usize; 3]) -> (Vec<u8>, usize, usize) {
    let format = grids[0].format();
    let slot_bytes = format.bytes_per_brick();
    let [bx, by, bz] = bricks;
    // Units of a row and their bytes: texels, or BC4 blocks of 4x4 texels.
    let (unit, unit_bytes) = match format {
        TexelFormat::Bc4 => (4, 8),
        _ => (1, format.bits_per_voxel() as usize / 8),
    };
    let per_brick = 8 / unit;
    let row_bytes = bx * per_brick * unit_bytes;
    let rows = by * per_brick;
    let mut out = vec![0u8; row_bytes * rows * bz * 8];
    let slots = grids
        .iter()
        .flat_map(|g| g.atlas().chunks_exact(slot_bytes));
    for (slot, texels) in slots.enumerate() {
        let brick = [slot % bx, (slot / bx) % by, slot / (bx * by)];
        for z in 0..8 {
            for row in 0..per_brick {
                // The slot's row `row` of slice `z`: `per_brick` units.
                let from = (z * per_brick + row) * per_brick * unit_bytes;
                let (tz, trow) = (brick[2] * 8 + z, brick[1] * per_brick + row);
                let to = (tz * rows + trow) * row_bytes + brick[0] * per_brick * unit_bytes;
                let n = per_brick * unit_bytes;
                out[to..to + n].copy_from_slice(&texels[from..from + n]);
            }
        }
    }
    (out, row_bytes, rows)
}

/// Uploads the atlases of `grids` as one 3D texture, the slots of each grid after those of
/// the grids before (a grid's first slot is its `atlas_base`). Grids of several formats, a
/// device without the format's features, or atlases beyond the device's largest 3D texture,
/// are a [`GpuError::SceneTooBig`].
pub(super) fn atlas_texture(
    ctx: &GpuContext,
    grids: &[&BrickedGrid],
) -> Result<wgpu::TextureView, GpuError> {
    let Some(first) = grids.first() else {
        return Err(GpuError::SceneTooBig(
            "texels in a 3D texture need a grid".to_string(),
        ));
    };
    if let Some(other) = grids.iter().find(|g| g.format() != first.format()) {
        return Err(GpuError::SceneTooBig(format!(
            "texels in one 3D texture need grids of one texel format, not {} and {}",
            first.format(),
            other.format()
        )));
    }
    let (format, needs) = texture_format(first.format());
    if !ctx.device.features().contains(needs) {
        return Err(GpuError::SceneTooBig(format!(
            "{} texels in a 3D texture need the device features {needs:?}, which it lacks",
            first.format()
        )));
    }
    let max_bricks = ctx.limits.max_texture_dimension_3d as usize / 8;
    let slots: usize = grids.iter().map(|g| g.atlas_slots()).sum();
    let bricks = brick_box(slots, max_bricks).ok_or_else(|| {
        GpuError::SceneTooBig(format!(
            "{slots} bricks do not fit a 3D texture of at most {} texels a side",
            ctx.limits.max_texture_dimension_3d
        ))
    })?;
    let (bytes, row_bytes, rows) = texture_bytes(grids, bricks);
    let size = wgpu::Extent3d {
        width: (bricks[0] * 8) as u32,
        height: (bricks[1] * 8) as u32,
        depth_or_array_layers: (bricks[2] * 8) as u32,
    };
    ctx.checked("uploading the atlas texture", || {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("volume atlas texture"),
            size,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        ctx.queue.write_texture(
            texture.as_image_copy(),
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row_bytes as u32),
                rows_per_image: Some(rows as u32),
            },
            size,
        );
        texture.create_view(&Default::default())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brick_boxes_hold_every_slot_within_the_side_limit() {
        for (slots, max) in [(1, 4), (5, 4), (16, 4), (17, 4), (64, 4), (0, 2), (1, 1)] {
            let b = brick_box(slots, max).unwrap();
            assert!(
                b.iter().all(|&s| (1..=max).contains(&s)),
                "{slots} {max}: {b:?}"
            );
            assert!(b[0] * b[1] * b[2] >= slots, "{slots} {max}: {b:?}");
        }
        assert_eq!(brick_box(65, 4), None);
        assert_eq!(brick_box(2, 1), None);
    }
}
