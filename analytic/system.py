"""The exact, sparse, time-binned system matrix A of DESIGN.md section 2.

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx,   row k N + n, column r M + c.

How it is computed
------------------
κ_n(τ) = S(t_{n+1} - τ) - S(t_n - τ) is smooth in τ except at the bin edges
t_n shifted by the waveform's breakpoints (0 and its duration). For each
(pixel, sensor) pair, with [d_lo, d_hi] the exact range of d over the
pixel, one of three routes:

- *Smooth pixels* (no breakpoint inside (d_lo, d_hi), and the pixel clear of
  the peaks of a under the source's and sensor's feet, see
  :data:`FOOT_CLEARANCE`): every entry a_k κ_n(d) is analytic on the pixel,
  integrated by the tensor Gauss ladder
  (:func:`analytic.quadrature.tensor_integrate`) with its error check; most
  pairs take this route, more of them at larger M.
- *Cut pixels*: in isochrone coordinates (τ, φ) (see :mod:`analytic.isochrone`)
  the entry is ∫ κ_n(τ) G(τ) dτ with G(τ) = ∫_{isochrone ∩ pixel} a J dφ.
  G is smooth except where an isochrone passes a pixel corner, touches an
  edge (a square-root branch point), is born at x*, or passes a foot; the
  τ-range is cut there and at κ's breakpoints, and each piece is mapped
  by :func:`analytic.quadrature.piece_map`, which turns a square-root end
  into an entire function and leaves a regular end alone. Each piece is
  integrated by the tensor rule in (τ, φ)
  (:func:`analytic.quadrature.isochrone_rule`) under the adaptive driver,
- or, near x* or a foot, or where that rule fails, by adaptive φ-integrals
  inside adaptive τ-integrals (:func:`analytic.quadrature.integrate`, the
  *adaptive* route, the slowest and most general).

:func:`pair_entries` computes one pair by any route, so that each fast route
can be checked against the adaptive one.

Each rule's error is estimated by the next rung of its Gauss ladder (and the
rungs' trend), and the value estimated is the one kept, relative to
∫ |integrand|; the quadrature asks for :data:`SAFETY` x ``tolerance`` and
the inner integrals for a tenth of that. Every entry, hence every row's
largest, is accurate to ``tolerance``, and the achieved error follows the
tolerance (each entry's relative error 2 to 4 times below it from 1e-2 to
1e-8 on the default scene: benchmarks/bench_model.py), so that a looser
tolerance is faster.

Assembly (geometry -> entries) runs once, compiled and in parallel over
pixels (all sensors of a pixel together, pixels dealt out in strides so the
threads stay balanced); the result is a SciPy sparse matrix to apply,
transpose and slice. Its memory is proportional to nnz(A), which is counted
exactly, per column, before anything of that size is allocated.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import scipy.sparse
from numba import prange

from .attenuation import attenuation_code, attenuation_of_distances
from .kernel_cache import njit
from .isochrone import (ellipse, first_arrival_point, make_frame, path_length_at,
                        rectangle_range, segment_minimum)
from .quadrature import (LINEAR, ROOT_BOTH, ROOT_END, ROOT_START, adapt, integrate, isochrone_rule,
                         make_workspace, piece_map, pixel_isochrone_integral, tensor_integrate)
from .errors import ResourceError
from .resources import available_memory
from .scene import MAX_TOLERANCE, MIN_TOLERANCE, Scene, check_heights, check_tolerance
from .waveforms import cumulative_scalar, make_waveform

__all__ = ["system_matrix", "forward", "count_entries", "check_tolerance", "pair_entries", "METHODS",
           "QuadratureWarning", "MIN_TOLERANCE", "MAX_TOLERANCE", "FOOT_CLEARANCE", "SAFETY"]

# The tolerance's range (analytic.scene.MIN_TOLERANCE, MAX_TOLERANCE): from
# 1e-9 down, a few dozen τ-pieces near tangencies stop at the rounding of
# their geometry (a QuadratureWarning says so); below 1e-10 the quadrature no
# longer converges: on the default scene 1e-11 takes about 10 times the time
# of 1e-6 with ~500 such pieces, 1e-12 about 60 times with ~5000, and 1e-300
# would refine every piece to its limit.
#: A pixel is integrated as a smooth 2-D function only if every foot is at
#: least this many pixel sides away, counting its height: sqrt(δ² + h²) >=
#: FOOT_CLEARANCE x side, δ the foot's distance from the pixel. The
#: attenuation's nearest complex singularity is that far, which bounds the
#: tensor rule's convergence rate.
FOOT_CLEARANCE = 1.0

#: The quadrature asks itself for this fraction of the tolerance: its error
#: estimates describe the values kept, and this margin covers their
#: occasional underestimate so that the achieved error stays below the
#: tolerance while following it.
SAFETY = 0.5
_INNER_FACTOR = 0.1      # inner (φ) integrals this much tighter than the outer ones
_TENSOR_PIECES = 64      # τ-pieces the (τ, φ) tensor rule may split into before the adaptive route takes over
# Path lengths closer than this (relative) are not told apart: the ellipse's
# axes near a tangency or the birth at t_min come from τ² - t², whose
# rounding makes G(τ) noise on finer scales (about 2·10⁴ roundings of τ).
_TAU_RESOLUTION = 4e-12
_BLOCKS_PER_THREAD = 16  # parallel jobs per thread; pixels are dealt to them in strides


# S(u) of analytic.waveforms (the same code), compiled inline: a call that
# passes the waveform record (it holds arrays) costs ~12 ns of reference
# counting, more than S itself.
_cumulative = njit(cache=True, inline="always")(cumulative_scalar.py_func)


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
def _pixel_bins(low, high, start, period, count, duration):
    """(first bin, number of bins) that light leaving a pixel at d in [low, high] reaches; (0, 0) if none.

    Light leaving at path length τ lands in [τ, τ + duration].
    """
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


@njit(cache=True, error_model="numpy", inline="always")
def _kernels(terms, start, period, first, bins, tau, scale, values, noise):
    """values[i] = scale κ_{first + i}(τ), i < bins, and noise[i] a bound on its rounding.

    κ_n = S(t_{n+1} - τ) - S(t_n - τ): where both values of S are close to
    the pulse's energy and κ is small, the difference keeps only their
    rounding, ~1e-16 of S (8 roundings allowed here).
    """
    lower = _cumulative(terms, _edge(start, period, first) - tau)
    size = abs(scale) * 8.0 * 2.2e-16
    for i in range(bins):
        upper = _cumulative(terms, _edge(start, period, first + i + 1) - tau)
        values[i] = scale * (upper - lower)
        noise[i] = size * (abs(upper) + abs(lower))
        lower = upper


@njit(cache=True, error_model="numpy", inline="always")
def _smooth_integrand(problem, x, y, values, noise):
    """a_k(x) κ_n(d(x)) for the pair's bins: the integrand of a smooth pixel."""
    frame, terms, start, period, first, bins = problem
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    _kernels(terms, start, period, first, bins, math.sqrt(ds2) + math.sqrt(dk2),
             attenuation_of_distances(frame, ds2, dk2), values, noise)


