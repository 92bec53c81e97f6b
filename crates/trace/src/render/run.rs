//! `hytrace render`: options, progress bar and output.

use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use hytrace_foundry::Foundry;
use hytrace_volume::CacheStats;

use super::detector::{ColorBy, DetectorError, DetectorStyle, Legend};
use super::spec::{RenderSpec, View, VolumeMode};
use super::{Effects, Image, Renderer};
use crate::cpu::CpuScene;
use crate::gpu::{gpu_or_cpu, warn_redone, GpuContext, GpuRenderer, GpuTimes, TexelStore};

/// Where a render runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RenderBackend {
    /// Our CPU path (rayon over rows).
    Cpu,
    /// Our WGSL render kernel through wgpu (f32): every effect, media of up to 16
    /// placements.
    Gpu,
    /// The GPU when one opens and the render is one it does, else the CPU.
    Auto,
}

/// What the GPU side of a render reports.
pub struct GpuRun {
    /// The adapter (name, type, backend, driver).
    pub adapter: String,
    /// The composition features of the render kernel.
    pub features: Vec<&'static str>,
    /// Upload, kernel and readback seconds.
    pub times: GpuTimes,
}

/// Renders on the GPU of `ctx`. Pixels whose samples ran out of the driver's loop budget
/// (llvmpipe's: `shaders/loop_budget.wgsl`) are rendered again on the CPU, which draws
/// the same random streams, so the image is the kernel's everywhere else and right
/// everywhere; `gpu_redone_on_cpu` in the stats counts them.
fn render_gpu(
    ctx: &GpuContext,
    renderer: &Renderer,
    texels: TexelStore,
    progress: &dyn Fn(u64),
) -> anyhow::Result<(Image, GpuRun)> {
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
        },
    ))
}

/// The render settings a caller may set; each overrides the scene's own (its `[render]`
/// table, or the defaults).
#[derive(Args, Clone, Debug, Default)]
pub struct RenderSettings {
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, value_parser = parse_size)]
    pub size: Option<[u32; 2]>,
    /// Samples per pixel (1: pixel centres).
    #[arg(long)]
    pub spp: Option<u32>,
    /// What the image shows.
    #[arg(long, value_enum)]
    pub view: Option<View>,
    /// How media are rendered.
    #[arg(long, value_enum)]
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
    /// a brick cache), e.g. 4G.
    #[arg(long, value_parser = crate::memory::parse_bytes)]
    pub memory: Option<u64>,
    /// Render the solid of this name transparent (repeatable): to see inside a detector's
    /// enclosures (`hytrace info` lists the solids).
    #[arg(long)]
    pub transparent: Vec<String>,
    #[command(flatten)]
    pub detector: DetectorArgs,
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
    #[arg(long, value_enum, value_name = "KEY")]
    pub color_by: Option<ColorBy>,
}

impl DetectorArgs {
    /// The style these options ask for.
    pub fn style(&self) -> DetectorStyle {
        DetectorStyle {
            depth: self.depth,
            show: self.show.clone(),
            hide: self.hide.clone(),
            color_by: self.color_by,
        }
    }

    /// Whether any option is given.
    pub fn any(&self) -> bool {
        self.style() != DetectorStyle::default()
    }
}

impl RenderSettings {
    /// Sets these settings on the scene's render description, checks that every
    /// transparent solid exists, and validates the result. A hierarchical scene gets its
    /// detector view, whose legend is returned.
    pub fn apply(&self, f: &Foundry, spec: &mut RenderSpec) -> anyhow::Result<Option<Legend>> {
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
        let mut legend = None;
        if spec.volumes.is_empty() {
            if self.detector.any() {
                return Err(DetectorError::NotHierarchical.into());
            }
        } else {
            let view = self.detector.style().apply(f, &spec.volumes)?;
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

/// Renders scene `f` as `spec` describes on `backend`, calling `progress` with the rows
/// done.
pub fn render(
    f: &Foundry,
    spec: &RenderSpec,
    backend: RenderBackend,
    texels: TexelStore,
    progress: &(dyn Fn(u64) + Sync),
) -> anyhow::Result<Rendered> {
    let t1 = Instant::now();
    let scene = CpuScene::<f32>::new(f)?;
    let renderer = Renderer::new(&scene, f, spec)?;
    let build_s = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let cpu = || renderer.render(progress).map(|image| (image, None));
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

/// Parses `WIDTHxHEIGHT`.
pub fn parse_size(text: &str) -> Result<[u32; 2], String> {
    let parse = |s: &str| s.trim().parse::<u32>().ok().filter(|v| *v > 0);
    match text.split_once(['x', 'X']) {
        Some((w, h)) => match (parse(w), parse(h)) {
            (Some(w), Some(h)) => Ok([w, h]),
            _ => Err(format!(
                "`{text}`: expected WIDTHxHEIGHT, both positive integers"
            )),
        },
        None => Err(format!("`{text}`: expected WIDTHxHEIGHT, e.g. 1280x720")),
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
