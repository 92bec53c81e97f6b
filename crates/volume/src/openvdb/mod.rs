//! OpenVDB `.vdb` files: a pure-Rust reader for scalar grids.
//!
//! [`VdbFile::open`] lists every grid of a file (name, value type, transform, bounding box,
//! active voxel count); [`VdbFile::load`] reads one float, double or half grid into a
//! [`VdbGrid`], a map of 8^3 blocks (OpenVDB's leaves and leaf-sized tiles) plus the larger
//! tiles, which implements [`VoxelGrid`]. [`read_vdb`] loads every scalar grid of a file.
//!
//! Supported: file format versions 222 to 225 (OpenVDB 3.0 to 12), standard 5-4-3 trees,
//! the codecs none, zip and Blosc (LZ4, as OpenVDB writes it), active-mask compression,
//! values saved as half floats, instanced grids (sharing another grid's tree), tiles at every
//! level, and the affine transforms (scale, translation, scale-translate, affine, unitary).
//! Not supported, each with a clear error: frustum transforms, other value types (vectors,
//! integers, booleans, points), trees of other shapes, files written as streams without grid
//! offsets. Double values are rounded to f32. Inactive voxels read as the background.
//!
//! The `vdb-rs` crate was not used: its 0.6.0 release panics on affine transforms, drops the
//! background and root tiles, misreads half-float files, and decodes Blosc through C code
//! that trusts sizes stored in the file.

mod codec;
mod format;

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::path::{Path, PathBuf};

use crate::decode_error::DecodeError;
use crate::dense::VolumeError;
use crate::grid::{Coord, GridMap, VoxelGrid, BLOCK_SIDE};
use crate::ranges::MAX_RANGE_BLOCKS;

use format::{Descriptor, Scalar, Storage, COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC, COMPRESS_ZIP};

/// What a `.vdb` file says about one of its grids, read without its voxels.
#[derive(Clone, Debug, PartialEq)]
pub struct VdbGridInfo {
    /// Grid name (several grids of a file may share one).
    pub name: String,
    /// Value type from the tree type: `float`, `double`, `half`, `vec3s`, `int32`, ...
    pub value_type: String,
    /// Tree type as stored, e.g. `Tree_float_5_4_3`.
    pub tree_type: String,
    /// Whether float values were saved as 16-bit halves.
    pub saved_as_half: bool,
    /// Codec of the grid's buffers: `none`, `zip` or `blosc`, with `+ active mask` when
    /// only active values are stored.
    pub compression: String,
    /// OpenVDB's transform type, e.g. `AffineMap`, `UniformScaleMap`.
    pub transform: String,
    /// The grid class metadata (`fog volume`, `level set`, ...), when present.
    pub class: Option<String>,
    /// Inclusive index bounds of the active voxels, as the file records them.
    pub bbox: Option<[Coord; 2]>,
    /// Number of active voxels (tiles count all their voxels), as the file records it.
    pub active_voxel_count: Option<u64>,
    /// Name of the grid whose tree this grid shares, when it is an instance.
    pub instance_of: Option<String>,
}

/// An opened `.vdb` file: its bytes and the list of its grids.
pub struct VdbFile {
    /// Where the file was read from.
    pub path: PathBuf,
    /// Every grid of the file, in file order.
    pub grids: Vec<VdbGridInfo>,
    data: Vec<u8>,
    descriptors: Vec<Descriptor>,
}

impl VdbFile {
    /// Reads the file and its grid list; errors name the file.
    pub fn open(path: &Path) -> Result<VdbFile, VolumeError> {
        let data = std::fs::read(path)
            .map_err(|e| VolumeError(format!("{}: cannot read: {e}", path.display())))?;
        VdbFile::from_bytes(path, data)
    }

    /// Reads the grid list of a file's contents already in memory; `path` names it in
    /// errors.
    pub fn from_bytes(path: &Path, data: Vec<u8>) -> Result<VdbFile, VolumeError> {
        let fail = |msg: DecodeError| VolumeError(format!("{}: {msg}", path.display()));
        let descriptors = format::descriptors(&data).map_err(fail)?;
        let grids = descriptors.iter().map(info).collect();
        Ok(VdbFile {
            path: path.to_path_buf(),
            grids,
            data,
            descriptors,
        })
    }

    /// Loads grid `index` of [`VdbFile::grids`]; errors (naming the file and the grid) for
    /// grids that are not float, double or half, for transforms that are not affine, and for
    /// corrupt data.
    pub fn load(&self, index: usize) -> Result<VdbGrid, VolumeError> {
        let d = self.descriptors.get(index).ok_or_else(|| {
            VolumeError(format!(
                "{}: no grid {index} (the file has {})",
                self.path.display(),
                self.descriptors.len()
            ))
        })?;
        let fail = |msg: DecodeError| {
            VolumeError(format!("{}: grid '{}': {msg}", self.path.display(), d.name))
        };
        let map = d.map.clone().map_err(fail)?;
        let owner = self.tree_owner(d).map_err(fail)?;
        let scalar = Scalar::of_tree(&owner.tree_type).ok_or_else(|| {
            fail(DecodeError(format!(
                "holds {} values ({}); only float, double and half grids are voxel sources",
                self.grids[index].value_type, owner.tree_type
            )))
        })?;
        let storage = Storage {
            scalar,
            half: owner.half,
            compression: owner.compression,
        };
        let topology = owner.topology_pos.ok_or_else(|| {
            fail(DecodeError(format!(
                "the transform of its tree's grid '{}' is unreadable",
                owner.name
            )))
        })?;
        let tree = format::tree(&self.data, topology, owner.block_pos, storage).map_err(fail)?;
        VdbGrid::build(self.grids[index].clone(), map, tree).map_err(fail)
    }

