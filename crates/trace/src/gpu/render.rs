//! The GPU renderer: the render kernel (`shaders/kernels/render.wgsl`) over the scene
//! uploaded as the scan uploads it, composed with only the effects the render calls for.
//! Its CPU twin is [`Renderer::render`]; `tests/gpu_render.rs` compares them pixel by
//! pixel. Media (up to [`RENDER_MAX_MEDIA`] placements) are rendered by emission-absorption,
//! single or multiple scattering, their grids in one set of shared arrays; more are refused
//! with [`GpuError::Unsupported`] (so `--backend auto` falls back to the CPU).

use std::time::Instant;

use super::compose::declared_constants;
use super::context::{compute_pipeline, whole_buffer_entries, GpuContext, GpuError};
use super::records::{
    RenderInstance, RenderItem, RenderMedium, RenderParams, VolumeParams, RENDER_CUT_INTERSECTION,
    RENDER_CUT_UNION, RENDER_EFFECT_SHADING, RENDER_EFFECT_SPECULAR, RENDER_LIGHT_DIRECTIONAL,
    RENDER_LIGHT_POINT, RENDER_MATERIAL_DIELECTRIC, RENDER_MATERIAL_DIFFUSE,
    RENDER_MATERIAL_EMITTER, RENDER_MATERIAL_MIRROR, RENDER_MATERIAL_SHELL,
    RENDER_MATERIAL_TRANSPARENT, RENDER_MAX_MEDIA, RENDER_VOLUMES_ABSORPTION,
    RENDER_VOLUMES_MULTIPLE, RENDER_VOLUMES_NONE, RENDER_VOLUMES_SINGLE, VOLUME_FILTER_TRILINEAR,
};
use super::streamed_store::{store_kernel_grid, PassSize, StorePool, StreamError, StreamStats};
use super::texels::{atlas_texture, texture_layout_entry, TexelStore, ATLAS_TEXTURE_BINDING};
use super::timing::{finish_batch, finish_pass, GpuTimes, PassTimer};
use super::tracer::{binding_bytes, kernel_source, SceneUpload};
use super::transmittance::{store_grid, KernelGrid, UploadedGrid, VolumeUpload};
use crate::render::camera::Projection;
use crate::render::cutaway::CutMode;
use crate::render::spec::{Light, Material, View, VolumeMode};
use crate::render::{Image, Renderer};
use hytrace_foundry::Transform64;
use hytrace_volume::{global_range, BrickStore, BrickedGrid, RangeMips};

const KERNEL: &str = "kernels/render";
/// Storage buffers of the render group (group 2).
const RENDER_BINDINGS: u32 = 5;
/// Samples (pixels x spp) per submission of one batch of rows (a dispatch per sample):
/// drivers may kill long submissions.
const SAMPLES_PER_BATCH: u64 = 1 << 20;

/// A render on the GPU.
#[derive(Debug)]
pub struct GpuImage {
    /// The image.
    pub image: Image,
    /// Where the time went.
    pub times: GpuTimes,
    /// Pixels (row-major indices) a sample of which ran out of the driver's loop budget
    /// (`shaders/loop_budget.wgsl`: llvmpipe only): their values are wrong, to be
    /// rendered again elsewhere.
    pub cut_short: Vec<u32>,
    /// What streaming a brick store did, for a render that streamed one.
    pub stream: Option<StreamStats>,
    /// A streamed render's first pass, every pixel: the pixels it deferred show the
    /// coarser level of detail of the bricks they lacked (what a viewer shows while the
    /// bricks arrive; the image converges to [`GpuImage::image`]).
    pub preview: Option<Image>,
}

impl GpuImage {
    /// Renders the pixels cut short again with `renderer` (the CPU twin of the kernel:
    /// the same samples of the same streams), so the image is right everywhere, and
    /// counts them in the times.
    pub fn redo_cut_short(&mut self, renderer: &Renderer) -> crate::Result<()> {
        let again = renderer.render_pixels(&self.cut_short)?;
        for (&p, value) in self.cut_short.iter().zip(again) {
            self.image.pixels[p as usize] = value;
        }
        self.times.redone_on_cpu = self.cut_short.len() as u64;
        Ok(())
    }
}

