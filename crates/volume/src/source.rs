//! Opening a volume by name: a NanoVDB file (`.nvdb`), an OpenVDB file (`.vdb`), a brick
//! store directory (read through a cache with a memory budget) or a procedural grid
//! (`sphere:...`, `box:...`), as a list of grids with a common summary.

use std::borrow::Cow;
use std::path::Path;

use crate::brick_store::{is_brick_store, store_bytes, BrickStore, StoreMeta};
use crate::ranges::RangeMips;

use crate::dense::{DenseGrid, VolumeError};
use crate::grid::{Coord, GridMap, VoxelGrid};
use crate::nanovdb::{read_nanovdb, NanoGrid};
use crate::openvdb::{VdbFile, VdbGrid};
use crate::procedural_spec::{is_procedural, procedural_grid};

/// A scalar grid from any source, sampled through [`VoxelGrid`].
pub enum Volume {
    /// A dense (procedural) grid.
    Dense(Box<DenseGrid>),
    /// A scalar grid of an OpenVDB file.
    Vdb(Box<VdbGrid>),
    /// A scalar grid of a NanoVDB file.
    Nano(Box<NanoGrid>),
    /// A brick store, read through its cache.
    Store(Box<BrickStore>),
}

impl Volume {
    /// Where the grid came from: `procedural`, `openvdb` or `nanovdb`.
    pub fn kind(&self) -> &'static str {
        match self {
            Volume::Dense(_) => "procedural",
            Volume::Vdb(_) => "openvdb",
            Volume::Nano(_) => "nanovdb",
            Volume::Store(_) => "brick-store",
        }
    }

    /// An error when lookups since the grid was opened could not read what they needed (a
    /// brick store's file failing after it was opened; such lookups read the background).
    pub fn check_reads(&self) -> Result<(), VolumeError> {
        match self {
            Volume::Store(s) => s.check().map_err(|e| VolumeError(e.to_string())),
            _ => Ok(()),
        }
    }

    /// The range mips of the grid's lookups: a brick store's own (read with it), else built
    /// from the voxels.
    pub fn range_mips(&self) -> Result<Cow<'_, RangeMips>, VolumeError> {
        match self {
            Volume::Store(s) => Ok(Cow::Borrowed(s.mips())),
            other => Ok(Cow::Owned(RangeMips::build(other)?)),
        }
    }

    fn inner(&self) -> &dyn VoxelGrid {
        match self {
            Volume::Dense(g) => g.as_ref(),
            Volume::Vdb(g) => g.as_ref(),
            Volume::Nano(g) => g.as_ref(),
            Volume::Store(g) => g.as_ref(),
        }
    }
}

impl VoxelGrid for Volume {
    fn background(&self) -> f32 {
        self.inner().background()
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        self.inner().voxel(ijk)
    }

    fn block_origins(&self) -> Result<Vec<Coord>, VolumeError> {
        self.inner().block_origins()
    }

    fn map(&self) -> &GridMap {
        self.inner().map()
    }

    fn read_box(&self, origin: Coord, dims: [u32; 3], out: &mut [f32]) {
        self.inner().read_box(origin, dims, out)
    }
}

/// What a file says about one of its grids.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GridSummary {
    /// Grid name.
    pub name: String,
    /// Value type as the file names it (`float`, `Fp8`, `Vec3f`, ...).
    pub value_type: String,
    /// Inclusive index-space bounding box of the active voxels.
    pub index_bbox: Option<[Coord; 2]>,
    /// World-space bounding box of the active voxels.
    pub world_bbox: Option<[[f64; 3]; 2]>,
    /// Active voxels (tiles counted voxel by voxel).
    pub active_voxels: u64,
    /// What the grid was read from: `nanovdb`, `openvdb`, `brick-store` or `procedural`.
    pub source_kind: &'static str,
    /// Bytes of the representation as read (the NanoVDB grid buffer, the in-memory
    /// OpenVDB blocks, the dense array, a brick store's files on disk).
    pub source_bytes: u64,
    /// A brick store's metadata (dimensions, bricks kept and dropped, quantization).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub brick_store: Option<StoreMeta>,
}

/// Why a grid of an opened volume cannot be sampled (a vector grid, say), without the
/// file's name.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct Unsampleable(pub String);

/// One grid of an opened volume: its summary and, for scalar grids, the grid itself.
pub struct NamedVolume {
    /// The summary.
    pub summary: GridSummary,
    /// The grid, or why it cannot be sampled (a vector grid, say).
    pub grid: Result<Volume, Unsampleable>,
}

/// World bounding box of the index box `[lo - 0.5, hi + 0.5]` (the voxels' extent).
pub fn world_bbox(map: &GridMap, bbox: [Coord; 2]) -> [[f64; 3]; 2] {
    let mut out = [[f64::INFINITY; 3], [f64::NEG_INFINITY; 3]];
    for corner in 0..8 {
        let p = std::array::from_fn(|k| {
            if corner >> k & 1 == 1 {
                bbox[1][k] as f64 + 0.5
            } else {
                bbox[0][k] as f64 - 0.5
            }
        });
        let w = map.index_to_world(p);
        for k in 0..3 {
            out[0][k] = out[0][k].min(w[k]);
            out[1][k] = out[1][k].max(w[k]);
        }
    }
    out
}

fn dense_summary(name: &str, g: &DenseGrid) -> GridSummary {
    let active = g.values.iter().filter(|v| **v != g.background).count() as u64;
    let bbox = [
        g.origin,
        std::array::from_fn(|k| g.origin[k] + g.dims[k] as i32 - 1),
    ];
    GridSummary {
        name: name.to_string(),
        value_type: "float".to_string(),
        index_bbox: Some(bbox),
        world_bbox: Some(world_bbox(&g.map, bbox)),
        active_voxels: active,
        source_kind: "procedural",
        source_bytes: (g.values.len() * 4) as u64,
        brick_store: None,
    }
}

