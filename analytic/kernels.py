"""One pair's entries of A over one pixel, by the quadrature routes of :mod:`analytic.system` (compiled).

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx

for one pair k (a :class:`~analytic.isochrone.Frame` in the rectangle's
frame) and one pixel p (a :class:`~analytic.isochrone.PixelBox`), over the
run of bins its light reaches (:class:`BinRun` of a :class:`TimeAxis`).
:func:`pair_entries` chooses the route, :func:`pair_by_method` forces one
(so that each fast route can be held to the adaptive one); the module
docstring of :mod:`analytic.system` says what each route does.

Every compiled function here takes records (NamedTuples, which Numba
passes by value) instead of long positional lists: a pixel box, a time
axis, a bin run, the waveform's pieces (:class:`~analytic.waveforms.WaveformTerms`),
the pair's frame and a :class:`Scratch`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .isochrone import Frame, PixelBox, ellipse, first_arrival_point, path_length_at, segment_minimum
from .kernel_cache import njit
from .attenuation import attenuation_of_distances
from .quadrature import (LINEAR, ROOT_BOTH, ROOT_END, ROOT_START, IsochronePiece, Workspace, adapt, integrate,
                         isochrone_rule, make_workspace, piece_map, pixel_isochrone_integral, tensor_integrate)
from .waveforms.pieces import ROUNDING, WaveformTerms, piece_of, piece_value

__all__ = ["TimeAxis", "BinRun", "Scratch", "RouteOutcome", "make_scratch", "pixel_bins", "pair_entries",
           "pair_by_method", "bin_of", "FOOT_CLEARANCE", "SAFETY", "AUTO", "SMOOTH", "ISOCHRONE", "ADAPTIVE"]

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

#: Routes of :func:`pair_by_method` (``analytic.system.METHODS`` names them).
AUTO, SMOOTH, ISOCHRONE, ADAPTIVE = 0, 1, 2, 3


class TimeAxis(NamedTuple):
    """Bins n = 0 ... count - 1 covering [start_opl + n T, start_opl + (n + 1) T), metres of path length.

    For a pair whose paths carry an added length (its ``offset``), the
    pair's axis starts that much earlier, so that the pair's geometric
    path d is binned as d + offset.
    """

    start_opl: float
    bin_width_opl: float
    count: int


class BinRun(NamedTuple):
    """The bins a (pair, pixel) reaches: ``first`` ... ``first + bins - 1`` (``bins`` 0: none)."""

    first: int
    bins: int


class Scratch(NamedTuple):
    """One thread's scratch: the outer and inner workspaces, crossing angles and arcs."""

    work: Workspace
    inner: Workspace
    angles: np.ndarray     # float64[8]
    arcs: np.ndarray       # float64[4, 2]


class RouteOutcome(NamedTuple):
    """What :func:`pair_by_method` did: whether its route applied and converged, and the failed pieces."""

    applies: bool
    converged: bool
    failures: int


class SmoothProblem(NamedTuple):
    """:func:`_smooth_integrand`'s problem: the pair and the bins' kernels."""

    frame: Frame
    kernel: "KernelProblem"


class KernelProblem(NamedTuple):
    """The time kernels κ_n of a run of bins (:func:`_kernels`)."""

    terms: WaveformTerms
    axis: TimeAxis
    run: BinRun


class CutProblem(NamedTuple):
    """:func:`_cut_integrand`'s problem: one τ-piece of one (pair, pixel), inner φ-integrals adaptive."""

    frame: Frame
    box: PixelBox
    kernel: KernelProblem
    kind: int
    tau_a: float
    span: float
    inner_rtol: float
    angles: np.ndarray
    arcs: np.ndarray
    inner: Workspace


@njit(cache=True, error_model="numpy")
def make_scratch(width):
    """A :class:`Scratch` for runs of up to ``width`` bins."""
    return Scratch(make_workspace(width), make_workspace(1), np.empty(8), np.empty((4, 2)))


