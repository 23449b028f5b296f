"""One pair's entries of A over one pixel, by the quadrature routes of :mod:`analytic.operator.system` (compiled).

    A[(k, n), p] = ∫_{pixel p} a_k(x) κ_n(d_k(x)) dx

for one pair k (a :class:`~analytic.kernels.isochrone.Frame` in the rectangle's
frame) and one pixel p (a :class:`~analytic.kernels.isochrone.PixelBox`), over the
run of bins its light reaches (:class:`BinRun` of a :class:`TimeAxis`).
:mod:`analytic.kernels.assembly` takes its own fast paths first, then the general routes here one at a
time (:func:`route_entries` with a :class:`Route`), and the tests force any one of them
(so that each fast route can be held to the adaptive one); the module
docstring of :mod:`analytic.operator.system` says what each route does.

Every compiled function here takes records (NamedTuples, which Numba
passes by value) instead of long positional lists: a pixel box, a time
axis, a bin run, the waveform's pieces (:class:`~analytic.waveforms.WaveformTerms`),
the pair's frame and a :class:`Scratch`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .bins import BinRun, KernelProblem, TimeAxis, bin_edge, bin_of, kernel_cut, kernel_values, pixel_bins
from .isochrone import Frame, PixelBox, ellipse, first_arrival_point, path_length_at, segment_minimum
from .cache import njit
from .attenuation import attenuation_of_distances
from .arcs import LINEAR, ROOT_BOTH, ROOT_END, ROOT_START, IsochronePiece, piece_map, pixel_isochrone_integral
from .quadrature import (Workspace, adapt, implements, integrand, integrate, make_workspace, surface_integrand,
                         tensor_integrate)
from .moments import MomentProblem, bin_moments, moment_weight, smooth_by_moments
from .strips import strip_entries
from .taylor import MAX_TERMS, kernel_taylor

__all__ = ["TimeAxis", "BinRun", "Scratch", "Column", "Route", "route_entries", "make_scratch", "pixel_bins",
           "clear_of_feet", "clear_of_birth", "scratch_failures", "bin_of", "MOMENTS", "DIRECT", "STRIP", "CUT",
           "AUTO_ARCS", "SMOOTH_ARCS", "ADAPTIVE_ARCS", "SERVED", "DOES_NOT_APPLY", "NOT_CONVERGED",
           "FOOT_CLEARANCE", "SAFETY"]

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

#: :class:`Route` codes, and how the cut route treats its arcs.
MOMENTS, DIRECT, STRIP, CUT = 0, 1, 2, 3
AUTO_ARCS, SMOOTH_ARCS, ADAPTIVE_ARCS = 0, 1, 2
#: What :func:`route_entries` did.
SERVED, DOES_NOT_APPLY, NOT_CONVERGED = 0, 1, 2


class Scratch(NamedTuple):
    """One thread's scratch: the workspaces, crossing angles and arcs, and the Taylor kernels' arrays."""

    work: Workspace
    inner: Workspace
    angles: np.ndarray         # float64[8]
    arcs: np.ndarray           # float64[4, 2]
    coefficients: np.ndarray   # float64[width, MAX_TERMS]: Taylor coefficients of the run's kernels
    lower_edge: np.ndarray     # float64[MAX_TERMS + 1]: S's derivatives at a bin edge
    upper_edge: np.ndarray
    moments: Workspace         # the moments' quadrature (MAX_TERMS components)


class Column(NamedTuple):
    """One (pixel, pair)'s run of bins and a range of d holding its path lengths."""

    run: BinRun
    low: float              # metres
    high: float
    exact: bool             # [low, high] is the pixel's exact range (else a bound around it)


class TauPiece(NamedTuple):
    """One τ-piece of a cut pixel: :func:`analytic.kernels.arcs.piece_map`'s ``kind``, [τ_a, τ_a + span]
    (metres), and the width in v below which it is not refined (its τ would only round)."""

    kind: int
    tau_a: float
    span: float
    resolution: float