/// A scene's render kernel on the GPU, compiled for one set of effects; it renders any
/// view of the scene ([`GpuRenderer::render`]) with those effects.
pub struct GpuRenderer {
    pipeline: wgpu::ComputePipeline,
    render_layout: wgpu::BindGroupLayout,
    scene_group: wgpu::BindGroup,
    /// The media's group 0.
    medium: Option<MediumGroup>,
    hierarchical: bool,
    features: Vec<&'static str>,
    /// The effect part of `features`, which every render must call for exactly.
    effects: Vec<&'static str>,
    source: String,
    /// Upload a streamed store whole before rendering ([`GpuRenderer::with_store_resident`]).
    resident_store: bool,
}

/// The media's group 0 as renders bind it.
enum MediumGroup {
    /// Grids uploaded whole: the bind group, and each grid's translation of index space.
    InCore(wgpu::BindGroup, Vec<[f64; 3]>),
    /// One brick store streamed through a pool each render sets up: group 0's layout, and
    /// the grid as the kernel reads it.
    Streamed(wgpu::BindGroupLayout, Box<UploadedGrid>),
}

impl MediumGroup {
    /// Each grid's translation of index space.
    fn shifts(&self) -> Vec<[f64; 3]> {
        match self {
            MediumGroup::InCore(_, shifts) => shifts.clone(),
            MediumGroup::Streamed(_, grid) => vec![grid.shift],
        }
    }
}

/// The pixels of one dispatch batch.
#[derive(Clone, Copy)]
enum Batch<'p> {
    /// `count` rows from `first`.
    Rows { first: u32, count: u32 },
    /// The pixels listed (row-major indices).
    Listed(&'p [u32]),
}

/// The per-render inputs of the kernel.
struct RenderInputs {
    params: RenderParams,
    items: Vec<RenderItem>,
    instances: Vec<RenderInstance>,
    media: Vec<RenderMedium>,
}

fn item(kind: u32, a: [f32; 4], b: [f32; 4]) -> RenderItem {
    RenderItem {
        kind,
        pad: [0; 3],
        a,
        b,
    }
}

fn rgb(c: [f64; 3], w: f64) -> [f32; 4] {
    [c[0] as f32, c[1] as f32, c[2] as f32, w as f32]
}

/// A material as a render item.
fn material_item(m: &Material) -> RenderItem {
    match *m {
        Material::Diffuse { colour } => item(RENDER_MATERIAL_DIFFUSE, rgb(colour, 0.0), [0.0; 4]),
        Material::Mirror { colour } => item(RENDER_MATERIAL_MIRROR, rgb(colour, 0.0), [0.0; 4]),
        Material::Dielectric {
            ior,
            absorption_length,
        } => item(
            RENDER_MATERIAL_DIELECTRIC,
            [0.0; 4],
            [
                ior as f32,
                absorption_length.unwrap_or(0.0) as f32,
                0.0,
                0.0,
            ],
        ),
        Material::Emitter { radiance } => {
            item(RENDER_MATERIAL_EMITTER, rgb(radiance, 0.0), [0.0; 4])
        }
        Material::Transparent => item(RENDER_MATERIAL_TRANSPARENT, [0.0; 4], [0.0; 4]),
        Material::Shell { colour, opacity } => item(
            RENDER_MATERIAL_SHELL,
            rgb(colour, 0.0),
            [opacity as f32, 0.0, 0.0, 0.0],
        ),
    }
}

/// Refuses what the kernel does not do: media read as stored in a brick store, more than
/// [`RENDER_MAX_MEDIA`] placed media, and scattering media with negative values (which the
/// CPU's trackers refuse).
fn check_supported(renderer: &Renderer) -> Result<(), GpuError> {
    let (Some(mode), Some(media)) = (renderer.effects.volumes, &renderer.media) else {
        return Ok(());
    };
    let count = media.scene.medium_count();
    let stores = (0..count as u32)
        .filter(|&m| media.scene.grid(m).store().is_some())
        .count();
    if stores > 0 && count > 1 {
        return Err(GpuError::Unsupported(format!(
            "the GPU renderer streams one medium read as stored in a brick store, alone; this scene has {count} media, {stores} of them brick stores read as stored (render with --backend cpu, or give the stores a texel format to brick them in memory)"
        )));
    }
    let placed = media.scene.placements().count();
    if placed > RENDER_MAX_MEDIA as usize {
        return Err(GpuError::Unsupported(format!(
            "the GPU renderer takes at most {RENDER_MAX_MEDIA} placed media; this scene places {placed} (render with --backend cpu)"
        )));
    }
    if mode == VolumeMode::EmissionAbsorption {
        return Ok(());
    }
    for medium in 0..media.scene.medium_count() {
        let lowest = global_range(media.scene.grid(medium as u32).ranges()).min;
        if lowest.is_nan() || lowest < 0.0 {
            return Err(GpuError::Unsupported(format!(
                "medium {medium}'s values go down to {lowest}; tracking a scattering medium needs densities >= 0"
            )));
        }
    }
    Ok(())
}