@njit(cache=True, error_model="numpy")
def bin_of(tau, axis):
    """floor((τ - start) / period) clamped to [-1, count] in floating point (no integer overflow)."""
    index = np.floor((tau - axis.start_opl) / axis.bin_width_opl)
    if not index >= -1.0:       # also NaN
        return -1
    if index > axis.count:
        return axis.count
    return int(index)


@njit(cache=True, error_model="numpy")
def pixel_bins(low, high, axis, duration):
    """The :class:`BinRun` that light leaving a pixel at d in [low, high] reaches (``bins`` 0 if none).

    Light leaving at path length τ lands in [τ, τ + duration].
    """
    first = max(0, bin_of(low, axis))
    last = min(axis.count - 1, bin_of(high + duration, axis))
    if last < first:
        return BinRun(0, 0)
    return BinRun(first, last - first + 1)


@njit(cache=True, error_model="numpy")
def _edge(axis, n):
    """t_n, the lower edge of bin n, metres (as Sampling.edges computes it)."""
    return axis.start_opl + axis.bin_width_opl * n


@njit(cache=True, error_model="numpy")
def _kernel_cut(low, high, terms, axis, run):
    """Whether a breakpoint of some κ_n (t_n shifted back by a kink of the waveform) lies strictly inside (low, high)."""
    for n in range(run.first, run.first + run.bins + 1):
        edge = _edge(axis, n)
        for i in range(terms.starts.size):
            if terms.kinks[i] and low < edge - terms.starts[i] < high:
                return True
    return False


@njit(cache=True, error_model="numpy")
def _clear_of_feet(frame, box):
    """Whether the attenuation's peaks under both feet are far enough for the tensor rule."""
    side = FOOT_CLEARANCE * max(box.x1 - box.x0, box.y1 - box.y0)
    for fx, fy, height in ((frame.source_x, frame.source_y, frame.source_height),
                           (frame.sensor_x, frame.sensor_y, frame.sensor_height)):
        dx = max(box.x0 - fx, 0.0, fx - box.x1)
        dy = max(box.y0 - fy, 0.0, fy - box.y1)
        if dx * dx + dy * dy + height * height < side * side:
            return False
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _kernels(problem, tau, scale, values, noise):
    """values[i] = scale κ_{first + i}(τ), i < bins, and noise[i] a bound on its rounding.

    κ_n = S(t_{n+1} - τ) - S(t_n - τ), taken piece by piece
    (:func:`analytic.waveforms.kernel_scalar`): within one piece the
    constants cancel exactly, so a kernel far in a pulse's tail keeps its
    own relative accuracy; the rounding bound counts each term's size.
    """
    terms = problem.terms
    axis = problem.axis
    first = problem.run.first
    lower_u = _edge(axis, first) - tau
    lower_piece = piece_of(terms, lower_u)
    lower_value, lower_size = (0.0, 0.0) if lower_piece < 0 else piece_value(terms, lower_piece, lower_u)
    lower_constant = 0.0 if lower_piece < 0 else terms.constants[lower_piece]
    size = abs(scale) * ROUNDING
    for i in range(problem.run.bins):
        upper_u = _edge(axis, first + i + 1) - tau
        upper_piece = piece_of(terms, upper_u)
        upper_value, upper_size = (0.0, 0.0) if upper_piece < 0 else piece_value(terms, upper_piece, upper_u)
        upper_constant = 0.0 if upper_piece < 0 else terms.constants[upper_piece]
        constant = upper_constant - lower_constant
        values[i] = scale * (constant + (upper_value - lower_value))
        noise[i] = size * (abs(constant) + upper_size + lower_size)
        lower_value, lower_size, lower_constant = upper_value, upper_size, upper_constant


@njit(cache=True, error_model="numpy", inline="always")
def _smooth_integrand(problem, x, y, values, noise):
    """a_k(x) κ_n(d(x)) for the pair's bins: the integrand of a smooth pixel."""
    frame = problem.frame
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    _kernels(problem.kernel, math.sqrt(ds2) + math.sqrt(dk2), attenuation_of_distances(frame, x, y, ds2, dk2),
             values, noise)


@njit(cache=True, error_model="numpy", inline="always")
def _kernel_weight(problem, tau, scale, values, noise):
    """scale κ_n(τ) for the piece's bins (the time weight of a cut piece), and its rounding."""
    _kernels(problem, tau, scale, values, noise)