class Route(NamedTuple):
    """Which general route :func:`route_entries` takes for a (pixel, pair), and how (runtime values: one compile).

    ``code``: :data:`MOMENTS` (the Taylor moments of a smooth pixel), :data:`DIRECT` (the smooth route with
    every kernel at every node), :data:`STRIP` (slabs between isochrones) or :data:`CUT` (the (τ, φ)
    quadrature). ``arcs`` (:data:`CUT` only): :data:`AUTO_ARCS` (the tensor rule in (τ, φ) where the
    pixel is clear of the feet and of x*), :data:`SMOOTH_ARCS` (always first) or :data:`ADAPTIVE_ARCS`
    (never). ``taylor`` (:data:`CUT` only): each τ-piece first through its moments.
    """

    code: int
    arcs: int = 0
    taylor: bool = True


class SmoothProblem(NamedTuple):
    """:func:`_smooth_integrand`'s problem: the pair and the bins' kernels."""

    frame: Frame
    kernel: "KernelProblem"


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


class CutMomentsProblem(CutProblem):
    """:func:`_cut_moments_integrand`'s problem: a :class:`CutProblem` whose ``kernel`` is a
    :class:`~analytic.kernels.moments.MomentProblem` (the piece's powers of τ); its own type chooses its integrand."""


@njit(cache=True, error_model="numpy")
def make_scratch(width):
    """A :class:`Scratch` for runs of up to ``width`` bins."""
    width = max(width, 1)
    return Scratch(make_workspace(width), make_workspace(1), np.empty(8), np.empty((4, 2)),
                   np.zeros((width, MAX_TERMS)), np.zeros(MAX_TERMS + 1), np.zeros(MAX_TERMS + 1),
                   make_workspace(MAX_TERMS))


@njit(cache=True, error_model="numpy", forceinline=True)
def clear_of_feet(frame, box):
    """Whether the attenuation's peaks under both feet are far enough for the tensor rule."""
    side = FOOT_CLEARANCE * max(box.x1 - box.x0, box.y1 - box.y0)
    for fx, fy, height in ((frame.source_x, frame.source_y, frame.source_height),
                           (frame.sensor_x, frame.sensor_y, frame.sensor_height)):
        dx = max(box.x0 - fx, 0.0, fx - box.x1)
        dy = max(box.y0 - fy, 0.0, fy - box.y1)
        if dx * dx + dy * dy + height * height < side * side:
            return False
    return True


@implements(surface_integrand, SmoothProblem)
@njit(cache=True, error_model="numpy")
def _smooth_integrand(problem, x, y, values, noise):
    """a_k(x) κ_n(d(x)) for the pair's bins: the integrand of a smooth pixel."""
    frame = problem.frame
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    kernel_values(problem.kernel, math.sqrt(ds2) + math.sqrt(dk2), attenuation_of_distances(frame, x, y, ds2, dk2),
             values, noise)


@njit(cache=True, error_model="numpy")
def _cut_response(problem, v):
    """(τ, G(τ) dτ/dv) at τ = piece_map(v): the pixel's response on its isochrone, φ-integrals adaptive."""
    tau, slope = piece_map(problem.kind, problem.tau_a, problem.span, v)
    curve = ellipse(problem.frame, tau)
    response = pixel_isochrone_integral(problem.frame, curve, problem.box, problem.inner_rtol, problem.angles,
                                        problem.arcs, problem.inner)
    return tau, response * slope


@implements(integrand, CutProblem)
@njit(cache=True, error_model="numpy")
def _cut_integrand(problem, v, values, noise):
    """κ_n(τ) G(τ) dτ/dv at τ = piece_map(v), for the piece's bins."""
    tau, weight = _cut_response(problem, v)
    if weight == 0.0:
        for i in range(problem.kernel.run.bins):
            values[i] = 0.0
            noise[i] = 0.0
        return
    kernel_values(problem.kernel, tau, weight, values, noise)


@implements(integrand, CutMomentsProblem)
@njit(cache=True, error_model="numpy")
def _cut_moments_integrand(problem, v, values, noise):
    """(τ - centre)^j G(τ) dτ/dv at τ = piece_map(v), j < count: the piece's moments."""
    tau, weight = _cut_response(problem, v)
    moment_weight(problem.kernel, tau, weight, values, noise)