@njit(cache=True, error_model="numpy", inline="always")
def _kernel_weight(problem, tau, scale, values, noise):
    """scale κ_n(τ) for the piece's bins (the time weight of a cut piece), and its rounding."""
    terms, start, period, first, bins = problem
    _kernels(terms, start, period, first, bins, tau, scale, values, noise)


@njit(cache=True, error_model="numpy")
def _cut_integrand(problem, v, values, noise):
    """κ_n(τ) G(τ) dτ/dv at τ = piece_map(v), for the piece's bins."""
    (frame, x0, x1, y0, y1, terms, start, period, first, bins, kind, tau_a, span, inner_rtol,
     angles, arcs, inner) = problem
    tau, slope = piece_map(kind, tau_a, span, v)
    cx, cy, a, b, j0, j1, j2 = ellipse(frame, tau)
    response = pixel_isochrone_integral(frame, cx, cy, a, b, j0, j1, j2, x0, x1, y0, y1, inner_rtol,
                                        angles, arcs, inner)
    weight = response * slope
    if weight == 0.0:
        for i in range(bins):
            values[i] = 0.0
            noise[i] = 0.0
        return
    _kernels(terms, start, period, first, bins, tau, weight, values, noise)


@njit(cache=True, error_model="numpy")
def _pixel_breakpoints(frame, x0, x1, y0, y1, low, high, start, period, first, bins, duration):
    """Sorted τ in [low, high] where the cut integrand stops being smooth, and which are roots.

    Returns (points, root): ``root[i]`` when G(τ) has a square-root
    behaviour at points[i] (an isochrone touching an edge inside it, born
    at x*, or passing a foot, where G is peaked), so that the τ-pieces
    next to it take a :func:`analytic.quadrature.piece_map` that smooths
    it; corners and kernel breakpoints are regular ends.
    """
    shifts = 2 if duration > 0.0 else 1
    points = np.empty(13 + shifts * (bins + 1))
    flags = np.zeros(13 + shifts * (bins + 1), dtype=np.bool_)
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
            flags[used] = True
            used += 1
    xs, ys = first_arrival_point(frame)
    if x0 <= xs <= x1 and y0 <= ys <= y1:
        points[used] = frame.first_arrival
        flags[used] = True
        used += 1
    # The attenuation peaks under the source and the sensor: cutting there
    # lets the τ-mapping crowd nodes onto the peak when they are low.
    for (fx, fy) in ((frame.source_x, frame.source_y), (frame.sensor_x, frame.sensor_y)):
        if x0 < fx < x1 and y0 < fy < y1:
            points[used] = path_length_at(frame, fx, fy)
            flags[used] = True
            used += 1
    for n in range(first, first + bins + 1):
        edge = _edge(start, period, n)
        points[used] = edge
        used += 1
        if duration > 0.0:
            points[used] = edge - duration
            used += 1
    order = np.argsort(points[:used])
    kept_points = np.empty(used)
    kept_flags = np.zeros(used, dtype=np.bool_)
    kept = 0
    for i in range(used):
        value = points[order[i]]
        if value < low or value > high:
            continue
        if kept > 0 and value <= kept_points[kept - 1]:
            kept_flags[kept - 1] = kept_flags[kept - 1] or flags[order[i]]
            continue
        kept_points[kept] = value
        kept_flags[kept] = flags[order[i]]
        kept += 1
    return kept_points[:kept], kept_flags[:kept]


