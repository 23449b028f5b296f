"""A's assembly holds to its memory estimate, near the limit, and a job beyond the limit is refused up front.

The estimate (:func:`analytic.operator.cost.model_cost`, from a sample of A's (pixel, pair)s, before any
work) is what the commands check against the memory available and print before a long job. tracemalloc
sees every array assembly allocates in Python (NumPy's), so its peak must stay under the estimate, and
the estimate not far above it (else a job that fits would be refused). The scenes leave most of their
(pixel, pair)s to the general routes, whose working set was once ~9 times A.
"""

import tracemalloc

import numpy as np
import pytest
import scipy.sparse

from analytic.operator import system

from analytic.errors import ResourceError
from analytic.operator.cost import model_cost, refuse_unaffordable
from analytic.operator.system import system_matrix
from analytic.scenes.common import Illumination, Sampling, default_scene
from analytic.scenes.relay_wall import RelayWallScene, Scan

_WALL_SAMPLING = Sampling(bin_width_opl=0.01, start_opl=1.99, count=240)


def _peak_bytes(scene, memory_limit):
    """(A, tracemalloc's peak in bytes) of assembling the scene's A (its kernels loaded before)."""
    system_matrix(scene)
    tracemalloc.start()
    try:
        matrix = system_matrix(scene, memory_limit=memory_limit)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    return matrix, peak


@pytest.mark.parametrize("scene", [
    RelayWallScene(pixels=8, reflectance=0.5, scan=Scan(type="confocal", grid=(8, 8)), sampling=_WALL_SAMPLING),
    RelayWallScene(pixels=6, reflectance=0.5, scan=Scan(type="exhaustive", grid=(4, 4)), sampling=_WALL_SAMPLING),
    default_scene(pixels=64, illumination=Illumination(waveform="butterworth")),
], ids=["confocal", "exhaustive", "plane"])
def test_peak_memory_near_the_limit_stays_under_the_estimate(scene):
    estimate = model_cost(scene).memory
    limit = int(1.02 * estimate)             # the job just fits: it must run, and within what it said
    matrix, peak = _peak_bytes(scene, limit)
    assert matrix.nnz > 0
    assert peak <= estimate <= 3 * peak      # 2.0 x with one thread: the routes' window per block, fewer blocks
    with pytest.raises(ResourceError, match="GiB.*limit"):
        system_matrix(scene, memory_limit=int(0.8 * peak))


def test_a_job_beyond_memory_is_refused_before_any_work():
    """2^16 pairs x 32² pixels: its estimate alone refuses it (counting it would take a minute)."""
    scene = RelayWallScene(pixels=32, reflectance=0.5, scan=Scan(type="confocal", grid=(256, 256)),
                           sampling=Sampling(bin_width_opl=0.02, start_opl=1.99, count=130))
    estimate = model_cost(scene, memory_limit=2**30).memory
    assert estimate > 2**30
    with pytest.raises(ResourceError, match=r"^sampling: .*about .* GiB .*estimated.*over the 1 GiB limit"):
        system_matrix(scene, memory_limit=2**30)
    with pytest.raises(ResourceError, match="estimated"):
        refuse_unaffordable(model_cost(scene), memory_limit=int(0.9 * estimate))


def test_progress_shows_counting_filling_and_the_general_routes(capsys):
    scene = RelayWallScene(pixels=4, reflectance=0.5, scan=Scan(type="confocal", grid=(6, 6)), sampling=_WALL_SAMPLING)
    quiet = system_matrix(scene)
    assert capsys.readouterr().err == ""      # the library prints nothing unless asked
    shown = system_matrix(scene, progress=True)
    bars = capsys.readouterr().err
    for name in ("counting A's entries", "system matrix", "cut pixels"):
        assert name in bars
    assert (quiet != shown).nnz == 0


@pytest.mark.parametrize("window", [1, 3, 7, 2**18])
def test_zeros_are_dropped_in_place_as_scipy_drops_them(rng, monkeypatch, window):
    """A's exact zeros go a window of slots at a time (no copy of A): the same CSR as SciPy's
    eliminate_zeros, rows with no entry, with only zeros and windows of one slot included."""
    monkeypatch.setattr(system, "ROUTE_SLOTS", window)
    dense = rng.random((40, 30)) * (rng.random((40, 30)) < 0.4)
    dense[[5, 6, 39]] = 0.0
    dense[7, 3:] = 0.0                          # after empty rows, a row of few entries: one window holds them
    stored = scipy.sparse.csr_array(dense)
    data, indices, indptr = stored.data.copy(), stored.indices.copy(), stored.indptr.astype(np.int64)
    data[rng.random(data.size) < 0.3] = 0.0                         # stored zeros, as a cancelling entry gives
    data[indptr[10]:indptr[11]] = 0.0                               # a row of stored zeros only
    expected = scipy.sparse.csr_array((data.copy(), indices.copy(), indptr.copy()), shape=dense.shape)
    expected.eliminate_zeros()
    kept = system._drop_zeros(data, indices, indptr)
    assert kept == expected.nnz < stored.nnz
    assert np.array_equal(data[:kept], expected.data) and np.array_equal(indices[:kept], expected.indices)
    assert np.array_equal(indptr, expected.indptr)
