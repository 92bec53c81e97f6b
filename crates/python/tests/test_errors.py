"""Bad input raises clear exceptions (the package's, with the command's messages) and
never takes the interpreter down."""

import subprocess
import sys

import numpy as np
import pytest

import hytrace
from conftest import EVERY_PROCESS, cli_error, random_rays


def message_after_source(text: str) -> str:
    """A message without the name of its source (a file for the command, the argument
    for Python): what follows the first `: `."""
    return text.split(": ", 1)[1]


@pytest.mark.parametrize(
    "bad, error",
    [
        (np.ones((4, 8), dtype=np.int64), hytrace.HytraceTypeError),
        (random_rays(4, 0).astype(np.complex128), hytrace.HytraceTypeError),
        (random_rays(4, 0).astype(np.float16), hytrace.HytraceTypeError),
        (random_rays(4, 0)[:, :7], hytrace.HytraceValueError),
        (random_rays(4, 0).ravel(), hytrace.HytraceValueError),
        (random_rays(4, 0).reshape(2, 2, 8), hytrace.HytraceValueError),
        ("rays", hytrace.HytraceTypeError),
    ],
)
def test_rays_of_the_wrong_type_or_shape_raise(cli, tmp_path, default_scene, bad, error):
    with pytest.raises(error) as raised:
        default_scene.scan(bad)
    assert isinstance(raised.value, hytrace.HytraceError)
    if error is hytrace.HytraceTypeError:
        # (The command's .npy reader refuses these element types before its rays check.)
        got = np.asarray(bad).dtype
        assert str(raised.value) == f"rays: rays must be float32 or float64, got {got}"
    else:
        np.save(tmp_path / "rays.npy", bad)
        p = cli("scan", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "h.npy",
                check=False)
        assert message_after_source(str(raised.value)) == message_after_source(cli_error(p))


@pytest.mark.parametrize(
    "row, column, value",
    [(0, 0, np.nan), (2, 5, np.inf), (1, 3, np.nan), (3, 7, -np.inf), (1, 7, -5.0)],
)
def test_rays_that_are_not_finite_raise_the_commands_message(
    cli, tmp_path, default_scene, row, column, value
):
    rays = random_rays(5, 1)
    rays[row, column] = value
    np.save(tmp_path / "rays.npy", rays)
    p = cli("scan", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "h.npy", check=False)
    for call in [default_scene.scan, default_scene.transmittance]:
        with pytest.raises(hytrace.HytraceValueError) as raised:
            call(rays)
        assert message_after_source(str(raised.value)) == message_after_source(cli_error(p))
        assert f"ray {row}" in str(raised.value)


def test_the_first_bad_ray_is_named_however_many_there_are(cli, tmp_path, default_scene):
    rays = random_rays(20_000, 1)
    rays[[3170, 15_000, 19_999], 4:7] = 0
    rays[9000, 0] = np.nan
    np.save(tmp_path / "rays.npy", rays)
    p = cli("scan", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "h.npy", check=False)
    with pytest.raises(hytrace.HytraceValueError, match="ray 3170: direction") as raised:
        default_scene.scan(rays)
    assert message_after_source(str(raised.value)) == message_after_source(cli_error(p))


def test_zero_directions_raise(default_scene):
    rays = random_rays(3, 1)
    rays[1, 4:7] = 0
    with pytest.raises(ValueError, match="ray 1: direction .* has zero length"):
        default_scene.scan(rays)


@pytest.mark.parametrize(
    "path", ["/nonexistent/scene.gdml", "/nonexistent/dir", "/nonexistent/s.toml",
             "/nonexistent/m.obj"]
)
def test_missing_scenes_raise_file_not_found_with_the_commands_message(cli, path):
    with pytest.raises(FileNotFoundError) as raised:
        hytrace.load(path)
    assert isinstance(raised.value, hytrace.HytraceError)
    assert str(raised.value) == cli_error(cli("info", path, check=False))


