"""The exact, sparse, time-binned system matrix A of DESIGN.md section 2.

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx,   row k N + n, column r M + c.

How it is computed
------------------
κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) is smooth in τ except at the bin edges
t_n shifted by the waveform's breakpoints (0 and its duration). For each
(pixel, sensor) pair, with [d_lo, d_hi] the exact range of d over the pixel:

- *Smooth pixels* (no breakpoint inside (d_lo, d_hi), and the pixel clear of
  the peaks of a under the source's and sensor's feet, see
  :data:`FOOT_CLEARANCE`): every entry a_k κ_n(d) is an analytic function on
  the pixel, integrated by the tensor Gauss ladder
  (:func:`analytic.quadrature.tensor_integrate`) with its error check.
- *Cut pixels* (the rest, and any smooth pixel whose ladder does not
  converge): in isochrone coordinates (τ, φ) (see :mod:`analytic.isochrone`)
  the entry is ∫ κ_n(τ) G(τ) dτ with G(τ) = ∫_{isochrone ∩ pixel} a J dφ.
  G is smooth except where an isochrone passes a pixel corner, touches an
  edge (a square-root branch point), is born at x*, or passes a foot; the
  τ-range is cut there and at κ's breakpoints, each piece is mapped through
  τ = τ_a + (τ_b - τ_a)(3v² - 2v³) (which turns square-root end behaviour
  into smooth behaviour) and integrated by adaptive quadrature
  (:func:`analytic.quadrature.integrate`), the inner φ-integral too.

Each rule's error is estimated by the next rung of its Gauss ladder, and the
value it estimates is the one kept, relative to ∫ |integrand|; the inner
integrals are held 10 times tighter. Every entry, hence every row's
largest, is accurate to about ``tolerance``.

Assembly (geometry -> entries) runs once, compiled and in parallel over
pixels (all sensors of a pixel together, pixels dealt out in strides so the
threads stay balanced); the result is a SciPy sparse matrix to apply,
transpose and slice. Its memory is proportional to nnz(A), which is counted
exactly, per column, before anything of that size is allocated.
"""

from __future__ import annotations

import math
import os
import warnings

import numpy as np
import scipy.sparse
from numba import njit, prange

from .attenuation import attenuation_at, attenuation_code
from .isochrone import (check_heights, ellipse, first_arrival_point, make_frame, path_length_at,
                        rectangle_range, segment_minimum)
from .quadrature import integrate, make_workspace, pixel_isochrone_integral, tensor_integrate
from .scene import Scene, SceneError
from .waveforms import cumulative_scalar, make_waveform

__all__ = ["system_matrix", "forward", "count_entries", "QuadratureWarning", "MIN_TOLERANCE",
           "MAX_TOLERANCE", "FOOT_CLEARANCE"]

#: Tightest tolerance supported: below it float64 sums of ~10⁴ rounded terms
#: no longer converge and the adaptive quadrature would refine without end.
MIN_TOLERANCE = 1e-10
#: Loosest tolerance accepted.
MAX_TOLERANCE = 0.1
#: A pixel is integrated as a smooth 2-D function only if every foot is at
#: least this many pixel sides away, counting its height: sqrt(δ² + h²) >=
#: FOOT_CLEARANCE x side, δ the foot's distance from the pixel. The
#: attenuation's nearest complex singularity is that far, which bounds the
#: tensor rule's convergence rate.
FOOT_CLEARANCE = 1.0

_INNER_FACTOR = 0.1      # inner (φ) integrals this much tighter than the outer ones
# Path lengths closer than this (relative) are not told apart: the ellipse's
# axes near a tangency or the birth at t_min come from τ² - t², whose
# rounding makes G(τ) noise on finer scales (about 2·10⁴ roundings of τ).
_TAU_RESOLUTION = 4e-12
_BLOCKS_PER_THREAD = 16  # parallel jobs per thread; pixels are dealt to them in strides


class QuadratureWarning(RuntimeWarning):
    """Some quadrature pieces stopped refining before meeting the tolerance."""


@njit(cache=True, error_model="numpy")
def _pixel_box(size, pixels, p):
    """[x0, x1] x [y0, y1] of pixel p = r M + c (row r from the top), metres."""
    delta = size / pixels
    r = p // pixels
    c = p % pixels
    return c * delta, (c + 1) * delta, (pixels - r - 1) * delta, (pixels - r) * delta


