"""The exact, sparse, time-binned system matrix A of DESIGN.md section 2.

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx,   row k N + n, column r M + c.

How it is computed
------------------
In isochrone coordinates (τ, φ) (see :mod:`analytic.isochrone`) the entry is
∫ κ_n(τ) G_{k,p}(τ) dτ with G_{k,p}(τ) = ∫_{isochrone ∩ pixel} a J dφ, the
pixel's own impulse response. G is smooth in τ except where an isochrone
passes a pixel corner, touches an edge (a square-root branch point), or is
born at x*; κ_n is smooth except at the bin edges shifted by the waveform's
breakpoints. The τ-range of each pixel is cut at all of these points, each
piece is mapped through τ = τ_a + (τ_b - τ_a)(3v² - 2v³) (which turns
square-root end behaviour into smooth behaviour), and integrated by adaptive
Gauss–Kronrod; the inner φ-integral is adaptive Gauss–Kronrod on arcs cut at
the pixel's edges. Every integrand is positive, so per-piece relative error
control bounds each entry's relative error: each entry, hence each row's
largest, is accurate to ``tolerance``.

Assembly (geometry -> entries) runs once, compiled and in parallel over
(pixel, sensor) pairs; the result is a SciPy sparse matrix to apply,
transpose and slice. Its memory is proportional to nnz(A), which is counted
exactly before anything is allocated.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import scipy.sparse
from numba import njit, prange

from .isochrone import (LAMBERTIAN, PAPER, TMIN, ellipse, first_arrival_point, make_frame,
                        path_length_at, rectangle_range, segment_minimum)
from .quadrature import GAUSS_WEIGHTS, KRONROD_NODES, KRONROD_WEIGHTS, pixel_isochrone_integral
from .scene import Scene, SceneError
from .waveforms import cumulative_scalar, make_waveform

__all__ = ["system_matrix", "forward", "count_entries", "QuadratureWarning"]

# Inner (φ) integrals are held 20 times tighter than the outer (τ) ones, so
# that their residue never looks like roughness to the outer error estimate.
_INNER_FACTOR = 0.05
_OUTER_STACK = 96
_MAX_PIECES = 4000  # rule applications per τ-piece before the rest is accepted as is


class QuadratureWarning(RuntimeWarning):
    """Some quadrature pieces stopped refining before meeting the tolerance."""


@njit(cache=True)
def _pixel_bins(frame, x0, x1, y0, y1, start, period, count, duration):
    """(first bin, number of bins) that a pixel can reach; (0, 0) if none."""
    low, high = rectangle_range(frame, x0, x1, y0, y1)
    low = max(low, start - duration)
    high = min(high, start + count * period)
    if not high > low:
        return 0, 0
    first = max(0, int(math.floor((low - start) / period)))
    last = min(count - 1, int(math.floor((high + duration - start) / period)))
    if last < first:
        return 0, 0
    return first, last - first + 1


@njit(cache=True)
def _pixel_breakpoints(frame, x0, x1, y0, y1, start, period, first, bins, terms):
    """Sorted τ where the pixel's integrand stops being smooth, within its τ-range."""
    duration = terms.duration
    low, high = rectangle_range(frame, x0, x1, y0, y1)
    low = max(low, start - duration)
    high = min(high, start + (first + bins) * period)
    shifts = 2 if duration > 0.0 else 1
    points = np.empty(12 + shifts * (bins + 1))
    used = 0
    points[used] = low
    used += 1
    points[used] = high
    used += 1
    for (cx, cy) in ((x0, y0), (x1, y0), (x0, y1), (x1, y1)):
        points[used] = path_length_at(frame, cx, cy)
        used += 1
    for (ax, ay, bx, by) in ((x0, y0, x1, y0), (x1, y0, x1, y1), (x0, y1, x1, y1), (x0, y0, x0, y1)):
        value, inside = segment_minimum(frame, ax, ay, bx, by)
        if inside:
            points[used] = value
            used += 1
    xs, ys = first_arrival_point(frame)
    if x0 <= xs <= x1 and y0 <= ys <= y1:
        points[used] = frame[TMIN]
        used += 1
    # The attenuation peaks under the source and the sensor: cutting there
    # helps the adaptive rule when they are low above the plane.
    for (fx, fy) in ((frame[0], frame[1]), (frame[3], frame[4])):
        if x0 < fx < x1 and y0 < fy < y1:
            points[used] = path_length_at(frame, fx, fy)
            used += 1
    for n in range(first, first + bins + 1):
        edge = start + n * period
        points[used] = edge
        used += 1
        if duration > 0.0:
            points[used] = edge - duration
            used += 1
    points = np.sort(points[:used])
    kept = 0
    for i in range(used):
        value = points[i]
        if value < low or value > high:
            continue
        if kept > 0 and value <= points[kept - 1]:
            continue
        points[kept] = value
        kept += 1
    return points[:kept]


