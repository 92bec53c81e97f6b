//! Option groups several subcommands share, as clap arguments that convert into the
//! library's plain settings.

use clap::Args;
use hytrace_trace::render::cutaway::{CutMode, CutPlane, Cutaway};
use hytrace_trace::render::detector::{ColorBy, DetectorStyle};
use hytrace_trace::render::run::{parse_size, RenderSettings};
use hytrace_trace::render::spec::{View, VolumeMode};
use hytrace_trace::volume::{
    EndianArg, EstimatorArg, EstimatorOptions, FilterArg, RawTypeArg, StoreOptions,
};

use super::choice::choice;

/// The estimator options of `hytrace volume transmittance` and `hytrace scan
/// --transmittance`.
#[derive(Clone, Copy, Debug, Args)]
pub struct EstimatorArgs {
    /// Estimator.
    #[arg(long, value_parser = choice::<EstimatorArg>(), default_value_t = EstimatorArg::Exact)]
    pub estimator: EstimatorArg,
    /// Step of `march`, world units.
    #[arg(long, default_value_t = 0.5)]
    pub step: f64,
    /// Samples per ray of the trackers (delta, ratio, residual).
    #[arg(long, default_value_t = 1)]
    pub spp: u32,
    /// Seed of the random streams (ray i uses stream i).
    #[arg(long, default_value_t = 0)]
    pub seed: u32,
    /// Density per unit of grid value (for scene media: a factor on each medium's own).
    #[arg(long, default_value_t = 1.0)]
    pub density_scale: f64,
    /// Lookup filter.
    #[arg(long, value_parser = choice::<FilterArg>(), default_value_t = FilterArg::Trilinear)]
    pub filter: FilterArg,
    /// Finest mip level of the local majorants (0: 8^3 bricks ... 3: 64^3).
    #[arg(long, default_value_t = 0)]
    pub level: usize,
    /// One majorant for the whole grid instead of local ones.
    #[arg(long)]
    pub global_majorant: bool,
}

impl From<EstimatorArgs> for EstimatorOptions {
    fn from(a: EstimatorArgs) -> EstimatorOptions {
        EstimatorOptions {
            estimator: a.estimator,
            step: a.step,
            spp: a.spp,
            seed: a.seed,
            density_scale: a.density_scale,
            filter: a.filter,
            level: a.level,
            global_majorant: a.global_majorant,
        }
    }
}

/// The options of `hytrace volume convert --store`.
#[derive(Clone, Debug, Args)]
pub struct StoreArgs {
    /// Voxels of a raw file along x, y, z (`X,Y,Z`; x fastest in the file, no header).
    #[arg(long)]
    pub dims: Option<String>,
    /// Element type of a raw file.
    #[arg(long, value_parser = choice::<RawTypeArg>())]
    pub dtype: Option<RawTypeArg>,
    /// Byte order of a raw file.
    #[arg(long, value_parser = choice::<EndianArg>(), default_value_t = EndianArg::Little)]
    pub endian: EndianArg,
    /// World size of a raw file's voxel along x, y, z (`SX,SY,SZ`).
    #[arg(long, default_value = "1,1,1")]
    pub spacing: String,
    /// World position of a raw file's first voxel (`X,Y,Z`).
    #[arg(long, default_value = "0,0,0", allow_hyphen_values = true)]
    pub origin: String,
    /// Value outside the volume and of dropped bricks.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub background: f32,
    /// Bricks whose values all lie within this of the background are dropped.
    #[arg(long, default_value_t = 0.0)]
    pub threshold: f32,
    /// The range the 16-bit codes span (`MIN,MAX`); the data's own range by default (a
    /// first pass over the file finds it).
    #[arg(long, allow_hyphen_values = true)]
    pub range: Option<String>,
    /// Memory the converter may hold resident (e.g. 2G): its window of brick layers and
    /// its tables; refused when that does not fit.
    #[arg(long, value_parser = hytrace_trace::memory::parse_bytes, default_value = "2G")]
    pub memory: u64,
}

impl From<StoreArgs> for StoreOptions {
    fn from(a: StoreArgs) -> StoreOptions {
        StoreOptions {
            dims: a.dims,
            dtype: a.dtype,
            endian: a.endian,
            spacing: a.spacing,
            origin: a.origin,
            background: a.background,
            threshold: a.threshold,
            range: a.range,
            memory: a.memory,
        }
    }
}

