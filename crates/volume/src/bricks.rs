//! Cutting a grid into 8^3 bricks with halo-inclusive value ranges.

use hytrace_foundry::{Brick, UNSET};

use crate::dense::DenseGrid;

/// Voxels per brick side.
pub const BRICK_SIZE: u32 = 8;

/// The bricks of `grid` that can return a value other than the background.
///
/// A brick covers voxels `origin .. origin + 8` on each axis. A trilinear lookup anywhere in
/// its bounds `[origin - 0.5, origin + 7.5]` reads voxels `origin - 1 ..= origin + 8`, so the
/// brick's `value_min`/`value_max` span that halo-inclusive block: `value_max` is a majorant of
/// every lookup in the brick, including for bricks whose own voxels are all background.
/// Bricks are aligned to multiples of 8 in index space, also for negative coordinates.
/// `atlas_slot` is left unset (no atlas yet) and `prim` is set when the bricks are added to a
/// Foundry.
pub fn bricks(grid: &DenseGrid) -> Vec<Brick> {
    let b = BRICK_SIZE as i64;
    // Brick index range: every brick whose halo-inclusive block [o - 1, o + 8] touches the
    // grid's voxels [g, g + d - 1], i.e. ceil((g - 8) / 8) ..= floor((g + d) / 8).
    let lo: [i64; 3] = std::array::from_fn(|k| (grid.origin[k] as i64 - b - 1).div_euclid(b) + 1);
    let hi: [i64; 3] =
        std::array::from_fn(|k| (grid.origin[k] as i64 + grid.dims[k] as i64).div_euclid(b));
    let mut out = Vec::new();
    for bz in lo[2]..=hi[2] {
        for by in lo[1]..=hi[1] {
            for bx in lo[0]..=hi[0] {
                let origin = [bx * b, by * b, bz * b];
                let (mut min, mut max, mut active) = (f32::INFINITY, f32::NEG_INFINITY, 0u32);
                for z in origin[2] - 1..=origin[2] + b {
                    for y in origin[1] - 1..=origin[1] + b {
                        for x in origin[0] - 1..=origin[0] + b {
                            let v = grid.get([x, y, z]);
                            min = min.min(v);
                            max = max.max(v);
                            let inside = (0..3)
                                .all(|k| [x, y, z][k] >= origin[k] && [x, y, z][k] < origin[k] + b);
                            active += (inside && v != grid.background) as u32;
                        }
                    }
                }
                if min == grid.background && max == grid.background {
                    continue;
                }
                let lo_corner = origin.map(|c| c as f32 - 0.5);
                out.push(Brick {
                    origin: origin.map(|c| c as i32),
                    level: 0,
                    atlas_slot: UNSET,
                    prim: UNSET,
                    value_min: min,
                    value_max: max,
                    aabb: [
                        lo_corner[0],
                        lo_corner[1],
                        lo_corner[2],
                        lo_corner[0] + BRICK_SIZE as f32,
                        lo_corner[1] + BRICK_SIZE as f32,
                        lo_corner[2] + BRICK_SIZE as f32,
                    ],
                    active_voxels: active,
                    size: BRICK_SIZE,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Deterministic pseudo-random numbers in [0, 1) (SplitMix64).
    fn rng(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    fn contains(b: &Brick, p: [f64; 3]) -> bool {
        (0..3).all(|k| p[k] >= b.aabb[k] as f64 && p[k] <= b.aabb[k + 3] as f64)
    }

    #[test]
    fn halo_ranges_bound_every_trilinear_lookup() {
        let mut state = 3;
        // Negative origin, sides that are not multiples of 8, random values.
        let mut g = DenseGrid::new([-13, -8, 5], [21, 16, 11], 0.0).unwrap();
        for v in g.values.iter_mut() {
            *v = if rng(&mut state) < 0.3 {
                0.0
            } else {
                (rng(&mut state) * 4.0 - 1.0) as f32
            };
        }
        let bricks = bricks(&g);
        for b in &bricks {
            for _ in 0..300 {
                let p: [f64; 3] =
                    std::array::from_fn(|k| b.aabb[k] as f64 + rng(&mut state) * BRICK_SIZE as f64);
                let v = crate::sample_trilinear(&g, p);
                assert!(
                    v >= b.value_min as f64 - 1e-6 && v <= b.value_max as f64 + 1e-6,
                    "{v} outside {}..{} at {p:?}",
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
                assert_eq!(crate::sample_trilinear(&g, p), 0.0, "{p:?}");
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
        let bricks = bricks(&g);
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
            assert!(bricks
                .iter()
                .any(|b| contains(b, q) && b.value_max >= crate::sample_trilinear(&g, q) as f32));
        }
    }
}
