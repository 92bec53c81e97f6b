//! The tree of a grid with scalar values: validated once at load, then walked by lookups.
//!
//! Root tiles are keyed by the upper 20 bits of each coordinate; an upper node holds 32^3
//! children of 128^3 voxels, a lower node 16^3 children of 8^3 voxels (the leaves). Child
//! offsets are relative to the parent (the root for root tiles). [`Tree::load`] checks that
//! every node lies inside the grid buffer, 32-byte aligned, reached once, and that the
//! node and voxel counts agree with the tree header, so lookups cannot leave the buffer;
//! they still read through checked accessors and fall back to the background.

use std::collections::{HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use super::bytes::{f32_at, f64_at, i64_at, offset_by, u32_at, u64_at, u8_at};
use super::layout::{leaf, root, Internal, NanoGridType, LOWER, UPPER};
use crate::decode_error::DecodeError;
use crate::grid::Coord;

/// How a grid stores its values.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ValueKind {
    /// f32 values (Float).
    F32,
    /// f64 values (Double).
    F64,
    /// `min + quantum * code` with fixed-width codes (Fp4, Fp8, Fp16).
    Quantized(u32),
    /// Like `Quantized` with the width chosen per leaf (FpN).
    VariableQuantized,
}

impl ValueKind {
    /// The kind of a grid type, or `None` when its values are not scalars this reader decodes.
    pub(crate) fn of(grid_type: NanoGridType) -> Option<ValueKind> {
        match grid_type {
            NanoGridType::Float => Some(ValueKind::F32),
            NanoGridType::Double => Some(ValueKind::F64),
            NanoGridType::Fp4 => Some(ValueKind::Quantized(4)),
            NanoGridType::Fp8 => Some(ValueKind::Quantized(8)),
            NanoGridType::Fp16 => Some(ValueKind::Quantized(16)),
            NanoGridType::FpN => Some(ValueKind::VariableQuantized),
            _ => None,
        }
    }

    /// Root node size before the tiles (bbox, table size, background, statistics, padding).
    fn root_size(self) -> usize {
        if self == ValueKind::F64 {
            96
        } else {
            64
        }
    }

    /// Offset of the background in the root node.
    fn root_background(self) -> usize {
        if self == ValueKind::F64 {
            32
        } else {
            28
        }
    }

    /// Offset of the value in a root tile.
    fn tile_value(self) -> usize {
        if self == ValueKind::F64 {
            24
        } else {
            20
        }
    }

    /// Offset of the value array (codes for quantized kinds) in a leaf.
    fn leaf_values(self) -> usize {
        if self == ValueKind::F64 {
            128
        } else {
            96
        }
    }

    /// Leaf size; for FpN the size follows the bit-width code `log2_bits` of its flags.
    fn leaf_size(self, log2_bits: u32) -> usize {
        match self {
            ValueKind::F32 => 96 + 512 * 4,
            ValueKind::F64 => 128 + 512 * 8,
            ValueKind::Quantized(bits) => 96 + 64 * bits as usize,
            ValueKind::VariableQuantized => 96 + (64 << log2_bits),
        }
    }
}

/// The root key of the 4096^3 region holding `ijk`.
fn root_key(ijk: Coord) -> u64 {
    let part = |c: i32| u64::from(c as u32 >> 12);
    part(ijk[0]) << 42 | part(ijk[1]) << 21 | part(ijk[2])
}

/// The origin of the region of `key`, when `key` is one [`root_key`] can produce.
fn key_origin(key: u64) -> Option<Coord> {
    let m = root::KEY_FIELD_MASK;
    let fields = [(key >> 42) & m, (key >> 21) & m, key & m];
    let origin = fields.map(|f| ((f as u32) << 12) as i32);
    (root_key(origin) == key).then_some(origin)
}