@pytest.mark.parametrize("path", ["/nonexistent/v.nvdb", "/nonexistent/v.vdb"])
def test_missing_volumes_raise_file_not_found_with_the_commands_message(cli, path):
    with pytest.raises(hytrace.HytraceFileNotFoundError) as raised:
        hytrace.Volume(path)
    assert str(raised.value) == cli_error(cli("volume", "info", path, check=False))


def test_bad_volume_specs_raise_the_commands_message(cli):
    for spec in ["sphere:-1", "cone:3", "sphere:abc"]:
        with pytest.raises(hytrace.HytraceError) as raised:
            hytrace.Volume(spec)
        assert not isinstance(raised.value, FileNotFoundError)
        assert str(raised.value) == cli_error(cli("volume", "info", spec, check=False))


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda s, r: s.scan(r, precision="f16"), "invalid value 'f16' for 'precision'"),
        (lambda s, r: s.scan(r, backend="cuda"), r"possible values: cpu, embree, gpu, auto"),
        (lambda s, r: s.transmittance(r, estimator="guess"), "'estimator'"),
        (lambda s, r: s.transmittance(r, filter="cubic"), "'filter'"),
        (lambda s, r: s.render(view="xray"), "'view'"),
        (lambda s, r: s.render(size="big"), "expected WIDTHxHEIGHT"),
        (lambda s, r: s.render(size=(0, 10)), "both positive integers"),
        (lambda s, r: s.render(transparent=["nope"]), "no solid of that name"),
        (lambda s, r: s.render(spp=0, size=(4, 4)), "render settings"),
        (lambda s, r: hytrace.Volume("sphere:3", repr="jpeg"), "'repr'"),
        (lambda s, r: hytrace.Volume("sphere:3").sample(np.zeros((2, 3)), space="uv"),
         "'space'"),
    ],
)
def test_bad_options_raise_value_errors(default_scene, call, match):
    with pytest.raises(hytrace.HytraceValueError, match=match):
        call(default_scene, random_rays(3, 2))


def test_backends_refuse_what_they_cannot_do_with_the_commands_message(
    cli, tmp_path, default_scene
):
    rays = random_rays(3, 2)
    np.save(tmp_path / "rays.npy", rays)
    p = cli("scan", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "h.npy",
            "--backend", "gpu", "--precision", "f64", check=False)
    with pytest.raises(hytrace.HytraceError) as raised:
        default_scene.scan(rays, backend="gpu", precision="f64")
    assert str(raised.value) == cli_error(p)
    with pytest.raises(hytrace.HytraceError, match="numbers its rays from 0"):
        default_scene.transmittance(rays, backend="gpu", first=3)


def test_points_that_are_not_finite_raise(cli, tmp_path):
    points = np.zeros((4, 3))
    points[2, 1] = np.nan
    np.save(tmp_path / "p.npy", points)
    p = cli("volume", "sample", "sphere:3", "--points", tmp_path / "p.npy",
            "--out", tmp_path / "v.npy", check=False)
    with pytest.raises(hytrace.HytraceValueError) as raised:
        hytrace.Volume("sphere:3").sample(points)
    assert message_after_source(str(raised.value)) == message_after_source(cli_error(p))
    with pytest.raises(hytrace.HytraceValueError, match=r"points need shape \(N, 3\)"):
        hytrace.Volume("sphere:3").sample(np.zeros((4, 2)))
    with pytest.raises(hytrace.HytraceTypeError):
        hytrace.Volume("sphere:3").sample(np.zeros((4, 3), dtype=np.int32))