@njit(cache=True, error_model="numpy")
def _cut_integrand(problem, v, values, noise):
    """κ_n(τ) G(τ) dτ/dv at τ = piece_map(v), for the piece's bins."""
    tau, slope = piece_map(problem.kind, problem.tau_a, problem.span, v)
    curve = ellipse(problem.frame, tau)
    response = pixel_isochrone_integral(problem.frame, curve, problem.box, problem.inner_rtol, problem.angles,
                                        problem.arcs, problem.inner)
    weight = response * slope
    if weight == 0.0:
        for i in range(problem.kernel.run.bins):
            values[i] = 0.0
            noise[i] = 0.0
        return
    _kernels(problem.kernel, tau, weight, values, noise)


@njit(cache=True, error_model="numpy")
def _pixel_breakpoints(frame, box, low, high, terms, axis, run):
    """Sorted τ in [low, high] where the cut integrand stops being smooth, and which are roots.

    Returns (points, root): ``root[i]`` when G(τ) has a square-root
    behaviour at points[i] (an isochrone touching an edge inside it, born
    at x*, or passing a foot, where G is peaked), so that the τ-pieces
    next to it take a :func:`analytic.quadrature.piece_map` that smooths
    it; corners and kernel breakpoints are regular ends.
    """
    kinks = 0
    for i in range(terms.starts.size):
        if terms.kinks[i]:
            kinks += 1
    room = 13 + kinks * (run.bins + 1)
    points = np.empty(room)
    flags = np.zeros(room, dtype=np.bool_)
    used = 0
    points[used] = low
    used += 1
    points[used] = high
    used += 1
    x0, x1, y0, y1 = box
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
    for n in range(run.first, run.first + run.bins + 1):
        edge = _edge(axis, n)
        for i in range(terms.starts.size):
            if terms.kinks[i]:
                points[used] = edge - terms.starts[i]
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
def _cut_entries(frame, box, low, high, terms, axis, run, rtol, smooth_arcs, out, scratch):
    """Add the pair's entries to out[:run.bins] by the cut (τ, φ) quadrature.

    ``smooth_arcs``: the integrand is smooth along every arc (the pixel is
    clear of the feet and of x*), so each τ-piece first tries the tensor
    rule in (τ, φ); otherwise, or when that fails, the inner φ-integrals
    are adaptive too.
    """
    duration = terms.duration
    work = scratch.work
    low = max(low, _edge(axis, 0) - duration)
    high = min(high, _edge(axis, run.first + run.bins))
    breakpoints, root = _pixel_breakpoints(frame, box, low, high, terms, axis, run)
    inner_rtol = rtol * _INNER_FACTOR
    for piece in range(len(breakpoints) - 1):
        tau_a = breakpoints[piece]
        tau_b = breakpoints[piece + 1]
        span = tau_b - tau_a
        if not span > 0.0:
            continue
        # bins whose kernel can be non-zero on the piece (one spare on each side for rounding)
        lo_bin = max(run.first, bin_of(tau_a, axis) - 1)
        hi_bin = min(run.first + run.bins - 1, bin_of(tau_b + duration, axis) + 1)
        if hi_bin < lo_bin:
            continue
        piece_run = BinRun(lo_bin, hi_bin - lo_bin + 1)
        target = out[lo_bin - run.first:]
        kind = (ROOT_BOTH if root[piece] and root[piece + 1] else ROOT_START if root[piece]
                else ROOT_END if root[piece + 1] else LINEAR)
        # dτ/dv <= 2 span: a v-piece this narrow spans under _TAU_RESOLUTION of τ
        resolution = _TAU_RESOLUTION * max(abs(tau_a), abs(tau_b)) / (2.0 * span)
        kernel = KernelProblem(terms, axis, piece_run)
        if smooth_arcs:
            trial = work.result
            for i in range(piece_run.bins):
                trial[i] = 0.0
            problem = IsochronePiece(kernel, frame, box, kind, tau_a, span, scratch.angles, scratch.arcs)
            failed = adapt(isochrone_rule, _kernel_weight, problem, 0.0, 1.0, rtol, piece_run.bins, trial, work,
                           resolution, _TENSOR_PIECES)
            if failed == 0:
                for i in range(piece_run.bins):
                    target[i] += trial[i]
                continue
            work.failures[0] -= failed     # not failures: the adaptive route takes the piece over
        problem = CutProblem(frame, box, kernel, kind, tau_a, span, inner_rtol, scratch.angles, scratch.arcs,
                             scratch.inner)
        integrate(_cut_integrand, problem, 0.0, 1.0, rtol, piece_run.bins, target, work, resolution)