/// The brick store the render streams (its only medium, read as stored; `check_supported`
/// refuses others beside it) and the range mips walks over it take, when media are
/// rendered.
fn streamed_medium<'r>(renderer: &'r Renderer) -> Option<(&'r BrickStore, &'r RangeMips)> {
    let media = renderer.media.as_ref()?;
    renderer.effects.volumes?;
    (media.scene.medium_count() == 1)
        .then(|| media.scene.grid(0).store())
        .flatten()
}

/// The kernel's parameters of medium `medium` uploaded as `grid`: the CPU's trackers'
/// (trilinear lookups, the finest local majorants; the march walks one global segment
/// whatever `global` says).
fn medium_params(renderer: &Renderer, medium: usize, grid: &UploadedGrid) -> VolumeParams {
    let scale = renderer
        .media
        .as_ref()
        .map(|media| media.scene.params(medium as u32, 0).density_scale);
    tracking_params(grid, scale)
}

/// The kernel's parameters of a medium uploaded as `grid` for the CPU's trackers
/// (trilinear lookups, the finest local majorants; the march walks one global segment
/// whatever `global` says), with its density scale when given: the renderer's and the
/// photon kernel's.
pub(super) fn tracking_params(grid: &UploadedGrid, density_scale: Option<f64>) -> VolumeParams {
    let mut params = grid.base;
    if let Some(scale) = density_scale {
        params.density_scale = scale as f32;
    }
    params.lookup_filter = VOLUME_FILTER_TRILINEAR;
    params.global = 0;
    params.finest = 0;
    params
}

/// The rows of the world-to-index transform `to_index` of a placed medium whose grid's
/// upload translated its index space by `shift` (a [`RenderMedium`]'s `rows`).
pub(super) fn placed_rows(to_index: &Transform64, shift: [f64; 3]) -> [[f32; 4]; 3] {
    std::array::from_fn(|r| {
        let row = to_index.rows[r];
        [
            row[0] as f32,
            row[1] as f32,
            row[2] as f32,
            (row[3] - shift[r]) as f32,
        ]
    })
}

/// The media's group 0 of grids uploaded whole: its layout and bind group, the grids'
/// parameters at binding 0 and their texels in `texture` when given.
pub(super) fn media_group(
    ctx: &GpuContext,
    volume: &VolumeUpload,
    params: &wgpu::Buffer,
    texture: Option<&wgpu::TextureView>,
) -> (wgpu::BindGroupLayout, wgpu::BindGroup) {
    let mut layout_entries = volume.layout_entries(ctx);
    let mut entries = volume.entries(params);
    if let Some(view) = texture {
        layout_entries.push(texture_layout_entry(ATLAS_TEXTURE_BINDING));
        entries.push(wgpu::BindGroupEntry {
            binding: ATLAS_TEXTURE_BINDING,
            resource: wgpu::BindingResource::TextureView(view),
        });
    }
    let layout = ctx
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("medium"),
            entries: &layout_entries,
        });
    let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("medium"),
        layout: &layout,
        entries: &entries,
    });
    (layout, group)
}

/// The effect features and `RENDER_EFFECT_*` bits of a render.
fn effect_features(renderer: &Renderer) -> (Vec<&'static str>, u32) {
    let fx = renderer.effects;
    let (mut features, mut bits) = (Vec::new(), 0);
    let scattering = matches!(
        fx.volumes,
        Some(VolumeMode::SingleScattering | VolumeMode::MultipleScattering)
    );
    if fx.shading {
        features.push("shading");
        bits |= RENDER_EFFECT_SHADING;
    }
    if fx.shading || scattering {
        // Shadow rays toward the lights.
        features.push("lights");
    }
    if fx.specular {
        features.push("specular");
        bits |= RENDER_EFFECT_SPECULAR;
    }
    match fx.volumes {
        None | Some(VolumeMode::Off) => {}
        Some(VolumeMode::EmissionAbsorption) => features.extend(["media", "absorption"]),
        Some(_) => features.extend(["media", "scattering"]),
    }
    (features, bits)
}