@njit(cache=True, error_model="numpy")
def _bin_of(tau, start, period, count):
    """floor((τ - start) / period) clamped to [-1, count] in floating point (no integer overflow)."""
    index = np.floor((tau - start) / period)
    if not index >= -1.0:       # also NaN
        return -1
    if index > count:
        return count
    return int(index)


@njit(cache=True, error_model="numpy")
def _pixel_bins(frame, x0, x1, y0, y1, start, period, count, duration):
    """(first bin, number of bins) that a pixel's light reaches; (0, 0) if none.

    Light leaving at path length τ lands in [τ, τ + duration].
    """
    low, high = rectangle_range(frame, x0, x1, y0, y1)
    first = max(0, _bin_of(low, start, period, count))
    last = min(count - 1, _bin_of(high + duration, start, period, count))
    if last < first:
        return 0, 0
    return first, last - first + 1


@njit(cache=True, error_model="numpy")
def _edge(start, period, n):
    """t_n, the lower edge of bin n, metres (as Sampling.edges computes it)."""
    return start + period * n


@njit(cache=True, error_model="numpy")
def _kernel_cut(low, high, start, period, first, bins, duration):
    """Whether a breakpoint of some κ_n (t_n, or t_n - duration) lies strictly inside (low, high)."""
    for n in range(first, first + bins + 1):
        edge = _edge(start, period, n)
        if low < edge < high:
            return True
        if duration > 0.0 and low < edge - duration < high:
            return True
    return False


@njit(cache=True, error_model="numpy")
def _clear_of_feet(frame, x0, x1, y0, y1):
    """Whether the attenuation's peaks under both feet are far enough for the tensor rule."""
    side = FOOT_CLEARANCE * max(x1 - x0, y1 - y0)
    for fx, fy, height in ((frame.source_x, frame.source_y, frame.source_height),
                           (frame.sensor_x, frame.sensor_y, frame.sensor_height)):
        dx = max(x0 - fx, 0.0, fx - x1)
        dy = max(y0 - fy, 0.0, fy - y1)
        if dx * dx + dy * dy + height * height < side * side:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _kernels(terms, start, period, first, bins, tau, scale, values):
    """values[i] = scale κ_{first + i}(τ), i < bins."""
    lower = cumulative_scalar(terms, _edge(start, period, first) - tau)
    for i in range(bins):
        upper = cumulative_scalar(terms, _edge(start, period, first + i + 1) - tau)
        values[i] = scale * (upper - lower)
        lower = upper


@njit(cache=True, error_model="numpy")
def _smooth_integrand(problem, x, y, values):
    """a_k(x) κ_n(d(x)) for the pair's bins: the integrand of a smooth pixel."""
    frame, terms, start, period, first, bins = problem
    _kernels(terms, start, period, first, bins, path_length_at(frame, x, y), attenuation_at(frame, x, y),
             values)


@njit(cache=True, error_model="numpy")
def _cut_integrand(problem, v, values):
    """κ_n(τ) G(τ) dτ/dv at τ = τ_a + span (3v² - 2v³), for the piece's bins."""
    (frame, x0, x1, y0, y1, terms, start, period, first, bins, tau_a, span, inner_rtol,
     angles, inner) = problem
    tau = tau_a + span * v * v * (3.0 - 2.0 * v)
    slope = 6.0 * span * v * (1.0 - v)
    cx, cy, a, b, j0, j1, j2 = ellipse(frame, tau)
    response = pixel_isochrone_integral(frame, cx, cy, a, b, j0, j1, j2, x0, x1, y0, y1, inner_rtol,
                                        angles, inner)
    weight = response * slope
    if weight == 0.0:
        for i in range(bins):
            values[i] = 0.0
        return
    _kernels(terms, start, period, first, bins, tau, weight, values)