/// The render settings of `hytrace render`; each overrides the scene's own (its `[render]`
/// table, or the defaults).
#[derive(Args, Clone, Debug, Default)]
pub struct RenderSettingsArgs {
    /// Image size, WIDTHxHEIGHT [default: 640x360, or the scene file's `[render]` size].
    #[arg(long, value_parser = parse_size, value_name = "WxH")]
    pub size: Option<[u32; 2]>,
    /// Samples per pixel (1: pixel centres) [default: 16, or the scene file's].
    #[arg(long, value_name = "N")]
    pub spp: Option<u32>,
    /// What the image shows [default: shaded, or the scene file's].
    #[arg(long, value_parser = choice::<View>())]
    pub view: Option<View>,
    /// How media are rendered [default: multiple-scattering when a medium scatters, else
    /// emission-absorption].
    #[arg(long, value_parser = choice::<VolumeMode>())]
    pub volumes: Option<VolumeMode>,
    /// Longest path (surface and medium scattering events).
    #[arg(long)]
    pub max_bounces: Option<u32>,
    /// Emission-absorption march step in voxels.
    #[arg(long)]
    pub step: Option<f64>,
    /// Seed of the random streams.
    #[arg(long)]
    pub seed: Option<u32>,
    /// Bytes each medium read as stored in a brick store may hold resident (its tables and
    /// a brick cache; on the GPU also its brick pool in device memory), e.g. 4G.
    #[arg(long, value_parser = hytrace_trace::memory::parse_bytes)]
    pub memory: Option<u64>,
    /// Render the solid of this name transparent (repeatable): to see inside a detector's
    /// enclosures (`hytrace info` lists the solids).
    #[arg(long)]
    pub transparent: Vec<String>,
    #[command(flatten)]
    pub cutaway: CutArgs,
    #[command(flatten)]
    pub detector: DetectorArgs,
}

/// The cut planes of a render.
#[derive(Args, Clone, Debug, Default)]
pub struct CutArgs {
    /// Cut away what lies beyond this plane (repeatable, at most 3): `x=C`, `y=C`, `z=C`
    /// remove the side above C (`-x=C` the side below), `NX,NY,NZ:D` the side of the plane
    /// n.p = D that n points to. Volumes drawn solid show their sections on the plane
    /// (hierarchical scenes: GDML detectors).
    #[arg(long = "cut", value_name = "PLANE", allow_hyphen_values = true)]
    pub planes: Vec<CutPlane>,
    /// How several planes combine, as Geant4's cutaway modes.
    #[arg(long = "cut-mode", value_parser = choice::<CutMode>(), value_name = "MODE", default_value_t = CutMode::Union)]
    pub mode: CutMode,
}

/// The options of detector views (GDML and other hierarchical scenes).
#[derive(Args, Clone, Debug, Default)]
#[command(next_help_heading = "GDML detectors (hierarchical scenes only)")]
pub struct DetectorArgs {
    /// Draw down to this depth of the placement tree (the world is 0, its daughters 1;
    /// with --show, the shown volumes are 0), as Geant4's drawing depth [default: all].
    #[arg(long, value_name = "N")]
    pub depth: Option<u32>,
    /// Draw only the volumes whose logical or physical name matches this glob (`*`, `?`;
    /// case-insensitive) and their contents (repeatable).
    #[arg(long, value_name = "PATTERN")]
    pub show: Vec<String>,
    /// Do not draw the volumes whose logical or physical name matches this glob (their
    /// daughters still are; repeatable).
    #[arg(long, value_name = "PATTERN")]
    pub hide: Vec<String>,
    /// What the colours tell apart [default: material, with the colours the file gives].
    /// Every detector view writes its legend beside the image (IMAGE.legend.json).
    #[arg(long, value_parser = choice::<ColorBy>(), value_name = "KEY")]
    pub color_by: Option<ColorBy>,
}

impl From<DetectorArgs> for DetectorStyle {
    fn from(a: DetectorArgs) -> DetectorStyle {
        DetectorStyle {
            depth: a.depth,
            show: a.show,
            hide: a.hide,
            color_by: a.color_by,
        }
    }
}

impl From<RenderSettingsArgs> for RenderSettings {
    fn from(a: RenderSettingsArgs) -> RenderSettings {
        RenderSettings {
            size: a.size,
            spp: a.spp,
            view: a.view,
            volumes: a.volumes,
            max_bounces: a.max_bounces,
            step: a.step,
            seed: a.seed,
            memory: a.memory,
            transparent: a.transparent,
            cutaway: Cutaway {
                planes: a.cutaway.planes,
                mode: a.cutaway.mode,
            },
            detector: a.detector.into(),
        }
    }
}
