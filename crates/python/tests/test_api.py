"""Every API function against the `hytrace` command on the same inputs, bit for bit."""

import json
import threading

import numpy as np
import pytest

import hytrace
from conftest import EVERY_PROCESS, DATA, random_rays


def same(a: np.ndarray, b: np.ndarray) -> None:
    """Equal bit for bit: dtype, shape and every value (infinities included)."""
    assert a.dtype == b.dtype, (a.dtype, b.dtype)
    assert a.shape == b.shape, (a.shape, b.shape)
    assert np.array_equal(a, b), np.argwhere(a != b)[:5]


def test_info_is_the_commands_json(cli, default_scene):
    assert default_scene.info() == json.loads(cli("info", "--json", "default").stdout)


def test_load_reads_scene_files_as_the_command_does(cli):
    path = DATA / "gdml" / "coverage.gdml"
    assert hytrace.load(path).info() == json.loads(cli("info", "--json", path).stdout)
    assert hytrace.load(str(path)).path == path


@pytest.mark.parametrize("precision", ["f32", "f64"])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_scan_equals_the_command(cli, tmp_path, default_scene, precision, dtype):
    rays = random_rays(3000, seed=1).astype(dtype)
    np.save(tmp_path / "rays.npy", rays)
    cli(
        "scan", "default", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "hits.npy",
        "--ids", tmp_path / "ids.npy", "--precision", precision,
    )
    hits, ids = default_scene.scan(rays, precision=precision)
    same(hits, np.load(tmp_path / "hits.npy"))
    same(ids, np.load(tmp_path / "ids.npy"))
    # Real answers: hits and misses, several instances crossed.
    crossed = ids[:, 0] >= 0
    assert 0.2 < crossed.mean() < 0.98
    assert np.isinf(hits[~crossed, 3]).all() and np.isfinite(hits[crossed, 3]).all()
    assert len(np.unique(ids[crossed, 0])) >= 3


def test_scan_reads_any_layout_alike(default_scene):
    rays = random_rays(500, seed=2)
    hits, ids = default_scene.scan(rays)
    fortran = np.asfortranarray(rays)
    strided = np.zeros((500, 16))
    strided[:, ::2] = rays
    # Misaligned, as arrays unpickled from a byte stream can be (Dask sends them so).
    buffer = bytearray(rays.nbytes + 1)
    misaligned = np.frombuffer(buffer, dtype=np.float64, offset=1, count=rays.size)
    misaligned = misaligned.reshape(rays.shape)
    misaligned[:] = rays
    assert not misaligned.flags.aligned
    for other in [fortran, strided[:, ::2], rays.tolist(), misaligned, misaligned[:, :]]:
        h, i = default_scene.scan(other)
        same(h, hits)
        same(i, ids)
    # Read in place, never written.
    before = rays.copy()
    default_scene.scan(rays)
    same(rays, before)


def test_scan_on_the_gpu_equals_the_command(cli, tmp_path, default_scene):
    rays = random_rays(64, seed=3)
    np.save(tmp_path / "rays.npy", rays)
    cli(
        "scan", "default", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "hits.npy",
        "--ids", tmp_path / "ids.npy", "--backend", "gpu",
    )
    hits, ids = default_scene.scan(rays, backend="gpu")
    same(hits, np.load(tmp_path / "hits.npy"))
    same(ids, np.load(tmp_path / "ids.npy"))


@pytest.mark.parametrize(
    "options",
    [
        {},
        {"estimator": "delta", "spp": 2, "seed": 5},
        {"estimator": "ratio", "seed": 1, "density_scale": 3.0, "filter": "nearest"},
        {"estimator": "march", "step": 2.0, "precision": "f64"},
        {"estimator": "residual", "global_majorant": True},
    ],
)
def test_transmittance_equals_the_command(cli, tmp_path, default_scene, options):
    rays = random_rays(2000, seed=4, spread=300.0)
    np.save(tmp_path / "rays.npy", rays)
    flags = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        flags += [flag] if value is True else [flag, value]
    cli(
        "scan", "default", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "hits.npy",
        "--transmittance", tmp_path / "t.npy", *flags,
    )
    got = default_scene.transmittance(rays, **options)
    same(got, np.load(tmp_path / "t.npy"))
    assert (got < 1).any() and (got == 1).any()


