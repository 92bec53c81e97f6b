//! Walking a ray through the range mips (hierarchical DDA) and through voxel cells.
//!
//! [`SegmentWalk`] cuts a ray into [`Segment`]s in increasing `t`, contiguous (each `t1` is
//! the next `t0`) and covering `[tmin, tmax]` exactly: the parts outside the range mips' box
//! (level [`LEVEL_OUTSIDE`], the background's constant range), and inside it one segment per
//! block visited. The walk starts at the coarsest level; a block whose range is constant
//! (min == max, such as empty space) is one segment at its level, any other block is entered
//! level by level down to the requested finest level. [`CellWalk`] cuts a piece of a ray
//! into the unit cells of the trilinear (or nearest) lookup.
//!
//! ## Why the ranges bound every lookup, also on faces and edges
//!
//! Block `b` of a level with side `s` owns `[s*b - 0.5, s*b + s - 0.5)` per axis, so every
//! block face at every level lies on a plane `8*j - 0.5`. Its range spans voxels
//! `s*b - 1 ..= s*b + s` (the halo). A lookup at `p` reads voxel `floor(p)` and, only where
//! `p` is not an integer, `floor(p) + 1` (trilinear and stochastic: both with a weight;
//! nearest: the closer one), per axis. So the range bounds every nearest, trilinear and
//! stochastic lookup in the closed slab `[s*b - 1, s*b + s]`: half a voxel beyond the
//! block on each side.
//! A point on a face, or within rounding error of one, is thus bounded by the ranges of both
//! blocks beside it, whichever claims it. The rule used to claim it (the face rule):
//!
//! - A face is crossed at the `t` computed by one formula, `(plane - origin) / dir`, the same
//!   for every level (plane positions are exact in f64), and a face met at the current `t`
//!   or before counts as crossed. Stepping, descending to a child block and the first block
//!   all decide by comparing those same numbers, so the walk cannot disagree with itself
//!   and never skips or revisits a block: ties (rays through edges and corners) give
//!   zero-length pieces, which are dropped.
//! - Along an axis where the direction is exactly 0 there is no crossing: the ray belongs to
//!   the block whose slab holds its coordinate, a point on a face to the block above it (the
//!   nearest lookup's `floor(p + 0.5)` convention). Zero components are branched on, never
//!   divided by.
//!
//! Rounding error in the walk's positions is about 1e-16 of the distances involved, far
//! below the half voxel of slack; the walk also moves the ray's origin to where it enters
//! the box, so its arithmetic only sees box-sized numbers even for origins 1e7 voxels away
//! (the GPU twin, in f32, relies on this).
//!
//! ## State, for the GPU twin
//!
//! Both walks are iterative with a small fixed state (origin, direction, level, cell, `t`,
//! a step budget): no recursion and no allocation per step. The budget bounds the number of
//! steps by the cells a ray can cross, so no input can make a walk loop forever.

use crate::dense::VolumeError;
use crate::grid::GridMap;
use crate::ranges::{RangeLevel, RangeMips, ValueRange};

/// Level of the segments outside the range mips' box, where every lookup is the background.
pub const LEVEL_OUTSIDE: u32 = u32::MAX;

/// Level of a segment that spans the whole box with one (global) range.
pub const LEVEL_GLOBAL: u32 = u32::MAX - 1;

/// A ray in world space: the points `origin + t * dir` for `tmin <= t <= tmax`. With a unit
/// `dir`, `t` is the world distance from the origin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point, `t = 0`.
    pub origin: [f64; 3],
    /// Direction (unit length, so that `t` measures world distance).
    pub dir: [f64; 3],
    /// Start of the ray's interval; finite.
    pub tmin: f64,
    /// End of the ray's interval; may be `+inf`. Below `tmin` the ray is empty.
    pub tmax: f64,
}

impl Ray {
    /// A ray from its parts (checked when it is taken to index space).
    pub fn new(origin: [f64; 3], dir: [f64; 3], tmin: f64, tmax: f64) -> Ray {
        Ray {
            origin,
            dir,
            tmin,
            tmax,
        }
    }
}

/// A ray in a grid's index space, with the same parameter `t` as the world ray it comes
/// from (its direction is the world direction mapped to index space, not normalized).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndexRay {
    /// Index-space point at `t = 0`.
    pub origin: [f64; 3],
    /// Index-space direction: index units per unit of `t`.
    pub dir: [f64; 3],
    /// Start of the interval.
    pub tmin: f64,
    /// End of the interval (may be `+inf`).
    pub tmax: f64,
}