@njit(cache=True, error_model="numpy")
def _pixel_breakpoints(frame, x0, x1, y0, y1, low, high, start, period, first, bins, duration):
    """Sorted τ in [low, high] where the cut integrand stops being smooth."""
    shifts = 2 if duration > 0.0 else 1
    points = np.empty(13 + shifts * (bins + 1))
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
        points[used] = frame.first_arrival
        used += 1
    # The attenuation peaks under the source and the sensor: cutting there
    # lets the τ-mapping crowd nodes onto the peak when they are low.
    for (fx, fy) in ((frame.source_x, frame.source_y), (frame.sensor_x, frame.sensor_y)):
        if x0 < fx < x1 and y0 < fy < y1:
            points[used] = path_length_at(frame, fx, fy)
            used += 1
    for n in range(first, first + bins + 1):
        edge = _edge(start, period, n)
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


@njit(cache=True, error_model="numpy")
def _cut_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                 out, work, inner, angles):
    """Add the pair's entries to out[:bins] by the cut (τ, φ) quadrature."""
    duration = terms.duration
    low = max(low, _edge(start, period, 0) - duration)
    high = min(high, _edge(start, period, first + bins))
    breakpoints = _pixel_breakpoints(frame, x0, x1, y0, y1, low, high, start, period, first, bins,
                                     duration)
    inner_rtol = rtol * _INNER_FACTOR
    for piece in range(len(breakpoints) - 1):
        tau_a = breakpoints[piece]
        tau_b = breakpoints[piece + 1]
        span = tau_b - tau_a
        if not span > 0.0:
            continue
        # bins whose kernel can be non-zero on the piece (one spare on each side for rounding)
        lo_bin = max(first, _bin_of(tau_a, start, period, count) - 1)
        hi_bin = min(first + bins - 1, _bin_of(tau_b + duration, start, period, count) + 1)
        if hi_bin < lo_bin:
            continue
        nb = hi_bin - lo_bin + 1
        problem = (frame, x0, x1, y0, y1, terms, start, period, lo_bin, nb, tau_a, span, inner_rtol,
                   angles, inner)
        # dτ/dv <= 1.5 span: a v-piece this narrow spans under _TAU_RESOLUTION of τ
        resolution = _TAU_RESOLUTION * max(abs(tau_a), abs(tau_b)) / (1.5 * span)
        integrate(_cut_integrand, problem, 0.0, 1.0, rtol, nb, out[lo_bin - first:], work, resolution)


@njit(cache=True, error_model="numpy")
def _pair_entries(frame, x0, x1, y0, y1, terms, start, period, count, first, bins, rtol,
                  out, work, inner, angles):
    """out[i] = A[(k, first + i), p] for one (sensor, pixel); True if the smooth path served."""
    for i in range(bins):
        out[i] = 0.0
    low, high = rectangle_range(frame, x0, x1, y0, y1)
    if (not _kernel_cut(low, high, start, period, first, bins, terms.duration)
            and _clear_of_feet(frame, x0, x1, y0, y1)):
        problem = (frame, terms, start, period, first, bins)
        if tensor_integrate(_smooth_integrand, problem, x0, x1, y0, y1, rtol, bins, out, work):
            return True
    _cut_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                 out, work, inner, angles)
    return False


@njit(parallel=True, cache=True, error_model="numpy")
def _count(source, sensors, mode, size, pixels, start, period, count, duration, per_pixel, widest):
    """per_pixel[p] = non-zeros of column p; widest[p] = most bins of one of its pairs."""
    sensor_count = sensors.shape[0]
    for p in prange(pixels * pixels):
        x0, x1, y0, y1 = _pixel_box(size, pixels, p)
        total = 0
        most = 0
        for k in range(sensor_count):
            frame = make_frame(source, sensors[k], mode)
            bins = _pixel_bins(frame, x0, x1, y0, y1, start, period, count, duration)[1]
            total += bins
            most = max(most, bins)
        per_pixel[p] = total
        widest[p] = most