def test_transmittance_streams_follow_the_first_ray_index(default_scene):
    rays = random_rays(1000, seed=5, spread=300.0)
    whole = default_scene.transmittance(rays, estimator="delta", seed=2)
    parts = [
        default_scene.transmittance(rays[a:b], estimator="delta", seed=2, first=a)
        for a, b in [(0, 333), (333, 334), (334, 1000)]
    ]
    same(np.concatenate(parts), whole)
    # Another first index draws other streams.
    shifted = default_scene.transmittance(rays, estimator="delta", seed=2, first=1)
    assert not np.array_equal(shifted, whole)


@pytest.mark.parametrize(
    "options, flags",
    [
        ({"size": (40, 30), "spp": 2}, ["--size", "40x30", "--spp", "2"]),
        ({"size": "24x16", "view": "normal"}, ["--size", "24x16", "--view", "normal"]),
        (
            {"size": (20, 20), "volumes": "off", "seed": 3, "max_bounces": 2},
            ["--size", "20x20", "--volumes", "off", "--seed", "3", "--max-bounces", "2"],
        ),
    ],
)
def test_render_equals_the_command(cli, tmp_path, default_scene, options, flags):
    cli("render", "default", "--out", tmp_path / "image.npy", *flags)
    image = default_scene.render(**options)
    same(image, np.load(tmp_path / "image.npy"))
    assert image.max() > 0


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_render_of_a_brick_store_within_a_memory_budget_equals_the_command(cli, tmp_path, backend):
    # A fog converted to a brick store, read as stored through a budget of 6 MiB (a cache
    # on the CPU, a brick pool on the GPU): the image equals the command's bit for bit.
    cli("volume", "convert", "sphere:40,0.5", "--store", "-o", tmp_path / "fog.bricks")
    scene = tmp_path / "fog.toml"
    scene.write_text('[volumes.fog]\nsource = "fog.bricks"\ndensity_scale = 0.05\n'
                     'emission = [0.5, 0.4, 0.3]\n\n[[place]]\nsolid = "fog"\n\n'
                     '[camera]\neye = [0, -200, 40]\ntarget = [0, 0, 0]\n\n'
                     '[render]\nvolumes = "emission-absorption"\n')
    cli("render", scene, "--out", tmp_path / "image.npy", "--size", "24x16", "--memory", "6M",
        "--backend", backend)
    image = hytrace.load(scene).render(size=(24, 16), memory=6 << 20, backend=backend)
    same(image, np.load(tmp_path / "image.npy"))
    assert image.max() > 0
    with pytest.raises(hytrace.HytraceError, match="fog.bricks.*too small"):
        hytrace.load(scene).render(size=(24, 16), memory=1, backend=backend)


def test_render_on_the_gpu_equals_the_command(cli, tmp_path, default_scene):
    cli("render", "default", "--out", tmp_path / "image.npy", "--size", "16x12",
        "--backend", "gpu")
    same(default_scene.render(size=(16, 12), backend="gpu"), np.load(tmp_path / "image.npy"))


@pytest.mark.parametrize(
    "spec", ["sphere:10,1", str(DATA / "nanovdb" / "density_zip.nvdb"),
             str(DATA / "openvdb" / "density_zip.vdb")]
)
@pytest.mark.parametrize(
    "options",
    [
        {},
        {"filter": "nearest", "space": "index"},
        {"filter": "stochastic", "seed": 7},
        {"majorant": 0},
    ],
)
def test_volume_sample_equals_the_command(cli, tmp_path, spec, options):
    volume = hytrace.Volume(spec)
    bbox = np.asarray(volume.info()["grids"][0]["world_bbox"], float)
    if options.get("space") == "index":
        bbox = np.asarray(volume.info()["grids"][0]["index_bbox"], float)
    rng = np.random.default_rng(8)
    points = rng.uniform(bbox[0] - 1, bbox[1] + 1, size=(4000, 3)).astype(np.float32)
    np.save(tmp_path / "points.npy", points)
    flags = []
    for name, value in options.items():
        flags += ["--" + name, value]
    cli("volume", "sample", spec, "--points", tmp_path / "points.npy",
        "--out", tmp_path / "v.npy", *flags)
    got = volume.sample(points, **options)
    same(got, np.load(tmp_path / "v.npy"))
    assert len(np.unique(got)) >= 2