@pytest.mark.parametrize(
    "source, count, options, match",
    [
        ("point:0,0,0", 0, {}, r"at least 1"),
        ("point:0,0", 10, {}, "source `point:0,0`"),
        ("laser:0,0,0", 10, {}, "source `laser:0,0,0`"),
        ("point:1e6,0,0", 10, {}, "outside the world"),
        ("point:0,0,0", 10, {"wavelength": -1.0}, "not a positive number"),
        ("point:0,0,0", 10, {"max_steps": 0}, "step limit"),
    ],
)
def test_bad_photon_runs_raise_the_commands_message(cli, tmp_path, source, count, options,
                                                    match):
    scene = hytrace.load(EVERY_PROCESS)
    with pytest.raises(hytrace.HytraceValueError, match=match) as raised:
        scene.photons(source, count, **options)
    flags = {"wavelength": "--wavelength", "max_steps": "--max-steps"}
    extra = [f"{flags[k]}={v}" for k, v in options.items()]
    p = cli("photons", EVERY_PROCESS, "--source", source, "-n", count,
            "--out", tmp_path / "h.npy", *extra, check=False)
    assert str(raised.value) == cli_error(p)


def test_bad_gensteps_raise_the_commands_message(cli, tmp_path):
    cube = EVERY_PROCESS.parent / "scintillator.gdml"
    scene = hytrace.load(cube)
    good = [2, 10, 1, 0, 0, 0, 0, 1, 0, 0, 1, 1, -1, 0]
    for bad, match in [
        ([7] + good[1:], "row 1: unknown kind 7"),
        (good[:1] + [-5] + good[2:], r"row 1: the number of photons \(column 1\) is -5"),
        (good[:2] + [9] + good[3:], "row 1: material index 9 out of range"),
    ]:
        rows = np.array([good, bad], dtype=np.float64)
        with pytest.raises(hytrace.HytraceValueError, match=match) as raised:
            scene.photons(gensteps=rows)
        np.save(tmp_path / "g.npy", rows)
        p = cli("photons", cube, "--gensteps", tmp_path / "g.npy", "--out", tmp_path / "h.npy",
                check=False)
        # The same message, the file named where the array is called `gensteps`.
        assert str(raised.value) == cli_error(p).replace(str(tmp_path / "g.npy"), "gensteps")
    with pytest.raises(hytrace.HytraceValueError, match="gensteps"):
        scene.photons(gensteps=np.zeros((2, 13)))
    with pytest.raises(hytrace.HytraceValueError, match="not both"):
        scene.photons("point:0,0,0", 10, gensteps=np.array([good], dtype=np.float64))


def test_negative_counts_and_seeds_raise_overflow_errors(default_scene):
    with pytest.raises(OverflowError):
        hytrace.load(EVERY_PROCESS).photons("point:0,0,0", -5)
    with pytest.raises(OverflowError):
        default_scene.transmittance(random_rays(2, 1), seed=-1)


def test_bad_input_never_takes_the_interpreter_down():
    # Every bad call in a fresh interpreter, which must finish normally.
    script = """
import numpy as np, hytrace
s = hytrace.load()
bad = [
    lambda: s.scan(np.zeros((0, 8))),
    lambda: s.scan(np.full((3, 8), np.nan)),
    lambda: s.scan(np.zeros((3, 8), dtype=np.float32)),
    lambda: s.scan(object()),
    lambda: s.scan(None),
    lambda: s.render(size=(1, 1), spp=1),
    lambda: hytrace.Volume("sphere:2").sample(np.zeros((0, 3))),
    lambda: hytrace.load("/nope"),
    lambda: hytrace.load(12),
]
for call in bad:
    try:
        call()
    except Exception:
        pass
print("alive")
"""
    p = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "alive"


def test_empty_inputs_give_empty_outputs(cli, tmp_path, default_scene):
    hits, ids = default_scene.scan(np.zeros((0, 8)))
    assert hits.shape == (0, 4) and ids.shape == (0, 3)
    np.save(tmp_path / "rays.npy", np.zeros((0, 8)))
    cli("scan", "--rays", tmp_path / "rays.npy", "--out", tmp_path / "h.npy")
    assert np.load(tmp_path / "h.npy").shape == (0, 4)