    /// The descriptor whose tree `d` uses: `d` itself or its instance parent.
    fn tree_owner<'a>(&'a self, mut d: &'a Descriptor) -> Result<&'a Descriptor, DecodeError> {
        for _ in 0..=self.descriptors.len() {
            if d.instance_parent.is_empty() {
                return Ok(d);
            }
            d = self
                .descriptors
                .iter()
                .find(|p| p.unique_name == d.instance_parent)
                .ok_or_else(|| {
                    DecodeError(format!("missing instance parent '{}'", d.instance_parent))
                })?;
        }
        Err(DecodeError("instance parents form a cycle".into()))
    }
}

fn info(d: &Descriptor) -> VdbGridInfo {
    let codec = if d.compression & COMPRESS_BLOSC != 0 {
        "blosc"
    } else if d.compression & COMPRESS_ZIP != 0 {
        "zip"
    } else {
        "none"
    };
    let mask = if d.compression & COMPRESS_ACTIVE_MASK != 0 {
        " + active mask"
    } else {
        ""
    };
    let body = d.tree_type.strip_prefix("Tree_").unwrap_or(&d.tree_type);
    VdbGridInfo {
        name: d.name.clone(),
        value_type: body.strip_suffix("_5_4_3").unwrap_or(body).to_string(),
        tree_type: d.tree_type.clone(),
        saved_as_half: d.half,
        compression: format!("{codec}{mask}"),
        transform: d.map_type.clone(),
        class: d.class.clone(),
        bbox: d.bbox,
        active_voxel_count: d.voxel_count,
        instance_of: (!d.instance_parent.is_empty()).then(|| {
            d.instance_parent
                .split(format::NAME_SEP)
                .next()
                .unwrap_or_default()
                .into()
        }),
    }
}

/// Loads every float, double and half grid of a `.vdb` file, in file order; grids of other
/// value types are skipped ([`VdbFile::open`] lists them). Errors name the file and grid.
pub fn read_vdb(path: &Path) -> Result<Vec<VdbGrid>, VolumeError> {
    let file = VdbFile::open(path)?;
    (0..file.grids.len())
        .filter(|&i| Scalar::of_tree(&file.descriptors[i].tree_type).is_some())
        .map(|i| file.load(i))
        .collect()
}

/// A hasher for block coordinates (FxHash's multiply-rotate): lookups are the hot path.
#[derive(Default)]
struct CoordHasher(u64);

