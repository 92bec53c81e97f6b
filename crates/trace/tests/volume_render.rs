//! `hytrace render VOLUME`: a .nvdb file, a brick store or a procedural grid rendered with
//! no scene file. At the pixel whose ray is the camera's central ray, the blue channel over
//! the background's (the glow has no blue) equals the transmittance of that ray computed by
//! the volume crate's exact estimator on the grid opened on its own; pixels whose rays miss
//! the grid's active box (one voxel wider: the trilinear support) are the background; the
//! median optical depth of the pixels that see the grid is near the rule's target; bad
//! input fails naming the file and writes no image. The GPU's render passes the same checks.

mod common;

use std::path::Path;

use common::{hytrace, read_values, render_on_gpu, repo, stderr};
use glam::DVec3;
use hytrace_trace::scene::{load_volume_render_scene, BACKGROUND, EMISSION, TARGET_DEPTH};
use hytrace_volume::{
    convert_grid, open_volume, transmittance, ConvertOptions, DenseGrid, Estimator, Ray,
    TransmittanceParams, VoxelGrid,
};

/// Image side: odd, so that the central pixel's centre is on the camera's axis.
const SIDE: usize = 41;

/// Whether the ray `o + t d` (t >= 0) meets the box `[lo, hi]` (slab test).
fn meets_box(o: DVec3, d: DVec3, lo: DVec3, hi: DVec3) -> bool {
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for k in 0..3 {
        let inv = 1.0 / d[k];
        let (a, b) = ((lo[k] - o[k]) * inv, (hi[k] - o[k]) * inv);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    t0 <= t1
}

/// The image of `hytrace render SOURCE` (no scene file) at pixel centres, as linear RGB.
fn render_cli(source: &str, dir: &Path) -> Vec<f64> {
    let out = dir.join("volume.npy");
    let size = format!("{SIDE}x{SIDE}");
    let run = hytrace(
        &[
            "render",
            source,
            "-o",
            out.to_str().unwrap(),
            "--size",
            &size,
            "--spp",
            "1",
        ],
        &[],
    );
    assert!(run.status.success(), "{source}: {}", stderr(&run));
    read_values(&out)
}

/// Checks the image `pixels` of `source` rendered with no scene file against the grid
/// itself.
fn check_volume_render(source: &str, pixels: &[f64]) {
    assert_eq!(pixels.len(), SIDE * SIDE * 3);
    let pixel = |i: usize, j: usize| {
        let k = 3 * (j * SIDE + i);
        [pixels[k], pixels[k + 1], pixels[k + 2]]
    };

    // The automatic camera and density scale, and the grid opened on its own.
    let (f, spec) = load_volume_render_scene(Path::new(source)).unwrap();
    let camera = spec.camera.expect("an automatic camera");
    let scale = f.optics.media[0].density_scale;
    let mut volumes = open_volume(source).unwrap();
    let named = volumes.remove(0);
    let grid = named.grid.unwrap();
    let mips = grid.range_mips().unwrap();
    let mut params = TransmittanceParams::new(Estimator::Exact);
    params.density_scale = scale;
    let eye = DVec3::from(camera.eye);
    let w = (DVec3::from(camera.target) - eye).normalize();
    let reference = |d: DVec3| {
        let ray = Ray::new(eye.into(), d.into(), 0.0, f64::INFINITY);
        transmittance(&grid, &mips, &ray, 0, &params)
            .unwrap()
            .transmittance
    };

    // The central ray: the blue channel is the background seen through the medium.
    let centre = pixel(SIDE / 2, SIDE / 2);
    let expected = reference(w);
    assert!(
        (1e-4..0.98).contains(&expected),
        "{source}: the central ray should cross the fog, T = {expected}"
    );
    let got = centre[2] / BACKGROUND[2];
    assert!(
        (got / expected - 1.0).abs() < 5e-3,
        "{source}: central pixel transmittance {got}, the exact estimator's {expected}"
    );
    assert!(
        centre[0] > BACKGROUND[0],
        "{source}: the fog glows: {centre:?}"
    );

    // Pixels whose rays miss the active box widened by a voxel show the background; the
    // median optical depth of those that see the grid is near the target.
    let [lo, hi] = named.summary.world_bbox.unwrap().map(DVec3::from);
    let voxel = (DVec3::from(grid.map().index_to_world([1.0, 1.0, 1.0]))
        - DVec3::from(grid.map().index_to_world([0.0; 3])))
    .length();
    let (lo, hi) = (lo - DVec3::splat(voxel), hi + DVec3::splat(voxel));
    let u = w.cross(DVec3::Z).normalize();
    let v = u.cross(w);
    let tan = (0.5 * camera.fov.unwrap().to_radians()).tan();
    let (mut misses, mut depths) = (0, Vec::new());
    for j in 0..SIDE {
        for i in 0..SIDE {
            let x = 2.0 * (i as f64 + 0.5) / SIDE as f64 - 1.0;
            let y = 1.0 - 2.0 * (j as f64 + 0.5) / SIDE as f64;
            let d = (w + tan * (x * u + y * v)).normalize();
            let p = pixel(i, j);
            if !meets_box(eye, d, lo, hi) {
                misses += 1;
                for c in 0..3 {
                    assert!(
                        (p[c] - BACKGROUND[c]).abs() < 1e-6,
                        "{source}: pixel ({i}, {j}) misses the grid but is {p:?}"
                    );
                }
            } else if p[2] < BACKGROUND[2] * (1.0 - 1e-4) {
                depths.push(-(p[2] / BACKGROUND[2]).ln());
            }
        }
    }
    assert!(
        misses > SIDE * SIDE / 4,
        "{source}: {misses} pixels miss the grid"
    );
    assert!(!depths.is_empty());
    depths.sort_by(f64::total_cmp);
    let median = depths[depths.len() / 2];
    assert!(
        (0.5 * TARGET_DEPTH..2.0 * TARGET_DEPTH).contains(&median),
        "{source}: median optical depth {median}, the rule aims at {TARGET_DEPTH}"
    );
    assert_eq!(
        EMISSION[2], 0.0,
        "the blue channel must carry the background only"
    );
}

#[test]
fn a_nanovdb_file_renders_with_no_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    let source = repo("tests/data/nanovdb/density_zip.nvdb");
    let source = source.to_str().unwrap();
    check_volume_render(source, &render_cli(source, dir.path()));
}