@njit(cache=True, error_model="numpy")
def _cut_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                 smooth_arcs, out, work, inner, angles, arcs):
    """Add the pair's entries to out[:bins] by the cut (τ, φ) quadrature.

    ``smooth_arcs``: the integrand is smooth along every arc (the pixel is
    clear of the feet and of x*), so each τ-piece first tries the tensor
    rule in (τ, φ); otherwise, or when that fails, the inner φ-integrals
    are adaptive too.
    """
    duration = terms.duration
    low = max(low, _edge(start, period, 0) - duration)
    high = min(high, _edge(start, period, first + bins))
    breakpoints, root = _pixel_breakpoints(frame, x0, x1, y0, y1, low, high, start, period, first, bins,
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
        target = out[lo_bin - first:]
        kind = (ROOT_BOTH if root[piece] and root[piece + 1] else ROOT_START if root[piece]
                else ROOT_END if root[piece + 1] else LINEAR)
        # dτ/dv <= 2 span: a v-piece this narrow spans under _TAU_RESOLUTION of τ
        resolution = _TAU_RESOLUTION * max(abs(tau_a), abs(tau_b)) / (2.0 * span)
        if smooth_arcs:
            trial = work.result
            for i in range(nb):
                trial[i] = 0.0
            problem = ((terms, start, period, lo_bin, nb), frame, x0, x1, y0, y1, kind, tau_a, span,
                       angles, arcs)
            failed = adapt(isochrone_rule, _kernel_weight, problem, 0.0, 1.0, rtol, nb, trial, work,
                           resolution, _TENSOR_PIECES)
            if failed == 0:
                for i in range(nb):
                    target[i] += trial[i]
                continue
            work.failures[0] -= failed     # not failures: the adaptive route takes the piece over
        problem = (frame, x0, x1, y0, y1, terms, start, period, lo_bin, nb, kind, tau_a, span,
                   inner_rtol, angles, arcs, inner)
        integrate(_cut_integrand, problem, 0.0, 1.0, rtol, nb, target, work, resolution)


@njit(cache=True, error_model="numpy")
def _pair_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                  out, work, inner, angles, arcs):
    """out[i] = A[(k, first + i), p] for one (sensor, pixel); True if the smooth path served.

    [low, high] is the pixel's range of d (:func:`analytic.isochrone.rectangle_range`).
    """
    for i in range(bins):
        out[i] = 0.0
    clear = _clear_of_feet(frame, x0, x1, y0, y1)
    if clear and not _kernel_cut(low, high, start, period, first, bins, terms.duration):
        problem = (frame, terms, start, period, first, bins)
        if tensor_integrate(_smooth_integrand, problem, x0, x1, y0, y1, rtol, bins, out, work):
            return True
    # Near x* the isochrones are small (and, with low points, needles): an arc
    # inside the pixel is a large part of its ellipse and varies faster in φ
    # than in τ, so there the φ-integrals stay adaptive.
    xs, ys = first_arrival_point(frame)
    side = FOOT_CLEARANCE * max(x1 - x0, y1 - y0)
    dx = max(x0 - xs, 0.0, xs - x1)
    dy = max(y0 - ys, 0.0, ys - y1)
    smooth_arcs = clear and dx * dx + dy * dy >= side * side
    _cut_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                 smooth_arcs, out, work, inner, angles, arcs)
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
            low, high = rectangle_range(frame, x0, x1, y0, y1)
            bins = _pixel_bins(low, high, start, period, count, duration)[1]
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
        arcs = np.empty((4, 2))
        served = 0
        for p in range(begin + block, end, blocks):
            x0, x1, y0, y1 = _pixel_box(size, pixels, p)
            offset = indptr[p]
            for k in range(sensor_count):
                frame = make_frame(source, sensors[k], mode)
                low, high = rectangle_range(frame, x0, x1, y0, y1)
                first, bins = _pixel_bins(low, high, start, period, count, terms.duration)
                if bins == 0:
                    continue
                for i in range(bins):
                    rows[offset + i] = k * count + first + i
                if _pair_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins,
                                 rtol, data[offset:offset + bins], work, inner, angles, arcs):
                    served += 1
                offset += bins
        failures[block] += work.failures[0] + inner.failures[0]
        smooth[block] += served


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
        raise ResourceError(f"plane.pixels: {scene.pixels}² pixels need {_gib(needed)} just to index "
                            f"A's columns, over the {_gib(limit)} limit; use fewer pixels")
    if needed > limit:
        raise ResourceError(f"sampling.count: {scene.sensor_count} sensors x {scene.sampling.count:,} "
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
    ResourceError
        When A, or its index arrays alone, would not fit in ``memory_limit``
        (the message names the setting to reduce).
    """
    return _count_columns(scene, memory_limit)[0]


def _count_columns(scene: Scene, memory_limit: int | None):
    """(non-zeros per column, most bins of one pair), refusing what would not fit."""
    limit = memory_limit if memory_limit is not None else available_memory() // 2
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
        raise ResourceError(f"sampling: the system matrix would hold {nnz:,} entries "
                            f"({_gib(needed)} while it is assembled), over the {_gib(limit)} limit; "
                            f"use fewer bins (sampling.count / period) or fewer pixels")
    return per_pixel, int(widest.max()) if len(widest) else 0


def _matrix_bytes(nnz: int, scene: Scene) -> int:
    """Peak bytes of assembly: CSC and CSR copies (data + index) and their pointers."""
    rows = scene.sensor_count * scene.sampling.count
    columns = scene.pixels ** 2
    index = _index_bytes(max(nnz, rows, columns))
    return 2 * nnz * (8 + index) + (columns + 1) * 8 + (rows + 1) * 8 + columns * 12


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
        I x a_k x area x path length: W/sr x m⁻⁴ x m² x m = W m⁻¹ per unit
        reflectance (the source's intensity I in W/sr is included).

    Raises
    ------
    SceneError
        A tolerance outside the supported range (``model.tolerance``), or a
        source or sensor too low to resolve (see
        :func:`analytic.scene.check_heights`).
    ResourceError
        An A that does not fit in memory (the need and the limit named).

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
    for begin, end in itertools.pairwise(bounds):
        _fill(source, sensors, mode, scene.size, scene.pixels, sampling.start_opl, sampling.bin_width_opl,
              sampling.count, terms, SAFETY * tolerance, width, int(begin), int(end), indptr, rows, data,
              failures, smooth)
        if bar is not None:
            bar.update(int(end - begin))
    if bar is not None:
        bar.close()
    if failures.sum():
        warnings.warn(f"{int(failures.sum())} quadrature pieces stopped refining before reaching "
                      f"tolerance {tolerance:g}", QuadratureWarning, stacklevel=2)
    # the source emits I s(t): A scales with its peak intensity I exactly
    data *= scene.intensity
    matrix = scipy.sparse.csc_array((data, rows, indptr.astype(index_type)), shape=shape)
    del data, rows
    matrix = matrix.tocsr()
    matrix.eliminate_zeros()
    return matrix


def _threads() -> int:
    import numba

    return int(numba.get_num_threads())


#: Quadrature routes of :func:`pair_entries`.
METHODS = ("auto", "smooth", "isochrone", "adaptive")


@njit(cache=True, error_model="numpy")
def _pair_by_method(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                    method, out, work, inner, angles, arcs):
    """One pair's entries by one route (index into METHODS); -1 if the smooth rule does not apply,
    -2 if it did not converge, else the number of quadrature failures."""
    for i in range(bins):
        out[i] = 0.0
    if method == 0:
        _pair_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                      out, work, inner, angles, arcs)
    elif method == 1:
        if (_kernel_cut(low, high, start, period, first, bins, terms.duration)
                or not _clear_of_feet(frame, x0, x1, y0, y1)):
            return -1
        if not tensor_integrate(_smooth_integrand, (frame, terms, start, period, first, bins), x0, x1, y0,
                                y1, rtol, bins, out, work):
            return -2
    else:
        _cut_entries(frame, x0, x1, y0, y1, low, high, terms, start, period, count, first, bins, rtol,
                     method == 2, out, work, inner, angles, arcs)
    return work.failures[0] + inner.failures[0]


def pair_entries(scene: Scene, sensor: int, pixel: int, *, method: str = "auto",
                 tolerance: float | None = None) -> tuple[int, np.ndarray]:
    """The non-zero run of column ``pixel`` for one sensor, by a chosen quadrature route.

    For tests and diagnosis: each fast route can be checked against the
    adaptive one on the same pair.

    Parameters
    ----------
    scene : Scene
    sensor : int
        Sensor index k.
    pixel : int
        Column p = r M + c.
    method : {"auto", "smooth", "isochrone", "adaptive"}
        "auto": what :func:`system_matrix` does. "smooth": the tensor rule
        on the whole pixel (only where no kernel breakpoint crosses it and
        it is clear of the feet). "isochrone": the cut quadrature with the
        tensor rule in (τ, φ) on each τ-piece. "adaptive": the cut
        quadrature with adaptive φ-integrals inside adaptive τ-integrals.
    tolerance : float, optional
        As for :func:`system_matrix`.

    Returns
    -------
    first : int
        The first bin n of the run.
    values : numpy.ndarray
        A[(k, first + i), p], units of A.

    Raises
    ------
    ValueError
        An unknown method, index out of range, or "smooth" where it does not
        apply or does not converge.
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if not 0 <= sensor < scene.sensor_count or not 0 <= pixel < scene.pixels ** 2:
        raise ValueError(f"sensor {sensor} or pixel {pixel} out of range")
    tolerance = check_tolerance(scene.tolerance if tolerance is None else tolerance)
    waveform, mode, source, sensors = _prepare(scene)
    terms = waveform.terms
    sampling = scene.sampling
    frame = make_frame(source, sensors[sensor], mode)
    x0, x1, y0, y1 = _pixel_box(scene.size, scene.pixels, pixel)
    low, high = rectangle_range(frame, x0, x1, y0, y1)
    first, bins = _pixel_bins(low, high, sampling.start_opl, sampling.bin_width_opl, sampling.count,
                              terms.duration)
    out = np.zeros(bins)
    status = _pair_by_method(frame, x0, x1, y0, y1, low, high, terms, sampling.start_opl,
                             sampling.bin_width_opl, sampling.count, first, bins, SAFETY * tolerance,
                             METHODS.index(method), out, make_workspace(max(bins, 1)), make_workspace(1),
                             np.empty(8), np.empty((4, 2)))
    if status == -1:
        raise ValueError(f"the smooth rule does not apply to pixel {pixel}, sensor {sensor}: a kernel "
                         f"breakpoint crosses it or a foot is near")
    if status == -2:
        raise ValueError(f"the smooth rule did not converge on pixel {pixel}, sensor {sensor}")
    if status > 0:
        warnings.warn(f"{status} quadrature pieces stopped refining before reaching tolerance "
                      f"{tolerance:g}", QuadratureWarning, stacklevel=2)
    return first, out


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
