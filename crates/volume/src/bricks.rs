//! Foundry brick records of a bricked grid or a brick store: the bounds and majorants the tracers build their
//! acceleration structures from.

use hytrace_foundry::{Brick, UNSET};

use crate::brick_store::BrickStore;
use crate::bricked::{BrickedGrid, NO_SLOT};
use crate::grid::{Coord, VoxelGrid, BLOCK_SIDE};
use crate::ranges::RangeMips;

impl BrickedGrid {
    /// One Foundry brick per 8^3 block whose level-0 range is not the constant background,
    /// in z, y, x order.
    ///
    /// A brick covers voxels `origin .. origin + 8` on each axis and bounds `[origin - 0.5,
    /// origin + 7.5]` in index space. A lookup anywhere in those bounds reads voxels
    /// `origin - 1 ..= origin + 8`, and `value_min`/`value_max` are the level-0 range of the
    /// decoded values over that halo-inclusive block, so `value_max` is a majorant of every
    /// lookup in the brick, also for bricks of background voxels next to data (those are not
    /// stored: `atlas_slot` unset, no active voxels). `atlas_slot` is the brick's slot in
    /// [`BrickedGrid::atlas`] (unset, [`NO_SLOT`], for constant bricks); `prim` is set when
    /// the bricks are added to a Foundry.
    pub fn foundry_bricks(&self) -> Vec<Brick> {
        block_bricks(self.ranges(), self.background(), |block| {
            self.entry(block)
                .map_or((NO_SLOT, 0), |e| (e.atlas_slot, e.active_voxels))
        })
    }
}

impl BrickStore {
    /// The Foundry bricks of the store, as [`BrickedGrid::foundry_bricks`] makes them from
    /// its range mips (which equal those of the store bricked in memory): no brick is read.
    /// `atlas_slot` is a kept brick's record in the store ([`NO_SLOT`] for the others);
    /// `active_voxels` is 0, the store does not count them.
    pub fn foundry_bricks(&self) -> Vec<Brick> {
        let origin = self.meta().index_origin;
        block_bricks(self.mips(), self.background(), |block| {
            let v = std::array::from_fn(|k| i64::from(block[k] * BLOCK_SIDE - origin[k]));
            (self.record_of(v).unwrap_or(NO_SLOT), 0)
        })
    }
}