fn check_ray(
    what: &str,
    origin: [f64; 3],
    dir: [f64; 3],
    tmin: f64,
    tmax: f64,
) -> Result<(), VolumeError> {
    let fail = |why: &str| {
        Err(VolumeError(format!(
            "{what} ray: {why} (origin {origin:?}, dir {dir:?}, t {tmin}..{tmax})"
        )))
    };
    if !origin.iter().all(|v| v.is_finite()) {
        fail("the origin must be finite")
    } else if !dir.iter().all(|v| v.is_finite()) || dir.iter().all(|v| *v == 0.0) {
        fail("the direction must be finite and non-zero")
    } else if !tmin.is_finite() {
        fail("tmin must be finite")
    } else if tmax.is_nan() {
        fail("tmax must not be NaN")
    } else {
        Ok(())
    }
}

impl IndexRay {
    /// An index-space ray; errors on a non-finite origin, a zero or non-finite direction, a
    /// non-finite `tmin` or a NaN `tmax`.
    pub fn new(
        origin: [f64; 3],
        dir: [f64; 3],
        tmin: f64,
        tmax: f64,
    ) -> Result<IndexRay, VolumeError> {
        check_ray("index-space", origin, dir, tmin, tmax)?;
        Ok(IndexRay {
            origin,
            dir,
            tmin,
            tmax,
        })
    }

    /// The world ray `ray` in the index space of `map` (the same `t` on both); errors as
    /// [`IndexRay::new`], for the world ray and for its image.
    pub fn from_world(ray: &Ray, map: &GridMap) -> Result<IndexRay, VolumeError> {
        check_ray("world", ray.origin, ray.dir, ray.tmin, ray.tmax)?;
        IndexRay::new(
            map.world_to_index(ray.origin),
            map.world_dir_to_index(ray.dir),
            ray.tmin,
            ray.tmax,
        )
    }

    /// The index-space point at `t`.
    pub fn at(&self, t: f64) -> [f64; 3] {
        std::array::from_fn(|k| self.origin[k] + t * self.dir[k])
    }
}

/// A piece `[t0, t1]` of a ray with a range bounding every lookup on it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    /// Start.
    pub t0: f64,
    /// End (`+inf` for the trailing outside segment of an infinite ray).
    pub t1: f64,
    /// Bounds of every nearest, trilinear and stochastic lookup on the segment.
    pub range: ValueRange,
    /// Mip level of the block that gave `range` (0 = 8^3 blocks), [`LEVEL_GLOBAL`] or
    /// [`LEVEL_OUTSIDE`].
    pub level: u32,
}

/// The range of every lookup anywhere: the union of the coarsest level and the background.
pub fn global_range(mips: &RangeMips) -> ValueRange {
    let top = mips.levels.last().map_or(&[][..], |l| &l.ranges[..]);
    top.iter()
        .fold(ValueRange::constant(mips.background), |r, b| r.union(*b))
}

/// Where the walk is: before the box, inside it, after it, finished.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Leading,
    Inside,
    Trailing,
    Done,
}

/// The segments of a ray, in increasing `t` (an iterator; see the module documentation).
#[derive(Clone, Debug)]
pub struct SegmentWalk<'a> {
    mips: &'a RangeMips,
    /// The index-space ray moved to start at `t = base`: positions are
    /// `origin + (t - base) * dir`, and the walk counts `t` from `base` ("local t").
    origin: [f64; 3],
    dir: [f64; 3],
    base: f64,
    tmin: f64,
    tmax: f64,
    /// Local t reached, and local t where the ray leaves the box (or `tmax`).
    t: f64,
    t_end: f64,
    phase: Phase,
    /// The single range of the box for a global walk.
    global: Option<ValueRange>,
    level: usize,
    finest: usize,
    top: usize,
    /// Block coordinates at `level`.
    cell: [i64; 3],
    /// Steps left; the walk needs fewer (see `new`).
    budget: u64,
}