@njit(parallel=True, cache=True, error_model="numpy")
def _fill(source, sensors, mode, size, pixels, start, period, count, terms, rtol, width,
          begin, end, indptr, rows, data, failures, smooth):
    """Entries of columns begin ... end - 1 into their CSC slots (rows, data)."""
    sensor_count = sensors.shape[0]
    blocks = failures.shape[0]
    for block in prange(blocks):
        work = make_workspace(width)
        inner = make_workspace(1)
        angles = np.empty(8)
        served = 0
        for p in range(begin + block, end, blocks):
            x0, x1, y0, y1 = _pixel_box(size, pixels, p)
            offset = indptr[p]
            for k in range(sensor_count):
                frame = make_frame(source, sensors[k], mode)
                first, bins = _pixel_bins(frame, x0, x1, y0, y1, start, period, count, terms.duration)
                if bins == 0:
                    continue
                for i in range(bins):
                    rows[offset + i] = k * count + first + i
                if _pair_entries(frame, x0, x1, y0, y1, terms, start, period, count, first, bins, rtol,
                                 data[offset:offset + bins], work, inner, angles):
                    served += 1
                offset += bins
        failures[block] += work.failures[0] + inner.failures[0]
        smooth[block] += served


def _available_memory() -> int:
    """Bytes of memory available now (MemAvailable), or the physical memory if unknown."""
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
    source = np.ascontiguousarray(scene.source, dtype=np.float64)
    sensors = np.ascontiguousarray(scene.sensors, dtype=np.float64)
    return waveform, attenuation_code(scene.attenuation), source, sensors


def _index_bytes(limit: int) -> int:
    return 4 if limit < 2**31 else 8


def _gib(count: float) -> str:
    return f"{count / 2**30:.3g} GiB"


def _check_layout(scene: Scene, limit: int) -> None:
    """Refuse, before allocating anything, what the column and row pointers alone cannot fit."""
    columns = scene.pixels ** 2
    rows = scene.sensor_count * scene.sampling.count
    # counting: per-column non-zeros and widest pair; then CSC and CSR pointers
    needed = columns * (8 + 4) + (columns + 1) * 8 + (rows + 1) * 8
    if columns * 12 > limit or (columns + 1) * 8 > limit:
        raise SceneError("plane.pixels", f"{scene.pixels}² pixels need {_gib(needed)} just to index "
                         f"A's columns, over the {_gib(limit)} limit; use fewer pixels")
    if needed > limit:
        raise SceneError("sampling.count", f"{scene.sensor_count} sensors x {scene.sampling.count:,} "
                         f"bins need {_gib(needed)} just to index A's rows, over the {_gib(limit)} "
                         f"limit; use fewer bins")


def count_entries(scene: Scene, *, memory_limit: int | None = None) -> np.ndarray:
    """Exact number of non-zeros of each column of A, counted before A is allocated.

    Parameters
    ----------
    scene : Scene
        The scene.
    memory_limit : int, optional
        Bytes A may use; default half the memory available now.

    Returns
    -------
    numpy.ndarray
        ``(M²,)`` int64: entries of column p (pixel p, every sensor).

    Raises
    ------
    SceneError
        When A, or its index arrays alone, would not fit in ``memory_limit``
        (a resource limit; the key names the setting to reduce).
    """
    return _count_columns(scene, memory_limit)[0]


def _count_columns(scene: Scene, memory_limit: int | None):
    """(non-zeros per column, most bins of one pair), refusing what would not fit."""
    limit = memory_limit if memory_limit is not None else _available_memory() // 2
    _check_layout(scene, limit)
    waveform, mode, source, sensors = _prepare(scene)
    sampling = scene.sampling
    per_pixel = np.empty(scene.pixels ** 2, dtype=np.int64)
    widest = np.empty(scene.pixels ** 2, dtype=np.int32)
    _count(source, sensors, mode, scene.size, scene.pixels, sampling.start_opl, sampling.bin_width_opl,
           sampling.count, waveform.duration, per_pixel, widest)
    nnz = int(per_pixel.sum())
    needed = _matrix_bytes(nnz, scene)
    if needed > limit:
        raise SceneError("sampling", f"the system matrix would hold {nnz:,} entries "
                         f"({_gib(needed)} while it is assembled), over the {_gib(limit)} limit; "
                         f"use fewer bins (sampling.count / period) or fewer pixels")
    return per_pixel, int(widest.max()) if len(widest) else 0


def _matrix_bytes(nnz: int, scene: Scene) -> int:
    """Peak bytes of assembly: CSC and CSR copies (data + index) and their pointers."""
    rows = scene.sensor_count * scene.sampling.count
    columns = scene.pixels ** 2
    index = _index_bytes(max(nnz, rows, columns))
    return 2 * nnz * (8 + index) + (columns + 1) * 8 + (rows + 1) * 8 + columns * 12


