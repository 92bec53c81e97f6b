//! The OpenVDB file layout, file format versions 222 to 225 (OpenVDB 3.0 to 12).
//!
//! A file is a header (magic number, format and library versions, UUID, file metadata), then
//! one descriptor per grid (name, tree type, instance parent, offsets of the grid, of its
//! leaf buffers and of the next descriptor). At its offset a grid holds its compression
//! flags, its metadata, its transform and its tree topology (root background and tiles,
//! 32^3 and 16^3 internal nodes with their child masks, value masks and tile values, leaf
//! value masks); its leaf buffers follow at the buffer offset, in topology order.
//! Everything is little-endian. Every read is bounds-checked: a truncated or corrupt file
//! yields an error message, never a panic, and no allocation exceeds what the file holds
//! (or a node's fixed size).

use crate::decode_error::DecodeError;
use crate::grid::{Coord, GridMap};

use super::codec::read_data;

/// Per-grid compression flags (io/Compression.h).
pub(super) const COMPRESS_ZIP: u32 = 0x1;
pub(super) const COMPRESS_ACTIVE_MASK: u32 = 0x2;
pub(super) const COMPRESS_BLOSC: u32 = 0x4;

const MAGIC: [u8; 8] = [0x20, 0x42, 0x44, 0x56, 0, 0, 0, 0];
/// OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION: per-grid compression, full node value arrays.
const MIN_VERSION: u32 = 222;
/// OPENVDB_FILE_VERSION_HALF_GRID (OpenVDB 12).
const MAX_VERSION: u32 = 225;
/// Separator of the suffix OpenVDB appends to repeated grid names.
pub(super) const NAME_SEP: char = '\u{1e}';
const HALF_SUFFIX: &str = "_HalfFloat";

/// A bounds-checked reader over the file's bytes.
pub(super) struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    pub(super) fn new(data: &'a [u8], pos: usize) -> Cursor<'a> {
        Cursor { data, pos }
    }

    pub(super) fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.data.len());
        let end = end.ok_or_else(|| {
            DecodeError(format!(
                "unexpected end of file: {n} bytes needed at byte {} of {}",
                self.pos,
                self.data.len()
            ))
        })?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }

    fn u32(&mut self) -> Result<u32, DecodeError> {
        self.array().map(u32::from_le_bytes)
    }

    fn i32(&mut self) -> Result<i32, DecodeError> {
        self.array().map(i32::from_le_bytes)
    }

    pub(super) fn i64(&mut self) -> Result<i64, DecodeError> {
        self.array().map(i64::from_le_bytes)
    }

    fn f64(&mut self) -> Result<f64, DecodeError> {
        self.array().map(f64::from_le_bytes)
    }

    fn vec3(&mut self) -> Result<[f64; 3], DecodeError> {
        Ok([self.f64()?, self.f64()?, self.f64()?])
    }

    fn coord(&mut self) -> Result<Coord, DecodeError> {
        Ok([self.i32()?, self.i32()?, self.i32()?])
    }

    fn string(&mut self) -> Result<String, DecodeError> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }

    /// A file offset stored as i64, checked to lie inside the file.
    fn offset(&mut self) -> Result<usize, DecodeError> {
        let v = self.i64()?;
        usize::try_from(v)
            .ok()
            .filter(|&o| o <= self.data.len())
            .ok_or_else(|| DecodeError(format!("offset {v} lies outside the file")))
    }

    fn mask(&mut self, bits: usize) -> Result<Vec<u64>, DecodeError> {
        let bytes = self.take(bits / 8)?;
        Ok(bytes
            .chunks_exact(8)
            .map(|w| u64::from_le_bytes(w.try_into().expect("8-byte chunk")))
            .collect())
    }
}

fn bit(mask: &[u64], i: usize) -> bool {
    mask[i >> 6] >> (i & 63) & 1 == 1
}