impl<'a> SegmentWalk<'a> {
    /// The hierarchical walk down to level `finest` (0 = 8^3 blocks; a coarser level gives
    /// coarser segments with looser ranges). Errors on a bad ray (see [`IndexRay::new`]) or a
    /// level the mips do not have.
    pub fn new(
        mips: &'a RangeMips,
        ray: &IndexRay,
        finest: usize,
    ) -> Result<SegmentWalk<'a>, VolumeError> {
        if finest >= mips.levels.len() {
            return Err(VolumeError(format!(
                "mip level {finest} requested, the range mips have {} levels",
                mips.levels.len()
            )));
        }
        SegmentWalk::start(mips, ray, finest, None)
    }

    /// The walk with one range for the whole box (normally [`global_range`]): the outside
    /// parts, and the part inside the box as one segment of level [`LEVEL_GLOBAL`].
    pub fn global(
        mips: &'a RangeMips,
        ray: &IndexRay,
        range: ValueRange,
    ) -> Result<SegmentWalk<'a>, VolumeError> {
        SegmentWalk::start(mips, ray, 0, Some(range))
    }

    fn start(
        mips: &'a RangeMips,
        ray: &IndexRay,
        finest: usize,
        global: Option<ValueRange>,
    ) -> Result<SegmentWalk<'a>, VolumeError> {
        check_ray("index-space", ray.origin, ray.dir, ray.tmin, ray.tmax)?;
        let Some(top_level) = mips.levels.last() else {
            return Err(VolumeError("the range mips have no levels".into()));
        };
        let top = mips.levels.len() - 1;
        let mut walk = SegmentWalk {
            mips,
            origin: ray.origin,
            dir: ray.dir,
            // Without an overlap with the box, the leading segment is the whole ray.
            base: ray.tmax,
            tmin: ray.tmin,
            tmax: ray.tmax,
            t: 0.0,
            t_end: 0.0,
            phase: Phase::Leading,
            global,
            level: top,
            finest,
            top,
            cell: [0; 3],
            budget: 0,
        };
        let Some(t_in) = box_entry(ray, top_level) else {
            return Ok(walk);
        };
        walk.base = t_in;
        walk.origin = ray.at(t_in);
        // Where the moved ray leaves the box, by the walk's own plane formula, so that the
        // last block's exit and the end of the walk are the same number.
        let side = top_level.side as f64;
        let mut t_end = ray.tmax - t_in;
        for k in 0..3 {
            if walk.dir[k] != 0.0 {
                let lo = top_level.lo[k] as i64;
                let far = if walk.dir[k] > 0.0 {
                    lo + top_level.dims[k] as i64
                } else {
                    lo
                };
                t_end = t_end.min(walk.plane_t(k, far, side));
            }
        }
        walk.t_end = t_end.max(0.0);
        walk.cell = walk.first_cell(top_level);
        // Each step moves the ray into the next block along one axis, at least one block of
        // level `finest`; between two steps the walk descends at most `top - finest` times.
        let depth = (top - finest) as u64;
        let fine_cells: u64 = top_level.dims.iter().map(|d| (*d as u64) << depth).sum();
        walk.budget = (fine_cells + 1) * (depth + 1) + 1;
        Ok(walk)
    }

    /// Local t at which the ray meets plane `j * side - 0.5` of axis `k` (`dir[k] != 0`).
    fn plane_t(&self, k: usize, j: i64, side: f64) -> f64 {
        (j as f64 * side - 0.5 - self.origin[k]) / self.dir[k]
    }

    /// Absolute t of local t.
    fn absolute(&self, t: f64) -> f64 {
        (self.base + t).min(self.tmax)
    }

    /// The block of the coarsest level holding the moved origin (local t = 0), by the face
    /// rule, kept inside the level's box.
    fn first_cell(&self, level: &RangeLevel) -> [i64; 3] {
        let s = level.side as f64;
        std::array::from_fn(|k| {
            let lo = level.lo[k] as i64;
            let hi = lo + level.dims[k] as i64 - 1;
            let guess = ((self.origin[k] + 0.5) / s)
                .floor()
                .clamp(lo as f64, hi as f64);
            let mut c = guess as i64;
            let d = self.dir[k];
            if d == 0.0 {
                while c < hi && self.origin[k] >= (c + 1) as f64 * s - 0.5 {
                    c += 1;
                }
                while c > lo && self.origin[k] < c as f64 * s - 0.5 {
                    c -= 1;
                }
            } else {
                // Entered when its entry face is met at t <= 0, left when its exit face is.
                let (step, last, first) = if d > 0.0 { (1, hi, lo) } else { (-1, lo, hi) };
                let exit = |c: i64| self.plane_t(k, c + (d > 0.0) as i64, s);
                let entry = |c: i64| self.plane_t(k, c + (d < 0.0) as i64, s);
                while c != last && exit(c) <= 0.0 {
                    c += step;
                }
                while c != first && entry(c) > 0.0 {
                    c -= step;
                }
            }
            c
        })
    }

    /// Moves to the child block of the current one that holds the ray at `t`.
    fn descend(&mut self) {
        self.level -= 1;
        let half = self.mips.levels[self.level].side as f64;
        for k in 0..3 {
            let mid = 2 * self.cell[k] + 1;
            let d = self.dir[k];
            let upper = if d > 0.0 {
                self.plane_t(k, mid, half) <= self.t
            } else if d < 0.0 {
                self.plane_t(k, mid, half) > self.t
            } else {
                self.origin[k] >= mid as f64 * half - 0.5
            };
            self.cell[k] = 2 * self.cell[k] + upper as i64;
        }
    }

    /// Steps into the next block along axis `k`, and up the levels as far as the face
    /// crossed is also a face of the coarser blocks.
    fn step(&mut self, k: usize) {
        let mut from = self.cell[k];
        self.cell[k] += if self.dir[k] > 0.0 { 1 } else { -1 };
        let mut to = self.cell[k];
        while self.level < self.top && from >> 1 != to >> 1 {
            self.level += 1;
            self.cell = self.cell.map(|c| c >> 1);
            from >>= 1;
            to >>= 1;
        }
    }

    fn segment(&self, t0: f64, t1: f64, range: ValueRange, level: u32) -> Segment {
        Segment {
            t0: self.absolute(t0),
            t1: self.absolute(t1),
            range,
            level,
        }
    }

    /// The next segment inside the box (possibly of zero length), or `None` at its end.
    fn inside_next(&mut self) -> Option<Segment> {
        if self.t >= self.t_end {
            return None;
        }
        if let Some(range) = self.global {
            self.t = self.t_end;
            return Some(self.segment(0.0, self.t_end, range, LEVEL_GLOBAL));
        }
        loop {
            if self.budget == 0 {
                // Unreachable by the bound in `new`; if it were reached, the rest of the box
                // gets a range valid everywhere rather than a wrong one or an endless loop.
                let seg = self.segment(self.t, self.t_end, global_range(self.mips), LEVEL_GLOBAL);
                self.t = self.t_end;
                return Some(seg);
            }
            self.budget -= 1;
            let side = self.mips.levels[self.level].side as f64;
            let (mut t_exit, mut axis) = (self.t_end, None);
            for k in 0..3 {
                if self.dir[k] != 0.0 {
                    let tk = self.plane_t(k, self.cell[k] + (self.dir[k] > 0.0) as i64, side);
                    if tk < t_exit {
                        (t_exit, axis) = (tk, Some(k));
                    }
                }
            }
            let t_exit = t_exit.max(self.t);
            let block = self.cell.map(|c| c as i32);
            let range = self.mips.range(self.level, block);
            if self.level > self.finest && range.min != range.max && t_exit > self.t {
                self.descend();
                continue;
            }
            let seg = self.segment(self.t, t_exit, range, self.level as u32);
            self.t = t_exit;
            if let Some(k) = axis {
                self.step(k);
            }
            return Some(seg);
        }
    }
}

