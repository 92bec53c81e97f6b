//! A brick store streamed through the GPU's brick pool (`hytrace_trace::gpu::GpuStreamedVolume`)
//! on lavapipe: with a pool far smaller than the store, so that the pool doubles, evicts and
//! rays are deferred, every transmittance equals bit for bit the same kernel's answer with
//! the whole store resident, and agrees ray by ray with the CPU twin (the estimators on the
//! store read through its cache) as the in-core GPU kernel does (`gpu_volume.rs`); the
//! bricks the request buffer asks for are those the CPU twin reads; bad budgets and a store
//! truncated while open are clear errors.

mod common;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use common::{gpu_stats, hytrace, read_f64};
use hytrace_foundry::layout::Scalar;
use hytrace_foundry::npy::write_array;
use hytrace_trace::gpu::{GpuContext, GpuStreamedVolume, StreamError};
use hytrace_volume::{
    convert_grid, transmittance_batch, BrickStore, ConvertOptions, Coord, DenseGrid, Estimate,
    Estimator, Filter, GridMap, Ray, Rng, TransmittanceParams, VoxelGrid, SUPERCHUNK_BRICKS,
};

/// Voxels along each side of the test volume: 20^3 bricks, about 6400 of them kept, more
/// than the smallest pool (one superchunk, 4096 bricks) holds.
const SIDE: i32 = 160;

/// A volume with noise in most bricks and every fifth brick (in a diagonal pattern) empty.
fn noisy_volume() -> DenseGrid {
    let mut g = DenseGrid::new([0; 3], [SIDE as u32; 3], 0.0).unwrap();
    let mut rng = Rng::new(5, 0, 0);
    for z in 0..SIDE {
        for y in 0..SIDE {
            for x in 0..SIDE {
                if (x / 8 + y / 8 + z / 8) % 5 == 0 {
                    continue;
                }
                let wave =
                    0.5 * ((0.21 * x as f64).sin() + (0.17 * y as f64 + 0.1 * z as f64).cos());
                g.set(
                    [x, y, z].map(i64::from),
                    (1.2 + wave + 0.3 * rng.next_f64()) as f32,
                );
            }
        }
    }
    g
}

/// The test store, converted once per test process into `dir`.
fn store_dir(dir: &Path) -> PathBuf {
    let out = dir.join("noise.bricks");
    let options = ConvertOptions {
        background: 0.0,
        threshold: 0.0,
        range: None,
        memory: 1 << 30,
    };
    convert_grid(&noisy_volume(), "noise", &options, &out, &|_, _| ()).unwrap();
    out
}

/// The GPU (`None` where `GpuContext::for_tests` skips), a temporary folder and the test
/// store converted into it and opened with a 1 GiB cache.
fn gpu_and_store() -> Option<(GpuContext, tempfile::TempDir, PathBuf, BrickStore)> {
    let ctx = GpuContext::for_tests()?;
    let tmp = tempfile::tempdir().unwrap();
    let dir = store_dir(tmp.path());
    let store = BrickStore::open(&dir, 1 << 30).unwrap();
    Some((ctx, tmp, dir, store))
}

/// Rays from outside the volume through random points of it, unit directions.
fn rays(count: usize) -> Vec<Ray> {
    let mut rng = Rng::new(9, 0, 0);
    let side = f64::from(SIDE);
    (0..count)
        .map(|_| {
            let from: [f64; 3] = std::array::from_fn(|_| -0.3 * side + 1.6 * side * rng.next_f64());
            let to: [f64; 3] = std::array::from_fn(|_| side * rng.next_f64());
            let d: [f64; 3] = std::array::from_fn(|k| to[k] - from[k]);
            let n = d.iter().map(|v| v * v).sum::<f64>().sqrt();
            Ray::new(from, d.map(|v| v / n), 0.0, 1e9)
        })
        .collect()
}

fn params(estimator: Estimator, filter: Filter) -> TransmittanceParams {
    let mut p = TransmittanceParams::new(estimator);
    p.filter = filter;
    p.spp = 2;
    p.seed = 3;
    p.density_scale = 0.01;
    p
}

/// The smallest budget a pool of the store accepts, from the error refusing one byte less.
fn least_budget(ctx: &GpuContext, store: &BrickStore) -> u64 {
    match GpuStreamedVolume::new(ctx, store, 1) {
        Err(StreamError::Budget { least, .. }) => least,
        other => panic!("a 1-byte budget: {:?}", other.err()),
    }
}

