//! One NanoVDB grid: its header facts, its raw buffer and lookups into it.

use super::bytes::{c_string, f64_at, i32_at, u32_at, u64_at};
use super::error::NanoError;
use super::layout::{
    grid, leaf_slot, root, tree, NanoCodec, NanoGridClass, NanoGridType, NanoVersion, MAGIC_GRID,
    MAGIC_NUMB,
};
use super::tree::{HeaderCounts, Hit, Tree, ValueKind};
use crate::dense::VolumeError;
use crate::grid::{Coord, GridMap, VoxelGrid, BLOCK_SIDE};
use crate::ranges::MAX_RANGE_BLOCKS;

/// Node counts of a grid's tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeCounts {
    /// Leaf nodes (8^3 voxels).
    pub leaves: u32,
    /// Lower internal nodes (128^3 voxels).
    pub lower: u32,
    /// Upper internal nodes (4096^3 voxels).
    pub upper: u32,
}

/// Active tile counts of a grid's tree, per level that holds the tiles.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TileCounts {
    /// Tiles of 8^3 voxels in lower nodes.
    pub lower: u32,
    /// Tiles of 128^3 voxels in upper nodes.
    pub upper: u32,
    /// Tiles of 4096^3 voxels in the root.
    pub root: u32,
}

/// A grid of a NanoVDB file: the raw NanoVDB buffer (as a GPU would read it) plus the facts
/// of its header. Float, Double, Fp4, Fp8, Fp16 and FpN grids are validated at load and
/// sampled through [`VoxelGrid`]; grids of other value types are listed but read as their
/// background (see [`NanoGrid::check_sampleable`]).
#[derive(Debug)]
pub struct NanoGrid {
    file: String,
    number: usize,
    name: String,
    codec: NanoCodec,
    version: NanoVersion,
    grid_type: NanoGridType,
    grid_class: NanoGridClass,
    map: GridMap,
    world_bbox: [[f64; 3]; 2],
    voxel_size: [f64; 3],
    index_bbox: [Coord; 2],
    node_counts: NodeCounts,
    tile_counts: TileCounts,
    voxel_count: u64,
    background: f32,
    buffer: Vec<u8>,
    tree: Option<Tree>,
}

fn triple<T>(read: impl Fn(usize) -> Option<T>, off: usize, stride: usize) -> Option<[T; 3]> {
    Some([read(off)?, read(off + stride)?, read(off + 2 * stride)?])
}