/// The entry parameter of `ray` into the box of `level`, when the ray overlaps it over a
/// positive length within `[tmin, tmax]`. Zero direction components are branched on.
fn box_entry(ray: &IndexRay, level: &RangeLevel) -> Option<f64> {
    if level.dims.contains(&0) {
        return None;
    }
    let s = level.side as f64;
    let (mut t_in, mut t_out) = (ray.tmin, ray.tmax);
    for k in 0..3 {
        let lo = level.lo[k] as f64 * s - 0.5;
        let hi = (level.lo[k] as f64 + level.dims[k] as f64) * s - 0.5;
        let (o, d) = (ray.origin[k], ray.dir[k]);
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
        } else {
            let (ta, tb) = ((lo - o) / d, (hi - o) / d);
            t_in = t_in.max(ta.min(tb));
            t_out = t_out.min(ta.max(tb));
        }
    }
    (t_in < t_out).then_some(t_in)
}

impl Iterator for SegmentWalk<'_> {
    type Item = Segment;

    fn next(&mut self) -> Option<Segment> {
        let outside = ValueRange::constant(self.mips.background);
        loop {
            let seg = match self.phase {
                Phase::Leading => {
                    self.phase = Phase::Inside;
                    Segment {
                        t0: self.tmin,
                        t1: self.base,
                        range: outside,
                        level: LEVEL_OUTSIDE,
                    }
                }
                Phase::Inside => match self.inside_next() {
                    Some(seg) => seg,
                    None => {
                        self.phase = Phase::Trailing;
                        continue;
                    }
                },
                Phase::Trailing => {
                    self.phase = Phase::Done;
                    Segment {
                        t0: self.absolute(self.t_end),
                        t1: self.tmax,
                        range: outside,
                        level: LEVEL_OUTSIDE,
                    }
                }
                Phase::Done => return None,
            };
            // Zero-length pieces (edges, corners, rounding) carry nothing.
            if seg.t1 > seg.t0 {
                return Some(seg);
            }
        }
    }
}