def test_volume_representations_equal_the_command(cli, tmp_path):
    spec = "sphere:12,1,3"
    points = np.random.default_rng(9).uniform(-14, 14, size=(3000, 3))
    np.save(tmp_path / "points.npy", points)
    for repr_ in ["bc4", "unorm8", "f16"]:
        cli("volume", "sample", spec, "--points", tmp_path / "points.npy",
            "--out", tmp_path / "v.npy", "--repr", repr_)
        same(hytrace.Volume(spec, repr=repr_).sample(points), np.load(tmp_path / "v.npy"))


def test_volume_transmittance_through_a_brick_store_equals_the_command(cli, tmp_path):
    store = tmp_path / "fog.bricks"
    cli("volume", "convert", "sphere:40,0.5", "--store", "-o", store)
    rng = np.random.default_rng(4)
    origins = rng.uniform(-60, 60, size=(500, 3))
    dirs = rng.normal(size=(500, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    rays = np.hstack([origins, np.zeros((500, 1)), dirs, np.full((500, 1), np.inf)])
    np.save(tmp_path / "rays.npy", rays)
    for options in [{}, {"estimator": "ratio", "spp": 4, "seed": 3}]:
        flags = []
        for name, value in options.items():
            flags += ["--" + name, value]
        cli("volume", "transmittance", store, "--rays", tmp_path / "rays.npy",
            "--out", tmp_path / "t.npy", "--memory", "6M", "--density-scale", "0.05", *flags)
        # A cache of 6 MiB, far below the store: the same answers, bit for bit.
        volume = hytrace.Volume(store, memory=6 << 20)
        got = volume.transmittance(rays, density_scale=0.05, **options)
        same(got, np.load(tmp_path / "t.npy"))
        assert got.min() < 0.99 and got.max() == 1.0 and len(np.unique(got)) > 100
    # On the GPU the store streams through a brick pool of the volume's memory.
    cli("volume", "transmittance", store, "--rays", tmp_path / "rays.npy",
        "--out", tmp_path / "t.npy", "--memory", "6M", "--density-scale", "0.05",
        "--backend", "gpu")
    got = hytrace.Volume(store, memory=6 << 20).transmittance(
        rays, density_scale=0.05, backend="gpu")
    same(got, np.load(tmp_path / "t.npy"))


def test_photons_equal_the_command(cli, tmp_path):
    scene = hytrace.load(EVERY_PROCESS)
    cli("photons", EVERY_PROCESS, "--source", "point:0,0,0", "-n", "3000", "--seed", "3",
        "--wavelength", "400", "--out", tmp_path / "hits.npy",
        f"--history={tmp_path / 'histories.npy'}")
    hits, histories = scene.photons("point:0,0,0", 3000, seed=3, wavelength=400.0,
                                    histories=True)
    same(hits, np.load(tmp_path / "hits.npy"))
    same(histories, np.load(tmp_path / "histories.npy"))
    assert len(hits) > 0
    same(scene.photons("point:0,0,0", 3000, seed=3, wavelength=400.0), hits)
    # Wavelengths drawn from a material's spectrum, as the command draws them.
    cli("photons", EVERY_PROCESS, "--source", "point:0,0,0", "-n", "3000", "--seed", "3",
        "--wavelength", "Liquid:SCINTILLATIONCOMPONENT1", "--out", tmp_path / "drawn.npy")
    drawn = scene.photons("point:0,0,0", 3000, seed=3,
                          wavelength="Liquid:SCINTILLATIONCOMPONENT1")
    same(drawn, np.load(tmp_path / "drawn.npy"))
    assert len(np.unique(drawn[:, 7])) > 10


def test_photon_ranges_equal_the_commands_first_option_and_the_whole_run(cli, tmp_path):
    scene = hytrace.load(EVERY_PROCESS)
    cli("photons", EVERY_PROCESS, "--source", "beam:0,0,-20:0,0,1:15", "-n", "800",
        "--first", "1200", "--out", tmp_path / "part.npy")
    same(scene.photons("beam:0,0,-20:0,0,1:15", 800, first=1200),
         np.load(tmp_path / "part.npy"))
    whole = scene.photons("beam:0,0,-20:0,0,1:15", 2000)
    parts = [scene.photons("beam:0,0,-20:0,0,1:15", n, first=a)
             for a, n in [(0, 1200), (1200, 800)]]
    same(np.concatenate(parts), whole)
    same(parts[1], np.load(tmp_path / "part.npy"))


def test_photons_through_a_brick_store_within_a_memory_budget_equal_the_command(cli, tmp_path):
    # A fog converted to a brick store, read as stored, in the tank of media_tank.gdml
    # between a beam and the sensor plate: with a budget of 6 MiB (the store's tables and
    # a cache of one superchunk's bricks) the hits and histories equal the command's with
    # `--memory 6M` and those of the default budget, bit for bit.
    cli("volume", "convert", "sphere:40,0.5", "--store", "-o", tmp_path / "fog.bricks")
    scene = tmp_path / "fog.toml"
    scene.write_text(f'[gdml.tank]\nfile = "{DATA / "photons" / "media_tank.gdml"}"\n\n'
                     '[volumes.fog]\nsource = "fog.bricks"\ndensity_scale = 0.05\n'
                     'albedo = 0.8\n\n[[place]]\nsolid = "fog"\n')
    source = "beam:0,0,-150:0,0,1:45"
    cli("photons", scene, "--source", source, "-n", "2000", "--seed", "4", "--memory", "6M",
        "--out", tmp_path / "hits.npy", f"--history={tmp_path / 'histories.npy'}")
    fog = hytrace.load(scene)
    hits, histories = fog.photons(source, 2000, seed=4, memory=6 << 20, histories=True)
    same(hits, np.load(tmp_path / "hits.npy"))
    same(histories, np.load(tmp_path / "histories.npy"))
    # Some photons crossed the fog, some were scattered or absorbed in it.
    assert 0 < len(hits) < 2000
    same(fog.photons(source, 2000, seed=4), hits)
    # A budget too small for the store is refused naming it and the least it needs; the
    # scene still runs with a budget that holds it.
    with pytest.raises(hytrace.HytraceError, match="fog.bricks.*too small.*give at least"):
        fog.photons(source, 10, memory=1)
    p = cli("photons", scene, "--source", source, "-n", "10", "--memory", "1",
            "--out", tmp_path / "refused.npy", check=False)
    assert p.returncode != 0 and "too small" in p.stderr
    same(fog.photons(source, 2000, seed=4, memory=6 << 20), hits)


# A scintillation step along x and a Cherenkov step of a fast electron down the z axis in
# the scintillator cube (material 1), in the layout of `hytrace photons --gensteps`.
GENSTEPS = np.array([
    [2, 3000, 1, 10.0, -20, 0, 0, 20, 0, 0, 0.5, 0.5, -1, 0],
    [1, 2000, 1, 50.0, 0, 0, 60, 0, 0, 20, 0.99, 0.98, -1, 0],
], dtype=np.float64)


def test_photons_from_gensteps_equal_the_command(cli, tmp_path):
    cube = DATA / "photons" / "scintillator.gdml"
    np.save(tmp_path / "g.npy", GENSTEPS)
    cli("photons", cube, "--gensteps", tmp_path / "g.npy", "--seed", "2",
        "--out", tmp_path / "hits.npy", f"--history={tmp_path / 'histories.npy'}")
    scene = hytrace.load(cube)
    hits, histories = scene.photons(gensteps=GENSTEPS, seed=2, histories=True)
    same(hits, np.load(tmp_path / "hits.npy"))
    same(histories, np.load(tmp_path / "histories.npy"))
    assert len(histories) == 5000 and len(hits) > 500
    # A range of the photons.
    cli("photons", cube, "--gensteps", tmp_path / "g.npy", "--first", "2500", "-n", "1000",
        "--out", tmp_path / "part.npy")
    same(scene.photons(None, 1000, gensteps=GENSTEPS, first=2500),
         np.load(tmp_path / "part.npy"))


def test_tracing_releases_the_gil(default_scene):
    rays = random_rays(400_000, seed=10)
    started, done = threading.Event(), threading.Event()

    def scan():
        started.set()
        default_scene.scan(rays)
        done.set()

    worker = threading.Thread(target=scan)
    worker.start()
    started.wait()
    ticks = 0
    while not done.is_set():
        ticks += 1
        done.wait(0.001)
    worker.join()
    # The main thread ran all along the scan (with the GIL held it could not have).
    assert ticks >= 10, ticks