impl NanoGrid {
    /// Parses grid `number` of `file` from its decoded buffer. `name` is the file metadata's
    /// name (it may be longer than the 255 characters the grid header keeps).
    pub(crate) fn parse(
        buffer: Vec<u8>,
        name: Option<String>,
        codec: NanoCodec,
        file: &str,
        number: usize,
    ) -> Result<NanoGrid, NanoError> {
        let name = name.unwrap_or_else(|| {
            c_string(
                buffer
                    .get(grid::NAME..grid::NAME + grid::NAME_SIZE)
                    .unwrap_or(&[]),
            )
        });
        let fail = |m: String| NanoError::new(file, format!("grid {number} '{name}': {m}"));
        let b = &buffer[..];
        let header_end = grid::SIZE + tree::SIZE;
        if b.len() < header_end {
            return Err(fail(format!(
                "grid buffer of {} bytes is shorter than the grid and tree headers ({header_end} bytes)",
                b.len()
            )));
        }
        // Every read below lies in the first `header_end` bytes, checked above.
        let u32_ = |off| u32_at(b, off).unwrap_or(0);
        let u64_ = |off| u64_at(b, off).unwrap_or(0);
        let magic = u64_(grid::MAGIC);
        if magic != MAGIC_NUMB && magic != MAGIC_GRID {
            return Err(fail(format!("bad grid magic {magic:#018x}")));
        }
        let version = NanoVersion::from_packed(u32_(grid::VERSION));
        if !version.is_supported() {
            return Err(fail(format!(
                "NanoVDB version {version} is not supported (this reader reads 32.3 and later 32.x)"
            )));
        }
        let stated_size = u64_(grid::GRID_SIZE);
        if stated_size != b.len() as u64 {
            return Err(fail(format!(
                "grid header states {stated_size} bytes, the file gives {}",
                b.len()
            )));
        }
        let f64s = |off| triple(|o| f64_at(b, o), off, 8).unwrap_or([f64::NAN; 3]);
        let matrix = [
            f64s(grid::MAP_MATRIX_F64),
            f64s(grid::MAP_MATRIX_F64 + 24),
            f64s(grid::MAP_MATRIX_F64 + 48),
        ];
        let map = GridMap::new(matrix, f64s(grid::MAP_VECTOR_F64)).map_err(|e| fail(e.0))?;
        let grid_type = NanoGridType::from_code(u32_(grid::TYPE));
        let grid_class = NanoGridClass::from_code(u32_(grid::CLASS));
        let t = grid::SIZE;
        let counts = |off| triple(|o| u32_at(b, o), off, 4).unwrap_or([0; 3]);
        let nodes = counts(t + tree::NODE_COUNT);
        let tiles = counts(t + tree::TILE_COUNT);
        let voxel_count = u64_(t + tree::VOXEL_COUNT);

        let root_delta = u64_(t + tree::ROOT_OFFSET);
        let root_at = usize::try_from(root_delta)
            .ok()
            .and_then(|d| t.checked_add(d))
            .filter(|r| {
                r.checked_add(root::TABLE_SIZE + 4)
                    .is_some_and(|e| e <= b.len())
            })
            .ok_or_else(|| {
                fail(format!(
                    "root offset {root_delta} beyond the grid buffer ({} bytes)",
                    b.len()
                ))
            })?;
        if root_at % 32 != 0 {
            return Err(fail(format!(
                "root node at byte {root_at} is not 32-byte aligned"
            )));
        }
        let bbox_part = |off| triple(|o| i32_at(b, o), off, 4).unwrap_or([0; 3]);
        let index_bbox = [
            bbox_part(root_at + root::BBOX),
            bbox_part(root_at + root::BBOX + 12),
        ];

        let tree = match ValueKind::of(grid_type) {
            Some(kind) => {
                let header = HeaderCounts {
                    nodes,
                    voxels: voxel_count,
                };
                Some(Tree::load(b, kind, root_at, header).map_err(|e| fail(e.0))?)
            }
            None => None,
        };
        Ok(NanoGrid {
            file: file.to_string(),
            number,
            codec,
            version,
            grid_type,
            grid_class,
            map,
            world_bbox: [f64s(grid::WORLD_BBOX), f64s(grid::WORLD_BBOX + 24)],
            voxel_size: f64s(grid::VOXEL_SIZE),
            index_bbox,
            node_counts: NodeCounts {
                leaves: nodes[0],
                lower: nodes[1],
                upper: nodes[2],
            },
            tile_counts: TileCounts {
                lower: tiles[0],
                upper: tiles[1],
                root: tiles[2],
            },
            voxel_count,
            background: tree.as_ref().map_or(0.0, |t| t.background() as f32),
            buffer,
            tree,
            name,
        })
    }

    /// The grid's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The grid's position in its file (0 for the first grid).
    pub fn number(&self) -> usize {
        self.number
    }

    /// The value type.
    pub fn grid_type(&self) -> NanoGridType {
        self.grid_type
    }

    /// What the grid represents.
    pub fn grid_class(&self) -> NanoGridClass {
        self.grid_class
    }

    /// The NanoVDB version that wrote the grid.
    pub fn version(&self) -> NanoVersion {
        self.version
    }

    /// How the grid was compressed in its file.
    pub fn codec(&self) -> NanoCodec {
        self.codec
    }

