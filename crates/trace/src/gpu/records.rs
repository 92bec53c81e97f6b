//! The records the tracing kernels share with the CPU beyond the Foundry's own: prepared
//! CSG trees and meshes ([`hytrace_csg::gpu_layout`]) and the tracer's placements, search
//! lists, BVH nodes, rays and hits. `shaders/generated/trace_records.wgsl` is generated
//! from them; a test fails when it is stale or when naga lays a struct out differently from
//! Rust.

use hytrace_csg::gpu_layout::{self, entry, RecordEntry};
use hytrace_foundry::record;
use hytrace_foundry::wgsl::push_struct;

/// Path of the generated file relative to the workspace root.
pub const GENERATED_PATH: &str = "shaders/generated/trace_records.wgsl";

record! {
    /// A node of the tracers' box BVHs: its box (f32, rounded outward), then either children
    /// `first, first + 1` (`count == 0`) or the items `first..first + count` of the item list.
    /// Indices are absolute in the uploaded arrays.
    pub struct BoxNode {
        /// Lower corner.
        pub lo: [f32; 3],
        /// First child node or first item.
        pub first: u32,
        /// Upper corner.
        pub hi: [f32; 3],
        /// Items of a leaf; 0 for an inner node.
        pub count: u32,
    }
}

record! {
    /// Members searched together: a group of instances (ids in the member list) or one
    /// solid's surface prims (`first..first + count` of the surface prims). Searched in
    /// order, or through a BVH (`has_bvh`): root node `root` (`u32::MAX` when the tree is
    /// empty) and the items with unbounded boxes, `unbounded_first..+unbounded_count` of the
    /// BVH item list, visited first.
    pub struct SearchList {
        /// First member.
        pub first: u32,
        /// Number of members.
        pub count: u32,
        /// 1 when the members sit in a BVH.
        pub has_bvh: u32,
        /// Root node of the BVH.
        pub root: u32,
        /// First unbounded item.
        pub unbounded_first: u32,
        /// Number of unbounded items.
        pub unbounded_count: u32,
        /// A group's largest member extent (the widest tolerance band about its members,
        /// `CpuScene::start_flags`); 0 for a solid's prims.
        pub largest: f32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// One placement of a solid: its frame (see [`hytrace_csg::gpu_layout::FrameRecord`]) and
    /// widened world bounds.
    pub struct Placement {
        /// The frame's rows, origin in `w`.
        pub rows: [[f32; 4]; 3],
        /// Lower corner of the world bounds.
        pub lo: [f32; 3],
        /// Index of the solid.
        pub solid: u32,
        /// Upper corner of the world bounds.
        pub hi: [f32; 3],
        /// 1 when the solid's signed distance bounds true distances in this placement (its
        /// CSG prims' and the frame's): nearness to its surface is then decided by it.
        pub sdf_decides: u32,
        /// The rest of the frame's origin (the translation) after rounding to f32 (the
        /// rows' `w`): rays are taken into the frame part by part.
        pub origin_lo: [f32; 3],
        /// Padding.
        pub pad_lo: u32,
        /// The centre of the solid's box in its own frame, where rays are rebased to.
        pub centre: [f32; 3],
        /// Twice the largest coordinate of the solid's box in its own frame: rays starting
        /// farther out are rebased.
        pub reach: f32,
    }
}

record! {
    /// A surface prim of a solid: its bounds in the solid's frame, and which tree or mesh.
    pub struct SurfacePrim {
        /// Lower corner of the bounds.
        pub lo: [f32; 3],
        /// `PRIM_CSG` or `PRIM_MESH` (Foundry prim kinds).
        pub kind: u32,
        /// Upper corner of the bounds.
        pub hi: [f32; 3],
        /// Index of the CSG tree or mesh.
        pub index: u32,
        /// Index of the Foundry prim.
        pub foundry_prim: u32,
        /// Padding.
        pub pad: [u32; 3],
    }
}

record! {
    /// A scan's parameters.
    pub struct ScanParams {
        /// Number of rays.
        pub ray_count: u32,
        /// 1 for a hierarchical scene (the navigator's answer), 0 for a flat one.
        pub hierarchical: u32,
        /// 2: the trip count of the loop-budget probe (`shaders/loop_budget.wgsl`).
        pub probe_trips: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// A ray of a scan: `tmin < t < tmax` along a unit direction.
    pub struct RayRecord {
        /// Origin.
        pub origin: [f32; 3],
        /// Start of the interval.
        pub tmin: f32,
        /// Direction.
        pub direction: [f32; 3],
        /// End of the interval (`INF` in the kernels stands for infinity).
        pub tmax: f32,
        /// The rest of the origin after rounding to f32 (`origin`), for the rebasing into
        /// instances' frames.
        pub origin_lo: [f32; 3],
        /// Padding.
        pub pad: u32,
    }
}

/// An f64 point as two f32 parts: the point rounded, and the rest rounded.
pub fn split_f64(v: [f64; 3]) -> ([f32; 3], [f32; 3]) {
    let hi = v.map(|c| c as f32);
    (
        hi,
        std::array::from_fn(|k| (v[k] - f64::from(hi[k])) as f32),
    )
}

record! {
    /// A scan's answer for one ray.
    pub struct HitRecord {
        /// Unit outward normal (world frame); 0 on a miss.
        pub normal: [f32; 3],
        /// Distance; `INF` (1e38) on a miss.
        pub t: f32,
        /// Instance crossed (`u32::MAX` on a miss).
        pub instance: u32,
        /// Foundry prim crossed (`u32::MAX` on a miss).
        pub prim: u32,
        /// 0, or the `STATUS_*` bits of a ray whose search was cut short.
        pub status: u32,
        /// Padding.
        pub pad: u32,
    }
}

/// [`HitRecord::status`] bit: the navigator's hierarchy was deeper than its loop bound.
pub const STATUS_DEPTH_LIMIT: u32 = 1;
/// [`HitRecord::status`] bit: the driver's loop budget cut the ray's loops short (llvmpipe:
/// `shaders/loop_budget.wgsl`); its answer is wrong.
pub const STATUS_LOOPS_CUT: u32 = 2;
/// [`HitRecord::status`] (and [`crate::cpu::Traced::flags`]) bit: the ray starts within the
/// tolerance band of a CSG surface by its signed distance (which side it starts on, and
/// whether a crossing there is the surface it starts on, are within rounding).
pub const STATUS_START_NEAR: u32 = 4;
/// Status bit: the ray starts within the band of the box of a solid whose signed distance
/// does not decide nearness (meshes, frames that scale distances): the host searches the
/// band ([`crate::cpu::CpuScene::starts_near_surface`]).
pub const STATUS_START_BAND: u32 = 8;
/// Status bit: a prim made a decision within rounding before the limit of its search: a
/// CSG prim skipped a span shorter than the tolerance as a touch (a chord through an edge,
/// a near-tangent), or a mesh's f32 triangle test hit or missed a triangle within the
/// rounding of its edge functions (a crossing beside an edge or vertex, or a near miss of
/// one: `Step::dropped`).
pub const STATUS_DROPPED_SPAN: u32 = 16;
/// The status bits of a ray whose search was cut short (its answer is not the trace's).
pub const STATUS_CUT_SHORT: u32 = STATUS_DEPTH_LIMIT | STATUS_LOOPS_CUT;
/// The status bits that are the trace's flags ([`crate::cpu::Traced::flags`]).
pub const STATUS_FLAGS: u32 = STATUS_START_NEAR | STATUS_START_BAND | STATUS_DROPPED_SPAN;

record! {
    /// What every ray of a GPU transmittance batch shares (`shaders/kernels/transmittance.wgsl`):
    /// the range mips' level boxes, the bricked grid's indirection box and the estimator.
    /// Rays come in the grid's index space as [`RayRecord`]s (direction not normalized).
    pub struct VolumeParams {
        /// Per mip level (finest first): first block x, y, z and the block side in voxels.
        pub level_lo: [[i32; 4]; 4],
        /// Per mip level: blocks along x, y, z and the level's first entry in the ranges.
        pub level_dims: [[u32; 4]; 4],
        /// Brick coordinate of the indirection box's first brick.
        pub brick_lo: [i32; 3],
        /// `VOLUME_FORMAT_*` of the atlas texels.
        pub format: u32,
        /// Bricks of the indirection box along x, y, z.
        pub brick_dims: [u32; 3],
        /// `VOLUME_ESTIMATOR_*`.
        pub estimator: u32,
        /// `VOLUME_FILTER_*` (`filter` is a WGSL reserved word).
        pub lookup_filter: u32,
        /// Samples per ray of the trackers.
        pub spp: u32,
        /// Seed of the random streams.
        pub seed: u32,
        /// Finest mip level of a local-majorant walk.
        pub finest: u32,
        /// 1: one global range for the whole box (global majorant, and the march).
        pub global: u32,
        /// The global range's minimum.
        pub global_min: f32,
        /// The global range's maximum.
        pub global_max: f32,
        /// The grid's background (outside the levels' boxes and the stored bricks).
        pub background: f32,
        /// Density per unit of grid value.
        pub density_scale: f32,
        /// Largest march step.
        pub march_step: f32,
        /// Rays in this batch.
        pub ray_count: u32,
        /// Index of the batch's first ray: ray `i` of the batch uses random stream
        /// `ray_offset + i`.
        pub ray_offset: u32,
        /// The grid's first entry in the indirection array (shared by several grids).
        pub indirection_base: u32,
        /// The grid's first word in the atlas (shared by several grids); for texels in a
        /// 3D texture, its first brick slot there.
        pub atlas_base: u32,
        /// 2: the trip count of the loop-budget probe (`shaders/loop_budget.wgsl`).
        pub probe_trips: u32,
        /// What the kernels' index space is translated by: a voxel `c` there is voxel
        /// `c + index_shift` of the grid (read by the raw NanoVDB lookup).
        pub index_shift: [i32; 3],
        /// Words of a raw NanoVDB grid's buffer in the atlas (0 for bricks).
        pub nanovdb_words: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// One ray's transmittance from the GPU (the twin of `hytrace_volume::Estimate`).
    pub struct TransmittanceRecord {
        /// The estimate (the mean over the samples for the trackers).
        pub transmittance: f32,
        /// Sample variance of the per-sample values (0 for one sample).
        pub variance: f32,
        /// Density lookups (quadrature nodes, march steps, tentative collisions).
        pub lookups: u32,
        /// Tentative collisions that did not end a sample.
        pub null_collisions: u32,
        /// 0, or `VOLUME_STATUS_*` bits of a ray the CPU would refuse.
        pub status: u32,
        /// Padding.
        pub pad: [u32; 3],
    }
}

record! {
    /// What every pixel of a GPU render shares (`shaders/kernels/render.wgsl`): the camera
    /// (see [`crate::render::camera`]), the image, the effects and where the materials
    /// and lights start in the item list.
    pub struct RenderParams {
        /// Eye position.
        pub eye: [f32; 3],
        /// `RENDER_VIEW_*`.
        pub view: u32,
        /// Forward unit vector.
        pub w: [f32; 3],
        /// 1: orthographic, 0: perspective.
        pub orthographic: u32,
        /// Right unit vector.
        pub u: [f32; 3],
        /// `tan(fov / 2)` (perspective) or half the view height (orthographic).
        pub extent: f32,
        /// True up unit vector.
        pub v: [f32; 3],
        /// Image width in pixels.
        pub width: u32,
        /// Environment radiance.
        pub environment: [f32; 3],
        /// Image height in pixels.
        pub height: u32,
        /// Samples per pixel.
        pub spp: u32,
        /// Seed of the random streams.
        pub seed: u32,
        /// Longest path.
        pub max_bounces: u32,
        /// `RENDER_EFFECT_*` bits compiled into this render.
        pub effects: u32,
        /// Depth view: distance shown white.
        pub depth_near: f32,
        /// Depth view: distance shown black.
        pub depth_far: f32,
        /// Number of point and directional lights (items after the materials).
        pub light_count: u32,
        /// First light in the item list.
        pub light_first: u32,
        /// 1 for a hierarchical scene (the navigator's answers).
        pub hierarchical: u32,
        /// First pixel row of this batch.
        pub row_offset: u32,
        /// Rows in this batch.
        pub row_count: u32,
        /// `RENDER_VOLUMES_*`: how the media are rendered (the volume group is bound unless
        /// none).
        pub volume_mode: u32,
        /// Number of placed media ([`RenderMedium`] entries).
        pub media_count: u32,
        /// Emission-absorption march step in voxels.
        pub medium_step: f32,
        /// The sample this dispatch takes (one dispatch per sample: the image holds the
        /// running sum until the last divides it).
        pub sample: u32,
        /// 2: the trip count of the loop-budget probe (`shaders/loop_budget.wgsl`).
        pub probe_trips: u32,
        /// Number of cut planes (0 to 3; see [`crate::render::cutaway`]).
        pub cut_count: u32,
        /// `RENDER_CUT_*`: how the planes' kept sides combine.
        pub cut_mode: u32,
        /// Pixels of this batch listed by index (a streamed render's pending pixels,
        /// `shaders/kernels/render.wgsl`); 0: the batch is `row_count` rows from
        /// `row_offset`.
        pub listed: u32,
        /// Padding.
        pub pad: u32,
        /// The cut planes: unit normal (pointing into the removed side) and offset.
        pub cuts: [[f32; 4]; 3],
    }
}

record! {
    /// One placed medium of a GPU render.
    pub struct RenderMedium {
        /// World to the medium's index space (translated as its grid's upload): the rows of
        /// a 3x4 affine.
        pub rows: [[f32; 4]; 3],
        /// Emission colour.
        pub emission: [f32; 3],
        /// Its grid's entry in the volume parameters.
        pub volume: u32,
        /// Scattering albedo.
        pub albedo: f32,
        /// Henyey-Greenstein asymmetry.
        pub g: f32,
        /// Seed of its shadow rays' ratio-tracking streams.
        pub seed: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// A material or a light (`kind`: `RENDER_MATERIAL_*` or `RENDER_LIGHT_*`) with two
    /// vectors of parameters: a material's colour (or radiance) in `a`, a dielectric's
    /// index and absorption length (0: none) in `b`; a light's position or travel
    /// direction in `a` and intensity or irradiance in `b`.
    pub struct RenderItem {
        /// What it is.
        pub kind: u32,
        /// Padding.
        pub pad: [u32; 3],
        /// First parameters.
        pub a: [f32; 4],
        /// Second parameters.
        pub b: [f32; 4],
    }
}

record! {
    /// What a render needs of an instance: its material (index into the items), solid,
    /// boundary and covering instance (`u32::MAX`: none; see the renderer's `covering`).
    pub struct RenderInstance {
        /// Material item.
        pub material: u32,
        /// Solid.
        pub solid: u32,
        /// Boundary.
        pub boundary: u32,
        /// The outermost of itself and its ancestors drawn solid.
        pub covering: u32,
    }
}

/// [`RenderParams::view`] values (the order of [`crate::render::spec::View`]).
pub const RENDER_VIEW_SHADED: u32 = 0;
/// Depth.
pub const RENDER_VIEW_DEPTH: u32 = 1;
/// Normal.
pub const RENDER_VIEW_NORMAL: u32 = 2;
/// Solid identity.
pub const RENDER_VIEW_SOLID: u32 = 3;
/// Prim identity.
pub const RENDER_VIEW_PRIM: u32 = 4;
/// Instance identity.
pub const RENDER_VIEW_INSTANCE: u32 = 5;
/// Boundary identity.
pub const RENDER_VIEW_BOUNDARY: u32 = 6;
/// [`RenderParams::cut_mode`] values: a point is drawn when any plane keeps it.
pub const RENDER_CUT_UNION: u32 = 0;
/// Only when every plane keeps it.
pub const RENDER_CUT_INTERSECTION: u32 = 1;
/// [`RenderParams::effects`] bit: direct light and hard shadows on diffuse surfaces.
pub const RENDER_EFFECT_SHADING: u32 = 1;
/// Mirrors and dielectrics.
pub const RENDER_EFFECT_SPECULAR: u32 = 2;
/// [`RenderParams::volume_mode`] values: no medium.
pub const RENDER_VOLUMES_NONE: u32 = 0;
/// Emission-absorption.
pub const RENDER_VOLUMES_ABSORPTION: u32 = 1;
/// Single scattering.
pub const RENDER_VOLUMES_SINGLE: u32 = 2;
/// Multiple scattering.
pub const RENDER_VOLUMES_MULTIPLE: u32 = 3;
/// Most placed media a GPU render takes.
pub const RENDER_MAX_MEDIA: u32 = 16;
/// [`RenderItem::kind`] of materials: diffuse.
pub const RENDER_MATERIAL_DIFFUSE: u32 = 0;
/// Mirror.
pub const RENDER_MATERIAL_MIRROR: u32 = 1;
/// Dielectric.
pub const RENDER_MATERIAL_DIELECTRIC: u32 = 2;
/// Emitter.
pub const RENDER_MATERIAL_EMITTER: u32 = 3;
/// Transparent.
pub const RENDER_MATERIAL_TRANSPARENT: u32 = 4;
/// Shell (an envelope: colour in `a`, opacity in `b.x`).
pub const RENDER_MATERIAL_SHELL: u32 = 5;
/// [`RenderItem::kind`] of lights: point.
pub const RENDER_LIGHT_POINT: u32 = 16;
/// Directional.
pub const RENDER_LIGHT_DIRECTIONAL: u32 = 17;

/// [`VolumeParams::estimator`] values.
pub const VOLUME_ESTIMATOR_EXACT: u32 = 0;
/// Midpoint march.
pub const VOLUME_ESTIMATOR_MARCH: u32 = 1;
/// Delta tracking.
pub const VOLUME_ESTIMATOR_DELTA: u32 = 2;
/// Ratio tracking.
pub const VOLUME_ESTIMATOR_RATIO: u32 = 3;
/// Residual ratio tracking.
pub const VOLUME_ESTIMATOR_RESIDUAL: u32 = 4;
/// [`VolumeParams::lookup_filter`] values: nearest.
pub const VOLUME_FILTER_NEAREST: u32 = 0;
/// Trilinear.
pub const VOLUME_FILTER_TRILINEAR: u32 = 1;
/// Stochastic.
pub const VOLUME_FILTER_STOCHASTIC: u32 = 2;
/// [`VolumeParams::format`] values: BC4 blocks.
pub const VOLUME_FORMAT_BC4: u32 = 0;
/// 8-bit normalized texels.
pub const VOLUME_FORMAT_UNORM8: u32 = 1;
/// 16-bit normalized texels.
pub const VOLUME_FORMAT_UNORM16: u32 = 2;
/// Half-precision texels.
pub const VOLUME_FORMAT_F16: u32 = 3;
/// Single-precision texels.
pub const VOLUME_FORMAT_F32: u32 = 4;
/// No bricks: a raw NanoVDB grid buffer in the atlas, read by `shaders/volume/nanovdb.wgsl`.
pub const VOLUME_FORMAT_NANOVDB: u32 = 5;
/// [`TransmittanceRecord::status`] bit: a tracker met a negative density (the CPU errors).
pub const VOLUME_STATUS_NEGATIVE: u32 = 1;
/// [`TransmittanceRecord::status`] bit: the march needs more than `u32::MAX` steps.
pub const VOLUME_STATUS_MARCH_STEPS: u32 = 2;
/// [`TransmittanceRecord::status`] bit: the driver's loop budget cut the ray's loops short
/// (llvmpipe: `shaders/loop_budget.wgsl`); its answer is wrong.
pub const VOLUME_STATUS_LOOPS_CUT: u32 = 4;
/// [`TransmittanceRecord::status`] bit of a streamed pass: the ray read a brick that is not
/// in the brick pool; its answer is discarded and it runs again once the brick is uploaded.
pub const VOLUME_STATUS_MISSING: u32 = 8;
/// Bit of a page-table (indirection) entry marking a brick store's kept brick that is not
/// in the GPU's brick pool (`crate::gpu::brick_pool`); the other bits are the brick's record
/// in the store, whose coarser level of detail a lookup reads while it requests the brick.
pub const VOLUME_ABSENT_BRICK: u32 = 1 << 31;
/// Words of the stream state's header (`shaders/volume/stream.wgsl`), before the requests.
pub const STREAM_HEADER_WORDS: u32 = 8;
/// Stream state header word: requests recorded in this pass (may exceed the capacity).
pub const STREAM_REQUESTED: u32 = 0;
/// Stream state header word: requests the request list holds.
pub const STREAM_CAPACITY: u32 = 1;
/// Stream state header word: first word of the per-brick request flags (one bit a brick).
pub const STREAM_FLAGS: u32 = 2;
/// Stream state header word: first word of the per-slot use stamps.
pub const STREAM_STAMPS: u32 = 3;
/// Stream state header word: this pass's number (the stamp lookups write).
pub const STREAM_PASS: u32 = 4;

/// The tracers' own records, in declaration order.
fn trace_records() -> Vec<RecordEntry> {
    vec![
        entry::<BoxNode>(),
        entry::<SearchList>(),
        entry::<Placement>(),
        entry::<SurfacePrim>(),
        entry::<ScanParams>(),
        entry::<RayRecord>(),
        entry::<HitRecord>(),
        entry::<hytrace_volume::BrickEntry>(),
        entry::<VolumeParams>(),
        entry::<TransmittanceRecord>(),
        entry::<RenderParams>(),
        entry::<RenderItem>(),
        entry::<RenderInstance>(),
        entry::<RenderMedium>(),
    ]
}

/// The WGSL text of the generated module.
pub fn generate() -> String {
    let mut out = String::from(
        "// GENERATED by hytrace-trace (crates/trace/src/gpu/records.rs) from the Rust record\n\
         // definitions. Do not edit: run `HYTRACE_BLESS=1 cargo test -p hytrace-tests --test\n\
         // wgsl_layout` to regenerate. A test fails when this file is stale.\n\n",
    );
    gpu_layout::push_wgsl(&mut out);
    push_struct::<BoxNode>(&mut out);
    push_struct::<SearchList>(&mut out);
    push_struct::<Placement>(&mut out);
    push_struct::<SurfacePrim>(&mut out);
    push_struct::<ScanParams>(&mut out);
    push_struct::<RayRecord>(&mut out);
    push_struct::<HitRecord>(&mut out);
    push_struct::<hytrace_volume::BrickEntry>(&mut out);
    push_struct::<VolumeParams>(&mut out);
    push_struct::<TransmittanceRecord>(&mut out);
    push_struct::<RenderParams>(&mut out);
    push_struct::<RenderItem>(&mut out);
    push_struct::<RenderInstance>(&mut out);
    push_struct::<RenderMedium>(&mut out);
    super::photon_records::push_photon_wgsl(&mut out);
    out.push_str(&format!(
        "const STATUS_DEPTH_LIMIT: u32 = {STATUS_DEPTH_LIMIT}u;\n\
         const STATUS_LOOPS_CUT: u32 = {STATUS_LOOPS_CUT}u;\n\
         const STATUS_START_NEAR: u32 = {STATUS_START_NEAR}u;\n\
         const STATUS_START_BAND: u32 = {STATUS_START_BAND}u;\n\
         const STATUS_DROPPED_SPAN: u32 = {STATUS_DROPPED_SPAN}u;\n\
         // Relative surface tolerance of the f32 kernels (hytrace_csg::Real).\n\
         const SURFACE_TOLERANCE: f32 = {:e};\n\
         // The gap between 1 and the next f32 (hytrace_csg::Real::EPSILON).\n\
         const EPSILON: f32 = {:e};\n\
         // Deepest box BVH the CPU accepts when it prepares a scene.\n\
         const BOX_BVH_MAX_DEPTH: u32 = {}u;\n",
        <f32 as hytrace_csg::Real>::SURFACE_TOLERANCE,
        <f32 as hytrace_csg::Real>::EPSILON,
        crate::cpu::BOX_BVH_MAX_DEPTH,
    ));
    let consts = [
        ("VOLUME_ESTIMATOR_EXACT", VOLUME_ESTIMATOR_EXACT),
        ("VOLUME_ESTIMATOR_MARCH", VOLUME_ESTIMATOR_MARCH),
        ("VOLUME_ESTIMATOR_DELTA", VOLUME_ESTIMATOR_DELTA),
        ("VOLUME_ESTIMATOR_RATIO", VOLUME_ESTIMATOR_RATIO),
        ("VOLUME_ESTIMATOR_RESIDUAL", VOLUME_ESTIMATOR_RESIDUAL),
        ("VOLUME_FILTER_NEAREST", VOLUME_FILTER_NEAREST),
        ("VOLUME_FILTER_TRILINEAR", VOLUME_FILTER_TRILINEAR),
        ("VOLUME_FILTER_STOCHASTIC", VOLUME_FILTER_STOCHASTIC),
        ("VOLUME_FORMAT_BC4", VOLUME_FORMAT_BC4),
        ("VOLUME_FORMAT_UNORM8", VOLUME_FORMAT_UNORM8),
        ("VOLUME_FORMAT_UNORM16", VOLUME_FORMAT_UNORM16),
        ("VOLUME_FORMAT_F16", VOLUME_FORMAT_F16),
        ("VOLUME_FORMAT_F32", VOLUME_FORMAT_F32),
        ("VOLUME_FORMAT_NANOVDB", VOLUME_FORMAT_NANOVDB),
        ("VOLUME_STATUS_NEGATIVE", VOLUME_STATUS_NEGATIVE),
        ("VOLUME_STATUS_MARCH_STEPS", VOLUME_STATUS_MARCH_STEPS),
        ("VOLUME_STATUS_LOOPS_CUT", VOLUME_STATUS_LOOPS_CUT),
        ("VOLUME_STATUS_MISSING", VOLUME_STATUS_MISSING),
        ("VOLUME_ABSENT_BRICK", VOLUME_ABSENT_BRICK),
        ("STREAM_HEADER_WORDS", STREAM_HEADER_WORDS),
        ("STREAM_REQUESTED", STREAM_REQUESTED),
        ("STREAM_CAPACITY", STREAM_CAPACITY),
        ("STREAM_FLAGS", STREAM_FLAGS),
        ("STREAM_STAMPS", STREAM_STAMPS),
        ("STREAM_PASS", STREAM_PASS),
        ("VOLUME_NO_BRICK", hytrace_volume::NO_BRICK),
        ("VOLUME_NO_SLOT", hytrace_volume::NO_SLOT),
        ("RENDER_VIEW_SHADED", RENDER_VIEW_SHADED),
        ("RENDER_VIEW_DEPTH", RENDER_VIEW_DEPTH),
        ("RENDER_VIEW_NORMAL", RENDER_VIEW_NORMAL),
        ("RENDER_VIEW_SOLID", RENDER_VIEW_SOLID),
        ("RENDER_VIEW_PRIM", RENDER_VIEW_PRIM),
        ("RENDER_VIEW_INSTANCE", RENDER_VIEW_INSTANCE),
        ("RENDER_VIEW_BOUNDARY", RENDER_VIEW_BOUNDARY),
        ("RENDER_CUT_UNION", RENDER_CUT_UNION),
        ("RENDER_CUT_INTERSECTION", RENDER_CUT_INTERSECTION),
        ("RENDER_EFFECT_SHADING", RENDER_EFFECT_SHADING),
        ("RENDER_EFFECT_SPECULAR", RENDER_EFFECT_SPECULAR),
        ("RENDER_VOLUMES_NONE", RENDER_VOLUMES_NONE),
        ("RENDER_MAX_MEDIA", RENDER_MAX_MEDIA),
        ("RENDER_VOLUMES_ABSORPTION", RENDER_VOLUMES_ABSORPTION),
        ("RENDER_VOLUMES_SINGLE", RENDER_VOLUMES_SINGLE),
        ("RENDER_VOLUMES_MULTIPLE", RENDER_VOLUMES_MULTIPLE),
        ("RENDER_MATERIAL_DIFFUSE", RENDER_MATERIAL_DIFFUSE),
        ("RENDER_MATERIAL_MIRROR", RENDER_MATERIAL_MIRROR),
        ("RENDER_MATERIAL_DIELECTRIC", RENDER_MATERIAL_DIELECTRIC),
        ("RENDER_MATERIAL_EMITTER", RENDER_MATERIAL_EMITTER),
        ("RENDER_MATERIAL_TRANSPARENT", RENDER_MATERIAL_TRANSPARENT),
        ("RENDER_MATERIAL_SHELL", RENDER_MATERIAL_SHELL),
        ("RENDER_LIGHT_POINT", RENDER_LIGHT_POINT),
        ("RENDER_LIGHT_DIRECTIONAL", RENDER_LIGHT_DIRECTIONAL),
    ];
    for (name, value) in consts {
        out.push_str(&format!("const {name}: u32 = {value}u;\n"));
    }
    out.push_str(&format!(
        "// Infinity of the volume kernels (hytrace_trace::gpu::GPU_INF).\nconst VOLUME_INF: f32 = {:e};\n",
        super::GPU_INF
    ));
    out
}

/// Every record declared in the generated module.
pub fn gpu_records() -> Vec<RecordEntry> {
    let mut all = gpu_layout::records();
    all.extend(trace_records());
    all.extend(super::photon_records::photon_records());
    all
}