/// Memory budget of a brick store opened by [`open_volume`]: 1 GiB.
pub const DEFAULT_STORE_BUDGET: u64 = 1 << 30;

/// Opens `spec`: a procedural grid, a brick store directory (with
/// [`DEFAULT_STORE_BUDGET`]) or a volume file (by extension).
pub fn open_volume(spec: &str) -> Result<Vec<NamedVolume>, VolumeError> {
    open_volume_with(spec, DEFAULT_STORE_BUDGET)
}

/// Opens `spec` as [`open_volume`] does, a brick store holding at most `store_budget` bytes
/// resident.
pub fn open_volume_with(spec: &str, store_budget: u64) -> Result<Vec<NamedVolume>, VolumeError> {
    if is_brick_store(Path::new(spec)) {
        return open_store(Path::new(spec), store_budget);
    }
    if is_procedural(spec) {
        let g = procedural_grid(spec)?;
        let summary = dense_summary("density", &g);
        return Ok(vec![NamedVolume {
            summary,
            grid: Ok(Volume::Dense(Box::new(g))),
        }]);
    }
    let path = Path::new(spec);
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    match extension.as_str() {
        "vdb" => open_vdb(path),
        "nvdb" => open_nanovdb(path),
        _ => Err(VolumeError(format!(
            "{spec}: unknown volume format `{extension}` (expected .nvdb, .vdb, a brick store directory, sphere:... or box:...)"
        ))),
    }
}

fn open_store(path: &Path, budget: u64) -> Result<Vec<NamedVolume>, VolumeError> {
    let store = BrickStore::open(path, budget).map_err(|e| VolumeError(e.to_string()))?;
    let meta = store.meta().clone();
    let lo = meta.index_origin;
    let bbox = [lo, std::array::from_fn(|k| lo[k] + meta.dims[k] as i32 - 1)];
    let bytes = store_bytes(path).map_err(|e| VolumeError(format!("{}: {e}", path.display())))?;
    Ok(vec![NamedVolume {
        summary: GridSummary {
            name: "density".to_string(),
            value_type: "u16 codes".to_string(),
            index_bbox: Some(bbox),
            world_bbox: Some(world_bbox(store.map(), bbox)),
            active_voxels: meta.kept_bricks * crate::brick_store::BRICK_VOXELS as u64,
            source_kind: "brick-store",
            source_bytes: bytes,
            brick_store: Some(meta),
        },
        grid: Ok(Volume::Store(Box::new(store))),
    }])
}

fn open_nanovdb(path: &Path) -> Result<Vec<NamedVolume>, VolumeError> {
    let file = read_nanovdb(path).map_err(|e| VolumeError(e.to_string()))?;
    Ok(file
        .grids
        .into_iter()
        .map(|g| NamedVolume {
            summary: GridSummary {
                name: g.name().to_string(),
                value_type: g.grid_type().to_string(),
                index_bbox: g.index_bbox(),
                world_bbox: g.world_bbox(),
                active_voxels: g.active_voxel_count(),
                source_kind: "nanovdb",
                source_bytes: g.buffer_bytes(),
                brick_store: None,
            },
            grid: match g.check_sampleable() {
                Ok(()) => Ok(Volume::Nano(Box::new(g))),
                Err(e) => Err(Unsampleable(e.message().to_string())),
            },
        })
        .collect())
}

fn open_vdb(path: &Path) -> Result<Vec<NamedVolume>, VolumeError> {
    let file = VdbFile::open(path)?;
    Ok((0..file.grids.len())
        .map(|i| {
            let info = &file.grids[i];
            let grid = file.load(i);
            let (world, bytes) = match (&grid, info.bbox) {
                (Ok(g), Some(bbox)) => (Some(world_bbox(g.map(), bbox)), g.memory_bytes()),
                (Ok(g), None) => (None, g.memory_bytes()),
                _ => (None, 0),
            };
            NamedVolume {
                summary: GridSummary {
                    name: info.name.clone(),
                    value_type: info.value_type.clone(),
                    index_bbox: info.bbox,
                    world_bbox: world,
                    active_voxels: info.active_voxel_count.unwrap_or(0),
                    source_kind: "openvdb",
                    source_bytes: bytes as u64,
                    brick_store: None,
                },
                grid: grid
                    .map(|g| Volume::Vdb(Box::new(g)))
                    .map_err(|e| Unsampleable(e.0)),
            }
        })
        .collect())
}

/// The grid named `name` (or the first grid when `None`) of an opened volume.
pub fn select_grid(
    spec: &str,
    grids: Vec<NamedVolume>,
    name: Option<&str>,
) -> Result<(GridSummary, Volume), VolumeError> {
    let names: Vec<String> = grids.iter().map(|g| g.summary.name.clone()).collect();
    let chosen = match name {
        None => grids.into_iter().next(),
        Some(n) => grids.into_iter().find(|g| g.summary.name == n),
    };
    let Some(chosen) = chosen else {
        return Err(VolumeError(format!(
            "{spec}: no grid {} (grids: {})",
            name.map_or("at all".to_string(), |n| format!("`{n}`")),
            names.join(", ")
        )));
    };
    match chosen.grid {
        Ok(g) => Ok((chosen.summary, g)),
        Err(why) => Err(VolumeError(format!(
            "{spec}: grid `{}`: {why}",
            chosen.summary.name
        ))),
    }
}