    /// Inclusive index-space bounding box of the active voxels, `None` for an empty grid.
    pub fn index_bbox(&self) -> Option<[Coord; 2]> {
        let [lo, hi] = self.index_bbox;
        (0..3).all(|a| lo[a] <= hi[a]).then_some(self.index_bbox)
    }

    /// World-space bounding box of the active voxels as the file states it, `None` for an
    /// empty grid.
    pub fn world_bbox(&self) -> Option<[[f64; 3]; 2]> {
        let [lo, hi] = self.world_bbox;
        (0..3).all(|a| lo[a] <= hi[a]).then_some(self.world_bbox)
    }

    /// Size of a voxel in world units along x, y, z.
    pub fn voxel_size(&self) -> [f64; 3] {
        self.voxel_size
    }

    /// Active voxels, tiles counted voxel by voxel (for sampleable grids checked at load
    /// against the tree itself).
    pub fn active_voxel_count(&self) -> u64 {
        self.voxel_count
    }

    /// Nodes per tree level.
    pub fn node_counts(&self) -> NodeCounts {
        self.node_counts
    }

    /// Active tiles per tree level.
    pub fn tile_counts(&self) -> TileCounts {
        self.tile_counts
    }

    /// Bytes of the grid in NanoVDB's representation (the size of [`NanoGrid::buffer`]).
    pub fn buffer_bytes(&self) -> u64 {
        self.buffer.len() as u64
    }

    /// The raw NanoVDB grid buffer, starting with the grid header.
    pub fn buffer(&self) -> &[u8] {
        &self.buffer
    }

    /// Whether the grid's values can be sampled (Float, Double, Fp4, Fp8, Fp16, FpN).
    pub fn is_sampleable(&self) -> bool {
        self.tree.is_some()
    }

    /// `Ok` when the grid's values can be sampled, else an error naming the file, the grid
    /// and its value type. Grids that cannot be sampled read as the background, 0.
    pub fn check_sampleable(&self) -> Result<(), NanoError> {
        if self.is_sampleable() {
            return Ok(());
        }
        Err(self.error(format!(
            "values of type {} cannot be sampled (only float, double, Fp4, Fp8, Fp16 and FpN grids)",
            self.grid_type
        )))
    }

    fn error(&self, message: String) -> NanoError {
        NanoError::new(
            &self.file,
            format!("grid {} '{}': {message}", self.number, self.name),
        )
    }

    /// Value of voxel `ijk` in f64: exact for Double grids, the f32 value otherwise.
    pub fn voxel_f64(&self, ijk: Coord) -> f64 {
        let Some(tree) = &self.tree else {
            return f64::from(self.background);
        };
        let buf = &self.buffer[..];
        match tree.find(buf, ijk) {
            Hit::Leaf(off) => tree
                .leaf(buf, off)
                .f64(buf, leaf_slot(ijk), tree.background()),
            Hit::Value(pos) => tree.tile_f64(buf, pos),
            Hit::Background => tree.background(),
        }
    }

    /// Origins of the 8^3 blocks that hold data (every leaf, every active tile cut into
    /// blocks); an error when they number [`MAX_RANGE_BLOCKS`] or more (only tiles of
    /// 4096^3 or very many 128^3 voxels get there).
    fn data_blocks(&self) -> Result<Vec<Coord>, NanoError> {
        let Some(tree) = &self.tree else {
            return Ok(Vec::new());
        };
        let count = tree.block_count();
        if count >= MAX_RANGE_BLOCKS {
            return Err(self.error(format!(
                "{count} blocks of 8^3 voxels hold data, more than the {MAX_RANGE_BLOCKS} a grid may list"
            )));
        }
        let mut out = Vec::with_capacity(count as usize);
        tree.for_each_block(&self.buffer, |o| out.push(o));
        Ok(out)
    }
}

