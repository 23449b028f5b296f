"""Assembly straight into CSR: the bound that settles most pairs, the slots each block fills, and the entries.

analytic.kernels.assembly decides each (pixel, pair)'s bins from an interval of
path length computed at the pixel's centre (analytic.kernels.isochrone.range_bound)
and serves the smooth pixels through their moments over that interval; it
writes every entry into its CSR slot by per-block counts. The interval must
hold the exact range; the matrix must not depend on the number of threads,
the blocks or the progress bar; and the entries of tiny pixels (the route
most of a fine scene takes) must be the integral of a over the pixel, here
against a Gauss-Legendre product rule written in NumPy.
"""

import math
import os
import pickle
import subprocess
import sys

import numba
import numpy as np
import pytest
import scipy.sparse

from analytic.kernels.isochrone import make_frame, range_bound, rectangle_range, PixelBox
from analytic.scenes.common import Illumination, Sampling, Scene
from analytic.operator.general_routes import _window_jobs
from analytic.operator.system import pair_entries, system_matrix


def test_bound_holds_the_exact_range(rng):
    """Small and large boxes, boxes holding x* or a foot, low and high points, feet far away."""
    for _ in range(3000):
        scale = 10.0 ** rng.uniform(-4, 1)
        source = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), 10.0 ** rng.uniform(-3, 1)])
        sensor = np.array([rng.uniform(-2, 2), rng.uniform(-2, 2), 10.0 ** rng.uniform(-3, 1)])
        frame = make_frame(source, sensor, 0)
        x0, y0 = rng.uniform(-1.5, 1.5, size=2)
        box = PixelBox(x0, x0 + scale * rng.uniform(0.2, 1), y0, y0 + scale * rng.uniform(0.2, 1))
        low, high = rectangle_range(frame, box)
        lo, hi = range_bound(frame, 0.5 * (box.x0 + box.x1), 0.5 * (box.y0 + box.y1), 0.5 * (box.x1 - box.x0),
                             0.5 * (box.y1 - box.y0))
        assert lo <= low <= high <= hi, (source, sensor, box)


def test_bound_is_tight_for_small_pixels():
    """For a 1 mm pixel 1 m away the interval exceeds the exact range by ~|δ|²/d, far below a bin."""
    frame = make_frame(np.array([0.5, 0.5, 1.0]), np.array([0.1, 0.9, 1.0]), 0)
    box = PixelBox(0.3, 0.301, 0.7, 0.701)
    low, high = rectangle_range(frame, box)
    lo, hi = range_bound(frame, 0.3005, 0.7005, 0.0005, 0.0005)
    assert (hi - lo) - (high - low) < 2e-6


def _scene(waveform="impulse", pixels=12):
    return Scene(pixels=pixels, reflectance=1.0, source=(0.3, 0.6, 0.4),
                 sensors=[(0.7, 0.2, 0.5), (0.1, 0.9, 0.3), (0.5, 0.5, 0.05)],
                 illumination=Illumination(waveform=waveform),
                 sampling=Sampling(bin_width_opl=0.07, start_opl=0.4, count=40))