@njit(cache=True, error_model="numpy")
def _smooth_arcs(frame, box, clear):
    """Whether the arcs inside the pixel are smooth enough for the (τ, φ) tensor rule.

    Near x* the isochrones are small (and, with low points, needles): an arc
    inside the pixel is a large part of its ellipse and varies faster in φ
    than in τ, so there the φ-integrals stay adaptive.
    """
    xs, ys = first_arrival_point(frame)
    side = FOOT_CLEARANCE * max(box.x1 - box.x0, box.y1 - box.y0)
    dx = max(box.x0 - xs, 0.0, xs - box.x1)
    dy = max(box.y0 - ys, 0.0, ys - box.y1)
    return clear and dx * dx + dy * dy >= side * side


@njit(cache=True, error_model="numpy")
def pair_entries(frame, box, low, high, terms, axis, run, rtol, out, scratch):
    """out[i] = A[(k, first + i), p] for one (pair, pixel); True if the smooth route served.

    Parameters
    ----------
    frame : Frame
        The pair, in the rectangle's frame.
    box : PixelBox
        The pixel, metres.
    low, high : float
        The pixel's range of d (:func:`analytic.isochrone.rectangle_range`), metres.
    terms : WaveformTerms
        The waveform's pieces.
    axis : TimeAxis
        The pair's bins.
    run : BinRun
        The bins the pixel's light reaches (:func:`pixel_bins`).
    rtol : float
        Relative accuracy of each entry.
    out : float64[:]
        At least ``run.bins`` long; overwritten.
    scratch : Scratch
        The thread's scratch (:func:`make_scratch` of at least ``run.bins``).
    """
    for i in range(run.bins):
        out[i] = 0.0
    clear = _clear_of_feet(frame, box)
    if clear and not _kernel_cut(low, high, terms, axis, run):
        if tensor_integrate(_smooth_integrand, SmoothProblem(frame, KernelProblem(terms, axis, run)), box, rtol,
                            run.bins, out, scratch.work):
            return True
    _cut_entries(frame, box, low, high, terms, axis, run, rtol, _smooth_arcs(frame, box, clear), out, scratch)
    return False


@njit(cache=True, error_model="numpy")
def pair_by_method(frame, box, low, high, terms, axis, run, rtol, method, out, scratch):
    """One (pair, pixel)'s entries by one route (``AUTO``, ``SMOOTH``, ``ISOCHRONE`` or ``ADAPTIVE``).

    Returns
    -------
    RouteOutcome
        ``applies`` False when the smooth route does not apply (a kernel
        breakpoint crosses the pixel or a foot is near), ``converged``
        False when it did not converge; ``failures``: quadrature pieces
        kept without meeting the tolerance.
    """
    for i in range(run.bins):
        out[i] = 0.0
    if method == AUTO:
        pair_entries(frame, box, low, high, terms, axis, run, rtol, out, scratch)
    elif method == SMOOTH:
        if _kernel_cut(low, high, terms, axis, run) or not _clear_of_feet(frame, box):
            return RouteOutcome(False, False, 0)
        if not tensor_integrate(_smooth_integrand, SmoothProblem(frame, KernelProblem(terms, axis, run)), box,
                                rtol, run.bins, out, scratch.work):
            return RouteOutcome(True, False, 0)
    else:
        _cut_entries(frame, box, low, high, terms, axis, run, rtol, method == ISOCHRONE, out, scratch)
    return RouteOutcome(True, True, scratch.work.failures[0] + scratch.inner.failures[0])