fn ones(mask: &[u64]) -> impl Iterator<Item = usize> + '_ {
    (0..mask.len() * 64).filter(move |&i| bit(mask, i))
}

/// What a descriptor and the head of its grid say, before the tree.
pub(super) struct Descriptor {
    /// Name as stored, with OpenVDB's suffix for repeated names.
    pub unique_name: String,
    pub name: String,
    /// Tree type without the half-float suffix, e.g. `Tree_float_5_4_3`.
    pub tree_type: String,
    pub instance_parent: String,
    pub half: bool,
    pub compression: u32,
    pub class: Option<String>,
    pub bbox: Option<[Coord; 2]>,
    pub voxel_count: Option<u64>,
    pub map_type: String,
    pub map: Result<GridMap, DecodeError>,
    /// Where the tree topology starts (unknown when the transform could not be read).
    pub topology_pos: Option<usize>,
    pub block_pos: usize,
}

/// The grid descriptors of a whole file.
pub(super) fn descriptors(data: &[u8]) -> Result<Vec<Descriptor>, DecodeError> {
    let mut cur = Cursor::new(data, 0);
    if cur.take(8).ok() != Some(&MAGIC[..]) {
        return Err(DecodeError("not an OpenVDB file (bad magic number)".into()));
    }
    let version = cur.u32()?;
    if version < MIN_VERSION {
        return Err(DecodeError(format!(
            "file format version {version} predates {MIN_VERSION} (OpenVDB 3.0); \
             re-save the file with a newer OpenVDB"
        )));
    }
    if version > MAX_VERSION {
        return Err(DecodeError(format!(
            "file format version {version} is newer than {MAX_VERSION}, the newest this reader knows"
        )));
    }
    let _library_version = (cur.u32()?, cur.u32()?);
    if cur.u8()? == 0 {
        return Err(DecodeError(
            "the file was written as a stream without grid offsets".into(),
        ));
    }
    let _uuid = cur.take(36)?;
    metadata(&mut cur)?;
    let count = cur.u32()?;
    let mut out = Vec::new();
    for _ in 0..count {
        let unique_name = cur.string()?;
        let stored_type = cur.string()?;
        let instance_parent = cur.string()?;
        let (grid_pos, block_pos, end_pos) = (cur.offset()?, cur.offset()?, cur.offset()?);
        // Each grid lies after its descriptor, so the walk only moves forward. An instance
        // has no buffers of its own (block offset 0).
        let blocks_ok = (grid_pos..=end_pos).contains(&block_pos)
            || (!instance_parent.is_empty() && block_pos == 0);
        if !(cur.pos <= grid_pos && grid_pos <= end_pos && blocks_ok) {
            return Err(DecodeError(format!(
                "corrupt offsets of grid '{unique_name}': {grid_pos}, {block_pos}, {end_pos}"
            )));
        }
        let mut g = Cursor::new(data, grid_pos);
        let compression = g.u32()?;
        if compression > (COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC) {
            return Err(DecodeError(format!(
                "grid '{unique_name}': unknown compression flags {compression:#x}"
            )));
        }
        let meta = metadata(&mut g)?;
        let map_type = g.string()?;
        let map = transform(&mut g, &map_type);
        let (tree_type, half_suffix) = match stored_type.strip_suffix(HALF_SUFFIX) {
            Some(t) => (t.to_string(), true),
            None => (stored_type, false),
        };
        out.push(Descriptor {
            name: unique_name
                .split(NAME_SEP)
                .next()
                .unwrap_or_default()
                .to_string(),
            unique_name,
            tree_type,
            instance_parent,
            half: half_suffix || meta.half,
            compression,
            class: meta.class,
            bbox: meta.bbox_min.zip(meta.bbox_max).map(|(a, b)| [a, b]),
            voxel_count: meta.voxel_count,
            map_type,
            topology_pos: map.is_ok().then_some(g.pos),
            map,
            block_pos,
        });
        cur = Cursor::new(data, end_pos);
    }
    Ok(out)
}