def check_tolerance(tolerance: float) -> float:
    """The tolerance as a float, or SceneError("model.tolerance") outside [MIN_TOLERANCE, MAX_TOLERANCE)."""
    tolerance = float(tolerance)
    if not MIN_TOLERANCE <= tolerance < MAX_TOLERANCE:
        raise SceneError("model.tolerance", f"must be in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}), got "
                         f"{tolerance:g}: float64 quadrature cannot converge below {MIN_TOLERANCE:g} "
                         f"(it would refine without end)")
    return tolerance


def system_matrix(scene: Scene, *, tolerance: float | None = None, memory_limit: int | None = None,
                  progress: bool = False) -> scipy.sparse.csr_array:
    """Assemble A for a scene.

    Parameters
    ----------
    scene : Scene
        Geometry, sampling, illumination and attenuation.
    tolerance : float, optional
        Relative accuracy of every entry (hence relative to its row's largest
        entry), in [MIN_TOLERANCE, MAX_TOLERANCE). Default: ``scene.tolerance``
        (1e-6). The achieved error follows it (see the module docstring).
    memory_limit : int, optional
        Bytes A may use; see :func:`count_entries`.
    progress : bool
        Show a progress bar over the pixels.

    Returns
    -------
    scipy.sparse.csr_array
        ``(K N, M²)`` float64; row k N + n, column r M + c; units of
        a_k x area x path length: m⁻² · m (W/sr per unit source).

    Raises
    ------
    SceneError
        A tolerance outside the supported range (``model.tolerance``), a
        source or sensor too low to resolve (see
        :func:`analytic.isochrone.check_heights`), or an A that does not fit
        in memory.

    Warns
    -----
    QuadratureWarning
        When some quadrature pieces stopped refining before the tolerance.

    Notes
    -----
    y = A f with f = ``image.ravel()`` gives y_k[n] = ∫ (g_k * s)(t) dt over
    bin n, with g_k(t) = ∫ f a_k δ(t - d_k) dx (DESIGN.md section 2).
    """
    tolerance = check_tolerance(scene.tolerance if tolerance is None else tolerance)
    check_heights(scene.size, scene.source, scene.sensors)
    per_pixel, width = _count_columns(scene, memory_limit)
    waveform, mode, source, sensors = _prepare(scene)
    terms = waveform.terms
    sampling = scene.sampling
    columns = scene.pixels ** 2
    shape = (scene.sensor_count * sampling.count, columns)
    indptr = np.zeros(columns + 1, dtype=np.int64)
    np.cumsum(per_pixel, out=indptr[1:])
    del per_pixel
    nnz = int(indptr[-1])
    index_type = np.int32 if _index_bytes(max(nnz, shape[0], shape[1])) == 4 else np.int64
    rows = np.empty(nnz, dtype=index_type)
    data = np.empty(nnz, dtype=np.float64)
    blocks = max(1, _BLOCKS_PER_THREAD * _threads())
    failures = np.zeros(blocks, dtype=np.int64)
    smooth = np.zeros(blocks, dtype=np.int64)
    chunks = min(100, columns) if progress else 1
    bounds = np.linspace(0, columns, chunks + 1).astype(np.int64)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=columns, desc="system matrix", unit="pixel", leave=False)
    for begin, end in zip(bounds[:-1], bounds[1:]):
        _fill(source, sensors, mode, scene.size, scene.pixels, sampling.start_opl, sampling.bin_width_opl,
              sampling.count, terms, tolerance, width, int(begin), int(end), indptr, rows, data,
              failures, smooth)
        if bar is not None:
            bar.update(int(end - begin))
    if bar is not None:
        bar.close()
    if failures.sum():
        warnings.warn(f"{int(failures.sum())} quadrature pieces stopped refining before reaching "
                      f"tolerance {tolerance:g}", QuadratureWarning, stacklevel=2)
    matrix = scipy.sparse.csc_array((data, rows, indptr.astype(index_type)), shape=shape)
    del data, rows
    matrix = matrix.tocsr()
    matrix.eliminate_zeros()
    return matrix


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


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