/// A multiplicative hash for root keys (keys are already well spread in their bits).
#[derive(Default)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for b in bytes {
            self.write_u64(u64::from(*b));
        }
    }

    fn write_u64(&mut self, k: u64) {
        let z = (self.0 ^ k ^ (k >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        self.0 = z ^ (z >> 32);
    }
}

/// What a root tile holds.
#[derive(Clone, Copy, Debug)]
enum RootSlot {
    /// An upper node at this buffer position.
    Child(usize),
    /// An active tile whose value is at this buffer position.
    Active(usize),
    /// An inactive tile (reads the background).
    Inactive,
}

/// Where a lookup ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Hit {
    /// In the leaf at this buffer position.
    Leaf(usize),
    /// In an active tile whose value is at this buffer position.
    Value(usize),
    /// In an inactive tile or outside every node.
    Background,
}

/// The counts a tree header states.
#[derive(Clone, Copy, Debug)]
pub(crate) struct HeaderCounts {
    /// Leaf, lower and upper nodes.
    pub nodes: [u32; 3],
    /// Active voxels, tiles counted voxel by voxel.
    pub voxels: u64,
}

/// A validated tree of scalar values.
#[derive(Debug)]
pub(crate) struct Tree {
    kind: ValueKind,
    /// Root tiles in file order with their region origins.
    tiles: Vec<(Coord, RootSlot)>,
    /// Root key -> the tile's slot.
    lookup: HashMap<u64, RootSlot, BuildHasherDefault<KeyHasher>>,
    background: f64,
    /// Number of 8^3 blocks with data: leaves plus active tiles expanded into blocks.
    blocks: u64,
}

/// Position and bit of slot `n` in a mask starting at `mask`.
fn mask_bit(buf: &[u8], mask: usize, n: usize) -> bool {
    u64_at(buf, mask + 8 * (n >> 6)).is_some_and(|w| w >> (n & 63) & 1 != 0)
}

/// The slots of an internal node that hold children and active tiles, in slot order.
fn internal_slots(buf: &[u8], node: usize, layout: &Internal) -> (Vec<usize>, Vec<usize>) {
    let (mut children, mut tiles) = (Vec::new(), Vec::new());
    let ones = |mut bits: u64, base: usize, out: &mut Vec<usize>| {
        while bits != 0 {
            out.push(base + bits.trailing_zeros() as usize);
            bits &= bits - 1;
        }
    };
    for w in 0..layout.slots() / 64 {
        let child = u64_at(buf, node + layout.child_mask + 8 * w).unwrap_or(0);
        let value = u64_at(buf, node + layout.value_mask + 8 * w).unwrap_or(0);
        ones(child, w * 64, &mut children);
        ones(value & !child, w * 64, &mut tiles);
    }
    (children, tiles)
}

/// Collects the distinct nodes of one level, refusing more than the header states.
struct Level {
    name: &'static str,
    stated: u32,
    seen: HashSet<usize>,
    nodes: Vec<(usize, Coord)>,
}

impl Level {
    /// A level of `stated` nodes of at least `size` bytes each; nodes do not overlap in a
    /// NanoVDB buffer, so more than fit in `buffer_len` bytes is an error (this also bounds
    /// the work of validating a corrupt tree by the buffer size).
    fn new(
        name: &'static str,
        stated: u32,
        size: usize,
        buffer_len: usize,
    ) -> Result<Level, DecodeError> {
        if (stated as usize).saturating_mul(size) > buffer_len {
            return Err(DecodeError(format!(
                "the tree header states {stated} {name} nodes of {size} bytes, more than fit in the grid buffer ({buffer_len} bytes)"
            )));
        }
        Ok(Level {
            name,
            stated,
            seen: HashSet::new(),
            nodes: Vec::new(),
        })
    }

    fn add(&mut self, off: usize, origin: Coord, parent: &str) -> Result<(), DecodeError> {
        if !self.seen.insert(off) {
            return Err(DecodeError(format!(
                "{parent} points at the {} at byte {off} a second time",
                self.name
            )));
        }
        if self.nodes.len() >= self.stated as usize {
            return Err(DecodeError(format!(
                "the tree holds more than the {} {} nodes its header states",
                self.stated, self.name
            )));
        }
        self.nodes.push((off, origin));
        Ok(())
    }