#[derive(Default)]
struct Meta {
    class: Option<String>,
    bbox_min: Option<Coord>,
    bbox_max: Option<Coord>,
    voxel_count: Option<u64>,
    half: bool,
}

/// Reads a metadata map, keeping the entries the reader uses.
fn metadata(cur: &mut Cursor) -> Result<Meta, DecodeError> {
    let mut m = Meta::default();
    for _ in 0..cur.u32()? {
        let name = cur.string()?;
        let ty = cur.string()?;
        let size = cur.u32()? as usize;
        let mut v = Cursor::new(cur.take(size)?, 0);
        match (name.as_str(), ty.as_str(), size) {
            ("class", "string", _) => m.class = Some(String::from_utf8_lossy(v.data).into()),
            ("file_bbox_min", "vec3i", 12) => m.bbox_min = Some(v.coord()?),
            ("file_bbox_max", "vec3i", 12) => m.bbox_max = Some(v.coord()?),
            ("file_voxel_count", "int64", 8) => m.voxel_count = u64::try_from(v.i64()?).ok(),
            ("is_saved_as_half_float", "bool", 1) => m.half = v.u8()? != 0,
            _ => {}
        }
    }
    Ok(m)
}

/// Reads the map of type `name` (math/Maps.h); only affine maps become a [`GridMap`].
fn transform(cur: &mut Cursor, name: &str) -> Result<GridMap, DecodeError> {
    const I: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let diag = |s: [f64; 3]| std::array::from_fn(|r| std::array::from_fn(|c| I[r][c] * s[r]));
    let (linear, translation) = match name {
        // Scale values, then voxel size, inverse scale, inverse scale squared, 1/(2 scale).
        "ScaleMap" | "UniformScaleMap" => {
            let s = cur.vec3()?;
            cur.take(4 * 24)?;
            (diag(s), [0.0; 3])
        }
        "ScaleTranslateMap" | "UniformScaleTranslateMap" => {
            let t = cur.vec3()?;
            let s = cur.vec3()?;
            cur.take(4 * 24)?;
            (diag(s), t)
        }
        "TranslationMap" => (I, cur.vec3()?),
        // A 4x4 matrix, row-major, for row vectors: world = [i j k 1] * M.
        "AffineMap" | "UnitaryMap" => {
            let mut m = [[0.0; 4]; 4];
            for v in m.iter_mut().flatten() {
                *v = cur.f64()?;
            }
            if m[0][3] != 0.0 || m[1][3] != 0.0 || m[2][3] != 0.0 || m[3][3] != 1.0 {
                return Err(DecodeError(format!(
                    "{name} has a projective last column {:?}",
                    [m[0][3], m[1][3], m[2][3], m[3][3]]
                )));
            }
            let linear = std::array::from_fn(|r| std::array::from_fn(|c| m[c][r]));
            (linear, [m[3][0], m[3][1], m[3][2]])
        }
        "NonlinearFrustumMap" => {
            return Err(DecodeError(
                "the transform is a frustum (NonlinearFrustumMap), which is not affine; \
                 only affine transforms are supported"
                    .into(),
            ))
        }
        other => return Err(DecodeError(format!("unknown transform type '{other}'"))),
    };
    GridMap::new(linear, translation).map_err(|e| DecodeError(e.0))
}

/// Scalar value types the reader loads.
#[derive(Clone, Copy, PartialEq, Debug)]
pub(super) enum Scalar {
    F16,
    F32,
    F64,
}

impl Scalar {
    pub(super) fn of_tree(tree_type: &str) -> Option<Scalar> {
        match tree_type {
            "Tree_half_5_4_3" => Some(Scalar::F16),
            "Tree_float_5_4_3" => Some(Scalar::F32),
            "Tree_double_5_4_3" => Some(Scalar::F64),
            _ => None,
        }
    }