impl Hasher for CoordHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(4) {
            let mut word = [0; 4];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u32(u32::from_le_bytes(word));
        }
    }

    fn write_u32(&mut self, v: u32) {
        self.0 = (self.0.rotate_left(5) ^ v as u64).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

type CoordMap<V> = HashMap<Coord, V, BuildHasherDefault<CoordHasher>>;

/// One 8^3 block: a leaf's values or a leaf-sized tile's value.
#[derive(Clone, Copy)]
enum Block {
    Leaf(u32),
    Constant(f32),
}

/// Sides of the tiles kept apart from the 8^3 blocks: a 32^3 node's tiles, the root's.
const WIDE_SIDES: [i32; 2] = [128, 4096];

/// A scalar OpenVDB grid in memory: 8^3 blocks that differ from the background, plus
/// 128^3 and 4096^3 tiles. Lookups cost one hash probe (up to three off the blocks).
pub struct VdbGrid {
    /// What the file says about the grid.
    pub info: VdbGridInfo,
    background: f32,
    map: GridMap,
    blocks: CoordMap<Block>,
    leaves: Vec<[f32; 512]>,
    wide: [CoordMap<f32>; 2],
}

impl VdbGrid {
    fn build(info: VdbGridInfo, map: GridMap, tree: format::Tree) -> Result<VdbGrid, DecodeError> {
        let mut g = VdbGrid {
            info,
            background: tree.background,
            map,
            blocks: CoordMap::default(),
            leaves: Vec::with_capacity(tree.leaves.len()),
            wide: Default::default(),
        };
        let duplicate = |c: Coord| DecodeError(format!("corrupt tree: two nodes at {c:?}"));
        for (origin, values) in tree.leaves {
            let block = Block::Leaf(g.leaves.len() as u32);
            if g.blocks.insert(origin, block).is_some() {
                return Err(duplicate(origin));
            }
            g.leaves.push(values);
        }
        for (origin, side, value) in tree.tiles {
            let old = match WIDE_SIDES.iter().position(|&s| s == side) {
                Some(w) => g.wide[w].insert(origin, value).map(|_| ()),
                None => g.blocks.insert(origin, Block::Constant(value)).map(|_| ()),
            };
            if old.is_some() {
                return Err(duplicate(origin));
            }
        }
        let per_tile = WIDE_SIDES.map(|s| (s as u64 / BLOCK_SIDE as u64).pow(3));
        let count = g.blocks.len() as u64
            + (0..2)
                .map(|w| g.wide[w].len() as u64 * per_tile[w])
                .sum::<u64>();
        if count > MAX_RANGE_BLOCKS {
            return Err(DecodeError(format!(
                "its tiles and leaves cover {count} blocks of 8^3 voxels, more than {MAX_RANGE_BLOCKS}"
            )));
        }
        Ok(g)
    }

    /// Bytes of the grid in memory: leaf values and the hash maps' entries.
    pub fn memory_bytes(&self) -> usize {
        let entry = size_of::<(Coord, Block)>();
        self.leaves.len() * size_of::<[f32; 512]>()
            + self.blocks.len() * entry
            + self
                .wide
                .iter()
                .map(|w| w.len() * size_of::<(Coord, f32)>())
                .sum::<usize>()
    }

    /// The contents of the 8^3 block at `origin` (a multiple of 8).
    fn block(&self, origin: Coord) -> BlockRef<'_> {
        match self.blocks.get(&origin) {
            Some(Block::Leaf(i)) => BlockRef::Leaf(&self.leaves[*i as usize]),
            Some(Block::Constant(v)) => BlockRef::Constant(*v),
            None => BlockRef::Constant(self.wide_tile(origin).unwrap_or(self.background)),
        }
    }

    fn wide_tile(&self, ijk: Coord) -> Option<f32> {
        WIDE_SIDES.iter().zip(&self.wide).find_map(|(side, tiles)| {
            if tiles.is_empty() {
                None
            } else {
                tiles.get(&ijk.map(|c| c & !(side - 1))).copied()
            }
        })
    }
}

enum BlockRef<'a> {
    Leaf(&'a [f32; 512]),
    Constant(f32),
}

impl VoxelGrid for VdbGrid {
    fn background(&self) -> f32 {
        self.background
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        match self.block(ijk.map(|c| c & !(BLOCK_SIDE - 1))) {
            BlockRef::Leaf(v) => v[(ijk[0] & 7 | (ijk[1] & 7) << 3 | (ijk[2] & 7) << 6) as usize],
            BlockRef::Constant(v) => v,
        }
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        let mut out: Vec<Coord> = self.blocks.keys().copied().collect();
        for (side, tiles) in WIDE_SIDES.iter().zip(&self.wide) {
            for origin in tiles.keys() {
                for z in (0..*side).step_by(BLOCK_SIDE as usize) {
                    for y in (0..*side).step_by(BLOCK_SIDE as usize) {
                        for x in (0..*side).step_by(BLOCK_SIDE as usize) {
                            out.push([origin[0] + x, origin[1] + y, origin[2] + z]);
                        }
                    }
                }
            }
        }
        Ok(out)
    }

    fn map(&self) -> &GridMap {
        &self.map
    }

    /// Copies whole rows per 8^3 block: one hash probe per block instead of per voxel.
    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        let b = BLOCK_SIDE as i64;
        let lo = origin.map(i64::from);
        let hi: [i64; 3] = std::array::from_fn(|k| lo[k] + dims[k] as i64);
        let (nx, ny) = (dims[0] as usize, dims[1] as usize);
        let first = lo.map(|c| c.div_euclid(b) * b);
        for bz in (first[2]..hi[2]).step_by(b as usize) {
            for by in (first[1]..hi[1]).step_by(b as usize) {
                for bx in (first[0]..hi[0]).step_by(b as usize) {
                    let start = [bx, by, bz];
                    // Blocks past the i32 index range read as the background.
                    let block = match start.map(i32::try_from) {
                        [Ok(x), Ok(y), Ok(z)] => self.block([x, y, z]),
                        _ => BlockRef::Constant(self.background),
                    };
                    let from: [i64; 3] = std::array::from_fn(|k| start[k].max(lo[k]));
                    let to: [i64; 3] = std::array::from_fn(|k| (start[k] + b).min(hi[k]));
                    let len = (to[0] - from[0]) as usize;
                    for z in from[2]..to[2] {
                        for y in from[1]..to[1] {
                            let row = ((z - lo[2]) as usize * ny + (y - lo[1]) as usize) * nx
                                + (from[0] - lo[0]) as usize;
                            let dst = &mut out[row..row + len];
                            match block {
                                BlockRef::Leaf(v) => {
                                    let at = ((z - bz) * 64 + (y - by) * 8 + from[0] - bx) as usize;
                                    dst.copy_from_slice(&v[at..at + len]);
                                }
                                BlockRef::Constant(v) => dst.fill(v),
                            }
                        }
                    }
                }
            }
        }
    }
}