    fn check_complete(&self) -> Result<(), DecodeError> {
        if self.nodes.len() != self.stated as usize {
            return Err(DecodeError(format!(
                "the tree header states {} {} nodes, the tree holds {}",
                self.stated,
                self.name,
                self.nodes.len()
            )));
        }
        Ok(())
    }
}

/// The node at `parent + delta` of `size` bytes, when it lies in `buf` and is aligned.
fn child_at(
    buf: &[u8],
    parent: usize,
    delta: i64,
    size: usize,
    what: &str,
) -> Result<usize, DecodeError> {
    let off = offset_by(parent, delta).ok_or_else(|| {
        DecodeError(format!(
            "{what} offset {delta} points before the grid buffer"
        ))
    })?;
    if off.checked_add(size).is_none_or(|end| end > buf.len()) {
        return Err(DecodeError(format!(
            "{what} offset {delta} (byte {off}, {size} bytes) beyond the grid buffer ({} bytes)",
            buf.len()
        )));
    }
    if off % 32 != 0 {
        return Err(DecodeError(format!(
            "{what} at byte {off} is not 32-byte aligned"
        )));
    }
    Ok(off)
}

impl Tree {
    /// Validates the tree whose root is at `root` in the grid buffer `buf`.
    pub(crate) fn load(
        buf: &[u8],
        kind: ValueKind,
        root: usize,
        counts: HeaderCounts,
    ) -> Result<Tree, DecodeError> {
        let table_size = u32_at(buf, root + root::TABLE_SIZE).ok_or_else(|| {
            DecodeError(format!("root node at byte {root} beyond the grid buffer"))
        })?;
        let background = if kind == ValueKind::F64 {
            f64_at(buf, root + kind.root_background())
        } else {
            f32_at(buf, root + kind.root_background()).map(f64::from)
        }
        .ok_or_else(|| DecodeError(format!("root node at byte {root} beyond the grid buffer")))?;
        let first_tile = root + kind.root_size();
        // The table must fit before anything is allocated for it.
        (table_size as usize)
            .checked_mul(root::TILE_SIZE)
            .and_then(|n| n.checked_add(first_tile))
            .filter(|end| *end <= buf.len())
            .ok_or_else(|| {
                DecodeError(format!(
                    "root table of {table_size} tiles beyond the grid buffer ({} bytes)",
                    buf.len()
                ))
            })?;

        let mut tree = Tree {
            kind,
            tiles: Vec::with_capacity(table_size as usize),
            lookup: HashMap::default(),
            background,
            blocks: 0,
        };
        let mut voxels: u128 = 0;
        let mut uppers = Level::new("upper", counts.nodes[2], UPPER.size, buf.len())?;
        for t in 0..table_size as usize {
            let tile = first_tile + t * root::TILE_SIZE;
            let word = |off| u64_at(buf, tile + off).unwrap_or(0);
            let key = word(root::TILE_KEY);
            let origin = key_origin(key)
                .ok_or_else(|| DecodeError(format!("root tile {t} has an invalid key {key:#x}")))?;
            if tree.lookup.contains_key(&key) {
                return Err(DecodeError(format!(
                    "root tile {t} repeats the key of an earlier tile"
                )));
            }
            let child = word(root::TILE_CHILD) as i64;
            let slot = if child != 0 {
                let what = format!("root tile {t} child");
                let upper = child_at(buf, root, child, UPPER.size, &what)?;
                uppers.add(upper, origin, &format!("root tile {t}"))?;
                RootSlot::Child(upper)
            } else if u32_at(buf, tile + root::TILE_STATE).unwrap_or(0) != 0 {
                voxels += 1 << 36;
                tree.blocks = tree.blocks.saturating_add(1 << 27);
                RootSlot::Active(tile + kind.tile_value())
            } else {
                RootSlot::Inactive
            };
            tree.lookup.insert(key, slot);
            tree.tiles.push((origin, slot));
        }
        uppers.check_complete()?;

        let mut lowers = Level::new("lower", counts.nodes[1], LOWER.size, buf.len())?;
        for (k, &(upper, origin)) in uppers.nodes.iter().enumerate() {
            let (children, tiles) = internal_slots(buf, upper, &UPPER);
            voxels += (tiles.len() as u128) << 21;
            tree.blocks = tree.blocks.saturating_add((tiles.len() as u64) << 12);
            for n in children {
                let delta = i64_at(buf, upper + UPPER.table + 8 * n).unwrap_or(0);
                let what = format!("upper node {k} child {n}");
                let lower = child_at(buf, upper, delta, LOWER.size, &what)?;
                lowers.add(lower, offset(origin, UPPER.child_offset(n)), &what)?;
            }
        }
        lowers.check_complete()?;

        let mut leaves = Level::new("leaf", counts.nodes[0], kind.leaf_size(0), buf.len())?;
        for (k, &(lower, origin)) in lowers.nodes.iter().enumerate() {
            let (children, tiles) = internal_slots(buf, lower, &LOWER);
            voxels += (tiles.len() as u128) << 9;
            tree.blocks = tree.blocks.saturating_add(tiles.len() as u64);
            for n in children {
                let delta = i64_at(buf, lower + LOWER.table + 8 * n).unwrap_or(0);
                let what = format!("lower node {k} child {n}");
                let log2_bits = if kind == ValueKind::VariableQuantized {
                    // The leaf's own flags give its size: read them once the header is in.
                    let head = child_at(buf, lower, delta, leaf::FP_CODES, &what)?;
                    let log2_bits = u32::from(u8_at(buf, head + leaf::FLAGS).unwrap_or(0) >> 5);
                    if log2_bits > 4 {
                        return Err(DecodeError(format!(
                            "FpN leaf at byte {head} ({what}) has bit-width code {log2_bits} (at most 4: 16 bits)"
                        )));
                    }
                    log2_bits
                } else {
                    0
                };
                let leaf_off = child_at(buf, lower, delta, kind.leaf_size(log2_bits), &what)?;
                let leaf_origin = offset(origin, LOWER.child_offset(n));
                leaves.add(leaf_off, leaf_origin, &what)?;
                for w in 0..8 {
                    let mask = u64_at(buf, leaf_off + leaf::VALUE_MASK + 8 * w).unwrap_or(0);
                    voxels += u128::from(mask.count_ones());
                }
            }
        }
        leaves.check_complete()?;
        tree.blocks = tree.blocks.saturating_add(leaves.nodes.len() as u64);

        if voxels != u128::from(counts.voxels) {
            return Err(DecodeError(format!(
                "the tree header states {} active voxels, the tree holds {voxels}",
                counts.voxels
            )));
        }
        Ok(tree)
    }