fn bits(e: &[Estimate]) -> Vec<u64> {
    e.iter().map(|e| e.transmittance.to_bits()).collect()
}

#[test]
fn a_pool_smaller_than_the_store_doubles_evicts_defers_and_answers_bit_for_bit() {
    let Some((ctx, _tmp, _, store)) = gpu_and_store() else {
        return;
    };
    let kept = store.meta().kept_bricks;
    assert!(kept > SUPERCHUNK_BRICKS as u64, "{kept} bricks kept");
    let least = least_budget(&ctx, &store);
    // One byte less is refused with a message naming what is needed.
    let err = GpuStreamedVolume::new(&ctx, &store, least - 1)
        .err()
        .unwrap();
    assert!(err.to_string().contains("give at least"), "{err}");
    let rays = rays(1500);
    for (estimator, filter) in [
        (Estimator::Exact, Filter::Trilinear),
        (Estimator::Ratio, Filter::Stochastic),
        (Estimator::Delta, Filter::Nearest),
    ] {
        let p = params(estimator, filter);
        let mut small = GpuStreamedVolume::new(&ctx, &store, least).unwrap();
        let (streamed, _) = small.transmittance(&ctx, &rays, &p).unwrap();
        let st = small.stats();
        eprintln!("{estimator:?} {filter:?}: {st:?}");
        assert_eq!(st.max_slots as usize, SUPERCHUNK_BRICKS, "{st:?}");
        assert!(
            st.pool_doublings >= 3,
            "the pool doubled from 512 slots: {st:?}"
        );
        assert!(st.passes >= 2 && st.deferred > 0, "{st:?}");
        if estimator == Estimator::Exact {
            // The exact estimator reads every brick along every ray: more than the pool
            // holds, so bricks are evicted and read again.
            assert!(st.bricks_evicted > 0, "{st:?}");
            assert!(st.bricks_uploaded > u64::from(st.max_slots), "{st:?}");
        }
        // The same kernel with every brick resident before the first pass.
        let mut whole = GpuStreamedVolume::new(&ctx, &store, 1 << 30).unwrap();
        whole.make_resident(&ctx).unwrap();
        let (resident, _) = whole.transmittance(&ctx, &rays, &p).unwrap();
        assert_eq!(whole.stats().passes, 1);
        assert_eq!(whole.stats().deferred, 0);
        assert_eq!(bits(&streamed), bits(&resident), "{estimator:?} {filter:?}");
        // The CPU twin on the store, ray by ray (as tests/gpu_volume.rs bounds the in-core
        // kernel): deterministic estimates within 1e-5; tracked ones mostly the same samples.
        let cpu = transmittance_batch(&store, store.mips(), &rays, &p).unwrap();
        let close = (cpu.iter().zip(&streamed))
            .filter(|(c, g)| (c.transmittance - g.transmittance).abs() <= 1e-4)
            .count();
        let worst = (cpu.iter().zip(&streamed))
            .map(|(c, g)| (c.transmittance - g.transmittance).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{estimator:?}: {close} of {} rays within 1e-4 of the CPU, worst {worst:e}",
            rays.len()
        );
        if estimator == Estimator::Exact {
            assert!(worst <= 1e-5, "{worst}");
        } else {
            assert!(close as f64 >= 0.97 * rays.len() as f64, "{close}");
        }
    }
}

/// The store read through, recording the bricks (page indices) every lookup reads.
struct Recording<'a> {
    store: &'a BrickStore,
    read: Mutex<HashSet<u32>>,
}

impl VoxelGrid for Recording<'_> {
    fn background(&self) -> f32 {
        self.store.background()
    }

    fn voxel(&self, ijk: Coord) -> f32 {
        let b = self.store.meta().bricks();
        if ijk.iter().all(|&c| (0..SIDE).contains(&c)) {
            let p = ijk.map(|c| c as usize / 8);
            self.read
                .lock()
                .unwrap()
                .insert(((p[2] * b[1] + p[1]) * b[0] + p[0]) as u32);
        }
        self.store.voxel(ijk)
    }

    fn block_origins(&self) -> Result<Vec<Coord>, hytrace_volume::VolumeError> {
        self.store.block_origins()
    }

    fn map(&self) -> &GridMap {
        self.store.map()
    }
}