    fn size(self) -> usize {
        match self {
            Scalar::F16 => 2,
            Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    /// The type buffers are stored in when the grid was saved with half floats.
    fn halved(self) -> Scalar {
        match self {
            Scalar::F16 | Scalar::F32 => Scalar::F16,
            Scalar::F64 => Scalar::F32,
        }
    }

    /// The value at the start of `b`, as f32; errors on values f32 cannot hold.
    fn decode(self, b: &[u8]) -> Result<f32, DecodeError> {
        let v = match self {
            Scalar::F16 => half::f16::from_le_bytes([b[0], b[1]]).to_f32(),
            Scalar::F32 => f32::from_le_bytes(b[..4].try_into().expect("4 bytes")),
            Scalar::F64 => {
                let d = f64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
                let f = d as f32;
                if d.is_finite() && !f.is_finite() {
                    return Err(DecodeError(format!("double value {d} does not fit in f32")));
                }
                f
            }
        };
        Ok(v)
    }

    fn read(self, cur: &mut Cursor) -> Result<f32, DecodeError> {
        self.decode(cur.take(self.size())?)
    }
}

/// How one grid's buffers are stored.
#[derive(Clone, Copy)]
pub(super) struct Storage {
    pub scalar: Scalar,
    pub half: bool,
    pub compression: u32,
}

/// A tree as the reader keeps it: only what differs from the background.
pub(super) struct Tree {
    pub background: f32,
    /// Leaf origin and its 8^3 values, x fastest, inactive voxels set to the background.
    pub leaves: Vec<(Coord, [f32; 512])>,
    /// Active tiles: origin, side (8, 128 or 4096) and value.
    pub tiles: Vec<(Coord, i32, f32)>,
}

/// Reads the tree whose topology starts at `topology_pos` and whose leaf buffers start at
/// `block_pos`.
pub(super) fn tree(
    data: &[u8],
    topology_pos: usize,
    block_pos: usize,
    st: Storage,
) -> Result<Tree, DecodeError> {
    let mut cur = Cursor::new(data, topology_pos);
    let _buffer_count = cur.i32()?;
    let background = st.scalar.read(&mut cur)?;
    if !background.is_finite() {
        return Err(DecodeError(format!(
            "background {background} is not finite"
        )));
    }
    let mut tree = Tree {
        background,
        leaves: Vec::new(),
        tiles: Vec::new(),
    };
    let (num_tiles, num_children) = (cur.u32()?, cur.u32()?);
    let aligned = |c: Coord, side: i32| -> Result<Coord, DecodeError> {
        if c.iter().all(|v| v & (side - 1) == 0) {
            Ok(c)
        } else {
            Err(DecodeError(format!("corrupt root entry at {c:?}")))
        }
    };
    for _ in 0..num_tiles {
        let origin = aligned(cur.coord()?, 4096)?;
        let value = st.scalar.read(&mut cur)?;
        if cur.u8()? != 0 {
            tree.add_tile(origin, 4096, value)?;
        }
    }
    // Leaf value masks in topology order; their buffers follow in the same order.
    let mut leaf_masks: Vec<(Coord, Vec<u64>)> = Vec::new();
    for _ in 0..num_children {
        let origin = aligned(cur.coord()?, 4096)?;
        let (children, values) = internal(&mut cur, st, 5, background)?;
        for (i, v) in values {
            tree.add_tile(child_origin(origin, i, 5, 7), 128, v)?;
        }
        for i in children {
            let origin4 = child_origin(origin, i, 5, 7);
            let (leaves, values) = internal(&mut cur, st, 4, background)?;
            for (i, v) in values {
                tree.add_tile(child_origin(origin4, i, 4, 3), 8, v)?;
            }
            for i in leaves {
                leaf_masks.push((child_origin(origin4, i, 4, 3), cur.mask(512)?));
            }
        }
    }
    let mut cur = Cursor::new(data, block_pos);
    for (origin, mask) in leaf_masks {
        cur.take(64)?; // the value mask again
        let values = compressed_values(&mut cur, st, 512, &mask, background)?;
        let mut leaf = [background; 512];
        for (i, v) in values.into_iter().enumerate() {
            // OpenVDB orders a leaf's voxels z fastest; the reader keeps x fastest.
            leaf[(i >> 6) | (i >> 3 & 7) << 3 | (i & 7) << 6] = v;
        }
        if leaf.iter().any(|&v| v != background) {
            tree.leaves.push((origin, leaf));
        }
    }
    Ok(tree)
}

impl Tree {
    fn add_tile(&mut self, origin: Coord, side: i32, value: f32) -> Result<(), DecodeError> {
        if !value.is_finite() {
            return Err(DecodeError(format!(
                "tile at {origin:?} has non-finite value {value}"
            )));
        }
        if value != self.background {
            self.tiles.push((origin, side, value));
        }
        Ok(())
    }
}

/// Origin of child `i` of a node of `log2` children per side, each `1 << child_log2` wide.
fn child_origin(origin: Coord, i: usize, log2: u32, child_log2: u32) -> Coord {
    let n = (1 << log2) - 1;
    let local = [i >> (2 * log2), (i >> log2) & n, i & n];
    std::array::from_fn(|k| origin[k] + ((local[k] as i32) << child_log2))
}

/// An internal node's topology: indices of its children and its active tiles' values.
type NodeTopology = (Vec<usize>, Vec<(usize, f32)>);

/// Reads an internal node with `1 << log2` children per side (InternalNode::readTopology).
fn internal(
    cur: &mut Cursor,
    st: Storage,
    log2: u32,
    background: f32,
) -> Result<NodeTopology, DecodeError> {
    let size = 1 << (3 * log2);
    let child_mask = cur.mask(size)?;
    let value_mask = cur.mask(size)?;
    let values = compressed_values(cur, st, size, &value_mask, background)?;
    let tiles = ones(&value_mask)
        .filter(|&i| !bit(&child_mask, i))
        .map(|i| (i, values[i]))
        .collect();
    Ok((ones(&child_mask).collect(), tiles))
}

/// Reads `count` node values (io::readCompressedValues); inactive ones come back as the
/// background, whatever the file stores for them.
fn compressed_values(
    cur: &mut Cursor,
    st: Storage,
    count: usize,
    value_mask: &[u64],
    background: f32,
) -> Result<Vec<f32>, DecodeError> {
    // 0: no inactive values or all +background; 1: all -background; 2: one other value;
    // 3: mask picks -/+background; 4: mask picks background or one value; 5: mask picks
    // one of two values; 6: every value is stored.
    let meta = cur.u8()?;
    if meta > 6 {
        return Err(DecodeError(format!(
            "corrupt node: inactive-value code {meta}"
        )));
    }
    if matches!(meta, 2 | 4 | 5) {
        cur.take(st.scalar.size())?;
    }
    if meta == 5 {
        cur.take(st.scalar.size())?;
    }
    if matches!(meta, 3..=5) {
        cur.take(count / 8)?; // selection mask
    }
    let active = ones(value_mask).count();
    let stored = if st.compression & COMPRESS_ACTIVE_MASK != 0 && meta != 6 {
        active
    } else {
        count
    };
    let ty = if st.half {
        st.scalar.halved()
    } else {
        st.scalar
    };
    // Half buffers of no values are not written at all (io::HalfWriter).
    let bytes = if st.half && stored == 0 {
        Vec::new()
    } else {
        read_data(cur, st.compression, stored * ty.size())?
    };
    let mut out = vec![background; count];
    let mut k = 0;
    for (i, slot) in out.iter_mut().enumerate() {
        let active = bit(value_mask, i);
        if stored == count || active {
            let v = ty.decode(&bytes[k * ty.size()..])?;
            k += 1;
            if active {
                if !v.is_finite() {
                    return Err(DecodeError(format!("non-finite voxel value {v}")));
                }
                *slot = v;
            }
        }
    }
    Ok(out)
}