    /// The background value.
    pub(crate) fn background(&self) -> f64 {
        self.background
    }

    /// The number of 8^3 blocks that hold data (leaves plus active tiles in blocks).
    pub(crate) fn block_count(&self) -> u64 {
        self.blocks
    }

    /// Walks from the root to the node holding voxel `ijk`.
    pub(crate) fn find(&self, buf: &[u8], ijk: Coord) -> Hit {
        let upper = match self.lookup.get(&root_key(ijk)) {
            Some(RootSlot::Child(upper)) => *upper,
            Some(RootSlot::Active(value)) => return Hit::Value(*value),
            _ => return Hit::Background,
        };
        let lower = match step(buf, upper, &UPPER, ijk) {
            Step::Child(lower) => lower,
            Step::Value(value) => return Hit::Value(value),
            Step::Background => return Hit::Background,
        };
        match step(buf, lower, &LOWER, ijk) {
            Step::Child(leaf) => Hit::Leaf(leaf),
            Step::Value(value) => Hit::Value(value),
            Step::Background => Hit::Background,
        }
    }

    /// The value of an active tile at buffer position `pos`, as f32.
    pub(crate) fn tile_f32(&self, buf: &[u8], pos: usize) -> f32 {
        if self.kind == ValueKind::F64 {
            f64_at(buf, pos).map_or(self.background as f32, |v| v as f32)
        } else {
            f32_at(buf, pos).unwrap_or(self.background as f32)
        }
    }