@njit(cache=True, error_model="numpy")
def _pixel_breakpoints(frame, box, low, high, terms, axis, run):
    """Sorted τ in [low, high] where the cut integrand stops being smooth, and which are roots.

    Returns (points, root): ``root[i]`` when G(τ) has a square-root
    behaviour at points[i] (an isochrone touching an edge inside it, born
    at x*, or passing a foot, where G is peaked), so that the τ-pieces
    next to it take a :func:`analytic.kernels.arcs.piece_map` that smooths
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
        edge = bin_edge(axis, n)
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
def _cut_entries(frame, box, column, terms, axis, rtol, smooth_arcs, taylor, out, scratch):
    """Add the pair's entries to out[:run.bins] by the cut (τ, φ) quadrature (``column``: the exact range).

    A real call (not inlined): compiled once for every caller;
    its cost per call (a reference count on each of the scratch's arrays) is small beside a cut
    pair's quadrature.

    ``smooth_arcs``: the integrand is smooth along every arc (the pixel is
    clear of the feet and of x*), so each τ-piece first tries the tensor
    rule in (τ, φ); otherwise, or when that fails, the inner φ-integrals
    are adaptive too. ``taylor``: each τ-piece first tries its moments
    (:func:`_piece_by_moments`); False integrates the kernels directly.
    """
    duration = terms.duration
    lead = terms.lead
    work = scratch.work
    run = column.run
    low = max(column.low, bin_edge(axis, 0) - duration)
    high = min(column.high, bin_edge(axis, run.first + run.bins) - lead)
    breakpoints, root = _pixel_breakpoints(frame, box, low, high, terms, axis, run)
    for piece in range(len(breakpoints) - 1):
        tau_a = breakpoints[piece]
        tau_b = breakpoints[piece + 1]
        span = tau_b - tau_a
        if not span > 0.0:
            continue
        # bins whose kernel can be non-zero on the piece (one spare on each side for rounding)
        lo_bin = max(run.first, bin_of(tau_a + lead, axis) - 1)
        hi_bin = min(run.first + run.bins - 1, bin_of(tau_b + duration, axis) + 1)
        if hi_bin < lo_bin:
            continue
        piece_run = BinRun(lo_bin, hi_bin - lo_bin + 1)
        target = out[lo_bin - run.first:]
        kind = (ROOT_BOTH if root[piece] and root[piece + 1] else ROOT_START if root[piece]
                else ROOT_END if root[piece + 1] else LINEAR)
        # dτ/dv <= 2 span: a v-piece this narrow spans under _TAU_RESOLUTION of τ
        resolution = _TAU_RESOLUTION * max(abs(tau_a), abs(tau_b)) / (2.0 * span)
        if taylor and _piece_by_moments(frame, box, terms, axis, piece_run, TauPiece(kind, tau_a, span, resolution),
                                        rtol, smooth_arcs, target, scratch):
            continue
        kernel = KernelProblem(terms, axis, piece_run)
        if smooth_arcs:
            trial = work.result
            for i in range(piece_run.bins):
                trial[i] = 0.0
            problem = IsochronePiece(kernel, frame, box, kind, tau_a, span, scratch.angles, scratch.arcs)
            failed = adapt(problem, 0.0, 1.0, rtol, piece_run.bins, trial, work, resolution, _TENSOR_PIECES)
            if failed == 0:
                for i in range(piece_run.bins):
                    target[i] += trial[i]
                continue
            work.failures[0] -= failed     # not failures: the adaptive route takes the piece over
        problem = CutProblem(frame, box, kernel, kind, tau_a, span, rtol * _INNER_FACTOR, scratch.angles,
                             scratch.arcs, scratch.inner)
        integrate(problem, 0.0, 1.0, rtol, piece_run.bins, target, work, resolution)


@njit(cache=True, error_model="numpy")
def _piece_by_moments(frame, box, terms, axis, run, piece, rtol, smooth_arcs, target, scratch):
    """A τ-piece's entries through its moments (:mod:`analytic.kernels.taylor`), added to target; False if not.

    The moments m_j = ∫ (τ - c)^j G(τ) dτ over the piece, by the (τ, φ) tensor rule where the arcs
    are smooth, else by adaptive φ-integrals inside adaptive τ-integrals; False (nothing added) when
    a kernel needs more Taylor terms than allowed over the piece, the tensor rule fails or an
    entry's terms cancel, and the caller integrates the kernels directly.
    """
    kind, tau_a, span, resolution = piece
    centre = tau_a + 0.5 * span
    half = 0.5 * span
    count = kernel_taylor(terms, axis, run, centre, half, rtol, scratch.coefficients, scratch.lower_edge,
                          scratch.upper_edge)
    if count == 0:
        return False
    moments = scratch.moments
    result = moments.result
    powers = MomentProblem(centre, count)
    if smooth_arcs:
        for j in range(count):
            result[j] = 0.0
        failed = adapt(IsochronePiece(powers, frame, box, kind, tau_a, span, scratch.angles, scratch.arcs),
                       0.0, 1.0, rtol, count, result, moments, resolution, _TENSOR_PIECES)
        if failed:
            moments.failures[0] -= failed   # not failures: the adaptive route takes the piece over
            smooth_arcs = False
    if not smooth_arcs:
        for j in range(count):
            result[j] = 0.0
        integrate(CutMomentsProblem(frame, box, powers, kind, tau_a, span, rtol * _INNER_FACTOR, scratch.angles,
                                    scratch.arcs, scratch.inner),
                  0.0, 1.0, rtol, count, result, moments, resolution)
    return bin_moments(scratch, count, run.bins, half, target)


@njit(cache=True, error_model="numpy", forceinline=True)
def clear_of_birth(frame, box, clear):
    """Whether the pixel is ``clear`` (of the feet) and clear of x*: its arcs are smooth enough for the (τ, φ) tensor rule.

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
def _smooth_direct(frame, box, terms, axis, run, rtol, out, work):
    """The smooth route with every kernel at every node (the tensor Gauss ladder); True when converged."""
    return tensor_integrate(SmoothProblem(frame, KernelProblem(terms, axis, run)), box, rtol, run.bins, out, work)


@njit(cache=True, error_model="numpy", inline="always")
def route_entries(route, frame, box, column, terms, axis, rtol, out, scratch):
    """One route's entries of one (pixel, pair) into out[:run.bins]: :data:`SERVED`, :data:`DOES_NOT_APPLY`
    or :data:`NOT_CONVERGED` (out zeroed then).

    Where each applies: the smooth routes (:data:`MOMENTS`, :data:`DIRECT`) to a pixel clear of the feet
    whose ``column`` (its exact range of d) no kernel breakpoint cuts; strips to one clear of the feet and
    of x*; the cut route to any, and it always serves (pieces that stop refining are counted as failures
    in ``scratch``).
    """
    run = column.run
    for i in range(run.bins):
        out[i] = 0.0
    clear = clear_of_feet(frame, box)
    if route.code == MOMENTS or route.code == DIRECT:
        if not clear or kernel_cut(column.low, column.high, terms, axis, run):
            return DOES_NOT_APPLY
        if route.code == MOMENTS:
            served = smooth_by_moments(frame, box, column.low, column.high, terms, axis, run, rtol, out, scratch)
        else:
            served = _smooth_direct(frame, box, terms, axis, run, rtol, out, scratch.work)
        return SERVED if served else NOT_CONVERGED
    smooth_arcs = clear_of_birth(frame, box, clear)
    if route.code == STRIP:
        if not smooth_arcs:
            return DOES_NOT_APPLY
        served = strip_entries(frame, box, column.low, column.high, terms, axis, run, rtol, out, scratch.work)
        return SERVED if served else NOT_CONVERGED
    if route.arcs != AUTO_ARCS:
        smooth_arcs = route.arcs == SMOOTH_ARCS
    _cut_entries(frame, box, column, terms, axis, rtol, smooth_arcs, route.taylor, out, scratch)
    return SERVED


@njit(cache=True, error_model="numpy", forceinline=True)
def scratch_failures(scratch):
    """Quadrature pieces kept without meeting the tolerance, over the scratch's three workspaces."""
    return scratch.work.failures[0] + scratch.inner.failures[0] + scratch.moments.failures[0]