@njit(cache=True)
def _pixel_entries(frame, x0, x1, y0, y1, start, period, first, bins, terms, rtol, out):
    """Fill out[i] = A[(k, first + i), p] for one (sensor, pixel); returns #unconverged pieces."""
    duration = terms.duration
    breakpoints = _pixel_breakpoints(frame, x0, x1, y0, y1, start, period, first, bins, terms)
    angles = np.empty(8)
    arc_stack = np.empty((128, 2))
    segments = np.empty((_OUTER_STACK, 2))
    width = bins + 2
    kronrod = np.empty(width)
    gauss = np.empty(width)
    response = np.empty(15)
    node_tau = np.empty(15)
    cumulative = np.empty((15, width + 1))
    inner_rtol = rtol * _INNER_FACTOR
    failures = 0
    for piece in range(len(breakpoints) - 1):
        tau_a = breakpoints[piece]
        tau_b = breakpoints[piece + 1]
        span = tau_b - tau_a
        if not span > 0.0:
            continue
        lo_bin = max(first, int(math.floor((tau_a - start) / period)) - 1)
        hi_bin = min(first + bins - 1, int(math.floor((tau_b + duration - start) / period)) + 1)
        if hi_bin < lo_bin:
            continue
        nb = hi_bin - lo_bin + 1
        segments[0, 0] = 0.0
        segments[0, 1] = 1.0
        waiting = 1
        applied = 0
        while waiting > 0:
            waiting -= 1
            applied += 1
            v_lo = segments[waiting, 0]
            v_hi = segments[waiting, 1]
            centre = 0.5 * (v_lo + v_hi)
            half = 0.5 * (v_hi - v_lo)
            for j in range(15):
                if j < 7:
                    v = centre - half * KRONROD_NODES[j]
                elif j == 7:
                    v = centre
                else:
                    v = centre + half * KRONROD_NODES[14 - j]
                tau = tau_a + span * v * v * (3.0 - 2.0 * v)
                dtau_dv = 6.0 * span * v * (1.0 - v)
                node_tau[j] = tau
                cx, cy, a, b, j0, j1, j2 = ellipse(frame, tau)
                value, ok = pixel_isochrone_integral(frame, cx, cy, a, b, j0, j1, j2, x0, x1, y0, y1,
                                                     inner_rtol, angles, arc_stack)
                if not ok:
                    failures += 1
                response[j] = value * dtau_dv
                for i in range(nb + 1):
                    cumulative[j, i] = cumulative_scalar(terms, start + (lo_bin + i) * period - tau)
            accept = True
            for i in range(nb):
                k_sum = 0.0
                g_sum = 0.0
                for j in range(15):
                    weight_index = j if j < 8 else 14 - j
                    kernel = cumulative[j, i + 1] - cumulative[j, i]
                    term = response[j] * kernel
                    k_sum += KRONROD_WEIGHTS[weight_index] * term
                    if weight_index % 2 == 1:   # the Gauss nodes, centre (7) included
                        g_sum += GAUSS_WEIGHTS[weight_index // 2] * term
                kronrod[i] = k_sum * half
                gauss[i] = g_sum * half
                if not abs(kronrod[i] - gauss[i]) <= rtol * abs(kronrod[i]):
                    accept = False
            # A piece only ~1e4 ulps of τ wide cannot be refined further: its
            # nodes differ by rounding. Its whole value is ~1e-12 of an entry's,
            # so it is kept as is without counting as a failure.
            w_lo = v_lo * v_lo * (3.0 - 2.0 * v_lo)
            w_hi = v_hi * v_hi * (3.0 - 2.0 * v_hi)
            unresolvable = span * (w_hi - w_lo) <= 4e-12 * abs(tau_b)
            stop = half < 1e-10 or waiting + 2 > _OUTER_STACK or applied > _MAX_PIECES
            if accept or stop or unresolvable:
                if not (accept or unresolvable):
                    failures += 1
                for i in range(nb):
                    out[lo_bin - first + i] += kronrod[i]
            else:
                segments[waiting, 0] = v_lo
                segments[waiting, 1] = centre
                segments[waiting + 1, 0] = centre
                segments[waiting + 1, 1] = v_hi
                waiting += 2
    return failures


@njit(cache=True)
def _pixel_box(size, pixels, p):
    """[x0, x1] x [y0, y1] of pixel p = r M + c (row r from the top), metres."""
    delta = size / pixels
    r = p // pixels
    c = p % pixels
    return c * delta, (c + 1) * delta, (pixels - r - 1) * delta, (pixels - r) * delta


@njit(parallel=True, cache=True)
def _count_bins(source, sensors, mode, size, pixels, start, period, count, duration, firsts, counts):
    sensor_count = sensors.shape[0]
    for job in prange(pixels * pixels * sensor_count):
        p = job // sensor_count
        k = job % sensor_count
        frame = make_frame(source, sensors[k], mode)
        x0, x1, y0, y1 = _pixel_box(size, pixels, p)
        first, bins = _pixel_bins(frame, x0, x1, y0, y1, start, period, count, duration)
        firsts[job] = first
        counts[job] = bins


@njit(parallel=True, cache=True)
def _fill(source, sensors, mode, size, pixels, start, period, count, terms, rtol,
          firsts, counts, offsets, rows, data):
    sensor_count = sensors.shape[0]
    failures = 0
    for job in prange(pixels * pixels * sensor_count):
        bins = counts[job]
        if bins == 0:
            continue
        p = job // sensor_count
        k = job % sensor_count
        frame = make_frame(source, sensors[k], mode)
        x0, x1, y0, y1 = _pixel_box(size, pixels, p)
        first = firsts[job]
        offset = offsets[job]
        out = data[offset:offset + bins]
        out[:] = 0.0
        for i in range(bins):
            rows[offset + i] = k * count + first + i
        failures += _pixel_entries(frame, x0, x1, y0, y1, start, period, first, bins, terms, rtol, out)
    return failures


def _available_memory() -> int:
    """Bytes of memory available now (MemAvailable), or a large number if unknown."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))


def _prepare(scene: Scene):
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    mode = LAMBERTIAN if scene.attenuation == "lambertian" else PAPER
    source = np.ascontiguousarray(scene.source, dtype=np.float64)
    sensors = np.ascontiguousarray(scene.sensors, dtype=np.float64)
    return waveform, mode, source, sensors


def count_entries(scene: Scene, *, memory_limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Exact per-(pixel, sensor) bin ranges of A, counted before allocation.

    Parameters
    ----------
    scene : Scene
        The scene.
    memory_limit : int, optional
        Bytes A may use; default half the memory available now.

    Returns
    -------
    firsts, counts : numpy.ndarray
        ``(M² K,)`` first bin and number of bins of each (pixel, sensor)
        pair, pixel-major.

    Raises
    ------
    SceneError
        When A (or the counting itself) would not fit in ``memory_limit``.
    """
    limit = memory_limit if memory_limit is not None else _available_memory() // 2
    jobs = scene.pixels ** 2 * scene.sensor_count
    if jobs * 16 > limit:
        raise SceneError("plane.pixels", f"{scene.pixels}² pixels x {scene.sensor_count} sensors "
                         f"needs {jobs * 16 / 2**30:.1f} GiB just to index A; "
                         f"limit {limit / 2**30:.1f} GiB")
    waveform, mode, source, sensors = _prepare(scene)
    sampling = scene.sampling
    firsts = np.empty(jobs, dtype=np.int64)
    counts = np.empty(jobs, dtype=np.int64)
    _count_bins(source, sensors, mode, scene.size, scene.pixels, sampling.start_opl, sampling.bin_width_opl,
                sampling.count, waveform.duration, firsts, counts)
    nnz = int(counts.sum())
    # data + row index, once in CSC and once in CSR, plus the index arrays above
    needed = nnz * (8 + 8) * 2 + jobs * 24
    if needed > limit:
        raise SceneError("sampling", f"the system matrix would hold {nnz:,} entries "
                         f"({needed / 2**30:.1f} GiB), over the {limit / 2**30:.1f} GiB available; "
                         f"use fewer bins (sampling.count / period) or fewer pixels")
    return firsts, counts


def system_matrix(scene: Scene, *, tolerance: float | None = None, memory_limit: int | None = None,
                  progress: bool = False) -> scipy.sparse.csr_array:
    """Assemble A for a scene.

    Parameters
    ----------
    scene : Scene
        Geometry, sampling, illumination and attenuation.
    tolerance : float, optional
        Relative accuracy of every entry (hence relative to its row's largest
        entry). Default: ``scene.tolerance`` (1e-6). The quadrature asks
        itself for a tenth of it.
    memory_limit : int, optional
        Bytes A may use; see :func:`count_entries`.
    progress : bool
        Show a progress bar over sensors.

    Returns
    -------
    scipy.sparse.csr_array
        ``(K N, M²)`` float64; row k N + n, column r M + c; units of
        a_k x area x path length: m⁻² · m (W/sr per unit source).

    Notes
    -----
    y = A f with f = ``image.ravel()`` gives y_k[n] = ∫ (g_k * s)(t) dt over
    bin n, with g_k(t) = ∫ f a_k δ(t - d_k) dx (DESIGN.md section 2).
    """
    tolerance = scene.tolerance if tolerance is None else float(tolerance)
    if not 0.0 < tolerance < 0.1:
        raise SceneError("model.tolerance", f"must be in (0, 0.1), got {tolerance}")
    firsts, counts = count_entries(scene, memory_limit=memory_limit)
    waveform, mode, source, sensors = _prepare(scene)
    terms = waveform.terms
    sampling = scene.sampling
    offsets = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts, out=offsets[1:])
    nnz = int(offsets[-1])
    rows = np.empty(nnz, dtype=np.int64)
    data = np.empty(nnz, dtype=np.float64)
    sensor_count = scene.sensor_count
    pixel_count = scene.pixels ** 2
    # One call per sensor keeps the progress bar moving; each is parallel over pixels.
    failures = 0
    iterator = range(sensor_count)
    if progress:
        from tqdm import tqdm
        iterator = tqdm(iterator, desc="system matrix", unit="sensor", leave=False)
    for k in iterator:
        select = np.arange(pixel_count) * sensor_count + k
        sub_firsts = firsts[select]
        sub_counts = counts[select]
        sub_offsets = np.zeros(pixel_count + 1, dtype=np.int64)
        np.cumsum(sub_counts, out=sub_offsets[1:])
        sub_rows = np.empty(int(sub_offsets[-1]), dtype=np.int64)
        sub_data = np.empty(int(sub_offsets[-1]), dtype=np.float64)
        failures += _fill(source, sensors[k:k + 1], mode, scene.size, scene.pixels, sampling.start_opl,
                          sampling.bin_width_opl, sampling.count, terms, tolerance * 0.1,
                          sub_firsts, sub_counts, sub_offsets, sub_rows, sub_data)
        sub_rows += k * sampling.count
        # scatter this sensor's runs into their slots of the pixel-major layout
        starts = offsets[select]
        positions = np.repeat(starts - sub_offsets[:-1], sub_counts) + np.arange(len(sub_rows))
        rows[positions] = sub_rows
        data[positions] = sub_data
    if failures:
        warnings.warn(f"{failures} quadrature pieces stopped refining before reaching "
                      f"tolerance {tolerance:g}", QuadratureWarning, stacklevel=2)
    indptr = offsets[::sensor_count].copy()
    shape = (sensor_count * sampling.count, pixel_count)
    matrix = scipy.sparse.csc_array((data, rows.astype(np.int32 if shape[0] < 2**31 else np.int64),
                                     indptr), shape=shape)
    matrix = matrix.tocsr()
    matrix.eliminate_zeros()
    return matrix


def forward(scene: Scene, matrix=None) -> np.ndarray:
    """The model's noiseless samples y_k[n].

    Parameters
    ----------
    scene : Scene
        The scene (its reflectance image is f).
    matrix : sparse matrix, optional
        A, if already assembled.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.
    """
    if matrix is None:
        matrix = system_matrix(scene)
    y = matrix @ scene.reflectance.ravel()
    return y.reshape(scene.sensor_count, scene.sampling.count)
