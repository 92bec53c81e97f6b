//! Renders of a scene medium read lazily from a brick store (`hytrace render --memory`):
//! with a brick cache smaller than the store, so that bricks are evicted and read again,
//! the image equals bit for bit (fixed seed) the render of the same store bricked in memory
//! (`format = "f32"`, which holds the store's decoded values exactly), by emission-absorption
//! and by multiple scattering; a budget below one superchunk is refused naming the least
//! one, and the GPU backend refuses such a medium with a clear error, writing no image.

mod common;

use std::path::{Path, PathBuf};

use common::{hytrace, read_values};
use hytrace_volume::{convert_grid, ConvertOptions, DenseGrid, Rng};

/// Voxels along each side of the test volume: 32^3 bricks, about 6800 of them kept (7 MiB
/// of 16-bit bricks), more than the cache of the least budget (one superchunk, 4096 bricks)
/// holds.
const SIDE: i32 = 256;

/// A cloud: noise inside a ball that leaves the volume's sides empty (so the store's own
/// range mips span more than its data), every fifth brick (in a diagonal pattern) empty.
fn cloud() -> DenseGrid {
    let mut g = DenseGrid::new([0; 3], [SIDE as u32; 3], 0.0).unwrap();
    let mut rng = Rng::new(11, 0, 0);
    let c = f64::from(SIDE) / 2.0;
    for z in 0..SIDE {
        for y in 0..SIDE {
            for x in 0..SIDE {
                let r = [x, y, z].map(|v| f64::from(v) + 0.5 - c);
                let r = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                if r > 0.75 * c || (x / 8 + y / 8 + z / 8) % 5 == 0 {
                    continue;
                }
                let wave = 0.4 * ((0.19 * f64::from(x)).sin() + (0.13 * f64::from(y + z)).cos());
                let value = (1.0 - r / c) * (1.2 + wave + 0.4 * rng.next_f64()) * 1.5;
                g.set([x, y, z].map(i64::from), value as f32);
            }
        }
    }
    g
}

/// Converts the cloud into a brick store `cloud.bricks` in `dir` and writes two scenes
/// placing it: `stored.toml` reads the store as stored, `in_core.toml` bricks it in memory.
fn scenes(dir: &Path) -> (PathBuf, PathBuf) {
    let options = ConvertOptions {
        background: 0.0,
        threshold: 0.0,
        range: None,
        memory: 1 << 30,
    };
    convert_grid(
        &cloud(),
        "density",
        &options,
        &dir.join("cloud.bricks"),
        &|_, _| (),
    )
    .unwrap();
    let scene = |name: &str, format: &str| {
        let text = format!(
            r#"
[volumes.cloud]
source = "cloud.bricks"
density_scale = 0.02
albedo = 0.9
g = 0.4
emission = [0.6, 0.3, 0.1]
{format}

[solids.floor]
shape = "box(600, 600, 4)"

[[place]]
solid = "cloud"
translate = [-128, -128, -32]

[[place]]
solid = "floor"
translate = [0, 0, -4]

[[lights]]
kind = "directional"
direction = [-0.5, 0.4, -0.75]
irradiance = [2.5, 2.4, 2.2]

[[lights]]
kind = "environment"
radiance = [0.2, 0.25, 0.35]

[camera]
eye = [380, -420, 260]
target = [0, 0, 90]
fov = 40
"#
        );
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    };
    (
        scene("stored.toml", ""),
        scene("in_core.toml", "format = \"f32\""),
    )
}

/// `hytrace render` of `scene` into `out` with `args` after the common ones.
fn render(scene: &Path, out: &Path, args: &[&str]) -> std::process::Output {
    let common = [
        "render",
        scene.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--size",
        "48x32",
        "--seed",
        "7",
        "--step",
        "0.5",
    ];
    hytrace(&[&common[..], args].concat(), &[])
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The error of a render of `scene` into `out` with `args` that must fail and write nothing.
fn refused(scene: &Path, out: &Path, args: &[&str]) -> String {
    let o = render(scene, out, args);
    assert!(!o.status.success());
    assert!(!out.exists());
    stderr(&o)
}

/// The least `--memory` the store accepts, from the error refusing a budget of one byte
/// (which must name it and write nothing).
fn least_memory(scene: &Path, dir: &Path) -> u64 {
    let text = refused(scene, &dir.join("refused.npy"), &["--memory", "1"]);
    assert!(
        text.contains("cloud.bricks") && text.contains("too small"),
        "{text}"
    );
    let least = text
        .split("give at least ")
        .nth(1)
        .unwrap_or_else(|| panic!("{text}"));
    least
        .trim()
        .trim_end_matches(|c: char| !c.is_ascii_digit())
        .parse()
        .unwrap_or_else(|e| panic!("{e}: {text}"))
}

#[test]
fn a_store_rendered_through_a_small_cache_equals_the_in_core_render_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let (stored, in_core) = scenes(tmp.path());
    let least = least_memory(&stored, tmp.path());
    let memory = least.to_string();
    for (mode, spp) in [("emission-absorption", "2"), ("multiple-scattering", "32")] {
        let image = |scene: &Path, name: &str, extra: &[&str]| {
            let out = tmp.path().join(format!("{mode}-{name}.npy"));
            let args = [&["--volumes", mode, "--spp", spp, "--stats"][..], extra].concat();
            let o = render(scene, &out, &args);
            assert!(o.status.success(), "{name}: {}", stderr(&o));
            let stats: serde_json::Value =
                serde_json::from_slice(o.stdout.split(|&b| b == b'\n').next().unwrap()).unwrap();
            (read_values(&out), stats)
        };
        let (lazy, stats) = image(&stored, "stored", &["--memory", &memory]);
        let store = &stats["store"];
        eprintln!("{mode}: {store}");
        let (read, cache) = (
            store["bricks_read"].as_u64(),
            store["cache_bricks"].as_u64(),
        );
        // The cache holds fewer bricks than the render read: bricks were evicted.
        assert!(read.unwrap() > cache.unwrap(), "{stats}");
        let (whole, stats) = image(&in_core, "in-core", &[]);
        assert!(stats.get("store").is_none(), "{stats}");
        assert!(lazy.iter().any(|&v| v > 0.0));
        let differ = (lazy.iter().zip(&whole))
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differ,
            0,
            "{mode}: {differ} of {} values differ",
            lazy.len()
        );
    }
}

#[test]
fn a_store_read_as_stored_is_refused_by_the_gpu_renderer() {
    let tmp = tempfile::tempdir().unwrap();
    let (stored, _) = scenes(tmp.path());
    let out = tmp.path().join("gpu.npy");
    let text = refused(&stored, &out, &["--backend", "gpu", "--spp", "1"]);
    assert!(
        text.contains("brick store read as stored") && text.contains("--backend cpu"),
        "{text}"
    );
}