impl VoxelGrid for NanoGrid {
    fn background(&self) -> f32 {
        self.background
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        let Some(tree) = &self.tree else {
            return self.background;
        };
        let buf = &self.buffer[..];
        match tree.find(buf, ijk) {
            Hit::Leaf(off) => tree
                .leaf(buf, off)
                .f32(buf, leaf_slot(ijk), self.background),
            Hit::Value(pos) => tree.tile_f32(buf, pos),
            Hit::Background => self.background,
        }
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        self.data_blocks().map_err(|e| VolumeError(e.to_string()))
    }

    fn map(&self) -> &GridMap {
        &self.map
    }

    /// Resolves each 8^3 block of the box once (one root-to-leaf walk per block) and
    /// decodes its voxels from the leaf, or fills them with the tile or background value.
    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        let total: usize = dims.iter().map(|d| *d as usize).product();
        let out = &mut out[..total];
        out.fill(self.background);
        let Some(tree) = &self.tree else {
            return;
        };
        let buf = &self.buffer[..];
        let b = i64::from(BLOCK_SIDE);
        // Voxel ranges per axis, clipped to the coordinates a grid can hold.
        let lo: [i64; 3] = std::array::from_fn(|a| i64::from(origin[a]));
        let hi: [i64; 3] =
            std::array::from_fn(|a| (lo[a] + i64::from(dims[a]) - 1).min(i64::from(i32::MAX)));
        if (0..3).any(|a| dims[a] == 0) {
            return;
        }
        let (dx, dy) = (dims[0] as usize, dims[1] as usize);
        for bz in lo[2].div_euclid(b)..=hi[2].div_euclid(b) {
            for by in lo[1].div_euclid(b)..=hi[1].div_euclid(b) {
                for bx in lo[0].div_euclid(b)..=hi[0].div_euclid(b) {
                    let block = [bx * b, by * b, bz * b];
                    let first: [i64; 3] = std::array::from_fn(|a| block[a].max(lo[a]));
                    let last: [i64; 3] = std::array::from_fn(|a| (block[a] + b - 1).min(hi[a]));
                    let hit = tree.find(buf, block.map(|c| c as i32));
                    let view = match hit {
                        Hit::Leaf(off) => Some(tree.leaf(buf, off)),
                        _ => None,
                    };
                    let constant = match hit {
                        Hit::Value(pos) => tree.tile_f32(buf, pos),
                        _ => self.background,
                    };
                    for z in first[2]..=last[2] {
                        for y in first[1]..=last[1] {
                            let row = ((z - lo[2]) as usize * dy + (y - lo[1]) as usize) * dx;
                            for x in first[0]..=last[0] {
                                let v = match &view {
                                    Some(leaf) => {
                                        let ijk = [x as i32, y as i32, z as i32];
                                        leaf.f32(buf, leaf_slot(ijk), self.background)
                                    }
                                    None => constant,
                                };
                                if let Some(o) = out.get_mut(row + (x - lo[0]) as usize) {
                                    *o = v;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nanovdb::layout::leaf;
    use std::collections::BTreeSet;

    #[test]
    fn fpn_leaves_use_several_bit_widths() {
        let bytes = include_bytes!("../../../../tests/data/nanovdb/density_fpn.nvdb");
        let file = crate::parse_nanovdb(bytes, "density_fpn.nvdb").unwrap();
        let g = &file.grids[0];
        let tree = g.tree.as_ref().unwrap();
        let mut widths = BTreeSet::new();
        for origin in g.block_origins().unwrap() {
            if let Hit::Leaf(off) = tree.find(&g.buffer, origin) {
                widths.insert(1u32 << (g.buffer[off + leaf::FLAGS] >> 5));
            }
        }
        // Smooth leaves need few bits, the noisy corner many (tolerance 0.002).
        assert!(widths.len() >= 3, "{widths:?}");
        assert_eq!(
            g.node_counts().leaves as usize,
            g.block_origins().unwrap().len()
        );
    }
}