/// The composition features (the scene's, then the effects') and the composed WGSL of
/// the render kernel for `renderer`, without a device.
pub fn compose_render_kernel(renderer: &Renderer) -> Result<(Vec<&'static str>, String), GpuError> {
    check_supported(renderer)?;
    let arrays = renderer
        .scene
        .gpu_arrays()
        .map_err(|e| GpuError::SceneTooBig(e.to_string()))?;
    let mut features = super::tracer::scene_features(&arrays);
    features.extend(effect_features(renderer).0);
    if streamed_medium(renderer).is_some() {
        features.extend(["streamed", "stream_lods"]);
    }
    let source = kernel_source(KERNEL, &features)?;
    Ok((features, source))
}

/// The kernel's inputs for `renderer` (materials deduplicated, then the lights, then the
/// placed media), each medium's index space translated by its grid's `shifts` entry.
fn inputs(renderer: &Renderer, hierarchical: bool, shifts: &[[f64; 3]]) -> RenderInputs {
    let mut items: Vec<RenderItem> = Vec::new();
    let mut instances = Vec::with_capacity(renderer.instance_material.len());
    for (i, m) in renderer.instance_material.iter().enumerate() {
        let it = material_item(m);
        let index = match items.iter().position(|x| *x == it) {
            Some(k) => k,
            None => {
                items.push(it);
                items.len() - 1
            }
        };
        instances.push(RenderInstance {
            material: index as u32,
            solid: renderer.instance_solid[i],
            boundary: renderer.instance_boundary[i],
            covering: renderer.covering[i],
        });
    }
    let light_first = items.len() as u32;
    for l in &renderer.lights {
        items.push(match *l {
            Light::Point {
                position,
                intensity,
            } => item(RENDER_LIGHT_POINT, rgb(position, 0.0), rgb(intensity, 0.0)),
            Light::Directional {
                direction,
                irradiance,
            } => item(
                RENDER_LIGHT_DIRECTIONAL,
                rgb(direction, 0.0),
                rgb(irradiance, 0.0),
            ),
            Light::Environment { .. } => unreachable!("kept apart by Renderer::new"),
        });
    }
    let cam = &renderer.camera;
    let v3 = |v: glam::DVec3| v.as_vec3().to_array();
    let (orthographic, extent) = match cam.projection {
        Projection::Perspective { tan_half_fov } => (0, tan_half_fov),
        Projection::Orthographic { half_height } => (1, half_height),
    };
    let s = &renderer.settings;
    let params = RenderParams {
        eye: v3(cam.eye),
        view: view_code(renderer.effects.view),
        w: v3(cam.w),
        orthographic,
        u: v3(cam.u),
        extent: extent as f32,
        v: v3(cam.v),
        width: s.size[0],
        environment: v3(renderer.environment),
        height: s.size[1],
        spp: s.spp,
        seed: s.seed,
        max_bounces: s.max_bounces,
        effects: effect_features(renderer).1,
        depth_near: renderer.depth_range[0] as f32,
        depth_far: renderer.depth_range[1] as f32,
        light_count: renderer.lights.len() as u32,
        light_first,
        hierarchical: hierarchical as u32,
        row_offset: 0,
        row_count: 0,
        volume_mode: RENDER_VOLUMES_NONE,
        media_count: 0,
        medium_step: s.step as f32,
        sample: 0,
        probe_trips: 2,
        cut_count: renderer.cutaway.planes.len() as u32,
        cut_mode: match renderer.cutaway.mode {
            CutMode::Union => RENDER_CUT_UNION,
            CutMode::Intersection => RENDER_CUT_INTERSECTION,
        },
        listed: 0,
        pad: 0,
        cuts: std::array::from_fn(|k| match renderer.cutaway.planes.get(k) {
            Some(c) => {
                let n = c.normal.map(|x| x as f32);
                [n[0], n[1], n[2], c.offset as f32]
            }
            None => [0.0; 4],
        }),
    };
    let mut params = params;
    let mut media = Vec::new();
    if let (Some(m), false) = (&renderer.media, shifts.is_empty()) {
        params.volume_mode = match renderer.effects.volumes {
            Some(VolumeMode::EmissionAbsorption) => RENDER_VOLUMES_ABSORPTION,
            Some(VolumeMode::SingleScattering) => RENDER_VOLUMES_SINGLE,
            Some(VolumeMode::MultipleScattering) => RENDER_VOLUMES_MULTIPLE,
            None | Some(VolumeMode::Off) => RENDER_VOLUMES_NONE,
        };
        for (k, ((_, medium), to_index)) in m.scene.placements().enumerate() {
            let shift = shifts[medium as usize];
            let optics = &m.optics[medium as usize];
            media.push(RenderMedium {
                rows: placed_rows(to_index, shift),
                emission: optics.emission.map(|c| c as f32),
                volume: medium,
                albedo: optics.albedo as f32,
                g: optics.g as f32,
                seed: m.scene.params(medium, k as u32).seed,
                pad: 0,
            });
        }
        params.media_count = media.len() as u32;
    }
    RenderInputs {
        params,
        items,
        instances,
        media,
    }
}

