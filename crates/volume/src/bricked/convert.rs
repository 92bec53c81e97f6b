//! Building a [`BrickedGrid`] from any voxel source.

use rayon::prelude::*;

use super::quantize::{self, VOXELS};
use super::{BrickEntry, BrickedGrid, TexelFormat, NO_BRICK, NO_SLOT};
use crate::dense::VolumeError;
use crate::grid::{Coord, VoxelGrid, BLOCK_SIDE};
use crate::ranges::{RangeMips, MAX_RANGE_BLOCKS};

/// Bricks encoded by one parallel task.
const CHUNK_BRICKS: usize = 64;

/// The encoded bricks of one chunk, with slots numbered from 0 within the chunk.
struct Chunk {
    entries: Vec<BrickEntry>,
    atlas: Vec<u8>,
    slots: u32,
    max_error: f64,
    bound: f64,
}

/// `x` rounded up to an f32.
fn f32_up(x: f64) -> f32 {
    let f = x as f32;
    if f64::from(f) < x {
        f.next_up()
    } else {
        f
    }
}

fn encode_chunk<G: VoxelGrid + ?Sized>(
    grid: &G,
    format: TexelFormat,
    origins: &[Coord],
) -> Result<Chunk, VolumeError> {
    let background = grid.background();
    let mut chunk = Chunk {
        entries: Vec::new(),
        atlas: Vec::new(),
        slots: 0,
        max_error: 0.0,
        bound: 0.0,
    };
    let side = BLOCK_SIDE as u32;
    let mut values = [0f32; VOXELS];
    for &origin in origins {
        grid.read_box(origin, [side; 3], &mut values);
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            let at = [i % 8, i / 8 % 8, i / 64].map(|c| c as i32);
            return Err(VolumeError(format!(
                "voxel {:?} of the brick at {origin:?} is {}: only finite values can be bricked",
                std::array::from_fn::<i32, 3, _>(|k| origin[k] + at[k]),
                values[i]
            )));
        }
        if values.iter().all(|v| *v == background) {
            continue;
        }
        let encoded = quantize::encode(format, &values, &mut chunk.atlas)
            .map_err(|problem| VolumeError(format!("brick at {origin:?} ({format}): {problem}")))?;
        let atlas_slot = if encoded.texels {
            chunk.slots += 1;
            chunk.slots - 1
        } else {
            NO_SLOT
        };
        chunk.entries.push(BrickEntry {
            origin,
            atlas_slot,
            offset: encoded.offset,
            scale: encoded.scale,
            active_voxels: values.iter().filter(|v| **v != background).count() as u32,
            max_error: f32_up(encoded.max_error),
        });
        chunk.max_error = chunk.max_error.max(encoded.max_error);
        chunk.bound = chunk.bound.max(encoded.bound);
    }
    Ok(chunk)
}

impl BrickedGrid {
    /// Converts `grid` into bricks of `format`.
    ///
    /// The bricks are the source's blocks ([`VoxelGrid::block_origins`], multiples of 8, read
    /// with [`VoxelGrid::read_box`]) whose voxels are not all the background. Each brick is
    /// quantized relative to its own `[min, max]` (see [`BrickedGrid::analytic_error_bound`]);
    /// a brick whose voxels are all equal stores no texels. Errors on non-finite voxels (naming
    /// the brick), on f16 values beyond its range, on ranges whose f32 decode would overflow
    /// and on an indirection box of more than [`MAX_RANGE_BLOCKS`] bricks.
    ///
    /// Bricks are encoded in parallel, in chunks of consecutive bricks (z, y, x order); each
    /// chunk numbers its atlas slots from 0 and the merge offsets them by the slots of the
    /// chunks before it (a prefix sum). Unlike Falcor's atomic slot counter this makes the
    /// output independent of thread scheduling: the same input gives byte-identical arrays.
    pub fn convert<G: VoxelGrid + ?Sized>(
        grid: &G,
        format: TexelFormat,
    ) -> Result<BrickedGrid, VolumeError> {
        let background = grid.background();
        if !background.is_finite() {
            return Err(VolumeError(format!(
                "the background is {background}: only finite values can be bricked"
            )));
        }
        let mut origins = grid.block_origins()?;
        if let Some(o) = origins
            .iter()
            .find(|o| o.iter().any(|c| c % BLOCK_SIDE != 0))
        {
            return Err(VolumeError(format!(
                "block origin {o:?} is not a multiple of {BLOCK_SIDE}"
            )));
        }
        origins.sort_unstable_by_key(|o| [o[2], o[1], o[0]]);
        origins.dedup();
        let chunks: Vec<Chunk> = origins
            .par_chunks(CHUNK_BRICKS)
            .map(|c| encode_chunk(grid, format, c))
            .collect::<Result<_, _>>()?;

        // Merge in brick order: slots offset by the slots of the chunks before.
        let atlas_len = chunks.iter().map(|c| c.atlas.len()).sum();
        let mut atlas = Vec::with_capacity(atlas_len);
        let mut table = Vec::with_capacity(chunks.iter().map(|c| c.entries.len()).sum());
        let (mut slots, mut max_error, mut analytic_bound) = (0u32, 0.0f64, 0.0f64);
        for c in chunks {
            table.extend(c.entries.into_iter().map(|e| BrickEntry {
                atlas_slot: if e.atlas_slot == NO_SLOT {
                    NO_SLOT
                } else {
                    e.atlas_slot + slots
                },
                ..e
            }));
            atlas.extend_from_slice(&c.atlas);
            slots += c.slots;
            max_error = max_error.max(c.max_error);
            analytic_bound = analytic_bound.max(c.bound);
        }

        // The dense indirection box over the stored bricks.
        let bricks: Vec<Coord> = table.iter().map(|e| e.origin.map(|c| c >> 3)).collect();
        let lo: Coord = std::array::from_fn(|k| bricks.iter().map(|b| b[k]).min().unwrap_or(0));
        let dims: [u64; 3] = std::array::from_fn(|k| {
            bricks
                .iter()
                .map(|b| (i64::from(b[k]) - i64::from(lo[k]) + 1) as u64)
                .max()
                .unwrap_or(0)
        });
        let count = dims.iter().product::<u64>();
        if count > MAX_RANGE_BLOCKS {
            return Err(VolumeError(format!(
                "the stored bricks span a box of {dims:?} bricks, more than {MAX_RANGE_BLOCKS}"
            )));
        }
        let dims = dims.map(|d| d as u32);
        let mut indirection = vec![NO_BRICK; count as usize];
        for (i, b) in bricks.iter().enumerate() {
            let local: [usize; 3] = std::array::from_fn(|k| (b[k] - lo[k]) as usize);
            let slot = local[0] + dims[0] as usize * (local[1] + dims[1] as usize * local[2]);
            indirection[slot] = i as u32;
        }

        let mut out = BrickedGrid {
            format,
            background,
            map: *grid.map(),
            lo,
            dims,
            indirection,
            table,
            atlas,
            ranges: RangeMips {
                background,
                levels: Vec::new(),
            },
            max_error,
            analytic_bound,
        };
        // Ranges of what lookups on this representation read: the decoded values.
        out.ranges = RangeMips::build(&out)?;
        Ok(out)
    }
}