    /// The value of an active tile at buffer position `pos`, as f64.
    pub(crate) fn tile_f64(&self, buf: &[u8], pos: usize) -> f64 {
        if self.kind == ValueKind::F64 {
            f64_at(buf, pos).unwrap_or(self.background)
        } else {
            f32_at(buf, pos).map_or(self.background, f64::from)
        }
    }

    /// A reader of the leaf at buffer position `off`.
    pub(crate) fn leaf(&self, buf: &[u8], off: usize) -> LeafView {
        let values = off + self.kind.leaf_values();
        let codes = |bits: u32| Decode::Codes {
            bits,
            minimum: f32_at(buf, off + leaf::FP_MINIMUM).unwrap_or(0.0),
            quantum: f32_at(buf, off + leaf::FP_QUANTUM).unwrap_or(0.0),
        };
        let decode = match self.kind {
            ValueKind::F32 => Decode::F32,
            ValueKind::F64 => Decode::F64,
            ValueKind::Quantized(bits) => codes(bits),
            ValueKind::VariableQuantized => {
                let log2_bits = u8_at(buf, off + leaf::FLAGS).unwrap_or(0) >> 5;
                codes(1 << log2_bits.min(4))
            }
        };
        LeafView {
            mask: off + leaf::VALUE_MASK,
            values,
            decode,
        }
    }

    /// Calls `f` with the origin of every 8^3 block that holds data: each leaf and each
    /// active tile cut into blocks.
    pub(crate) fn for_each_block(&self, buf: &[u8], mut f: impl FnMut(Coord)) {
        let mut blocks_of = |origin: Coord, side: i32| {
            for x in (0..side).step_by(8) {
                for y in (0..side).step_by(8) {
                    for z in (0..side).step_by(8) {
                        f([origin[0] + x, origin[1] + y, origin[2] + z]);
                    }
                }
            }
        };
        for &(origin, slot) in &self.tiles {
            let upper = match slot {
                RootSlot::Child(upper) => upper,
                RootSlot::Active(_) => {
                    blocks_of(origin, 4096);
                    continue;
                }
                RootSlot::Inactive => continue,
            };
            let (lowers, tiles) = internal_slots(buf, upper, &UPPER);
            for n in tiles {
                blocks_of(offset(origin, UPPER.child_offset(n)), 128);
            }
            for n in lowers {
                let lower_origin = offset(origin, UPPER.child_offset(n));
                let Some(lower) =
                    i64_at(buf, upper + UPPER.table + 8 * n).and_then(|d| offset_by(upper, d))
                else {
                    continue;
                };
                let (leaves, tiles) = internal_slots(buf, lower, &LOWER);
                for n in leaves.into_iter().chain(tiles) {
                    blocks_of(offset(lower_origin, LOWER.child_offset(n)), 8);
                }
            }
        }
    }
}

fn offset(origin: Coord, by: [i32; 3]) -> Coord {
    std::array::from_fn(|a| origin[a] + by[a])
}

/// Where one step down an internal node leads.
enum Step {
    /// The child node at this buffer position.
    Child(usize),
    /// An active tile whose value is at this buffer position.
    Value(usize),
    /// An inactive tile.
    Background,
}

/// One step down the internal node at `node` towards voxel `ijk`.
fn step(buf: &[u8], node: usize, layout: &Internal, ijk: Coord) -> Step {
    let n = layout.slot(ijk);
    let entry = node + layout.table + 8 * n;
    if mask_bit(buf, node + layout.child_mask, n) {
        i64_at(buf, entry)
            .and_then(|d| offset_by(node, d))
            .map_or(Step::Background, Step::Child)
    } else if mask_bit(buf, node + layout.value_mask, n) {
        Step::Value(entry)
    } else {
        Step::Background
    }
}

