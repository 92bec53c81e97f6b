"""`hytrace.dask` on a LocalCluster of 1, 2 and 4 worker processes: the same arrays bit
for bit as one in-process call, for any chunking."""

import dask.array as da
import numpy as np
import pytest
from dask.distributed import Client, LocalCluster

import hytrace
import hytrace.dask as hd
from conftest import EVERY_PROCESS, random_rays

RAYS = random_rays(3000, seed=21, spread=300.0)
CHUNKINGS = {1: (3000,), 2: (1000, 2000), 4: (700, 800, 1, 1499)}
PHOTONS = 3000
SOURCE = "point:0,0,0"


@pytest.fixture(scope="module")
def whole():
    """The in-process answers: one call on all rays, one photon run on all photons."""
    scene = hytrace.load("default")
    hits, ids = scene.scan(RAYS)
    t = scene.transmittance(RAYS, estimator="ratio", seed=4, spp=2)
    photon_hits, histories = hytrace.load(EVERY_PROCESS).photons(
        SOURCE, PHOTONS, seed=9, histories=True
    )
    return hits, ids, t, photon_hits, histories


@pytest.fixture(scope="module", params=[1, 2, 4])
def client(request):
    with LocalCluster(
        n_workers=request.param,
        threads_per_worker=1,
        processes=True,
        dashboard_address=None,
        memory_limit=0,
    ) as cluster, Client(cluster) as c:
        c.wait_for_workers(request.param)
        yield request.param, c


def test_scan_transmittance_and_photons_equal_one_call(client, whole):
    workers, c = client
    hits, ids, t, photon_hits, histories = whole
    rays = da.from_array(RAYS, chunks=(CHUNKINGS[workers], 8))
    got_hits, got_ids = hd.scan("default", rays)
    got_t = hd.transmittance("default", rays, estimator="ratio", seed=4, spp=2)
    assert got_hits.chunks[0] == CHUNKINGS[workers]
    got_hits, got_ids, got_t = c.compute([got_hits, got_ids, got_t], sync=True)
    for got, want in [(got_hits, hits), (got_ids, ids), (got_t, t)]:
        assert got.dtype == want.dtype and np.array_equal(got, want)
    chunk = [PHOTONS, 1000, 700][[1, 2, 4].index(workers)]
    p_hits, p_histories = hd.photons(
        EVERY_PROCESS, SOURCE, PHOTONS, chunk=chunk, seed=9, histories=True
    )
    p_hits, p_histories = c.compute([p_hits, p_histories], sync=True)
    assert np.array_equal(p_hits, photon_hits) and np.array_equal(p_histories, histories)
    assert len(photon_hits) > 0 and (t < 1).any()
    # The tasks ran on the workers, which loaded each scene once.
    loaded = c.run(lambda: sorted(k[0] for k in hd._scenes))
    assert len(loaded) == workers
    assert any(loaded.values())
    assert all(len(v) == len(set(v)) for v in loaded.values())


def test_rays_of_the_wrong_shape_are_refused_before_any_work():
    with pytest.raises(hytrace.HytraceValueError, match=r"need shape \(N, 8\)"):
        hd.scan("default", da.zeros((10, 7)))
    with pytest.raises(hytrace.HytraceValueError, match="first is set per chunk"):
        hd.transmittance("default", da.zeros((10, 8)), first=3)
    with pytest.raises(hytrace.HytraceValueError):
        hd.photon_ranges(10, 0)
    assert hd.photon_ranges(10, 4) == [(0, 4), (4, 4), (8, 2)]
