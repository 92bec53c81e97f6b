//! `hytrace render`: options, progress bar and output.

use std::time::Instant;

use crate::error::{bail, Context};
use hytrace_foundry::Foundry;
use hytrace_volume::CacheStats;

use super::cutaway::Cutaway;
use super::detector::{DetectorError, DetectorStyle, Legend};
use super::spec::{RenderSpec, View, VolumeMode};
use super::{Effects, Image, Renderer};
use crate::cpu::CpuScene;
use crate::gpu::{
    gpu_or_cpu, warn_redone, GpuContext, GpuRenderer, GpuTimes, StreamStats, TexelStore,
};

/// Where a render runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RenderBackend {
    /// Our CPU path (rayon over rows).
    Cpu,
    /// Our WGSL render kernel through wgpu (f32): every effect, media of up to 16
    /// placements.
    Gpu,
    /// The GPU when one opens and the render is one it does, else the CPU.
    Auto,
}

crate::choice::named!(RenderBackend {
    (RenderBackend::Cpu, "cpu", [], "Our CPU path (rayon over rows)"),
    (RenderBackend::Gpu, "gpu", [], "Our WGSL render kernel through wgpu (f32): every effect, media of up to 16 placements"),
    (RenderBackend::Auto, "auto", [], "The GPU when one opens and the render is one it does, else the CPU"),
});

/// What the GPU side of a render reports.
pub struct GpuRun {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The composition features of the render kernel.
    pub features: Vec<&'static str>,
    /// Upload, kernel and readback seconds.
    pub times: GpuTimes,
    /// What streaming a brick store medium did (a medium read as stored).
    pub stream: Option<StreamStats>,
    /// The streamed render's first pass (deferred pixels at the coarser level of detail).
    pub preview: Option<Image>,
}

/// Renders on the GPU of `ctx` (`progress` as [`GpuRenderer::render`] calls it). Pixels
/// whose samples ran out of the driver's loop budget (llvmpipe's:
/// `shaders/loop_budget.wgsl`) are rendered again on the CPU, which draws the same random
/// streams, so the image is the kernel's everywhere else and right everywhere;
/// `gpu_redone_on_cpu` in the stats counts them.
fn render_gpu(
    ctx: &GpuContext,
    renderer: &Renderer,
    texels: TexelStore,
    progress: &dyn Fn(u64),
) -> crate::Result<(Image, GpuRun)> {
    let gpu = GpuRenderer::with_texels(ctx, renderer, texels)?;
    let mut run = gpu.render(ctx, renderer, progress)?;
    run.redo_cut_short(renderer)?;
    warn_redone(
        &ctx.describe(),
        &run.times,
        run.image.pixels.len(),
        "pixels",
    );
    Ok((
        run.image,
        GpuRun {
            adapter: ctx.describe(),
            features: gpu.features().to_vec(),
            times: run.times,
            stream: run.stream,
            preview: run.preview,
        },
    ))
}

/// The render settings a caller may set; each overrides the scene's own (its `[render]`
/// table, or the defaults).
#[derive(Clone, Debug, Default)]
pub struct RenderSettings {
    /// Image size, WIDTHxHEIGHT.
    pub size: Option<[u32; 2]>,
    /// Samples per pixel (1: pixel centres).
    pub spp: Option<u32>,
    /// What the image shows.
    pub view: Option<View>,
    /// How media are rendered.
    pub volumes: Option<VolumeMode>,
    /// Longest path (surface and medium scattering events).
    pub max_bounces: Option<u32>,
    /// Emission-absorption march step in voxels.
    pub step: Option<f64>,
    /// Seed of the random streams.
    pub seed: Option<u32>,
    /// Bytes each medium read as stored in a brick store may hold resident (its tables and
    /// a brick cache).
    pub memory: Option<u64>,
    /// Render the solid of this name transparent (repeatable): to see inside a detector's
    /// enclosures (`hytrace info` lists the solids).
    pub transparent: Vec<String>,
    /// Cut planes (none: the scene's own, which has none unless set in code).
    pub cutaway: Cutaway,
    /// The detector view's style (GDML and other hierarchical scenes).
    pub detector: DetectorStyle,
}