#[test]
fn the_request_buffer_asks_for_the_bricks_the_cpu_twin_reads() {
    let Some((ctx, _tmp, _, store)) = gpu_and_store() else {
        return;
    };
    let rays = rays(200);
    let p = params(Estimator::Exact, Filter::Trilinear);
    // A pool holding the whole store: nothing is evicted, so what is resident after the
    // run is every brick requested.
    let mut pool = GpuStreamedVolume::new(&ctx, &store, 1 << 30).unwrap();
    pool.transmittance(&ctx, &rays, &p).unwrap();
    assert_eq!(pool.stats().bricks_evicted, 0);
    let requested: HashSet<u32> = pool.resident_bricks().into_iter().collect();
    let recording = Recording {
        store: &store,
        read: Mutex::new(HashSet::new()),
    };
    transmittance_batch(&recording, store.mips(), &rays, &p).unwrap();
    let records = store.brick_records();
    let read: HashSet<u32> = (recording.read.into_inner().unwrap().into_iter())
        .filter(|&b| records[b as usize].is_some())
        .collect();
    let differ = requested.symmetric_difference(&read).count();
    eprintln!(
        "{} bricks requested, {} read by the CPU, {differ} differ",
        requested.len(),
        read.len()
    );
    assert!(read.len() > 1000);
    // Lookups within f32 rounding of a brick face may fall on either side.
    assert!(differ * 200 <= read.len(), "{differ} of {}", read.len());
    assert_eq!(pool.stats().bricks_uploaded as usize, requested.len());
}

#[test]
fn a_store_truncated_while_open_is_an_error_naming_its_file() {
    let Some((ctx, _tmp, dir, store)) = gpu_and_store() else {
        return;
    };
    let mut pool = GpuStreamedVolume::new(&ctx, &store, 1 << 30).unwrap();
    std::fs::OpenOptions::new()
        .write(true)
        .open(dir.join("bricks.bin"))
        .unwrap()
        .set_len(4096)
        .unwrap();
    let err = pool
        .transmittance(
            &ctx,
            &rays(50),
            &params(Estimator::Exact, Filter::Trilinear),
        )
        .expect_err("a truncated store must fail");
    let text = format!("{err:#}");
    assert!(
        text.contains("bricks.bin") && text.contains("reading brick"),
        "{text}"
    );
}

#[test]
fn volume_transmittance_streams_a_store_on_the_gpu_as_the_cpu_answers() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = store_dir(tmp.path());
    let rays_path = tmp.path().join("rays.npy");
    let rows: Vec<f64> = (rays(300).iter())
        .flat_map(|r| {
            let (o, d) = (r.origin, r.dir);
            [o[0], o[1], o[2], 0.0, d[0], d[1], d[2], f64::INFINITY]
        })
        .collect();
    write_array(
        &rays_path,
        Scalar::F64,
        &[300, 8],
        bytemuck::cast_slice(&rows),
    )
    .unwrap();
    // `volume transmittance` of the store on `backend` with `memory`, written to `out`.
    let command = |backend: &str, memory: &str, out: &str| {
        let (dir, rays) = (dir.to_str().unwrap(), rays_path.to_str().unwrap());
        let out = tmp.path().join(out);
        let args = [
            "volume",
            "transmittance",
            dir,
            "--rays",
            rays,
            "--backend",
            backend,
            "--memory",
            memory,
            "--density-scale",
            "0.01",
            "--stats",
            "--out",
        ];
        (
            hytrace(&[&args[..], &[out.to_str().unwrap()]].concat(), &[]),
            out,
        )
    };
    let run = |backend: &str, memory: &str, out: &str| {
        let (o, out) = command(backend, memory, out);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (read_f64(&out), o)
    };
    let (gpu, out) = run("gpu", "5M", "gpu.npy");
    let stats = gpu_stats(&out);
    let stream = &stats["stream"];
    assert!(stream["passes"].as_u64().unwrap() > 1, "{stats}");
    assert!(stream["bricks_uploaded"].as_u64().unwrap() > 0, "{stats}");
    let (cpu, _) = run("cpu", "5M", "cpu.npy");
    let worst = gpu
        .iter()
        .zip(&cpu)
        .map(|(g, c)| (g - c).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-5, "{worst}");
    // A budget below one superchunk's bricks is refused, naming what it needs.
    let (bad, _) = command("gpu", "2M", "x.npy");
    assert!(!bad.status.success());
    let text = String::from_utf8_lossy(&bad.stderr);
    assert!(
        text.contains("too small") && text.contains("give at least"),
        "{text}"
    );
    assert!(!tmp.path().join("x.npy").exists());
}