def _matrix_on_threads(scene, threads, folder):
    """``system_matrix(scene)`` with Numba on ``threads`` threads: here when this process may start that many,
    else in a child told so (a pytest-xdist worker runs Numba on one thread, tests/conftest.py)."""
    if threads <= numba.config.NUMBA_NUM_THREADS:
        previous = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            return system_matrix(scene)
        finally:
            numba.set_num_threads(previous)
    scene_file, matrix_file = folder / f"scene-{threads}.pickle", folder / f"matrix-{threads}.npz"
    scene_file.write_bytes(pickle.dumps(scene))
    code = ("import pickle, sys, numba, scipy.sparse\n"
            "from analytic.operator.system import system_matrix\n"
            "assert numba.get_num_threads() == int(sys.argv[3])\n"
            "scipy.sparse.save_npz(sys.argv[2], system_matrix(pickle.loads(open(sys.argv[1], 'rb').read())))\n")
    done = subprocess.run([sys.executable, "-c", code, str(scene_file), str(matrix_file), str(threads)],
                          env={**os.environ, "NUMBA_NUM_THREADS": str(threads)}, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    return scipy.sparse.csr_array(scipy.sparse.load_npz(matrix_file))


@pytest.mark.parametrize("waveform", ["impulse", "butterworth"])
def test_matrix_is_its_columns_whatever_the_threads(waveform, tmp_path):
    """Every column is the one pair_entries(method="auto") computes alone, on 1 thread or 2, with or
    without the progress bar (which fills the blocks in many steps): the CSR slots are right."""
    scene = _scene(waveform)
    matrix = _matrix_on_threads(scene, 2, tmp_path)
    single = _matrix_on_threads(scene, 1, tmp_path)
    stepped = system_matrix(scene, progress=True)
    for other in (single, stepped):
        assert (matrix != other).nnz == 0
        assert np.array_equal(matrix.indptr, other.indptr) and np.array_equal(matrix.indices, other.indices)
    assert matrix.has_sorted_indices
    dense = matrix.toarray()
    count = scene.sampling.count
    for sensor in range(scene.sensor_count):
        for pixel in range(scene.pixels ** 2):
            first, values = pair_entries(scene, sensor, pixel)
            column = np.zeros(count)
            column[first:first + len(values)] = values
            assert np.array_equal(dense[sensor * count:(sensor + 1) * count, pixel], column), (sensor, pixel)


def _gauss_pixel(scene, sensor, pixel, order=6):
    """∫_pixel a_k dx by an order x order Gauss-Legendre product rule, in NumPy (docs/design.md section 2)."""
    delta = scene.size / scene.pixels
    r, c = divmod(pixel, scene.pixels)
    nodes, weights = np.polynomial.legendre.leggauss(order)
    x = c * delta + 0.5 * delta * (nodes + 1.0)
    y = scene.size - (r + 1) * delta + 0.5 * delta * (nodes + 1.0)
    x, y = np.meshgrid(x, y)
    weight = np.outer(weights, weights) * (0.5 * delta) ** 2
    sx, sy, hs = scene.source
    kx, ky, hk = scene.sensors[sensor]
    ds = np.sqrt((x - sx) ** 2 + (y - sy) ** 2 + hs ** 2)
    dk = np.sqrt((x - kx) ** 2 + (y - ky) ** 2 + hk ** 2)
    value = scene.intensity * hs * hk / (math.pi * ds ** 3 * dk ** 3)
    return float((weight * value).sum()), float((ds + dk).min()), float((ds + dk).max())


def test_tiny_pixels_inside_one_bin_are_the_integral_of_the_attenuation(rng):
    """Impulse: an entry whose pixel lies inside one bin is ∫_pixel a (κ = 1 there), to the tolerance."""
    scene = Scene(pixels=600, reflectance=1.0, source=(0.5, 0.5, 1.0),
                  sensors=[(0.0, 0.0, 1.0), (1.0, 0.3, 0.7)],
                  sampling=Sampling(bin_width_opl=0.1, start_opl=2.0, count=10))
    matrix = system_matrix(scene).tocsc()
    count = scene.sampling.count
    checked = 0
    delta = scene.size / scene.pixels
    for pixel in rng.choice(scene.pixels ** 2, size=60, replace=False):
        for sensor in range(scene.sensor_count):
            expected, low, high = _gauss_pixel(scene, sensor, int(pixel))
            margin = 2.0 * delta            # d changes by at most 2 per metre: the nodes miss less than this
            first = math.floor((low - margin - scene.sampling.start_opl) / scene.sampling.bin_width_opl)
            last = math.floor((high + margin - scene.sampling.start_opl) / scene.sampling.bin_width_opl)
            if first != last or not 0 <= first < count:
                continue
            column = matrix[:, [int(pixel)]].toarray().ravel()[sensor * count:(sensor + 1) * count]
            assert np.count_nonzero(column) == 1 and column[first] > 0.0
            assert abs(column[first] - expected) <= 1e-6 * expected, (sensor, pixel)
            checked += 1
    assert checked >= 80


def test_a_window_of_slots_without_left_pairs_gives_no_jobs():
    """The general routes gather a block's left pairs window by window; a window where the first pass served every
    pair (its block's left pairs lie in its other windows: common once cut pixels are served there) holds no NaN
    and gives no job, and a NaN slot gives its (pair, pixel, bin)."""
    bins = 4
    starts, ends = np.array([0, 2, 4, 6]), np.array([2, 4, 6, 8])      # one pair's four rows, two slots each
    data = np.arange(8.0)
    indices = np.arange(10, 18, dtype=np.int32)
    jobs = _window_jobs(starts, ends, 4, indices, data, bins)
    assert jobs.pairs.size == 0 and list(jobs.offsets) == [0] and jobs.slots.size == 0
    data[5] = np.nan
    jobs = _window_jobs(starts, ends, 4, indices, data, bins)
    assert (list(jobs.pairs), list(jobs.pixels), list(jobs.firsts), list(jobs.slots)) == ([1], [15], [2], [5])

