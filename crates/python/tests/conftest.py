"""Fixtures of the hytrace Python tests: the `hytrace` command (the oracle every API
function is compared with, bit for bit), rays and the repository's test data."""

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]
DATA = REPO / "tests" / "data"
EVERY_PROCESS = DATA / "photons" / "every_process.gdml"


def _hytrace_binary() -> Path:
    """The command built by cargo from this checkout (`HYTRACE_BIN` overrides)."""
    given = os.environ.get("HYTRACE_BIN")
    if given:
        return Path(given)
    subprocess.run(
        ["cargo", "build", "-q", "-p", "hytrace-trace", "--bin", "hytrace"],
        cwd=REPO,
        check=True,
    )
    return REPO / "target" / "debug" / "hytrace"


@pytest.fixture(scope="session")
def cli():
    """Runs `hytrace ARGS...`; returns the completed process (check=False)."""
    binary = _hytrace_binary()

    def run(*args, check=True):
        p = subprocess.run(
            [str(binary), *map(str, args)], capture_output=True, text=True
        )
        if check and p.returncode != 0:
            raise AssertionError(f"hytrace {' '.join(map(str, args))}: {p.stderr}")
        return p

    return run


def cli_error(process) -> str:
    """The message of a failed command: its stderr after `hytrace: error: `."""
    assert process.returncode != 0, process.stdout
    prefix = "hytrace: error: "
    line = process.stderr.strip()
    assert line.startswith(prefix), line
    return line[len(prefix) :]


def random_rays(n: int, seed: int, spread: float = 600.0) -> np.ndarray:
    """`n` rays (N, 8) float64 from a cloud of origins (normal, `spread` mm) around the
    origin in random directions (not normalized), a fifth with a finite tmax."""
    rng = np.random.default_rng(seed)
    origins = rng.normal(scale=spread, size=(n, 3))
    directions = rng.normal(size=(n, 3))
    tmax = np.where(rng.random(n) < 0.2, rng.uniform(1, 4 * spread, n), np.inf)
    return np.column_stack([origins, np.zeros(n), directions, tmax])


@pytest.fixture(scope="session")
def default_scene():
    import hytrace

    return hytrace.load("default")