impl RenderSettings {
    /// Sets these settings on the scene's render description, checks that every
    /// transparent solid exists, and validates the result. A hierarchical scene gets its
    /// detector view, whose legend is returned.
    pub fn apply(&self, f: &Foundry, spec: &mut RenderSpec) -> crate::Result<Option<Legend>> {
        let s = &mut spec.settings;
        s.size = self.size.unwrap_or(s.size);
        s.spp = self.spp.unwrap_or(s.spp);
        s.view = self.view.unwrap_or(s.view);
        s.volumes = self.volumes.or(s.volumes);
        s.max_bounces = self.max_bounces.unwrap_or(s.max_bounces);
        s.step = self.step.unwrap_or(s.step);
        s.seed = self.seed.unwrap_or(s.seed);
        s.memory = self.memory.unwrap_or(s.memory);
        for name in &self.transparent {
            if !f.solid_names.contains(name) {
                bail!("--transparent {name}: the scene has no solid of that name");
            }
            spec.transparent_solids.push(name.clone());
        }
        if !self.cutaway.planes.is_empty() {
            spec.cutaway = self.cutaway.clone();
        }
        let mut legend = None;
        if spec.volumes.is_empty() {
            if self.detector != DetectorStyle::default() {
                return Err(DetectorError::NotHierarchical.into());
            }
        } else {
            let view = self.detector.apply(f, &spec.volumes)?;
            spec.instance_materials = view.materials;
            legend = Some(view.legend);
        }
        spec.validate().context("render settings")?;
        Ok(legend)
    }
}

/// A finished render: the image, where it ran and where its time went.
pub struct Rendered {
    /// The image (linear radiance).
    pub image: Image,
    /// The effects the render simulated.
    pub effects: Effects,
    /// Seconds preparing the scene and the renderer.
    pub build_s: f64,
    /// Seconds rendering.
    pub render_s: f64,
    /// Set when it ran on the GPU.
    pub gpu: Option<GpuRun>,
    /// The brick caches of the media read as stored in brick stores, summed.
    pub stores: Option<CacheStats>,
}

/// Renders scene `f` as `spec` describes on `backend`, calling `progress` with the row
/// samples done (rows times samples per pixel, `height * spp` in all): the CPU renders a
/// row's samples together, the GPU one sample pass of a batch of rows after the other.
pub fn render(
    f: &Foundry,
    spec: &RenderSpec,
    backend: RenderBackend,
    texels: TexelStore,
    progress: &(dyn Fn(u64) + Sync),
) -> crate::Result<Rendered> {
    let t1 = Instant::now();
    let scene = CpuScene::<f32>::new(f)?;
    let renderer = Renderer::new(&scene, f, spec)?;
    let build_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let spp = u64::from(spec.settings.spp);
    let cpu = || {
        renderer
            .render(&|rows| progress(rows * spp))
            .map(|image| (image, None))
    };
    let gpu = |ctx: GpuContext| {
        render_gpu(&ctx, &renderer, texels, progress).map(|(image, run)| (image, Some(run)))
    };
    let (image, gpu) = match backend {
        RenderBackend::Cpu => cpu()?,
        RenderBackend::Gpu => gpu(GpuContext::new()?)?,
        RenderBackend::Auto => gpu_or_cpu("renders", gpu, cpu)?,
    };
    let media = renderer.media.as_ref().map(|m| &m.scene);
    if let Some(media) = media {
        // A brick store that failed while rendering read the background: no image.
        media.check_reads()?;
    }
    Ok(Rendered {
        image,
        effects: renderer.effects(),
        build_s,
        render_s: t2.elapsed().as_secs_f64(),
        gpu,
        stores: media.and_then(|m| m.store_stats()),
    })
}

/// An image size that cannot be parsed.
#[derive(Debug, PartialEq, thiserror::Error)]
pub enum SizeError {
    /// No `x` between the width and the height.
    #[error("`{0}`: expected WIDTHxHEIGHT, e.g. 1280x720")]
    NoSeparator(String),
    /// The width or the height is not a positive integer.
    #[error("`{0}`: expected WIDTHxHEIGHT, both positive integers")]
    NotPositive(String),
}

/// Parses `WIDTHxHEIGHT`.
pub fn parse_size(text: &str) -> Result<[u32; 2], SizeError> {
    let parse = |s: &str| s.trim().parse::<u32>().ok().filter(|v| *v > 0);
    match text.split_once(['x', 'X']) {
        Some((w, h)) => match (parse(w), parse(h)) {
            (Some(w), Some(h)) => Ok([w, h]),
            _ => Err(SizeError::NotPositive(text.to_string())),
        },
        None => Err(SizeError::NoSeparator(text.to_string())),
    }
}

#[cfg(test)]
mod tests {
    use super::parse_size;

    #[test]
    fn sizes_parse_and_bad_ones_are_refused() {
        assert_eq!(parse_size("1280x720"), Ok([1280, 720]));
        assert_eq!(parse_size("64X48"), Ok([64, 48]));
        for bad in ["1280", "0x10", "ax3", "12x", "-3x4"] {
            assert!(parse_size(bad).is_err(), "{bad}");
        }
    }
}