#[test]
fn a_nanovdb_file_renders_on_the_gpu_with_no_scene_file() {
    let source = repo("tests/data/nanovdb/density_zip.nvdb");
    let (f, mut spec) = load_volume_render_scene(&source).unwrap();
    spec.settings.size = [SIDE as u32; 2];
    spec.settings.spp = 1;
    let Some(image) = render_on_gpu(&f, &spec) else {
        return;
    };
    let pixels: Vec<f64> = image
        .pixels
        .iter()
        .flatten()
        .map(|&c| f64::from(c))
        .collect();
    check_volume_render(source.to_str().unwrap(), &pixels);
}

#[test]
fn a_brick_store_and_a_procedural_fog_render_with_no_scene_file() {
    let dir = tempfile::tempdir().unwrap();
    // A ball of linearly falling density in a 24^3 grid with 0.5 voxels, off the origin.
    let mut g = DenseGrid::new([4, -8, 0], [24, 24, 24], 0.0).unwrap();
    for z in 0..24i64 {
        for y in 0..24i64 {
            for x in 0..24i64 {
                let r = [x, y, z].map(|c| c as f64 - 11.5);
                let r = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
                if r < 11.0 {
                    g.set([x + 4, y - 8, z], (3.0 * (1.0 - r / 11.0)) as f32);
                }
            }
        }
    }
    let store = dir.path().join("ball.bricks");
    let options = ConvertOptions {
        background: 0.0,
        threshold: 0.0,
        range: None,
        memory: 1 << 30,
    };
    convert_grid(&g, "density", &options, &store, &|_, _| ()).unwrap();
    for source in [store.to_str().unwrap(), "sphere:8,0.5,3"] {
        check_volume_render(source, &render_cli(source, dir.path()));
    }
}

#[test]
fn unreadable_volumes_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let bytes = std::fs::read(repo("tests/data/nanovdb/density_zip.nvdb")).unwrap();
    let truncated = dir.path().join("truncated.nvdb");
    std::fs::write(&truncated, &bytes[..bytes.len() / 3]).unwrap();
    let missing = dir.path().join("missing.vdb");
    // A grid whose background is not zero is no fog.
    let background = repo("tests/data/openvdb/density_zip.vdb");
    for bad in [&truncated, &missing, &background] {
        let out = dir.path().join("bad.png");
        let run = hytrace(
            &["render", bad.to_str().unwrap(), "-o", out.to_str().unwrap()],
            &[],
        );
        let err = stderr(&run);
        assert!(!run.status.success(), "{}: accepted", bad.display());
        let name = bad.file_name().unwrap().to_str().unwrap();
        assert!(err.contains(name), "{name}: {err}");
        assert!(!err.contains("panicked"), "{err}");
        assert!(!out.exists(), "{}: wrote an image", bad.display());
    }
}
