//! `hytrace render`: options, the progress bar and the report.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context};
use clap::Args;
use hytrace_foundry::gdml::GdmlOptions;
use hytrace_foundry::npy::write_atomically;
use hytrace_trace::gpu::{add_gpu_stats, TexelStore};
use hytrace_trace::render::run::{render, RenderBackend, RenderSettings, Rendered};
use hytrace_trace::render::{write_image, Effects, ExrPrecision, IMAGE_EXTENSIONS};
use hytrace_trace::scene::load_render_scene;

use super::choice::choice;
use super::options::RenderSettingsArgs;

/// The options of `hytrace render`; each overrides the scene file's `[render]` table.
#[derive(Args, Debug)]
pub struct RenderArgs {
    /// `default` (or nothing) for the embedded default scene, a .toml scene file, a .gdml
    /// file, a mesh, a Foundry directory, or a volume (.nvdb, .vdb, a brick store, sphere:R)
    /// rendered with an automatic camera and transfer function.
    pub scene: Option<PathBuf>,
    /// The image: .png (8-bit sRGB), .npy (float32 linear radiance, height x width x 3) or
    /// .exr (OpenEXR linear RGB, see --exr).
    #[arg(short, long, default_value = "out/render.png")]
    pub out: PathBuf,
    /// The sample type of an .exr image: float (32-bit, the radiance exactly) or half.
    #[arg(long, value_parser = choice::<ExrPrecision>(), value_name = "TYPE", default_value_t = ExrPrecision::Float)]
    pub exr: ExrPrecision,
    /// Where it renders.
    #[arg(long, value_parser = choice::<RenderBackend>(), default_value_t = RenderBackend::Cpu)]
    pub backend: RenderBackend,
    /// Where the GPU reads the media's texels from: a storage buffer, decoded as on the CPU,
    /// or one 3D texture of their texel format (BC4 then decoded by the device; every
    /// medium in one format).
    #[arg(long, value_parser = choice::<TexelStore>(), default_value_t = TexelStore::Storage)]
    pub gpu_texels: TexelStore,
    #[command(flatten)]
    pub settings: RenderSettingsArgs,
    /// Also write the first pass of a GPU render that streams a brick store (what a viewer
    /// shows while bricks arrive: pixels that lacked a brick at its coarser level of
    /// detail), same formats as --out.
    #[arg(long, value_name = "IMAGE")]
    pub preview: Option<PathBuf>,
    /// Print which effects and kernels the scene uses, and render nothing.
    #[arg(long)]
    pub explain: bool,
    /// Print one JSON line of timings.
    #[arg(long)]
    pub stats: bool,
}

/// Where the legend of the image `out` goes: `IMAGE.legend.EXT` beside it (`json`, `png`).
fn legend_path(out: &Path, ext: &str) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    out.with_file_name(format!("{stem}.legend.{ext}"))
}

/// Runs `hytrace render`.
pub fn run(args: RenderArgs, options: &GdmlOptions) -> anyhow::Result<()> {
    let ext = args.out.extension().and_then(|e| e.to_str());
    if !matches!(ext, Some("png" | "npy" | "exr")) && !args.explain {
        bail!(
            "{}: the image must be a {IMAGE_EXTENSIONS} file",
            args.out.display()
        );
    }
    if let Some(p) = &args.preview {
        let ext = p.extension().and_then(|e| e.to_str());
        if !matches!(ext, Some("png" | "npy" | "exr")) {
            bail!(
                "--preview {}: the image must be a {IMAGE_EXTENSIONS} file",
                p.display()
            );
        }
        if args.backend == RenderBackend::Cpu {
            bail!(
                "--preview shows a GPU render's first pass, while bricks of a brick store \
                 are missing; the CPU reads every brick when it needs it: give --backend gpu"
            );
        }
    }
    let t0 = Instant::now();
    let (f, mut spec) = load_render_scene(args.scene.as_deref(), options)?;
    let legend = RenderSettings::from(args.settings.clone()).apply(&f, &mut spec)?;
    if args.explain {
        for line in Effects::of(&f, &spec).explain() {
            println!("{line}");
        }
        println!(
            "backends: the CPU path is monomorphised over these effects; the GPU kernel \
             composes only their WGSL (geometry views, surfaces, specular, media of up to \
             16 placements by emission-absorption, single or multiple scattering)"
        );
        return Ok(());
    }
    let load_s = t0.elapsed().as_secs_f64();
    let [width, height] = spec.settings.size;
    // Rows times samples: the GPU reports each sample pass, the CPU each row.
    let passes = u64::from(height) * u64::from(spec.settings.spp);
    let bar = hytrace_trace::progress::bar(passes, "rendering", "row samples");
    let progress = |done| bar.set_position(done);
    let Rendered {
        image,
        effects: fx,
        build_s,
        render_s,
        gpu: gpu_run,
        stores,
    } = render(&f, &spec, args.backend, args.gpu_texels, &progress)?;
    bar.finish_and_clear();
    write_image(&image, &args.out, args.exr)?;
    if let Some(path) = &args.preview {
        match gpu_run.as_ref().and_then(|g| g.preview.as_ref()) {
            Some(first) => write_image(first, path, args.exr)?,
            None => eprintln!(
                "--preview {}: not written: this render streamed no brick store on the GPU, \
                 so it had no pass with bricks missing",
                path.display()
            ),
        }
    }
    if let Some(legend) = &legend {
        let path = legend_path(&args.out, "json");
        let text = serde_json::to_string_pretty(&legend.to_json())?;
        write_atomically(&path, |w| w.write_all(text.as_bytes()))
            .with_context(|| format!("writing the legend {}", path.display()))?;
        write_image(&legend.image(), &legend_path(&args.out, "png"), args.exr)?;
    }
    let samples = width as f64 * height as f64 * spec.settings.spp as f64;
    if args.stats {
        let mut line = serde_json::json!({
            "backend": if gpu_run.is_some() { "gpu" } else { "cpu" },
            "width": width,
            "height": height,
            "spp": spec.settings.spp,
            "view": fx.view.to_string(),
            "shading": fx.shading,
            "specular": fx.specular,
            "volumes": fx.volumes.map(|v| v.to_string()),
            "load_s": load_s,
            "build_s": build_s,
            "render_s": render_s,
            "samples_per_s": samples / render_s.max(1e-9),
            "threads": rayon::current_num_threads(),
        });
        if let Some(g) = &gpu_run {
            add_gpu_stats(&mut line, &g.adapter, &g.features, &g.times);
            if let Some(st) = &g.stream {
                line["stream"] = st.json("pixels_deferred");
            }
        }
        if let Some(c) = stores {
            line["store"] = c.json();
        }
        println!("{line}");
    }
    eprintln!(
        "{width}x{height}, {} spp in {render_s:.2} s; wrote {}",
        spec.settings.spp,
        args.out.display()
    );
    Ok(())
}