/// The Foundry bricks of the blocks whose level-0 range in `mips` is not the constant
/// `background`; `texels` gives a block's atlas slot and active voxels.
fn block_bricks(
    mips: &RangeMips,
    background: f32,
    texels: impl Fn(Coord) -> (u32, u32),
) -> Vec<Brick> {
    let level = &mips.levels[0];
    let [nx, ny, _] = level.dims.map(|d| d as usize);
    let side = BLOCK_SIDE as f32;
    let mut out = Vec::new();
    for (i, range) in level.ranges.iter().enumerate() {
        if range.is_constant(background) {
            continue;
        }
        let local = [i % nx, i / nx % ny, i / (nx * ny)];
        let block = std::array::from_fn(|k| level.lo[k] + local[k] as i32);
        let origin = block.map(|c| c * BLOCK_SIDE);
        let (atlas_slot, active_voxels) = texels(block);
        let lo = origin.map(|c| c as f32 - 0.5);
        out.push(Brick {
            origin,
            level: 0,
            atlas_slot,
            prim: UNSET,
            value_min: range.min,
            value_max: range.max,
            aabb: [
                lo[0],
                lo[1],
                lo[2],
                lo[0] + side,
                lo[1] + side,
                lo[2] + side,
            ],
            active_voxels,
            size: BLOCK_SIDE as u32,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{fog_sphere, sample_trilinear, DenseGrid, Rng, TexelFormat};

    /// The next uniform number in [0, 1) of `state` (the crate's counter-based generator).
    fn rng(state: &mut Rng) -> f64 {
        state.next_f64()
    }

    fn contains(b: &Brick, p: [f64; 3]) -> bool {
        (0..3).all(|k| p[k] >= b.aabb[k] as f64 && p[k] <= b.aabb[k + 3] as f64)
    }

    fn foundry_bricks(g: &DenseGrid, format: TexelFormat) -> (BrickedGrid, Vec<Brick>) {
        let bricked = BrickedGrid::convert(g, format).unwrap();
        let bricks = bricked.foundry_bricks();
        (bricked, bricks)
    }

    #[test]
    fn halo_ranges_bound_every_trilinear_lookup() {
        let mut state = Rng::new(3, 0, 0);
        // Negative origin, sides that are not multiples of 8, random values.
        let mut g = DenseGrid::new([-13, -8, 5], [21, 16, 11], 0.0).unwrap();
        for v in g.values.iter_mut() {
            *v = if rng(&mut state) < 0.3 {
                0.0
            } else {
                (rng(&mut state) * 4.0 - 1.0) as f32
            };
        }
        for format in [TexelFormat::F32, TexelFormat::Bc4] {
            let (bricked, bricks) = foundry_bricks(&g, format);
            for b in &bricks {
                assert_eq!(b.origin.map(|c| c.rem_euclid(BLOCK_SIDE)), [0; 3]);
                for _ in 0..300 {
                    let p: [f64; 3] = std::array::from_fn(|k| {
                        b.aabb[k] as f64 + rng(&mut state) * BLOCK_SIDE as f64
                    });
                    let v = sample_trilinear(&bricked, p);
                    assert!(
                        v >= b.value_min as f64 - 1e-6 && v <= b.value_max as f64 + 1e-6,
                        "{format}: {v} outside {}..{} at {p:?}",
                        b.value_min,
                        b.value_max
                    );
                }
            }
            // Outside every brick, lookups return the background.
            for _ in 0..20_000 {
                let p: [f64; 3] = std::array::from_fn(|k| {
                    g.origin[k] as f64 - 12.0 + rng(&mut state) * (g.dims[k] as f64 + 24.0)
                });
                if !bricks.iter().any(|b| contains(b, p)) {
                    assert_eq!(sample_trilinear(&bricked, p), 0.0, "{p:?}");
                }
            }
        }
    }

    #[test]
    fn no_voxel_lost_at_multiples_of_eight() {
        // A grid whose extent ends exactly on a brick boundary (max = 0 mod 8).
        let mut g = DenseGrid::new([0, 0, 0], [16, 16, 16], 0.0).unwrap();
        let corners = [[0, 0, 0], [15, 15, 15], [0, 15, 7], [8, 0, 15]];
        for c in corners {
            g.set(c, 1.0);
        }
        let (bricked, bricks) = foundry_bricks(&g, TexelFormat::Unorm8);
        let active: u32 = bricks.iter().map(|b| b.active_voxels).sum();
        assert_eq!(active as usize, corners.len());
        for c in corners {
            let p = c.map(|v| v as f64);
            assert!(
                bricks.iter().any(|b| contains(b, p) && b.value_max == 1.0),
                "voxel {c:?} lost"
            );
            // Half a voxel beyond the grid's last voxel the lookup is still non-zero and bounded.
            let q = p.map(|v| v + 0.5);
            let v = sample_trilinear(&bricked, q) as f32;
            assert!(v > 0.0);
            assert!(bricks.iter().any(|b| contains(b, q) && b.value_max >= v));
        }
        // Background bricks next to data are Foundry bricks without texels.
        let halo_only = bricks.iter().find(|b| b.origin == [16, 16, 16]).unwrap();
        assert_eq!((halo_only.atlas_slot, halo_only.active_voxels), (UNSET, 0));
        assert_eq!(halo_only.value_max, 1.0);
    }

    #[test]
    fn fog_sphere_bricks_count_every_active_voxel() {
        let g = fog_sphere(20.0, 4.0).unwrap();
        assert_eq!(g.get([0, 0, 0]), 1.0);
        assert_eq!(g.get([18, 0, 0]), 0.5);
        assert_eq!(g.get([20, 0, 0]), 0.0);
        let (bricked, bricks) = foundry_bricks(&g, TexelFormat::F32);
        let active: u32 = bricks.iter().map(|b| b.active_voxels).sum();
        assert_eq!(
            active as usize,
            g.values.iter().filter(|v| **v != 0.0).count()
        );
        // Slots name the stored, non-constant bricks, each once.
        let mut slots: Vec<u32> = bricks
            .iter()
            .map(|b| b.atlas_slot)
            .filter(|s| *s != UNSET)
            .collect();
        slots.sort_unstable();
        slots.dedup();
        assert_eq!(slots.len(), bricked.atlas_slots());
    }
}