/// How a leaf's values decode.
#[derive(Clone, Copy, Debug)]
enum Decode {
    F32,
    F64,
    /// `minimum + quantum * code` with `bits`-bit codes packed from the low bits of
    /// little-endian words (NanoVDB's Fp4/Fp8/Fp16/FpN decoding, in f32).
    Codes {
        bits: u32,
        minimum: f32,
        quantum: f32,
    },
}

/// Reads the voxels of one leaf.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LeafView {
    mask: usize,
    values: usize,
    decode: Decode,
}

impl LeafView {
    /// Whether voxel slot `n` is active.
    fn active(&self, buf: &[u8], n: usize) -> bool {
        mask_bit(buf, self.mask, n)
    }

    fn code(&self, buf: &[u8], n: usize, bits: u32) -> Option<u32> {
        let bit = n * bits as usize;
        let word = u32_at(buf, self.values + 4 * (bit >> 5))?;
        let mask = ((1u64 << bits) - 1) as u32;
        Some((word >> (bit & 31)) & mask)
    }

    /// Voxel slot `n` as f32 (`background` when inactive).
    pub(crate) fn f32(&self, buf: &[u8], n: usize, background: f32) -> f32 {
        if !self.active(buf, n) {
            return background;
        }
        match self.decode {
            Decode::F32 => f32_at(buf, self.values + 4 * n),
            Decode::F64 => f64_at(buf, self.values + 8 * n).map(|v| v as f32),
            Decode::Codes {
                bits,
                minimum,
                quantum,
            } => self
                .code(buf, n, bits)
                .map(|c| c as f32 * quantum + minimum),
        }
        .unwrap_or(background)
    }

    /// Voxel slot `n` as f64 (`background` when inactive); exact for f64 grids.
    pub(crate) fn f64(&self, buf: &[u8], n: usize, background: f64) -> f64 {
        match self.decode {
            Decode::F64 if self.active(buf, n) => {
                f64_at(buf, self.values + 8 * n).unwrap_or(background)
            }
            Decode::F64 => background,
            _ => f64::from(self.f32(buf, n, background as f32)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn root_keys_round_trip_and_reject_stray_bits() {
        for ijk in [
            [0, 0, 0],
            [-1, -1, -1],
            [4096, -4097, i32::MAX],
            [i32::MIN, 5, 7],
        ] {
            let key = root_key(ijk);
            let origin = key_origin(key).unwrap();
            assert_eq!(origin, ijk.map(|c| c & !4095));
            assert_eq!(root_key(origin), key);
        }
        assert_eq!(key_origin(1 << 20), None);
        assert_eq!(key_origin(1 << 63), None);
    }

    #[test]
    fn codes_unpack_from_little_endian_words() {
        // Slot n of a b-bit code array sits at bits n*b .. n*b+b of the byte stream.
        let mut buf = vec![0u8; 64 + 96 + 1024];
        let view = |bits| LeafView {
            mask: 0,
            values: 96,
            decode: Decode::Codes {
                bits,
                minimum: 1.0,
                quantum: 0.5,
            },
        };
        buf[..64].fill(0xff);
        buf[96] = 0xab; // Fp4: slot 0 = 0xb, slot 1 = 0xa
        buf[97] = 0x12;
        assert_eq!(view(4).f32(&buf, 0, -1.0), 1.0 + 0.5 * 11.0);
        assert_eq!(view(4).f32(&buf, 1, -1.0), 1.0 + 0.5 * 10.0);
        assert_eq!(view(8).f32(&buf, 1, -1.0), 1.0 + 0.5 * 18.0);
        assert_eq!(view(16).f32(&buf, 0, -1.0), 1.0 + 0.5 * 0x12ab as f32);
        assert_eq!(view(1).f32(&buf, 3, -1.0), 1.5); // 0xab = 1010_1011: bit 3 is 1
        assert_eq!(view(2).f32(&buf, 2, -1.0), 1.0 + 0.5 * 2.0); // bits 4..6 of 0xab = 0b10
        buf[0] = 0xfe; // slot 0 inactive
        assert_eq!(view(4).f32(&buf, 0, -1.0), -1.0);
    }
}