/// Largest index-space coordinate a [`CellWalk`] accepts.
const MAX_COORD: f64 = (1u64 << 40) as f64;

/// The piece of a ray inside one cell of a [`CellWalk`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellPiece {
    /// Start.
    pub t0: f64,
    /// End.
    pub t1: f64,
    /// The cell: for trilinear cells the voxel at its low corner (the cell spans
    /// `[i, i + 1]` per axis), for nearest cells the voxel read (`[i - 0.5, i + 0.5]`).
    pub cell: [i64; 3],
    /// Index-space point at `t0`; the point at `t` is `entry + (t - t0) * dir`.
    pub entry: [f64; 3],
}

/// The cells of a unit lattice that a ray crosses between two parameters, in order (an
/// iterator). Trilinear cells lie between voxel centres: inside one, a trilinear lookup
/// along a line is a cubic polynomial of `t`. Nearest cells are centred on voxels: inside
/// one, a nearest lookup is constant. Faces follow the same rule as [`SegmentWalk`].
#[derive(Clone, Debug)]
pub struct CellWalk {
    /// The ray moved to start at `base`, counted in local t as in [`SegmentWalk`].
    origin: [f64; 3],
    dir: [f64; 3],
    base: f64,
    end: f64,
    /// Cell `i` spans `[i + offset, i + 1 + offset]`.
    offset: f64,
    t: f64,
    t_end: f64,
    cell: [i64; 3],
    budget: u64,
}

impl CellWalk {
    /// The trilinear cells of `ray` over `[t0, t1]`; nothing unless both are finite and the
    /// points within 2^40 voxels of the index-space origin.
    pub fn trilinear(ray: &IndexRay, t0: f64, t1: f64) -> CellWalk {
        CellWalk::new(ray, t0, t1, 0.0)
    }

    /// The nearest cells of `ray` over `[t0, t1]`, with the same conditions.
    pub fn nearest(ray: &IndexRay, t0: f64, t1: f64) -> CellWalk {
        CellWalk::new(ray, t0, t1, -0.5)
    }

    fn new(ray: &IndexRay, t0: f64, t1: f64, offset: f64) -> CellWalk {
        let len = t1 - t0;
        let mut walk = CellWalk {
            origin: ray.at(t0),
            dir: ray.dir,
            base: t0,
            end: t1,
            offset,
            t: 0.0,
            t_end: len,
            cell: [0; 3],
            budget: 0,
        };
        // Cell indices stay far from i64's ends (and positions exact to well below a cell).
        let usable = len > 0.0
            && len.is_finite()
            && walk.dir.iter().all(|v| v.is_finite())
            && (0..3).all(|k| (walk.origin[k] + len * walk.dir[k]).abs() < MAX_COORD)
            && walk.origin.iter().all(|v| v.abs() < MAX_COORD);
        if !usable {
            walk.t_end = 0.0;
            return walk;
        }
        walk.cell = std::array::from_fn(|k| walk.first_cell(k));
        // A line crosses at most |d_k| * len + 1 faces per axis.
        let faces: f64 = walk.dir.iter().map(|d| (d.abs() * len).ceil() + 1.0).sum();
        walk.budget = faces as u64 + 1;
        walk
    }

    /// Local t at which the ray meets face `j + offset` of axis `k` (`dir[k] != 0`).
    fn plane_t(&self, k: usize, j: i64) -> f64 {
        (j as f64 + self.offset - self.origin[k]) / self.dir[k]
    }

    /// Absolute t of local t; the end is exactly `t1`.
    fn absolute(&self, t: f64) -> f64 {
        if t >= self.t_end {
            self.end
        } else {
            (self.base + t).min(self.end)
        }
    }