impl GpuRenderer {
    /// Uploads the scene of `renderer` and compiles its render kernel with the effects it
    /// calls for.
    pub fn new(ctx: &GpuContext, renderer: &Renderer) -> Result<GpuRenderer, GpuError> {
        Self::with_texels(ctx, renderer, TexelStore::Storage)
    }

    /// [`GpuRenderer::new`] with the media's texels read from `store`: the atlas' storage
    /// buffer, or one 3D texture ([`TexelStore::Texture`]; media of several texel formats,
    /// or a device without the format's texture features, are a [`GpuError::SceneTooBig`]).
    pub fn with_texels(
        ctx: &GpuContext,
        renderer: &Renderer,
        store: TexelStore,
    ) -> Result<GpuRenderer, GpuError> {
        let (mut features, mut source) = compose_render_kernel(renderer)?;
        // Features the arrays and texels add recompose the kernel.
        let composed = features.len();
        // Pipeline constants of the arrays split in chunks (their features recompose it).
        let mut constants = Vec::new();
        // Every medium's grid in the shared arrays, with the trackers' parameters (the
        // CPU's: trilinear lookups, the finest local majorants; the march walks one global
        // segment whatever `global` says).
        let streamed = streamed_medium(renderer)
            .map(|(store, mips)| store_grid(store_kernel_grid(store, mips)))
            .transpose()?;
        let medium = match &renderer.media {
            None => None,
            Some(_) if streamed.is_some() => None,
            Some(media) => {
                // `check_supported` refused media read as stored.
                let bricked: Vec<&BrickedGrid> = (0..media.scene.medium_count())
                    .filter_map(|m| media.scene.grid(m as u32).bricked())
                    .collect();
                let (grids, texture): (Vec<KernelGrid>, _) = match store {
                    TexelStore::Storage => (
                        bricked.iter().map(|g| KernelGrid::Bricked(g)).collect(),
                        None,
                    ),
                    TexelStore::Texture => (
                        bricked
                            .iter()
                            .map(|g| KernelGrid::TexturedBricks(g))
                            .collect(),
                        Some(atlas_texture(ctx, &bricked)?),
                    ),
                };
                let volume = VolumeUpload::new(ctx, &grids)?;
                let (chunked, volume_constants) = volume.kernel_options();
                features.extend(chunked);
                if texture.is_some() {
                    features.push("atlas_texture");
                }
                constants.extend(volume_constants);
                let params: Vec<VolumeParams> = (volume.grids.iter().enumerate())
                    .map(|(m, g)| medium_params(renderer, m, g))
                    .collect();
                let params = ctx.input_buffer("medium params", &binding_bytes(&params));
                let shifts: Vec<[f64; 3]> = volume.grids.iter().map(|g| g.shift).collect();
                Some((volume, params, texture, shifts))
            }
        };
        let medium_bindings = match (&medium, &streamed) {
            (Some((v, ..)), _) => v.binding_count(),
            (None, Some(_)) => 7,
            (None, None) => 0,
        };
        let render_bindings = RENDER_BINDINGS + u32::from(streamed.is_some());
        let upload = SceneUpload::new(
            ctx,
            renderer.scene,
            "render",
            render_bindings + medium_bindings,
        )?;
        features.extend(upload.features.iter().filter(|f| f.starts_with("chunked_")));
        constants.extend(upload.constants.iter().cloned());
        if features.len() > composed {
            source = kernel_source(KERNEL, &features)?;
            constants = declared_constants(&source, &constants);
        }
        ctx.checked("building the render kernel", || {
            let module = ctx.wgsl_module(KERNEL, &source);
            let render_layout = ctx.storage_layout("render", render_bindings, &[3]);
            let medium_group = medium.as_ref().map(|(volume, params, texture, shifts)| {
                let (layout, group) = media_group(ctx, volume, params, texture.as_ref());
                (layout, MediumGroup::InCore(group, shifts.clone()))
            });
            let medium_group = medium_group.or_else(|| {
                let (grid, _) = streamed.as_ref()?;
                let layout = StorePool::group_layout(ctx, "streamed medium", true);
                Some((
                    layout.clone(),
                    MediumGroup::Streamed(layout, Box::new(*grid)),
                ))
            });
            let group0 = medium_group.as_ref().map(|(layout, _)| layout);
            let pipeline_layout =
                ctx.device
                    .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some("render"),
                        bind_group_layouts: &[group0, Some(&upload.layout), Some(&render_layout)],
                        immediate_size: 0,
                    });
            GpuRenderer {
                pipeline: compute_pipeline(ctx, &pipeline_layout, &module, "render", &constants),
                render_layout,
                scene_group: upload.group.clone(),
                medium: medium_group.map(|(_, group)| group),
                hierarchical: upload.hierarchical,
                features: features.clone(),
                effects: effect_features(renderer).0,
                source: source.clone(),
                resident_store: false,
            }
        })
    }

    /// This renderer uploading a streamed brick store whole before it renders: the
    /// in-core reference of a streamed render (the budget must hold every kept brick).
    pub fn with_store_resident(mut self) -> Self {
        self.resident_store = true;
        self
    }

    /// The composition features of the kernel (the scene's, `shading`, `specular`).
    pub fn features(&self) -> &[&'static str] {
        &self.features
    }

    /// The composed WGSL of the kernel.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Renders the image `renderer` describes (the scene and effects this kernel was
    /// built for; any view, camera, lights and settings), in batches of rows, one sample
    /// pass after the other; `progress` gets the row samples finished so far (rows times
    /// samples per pixel: `height * spp` in all). A medium read as stored in a brick store
    /// is streamed through a brick pool of at most the render's `memory` bytes
    /// (`render_streamed`).
    pub fn render(
        &self,
        ctx: &GpuContext,
        renderer: &Renderer,
        progress: &dyn Fn(u64),
    ) -> crate::Result<GpuImage> {
        // The scene is the caller's promise; the effects are checked.
        check_supported(renderer)?;
        let effects = effect_features(renderer).0;
        if effects != self.effects {
            return Err(GpuError::Operation {
                what: "render".into(),
                problem: format!(
                    "the kernel was built for features {:?}, this render needs the effects {effects:?}",
                    self.features
                ),
            }
            .into());
        }
        let shifts = self.medium.as_ref().map_or(Vec::new(), MediumGroup::shifts);
        let inputs = inputs(renderer, self.hierarchical, &shifts);
        if let Some(MediumGroup::Streamed(layout, _)) = &self.medium {
            return self.render_streamed(ctx, renderer, &inputs, layout, progress);
        }
        let group0 = match &self.medium {
            Some(MediumGroup::InCore(group, _)) => Some(group),
            _ => None,
        };
        let (width, height) = (inputs.params.width, inputs.params.height);
        let rows_per_batch = (self.batch_pixels(ctx, &inputs) / width as u64).max(1) as u32;
        let mut pixels = Vec::with_capacity(width as usize * height as usize);
        let mut cut_short = Vec::new();
        let mut times = GpuTimes::default();
        let spp = u64::from(inputs.params.spp);
        let mut row = 0;
        while row < height {
            let count = rows_per_batch.min(height - row);
            let batch = Batch::Rows { first: row, count };
            let done = u64::from(row) * spp;
            let passed = |passes: u32| progress(done + u64::from(count) * u64::from(passes));
            for texel in self.dispatch(ctx, &inputs, batch, group0, &mut times, &passed)? {
                if texel[3] != 0.0 {
                    cut_short.push(pixels.len() as u32);
                }
                pixels.push([texel[0], texel[1], texel[2]]);
            }
            row += count;
            progress(u64::from(row) * spp);
        }
        Ok(GpuImage {
            image: Image {
                width,
                height,
                pixels,
            },
            times,
            cut_short,
            stream: None,
            preview: None,
        })
    }

    /// Pixels a batch takes: [`SAMPLES_PER_BATCH`] samples, within the device's binding
    /// limit on the image's buffer.
    fn batch_pixels(&self, ctx: &GpuContext, inputs: &RenderInputs) -> u64 {
        let per_pixel = inputs.params.spp as u64;
        let limit = (ctx.limits.max_storage_buffer_binding_size / 16).max(1);
        (SAMPLES_PER_BATCH / per_pixel).clamp(1, limit)
    }

    /// A render whose medium is a brick store streamed through a brick pool, in passes: a
    /// pass renders every sample of its pending pixels; a pixel a sample of which read a
    /// brick the pool lacked is discarded and rendered again in a later pass, after the
    /// host uploaded the bricks the pass requested, so every pixel is the kernel's answer
    /// with its bricks resident (the image equals, bit for bit, the render with the whole
    /// store resident). Pass sizes halve while a pass finishes no pixel and places no
    /// brick; a pixel that alone needs more bricks than the pool holds is a
    /// [`StreamError::PoolTooSmall`].
    fn render_streamed(
        &self,
        ctx: &GpuContext,
        renderer: &Renderer,
        inputs: &RenderInputs,
        layout: &wgpu::BindGroupLayout,
        progress: &dyn Fn(u64),
    ) -> crate::Result<GpuImage> {
        let (store, mips) = streamed_medium(renderer).ok_or_else(|| GpuError::Operation {
            what: "render".into(),
            problem: "the kernel was built to stream a brick store this render lacks".into(),
        })?;
        let mut pool = StorePool::new(ctx, store, mips, renderer.settings.memory)?;
        if self.resident_store {
            pool.make_resident(ctx)?;
        }
        let params = [medium_params(renderer, 0, pool.grid())];
        let params = ctx.input_buffer("medium params", &binding_bytes(&params));
        let (width, height) = (inputs.params.width, inputs.params.height);
        let total = width as usize * height as usize;
        let mut pixels = vec![[0.0f32; 3]; total];
        let mut cut_short = Vec::new();
        let mut times = GpuTimes::default();
        let mut pending: Vec<u32> = (0..total as u32).collect();
        let mut size = PassSize::new(total);
        let mut preview = None;
        let batch = self.batch_pixels(ctx, inputs) as usize;
        while !pending.is_empty() {
            let pass = pool.begin_pass(ctx)?;
            let run = &pending[..size.of(pending.len())];
            let mut missing = Vec::new();
            for chunk in run.chunks(batch) {
                let group0 = pool.group(ctx, layout, "streamed medium", &params, true);
                let batch = Batch::Listed(chunk);
                let texels =
                    self.dispatch(ctx, inputs, batch, Some(&group0), &mut times, &|_| {})?;
                for (&p, texel) in chunk.iter().zip(texels) {
                    if texel[3] >= 2.0 {
                        missing.push(p);
                        // The first pass's value, shown until the pixel is rendered again.
                        pixels[p as usize] = [texel[0], texel[1], texel[2]];
                        continue;
                    }
                    if texel[3] != 0.0 {
                        cut_short.push(p);
                    }
                    pixels[p as usize] = [texel[0], texel[1], texel[2]];
                }
            }
            let finished = run.len() - missing.len();
            pool.defer(missing.len());
            if pass == 1 {
                // The first pass runs every pixel.
                preview = Some(Image {
                    width,
                    height,
                    pixels: pixels.clone(),
                });
            }
            let placed = pool.end_pass(ctx, pass)?;
            let rest = pending[run.len()..].to_vec();
            pending = missing;
            pending.extend(rest);
            if size.stuck_after(finished, placed) {
                let p = pending[0];
                return Err(StreamError::PoolTooSmall {
                    item: format!("pixel ({}, {})", p % width, p / width),
                    slots: pool.slots(),
                }
                .into());
            }
            let rows = ((total - pending.len()) / width as usize) as u64;
            progress(rows * u64::from(inputs.params.spp));
        }
        cut_short.sort_unstable();
        Ok(GpuImage {
            image: Image {
                width,
                height,
                pixels,
            },
            times,
            cut_short,
            stream: Some(pool.stats()),
            preview,
        })
    }

    /// One batch of pixels, every sample (a submission per sample, each but the last
    /// waited for here so that `progress` hears of it, with the passes done): each pixel's
    /// summed radiance over the samples, and in `w` 1 when a sample ran out of the
    /// driver's loop budget, 2 when one read a brick a streamed pool lacked.
    fn dispatch(
        &self,
        ctx: &GpuContext,
        inputs: &RenderInputs,
        batch: Batch,
        group0: Option<&wgpu::BindGroup>,
        times: &mut GpuTimes,
        progress: &dyn Fn(u32),
    ) -> Result<Vec<[f32; 4]>, GpuError> {
        let (row_offset, row_count, listed) = match batch {
            Batch::Rows { first, count } => (first, count, None),
            Batch::Listed(pixels) => (0, 0, Some(pixels)),
        };
        let n = listed.map_or((inputs.params.width * row_count) as usize, <[u32]>::len);
        let out_size = (n * 16) as u64;
        let t0 = Instant::now();
        let (out, _keep, samples) = ctx.checked("render dispatch", || {
            let image = ctx.output_buffer("image", out_size);
            let mut shared = vec![
                ctx.input_buffer("render items", &binding_bytes(&inputs.items)),
                ctx.input_buffer("render instances", &binding_bytes(&inputs.instances)),
                ctx.input_buffer("render media", &binding_bytes(&inputs.media)),
            ];
            if let Some(pixels) = listed {
                shared.push(ctx.input_buffer("render pixels", bytemuck::cast_slice(pixels)));
            }
            // One dispatch per sample, each with its parameters.
            let samples: Vec<wgpu::BindGroup> = (0..inputs.params.spp)
                .map(|sample| {
                    let params = RenderParams {
                        row_offset,
                        row_count,
                        listed: n as u32 * u32::from(listed.is_some()),
                        sample,
                        ..inputs.params
                    };
                    let mut buffers = vec![
                        ctx.input_buffer("render params", &binding_bytes(&[params])),
                        shared[0].clone(),
                        shared[1].clone(),
                        image.clone(),
                        shared[2].clone(),
                    ];
                    buffers.extend(shared.get(3).cloned());
                    ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
                        label: Some("render"),
                        layout: &self.render_layout,
                        entries: &whole_buffer_entries(&buffers),
                    })
                })
                .collect();
            (image.clone(), shared, samples)
        })?;
        let mut groups = vec![(1, &self.scene_group)];
        if let Some(medium) = group0 {
            groups.push((0, medium));
        }
        let upload = t0.elapsed();
        let submit = |sample: &wgpu::BindGroup, timer: Option<&PassTimer>| {
            ctx.checked("render dispatch", || {
                let pass = std::slice::from_ref(sample);
                ctx.submit_sequence(
                    "render",
                    &self.pipeline,
                    &groups,
                    (2, pass),
                    n as u32,
                    timer,
                );
            })
        };
        let (last, earlier) = samples.split_last().ok_or_else(|| GpuError::Operation {
            what: "render".into(),
            problem: "no sample per pixel".into(),
        })?;
        for (k, sample) in earlier.iter().enumerate() {
            let timer = PassTimer::new(ctx, "render timestamps");
            let submitted = Instant::now();
            submit(sample, timer.as_ref())?;
            finish_pass(ctx, "render kernel", submitted, timer.as_ref(), times)?;
            progress(k as u32 + 1);
        }
        let timer = PassTimer::new(ctx, "render timestamps");
        // The batch's upload began `upload` before its last pass was submitted.
        let started = Instant::now() - upload;
        submit(last, timer.as_ref())?;
        let bytes = finish_batch(
            ctx,
            "render kernel",
            started,
            &out,
            out_size,
            timer.as_ref(),
            times,
        )?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }
}

/// The kernel's code of a view.
fn view_code(view: View) -> u32 {
    use super::records::*;
    match view {
        View::Shaded => RENDER_VIEW_SHADED,
        View::Depth => RENDER_VIEW_DEPTH,
        View::Normal => RENDER_VIEW_NORMAL,
        View::Solid => RENDER_VIEW_SOLID,
        View::Prim => RENDER_VIEW_PRIM,
        View::Instance => RENDER_VIEW_INSTANCE,
        View::Boundary => RENDER_VIEW_BOUNDARY,
    }
}