    fn first_cell(&self, k: usize) -> i64 {
        let (o, d) = (self.origin[k], self.dir[k]);
        let mut c = (o - self.offset).floor() as i64;
        if d == 0.0 {
            while o >= (c + 1) as f64 + self.offset {
                c += 1;
            }
            while o < c as f64 + self.offset {
                c -= 1;
            }
        } else {
            let step = if d > 0.0 { 1 } else { -1 };
            while self.plane_t(k, c + (d > 0.0) as i64) <= 0.0 {
                c += step;
            }
            while self.plane_t(k, c + (d < 0.0) as i64) > 0.0 {
                c -= step;
            }
        }
        c
    }
}

impl Iterator for CellWalk {
    type Item = CellPiece;

    fn next(&mut self) -> Option<CellPiece> {
        while self.t < self.t_end {
            let (mut t_exit, mut axis) = (self.t_end, None);
            // The budget cannot run out before the end (see `new`); if it did, the last
            // piece would run to the end rather than loop.
            if self.budget > 1 {
                for k in 0..3 {
                    if self.dir[k] != 0.0 {
                        let tk = self.plane_t(k, self.cell[k] + (self.dir[k] > 0.0) as i64);
                        if tk < t_exit {
                            (t_exit, axis) = (tk, Some(k));
                        }
                    }
                }
            }
            self.budget = self.budget.saturating_sub(1);
            let t_exit = t_exit.max(self.t);
            let piece = CellPiece {
                t0: self.absolute(self.t),
                t1: self.absolute(t_exit),
                cell: self.cell,
                entry: std::array::from_fn(|k| self.origin[k] + self.t * self.dir[k]),
            };
            self.t = t_exit;
            if let Some(k) = axis {
                self.cell[k] += if self.dir[k] > 0.0 { 1 } else { -1 };
            }
            if piece.t1 > piece.t0 {
                return Some(piece);
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::DenseGrid;

    fn noisy_grid() -> DenseGrid {
        let mut g = DenseGrid::new([0; 3], [64, 64, 64], 0.0).unwrap();
        for (i, v) in g.values.iter_mut().enumerate() {
            *v = (i.wrapping_mul(2_654_435_761) % 97) as f32;
        }
        g
    }

    #[test]
    fn budget_outlasts_the_longest_walk() {
        // Every block differs, so the walk descends everywhere; the main diagonal crosses
        // the most blocks, through their corners.
        let g = noisy_grid();
        let mips = RangeMips::build(&g).unwrap();
        let d = [1.0 / 3f64.sqrt(); 3];
        for (origin, level) in [([-0.5; 3], 0), ([-20.0, -19.5, -21.0], 0), ([-0.5; 3], 2)] {
            let ray = IndexRay::new(origin, d, 0.0, f64::INFINITY).unwrap();
            let mut walk = SegmentWalk::new(&mips, &ray, level).unwrap();
            let start = walk.budget;
            let count = walk.by_ref().filter(|s| s.level == level as u32).count();
            assert!(count >= 8 >> level, "{count}");
            assert!(
                walk.budget > 0 && walk.budget < start,
                "{} of {start}",
                walk.budget
            );
        }
    }

    #[test]
    fn points_on_faces_follow_the_face_rule() {
        let g = noisy_grid();
        let mips = RangeMips::build(&g).unwrap();
        // On the face x = 7.5 between blocks 0 and 1: moving up or along it, block 1;
        // moving down, block 0.
        for (dx, block) in [(1.0, 1), (0.0, 1), (-1.0, 0)] {
            let dir = [dx, 1.0, 0.5];
            let ray = IndexRay::new([7.5, 3.0, 3.0], dir, 0.0, 100.0).unwrap();
            let mut walk = SegmentWalk::new(&mips, &ray, 0).unwrap();
            let first = walk.next().unwrap();
            assert_eq!(first.range, mips.range(0, [block, 0, 0]), "dx {dx}");
        }
        // The same for the unit cells, on x = 2 (trilinear) and x = 2.5 (nearest).
        for (dx, cell) in [(1.0, 2), (0.0, 2), (-1.0, 1)] {
            let ray = IndexRay::new([2.0, 0.25, 0.25], [dx, 1.0, 0.0], 0.0, 1.0).unwrap();
            let piece = CellWalk::trilinear(&ray, 0.0, 0.5).next().unwrap();
            assert_eq!(piece.cell, [cell, 0, 0], "dx {dx}");
            let ray = IndexRay::new([2.5, 0.25, 0.25], [dx, 1.0, 0.0], 0.0, 1.0).unwrap();
            let piece = CellWalk::nearest(&ray, 0.0, 0.1).next().unwrap();
            assert_eq!(piece.cell, [cell + 1, 0, 0], "dx {dx}");
        }
    }
}
