"""A cut pixel by strips: the pixel's share of each slab between two isochrones, in closed-form limits (compiled).

A bin edge (or another kink of the kernels) that crosses a pixel splits it
into slabs {τ_a <= d <= τ_b}; on each slab every kernel κ_n(d) is smooth,
so the entries are smooth integrals over a region with curved sides. The
sides are conics (:mod:`analytic.kernels.conics`): along a line of the pixel an
isochrone is a quadratic with closed-form roots. With the outer variable u
chosen along the isochrones (the axis across which d changes least), the
inner limits w(u) are smooth between the u where a side meets the pixel's
edge, found in closed form too; the region is then a few pieces of tensor
Gauss rules, no root-finding and no adaptive splitting.

The route applies to pixels clear of the attenuation's peaks and of the
point x* (there the isochrones turn inside the pixel, and the routes of
:mod:`analytic.kernels` take over). Each entry is the G_4 x G_4 rule,
accepted when G_3 x G_3 agrees with it within the tolerance (for a smooth
integrand the difference far exceeds G_4's own error); otherwise nothing is
kept and the caller integrates the pixel its other way. For a step-function S
(the impulse) every κ_n is constant on a slab, so the rules integrate a_k alone
and the kernels are taken once per slab. A pixel that one isochrone cuts (the
common case for small pixels) has two slabs with the same side: they are
integrated together, its roots found once per node; for a step-function S it is
first tried by :func:`single_cut`: the two slabs' ∫ a_k alone, scalars only, by a
ladder G_2 x G_2, G_3 x G_3, ... (each rung judged by the one below), which for the
small pixels of a fine image stops at G_3 (a few microseconds less per cut pair than
the G_4 x G_4 rule with its arrays).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .attenuation import attenuation_of_distances
from .bins import BinRun, KernelProblem, bin_edge, bin_of, kernel_values
from .conics import across, crossings, inner_roots, inner_roots_within, isochrone_conic, ordered, turns_inside
from .cache import njit
from .quadrature import GAUSS_NODES, GAUSS_WEIGHTS
from .pieces import ROUNDING

__all__ = ["strip_entries", "single_cut", "cut_pieces", "cut_rung", "Across", "Slab", "Sums", "HIGH_ORDER",
           "LOW_ORDER", "FIRST_RUNG", "LAST_RUNG"]

class Across(NamedTuple):
    """The pixel in the axes the strips integrate in: rows along w at each u (``swap``: u is y, w is x)."""

    swap: bool
    w0: float               # the pixel's w-edges, metres
    w1: float


class Slab(NamedTuple):
    """The region between the isochrones d = τ_a and d = τ_b (a side may be absent: the pixel's edge bounds it)."""

    lower: tuple            # the conic of d = τ_a (analytic.kernels.conics.isochrone_conic)
    upper: tuple            # the conic of d = τ_b
    tau_a: float            # metres
    tau_b: float
    has_lower: bool
    has_upper: bool


class Sums(NamedTuple):
    """Where a rule adds: one node's kernels (``values``, ``noise``), and per-bin totals (``total``; with
    ``judged``, ∫ |f| in ``magnitude`` and f's rounding in ``rounding``); ``steps``: the kernels are
    constant on the slab (a step-function S), so the rule integrates a_k alone."""

    values: np.ndarray
    noise: np.ndarray
    total: np.ndarray
    magnitude: np.ndarray
    rounding: np.ndarray
    judged: bool
    steps: bool


#: The rule kept (G_n in each variable) and the one that judges it.
HIGH_ORDER = 4
LOW_ORDER = 3
#: :func:`single_cut`'s ladder: G_n x G_n from n = FIRST_RUNG, each judged by G_{n-1} x G_{n-1}, up to LAST_RUNG.
FIRST_RUNG = 3
LAST_RUNG = 6


@njit(cache=True, error_model="numpy", forceinline=True)
def _add_crossings(frame, conic, tau, w, lo, hi, swap, points, used):
    """Append the u in (lo, hi) where the isochrone crosses the line at w; returns the new count."""
    for u in crossings(frame, conic, tau, w, lo, hi, swap):
        if u < np.inf:
            points[used] = u
            used += 1
    return used


@njit(cache=True, error_model="numpy", forceinline=True)
def _slab_pieces(frame, box, slab, swap, points):
    """Sorted u-breakpoints of the slab's region (the pixel's u-edges and the sides' crossings of its w-edges).

    Returns the count, or -1 when a side turns inside the pixel (the route does not apply).
    """
    u0, u1, w0, w1 = (box.y0, box.y1, box.x0, box.x1) if swap else (box.x0, box.x1, box.y0, box.y1)
    points[0] = u0
    used = 1
    for present, conic, tau in ((slab.has_lower, slab.lower, slab.tau_a), (slab.has_upper, slab.upper, slab.tau_b)):
        if present:
            if turns_inside(conic, u0, u1, w0, w1):
                return -1
            used = _add_crossings(frame, conic, tau, w0, u0, u1, swap, points, used)
            used = _add_crossings(frame, conic, tau, w1, u0, u1, swap, points, used)
    points[used] = u1
    used += 1
    points[:used].sort()
    return used


@njit(cache=True, error_model="numpy", forceinline=True)
def _region_rows(frame, slab, swap, u, w0, w1):
    """The inner intervals of the slab's region on the line at u: up to two (w_a, w_b), as four numbers.

    {d <= τ_b} is one interval on the line (d is convex), {d >= τ_a} the complement of one.
    """
    below_low, below_high = -np.inf, np.inf          # {d <= τ_b}
    if slab.has_upper:
        below_low, below_high, real = inner_roots(frame, slab.upper, slab.tau_b, u, swap)
        if not real:
            return 0.0, 0.0, 0.0, 0.0
    hole_low, hole_high = np.inf, np.inf              # {d < τ_a}: removed
    if slab.has_lower:
        low, high, real = inner_roots(frame, slab.lower, slab.tau_a, u, swap)
        if real:
            hole_low, hole_high = low, high
    start, stop = max(w0, below_low), min(w1, below_high)
    return start, min(stop, hole_low), max(start, hole_high), stop


@njit(cache=True, error_model="numpy", forceinline=True)
def _row_node(frame, swap, u, wa, wb, order, jw):
    """(d, weight x a_k) at node jw of G_order over [wa, wb] of the line at u."""
    hw = 0.5 * (wb - wa)
    w = 0.5 * (wa + wb) + hw * GAUSS_NODES[order, jw]
    x, y = (w, u) if swap else (u, w)
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    return (math.sqrt(ds2) + math.sqrt(dk2),
            hw * GAUSS_WEIGHTS[order, jw] * attenuation_of_distances(frame, x, y, ds2, dk2))


@njit(cache=True, error_model="numpy", forceinline=True)
def _row_rule(frame, kernel, swap, u, wu, wa, wb, order, sums):
    """G_order in w over [wa, wb] of the row at u (weight ``wu``), added to ``sums`` as :func:`_slab_rule` says."""
    scalar = 0.0
    scalar_magnitude = 0.0
    if not wb > wa:
        return scalar, scalar_magnitude
    if sums.steps:
        scalar, scalar_magnitude = _row_integral(frame, swap, u, wa, wb, order)
        return wu * scalar, wu * scalar_magnitude
    values, noise, total = sums.values, sums.noise, sums.total
    for jw in range(order):
        tau, weight = _row_node(frame, swap, u, wa, wb, order, jw)
        kernel_values(kernel, tau, wu * weight, values, noise)
        for i in range(kernel.run.bins):
            total[i] += values[i]
        if sums.judged:
            for i in range(kernel.run.bins):
                sums.magnitude[i] += abs(values[i])
                sums.rounding[i] += noise[i]
    return scalar, scalar_magnitude


@njit(cache=True, error_model="numpy", forceinline=True)
def _slab_rule(frame, kernel, slab, across, ua, ub, order, sums):
    """G_order x G_order of a_k κ_n(d) over the slab's region for u in [ua, ub], added to sums.total (per bin).

    ``sums.judged``: also add ∫ |f| and f's rounding to its magnitude and rounding (the rule that is kept;
    the rule that only judges it needs neither). ``sums.steps``: the kernels are constant on the slab
    (a step-function S): the rule integrates a_k alone and returns (∫ a_k, ∫ |a_k|), adding nothing,
    and its caller multiplies by the kernels once; else it returns (0, 0).
    """
    cu = 0.5 * (ua + ub)
    hu = 0.5 * (ub - ua)
    scalar = 0.0
    scalar_magnitude = 0.0
    for ju in range(order):
        u = cu + hu * GAUSS_NODES[order, ju]
        wu = hu * GAUSS_WEIGHTS[order, ju]
        first_a, first_b, second_a, second_b = _region_rows(frame, slab, across.swap, u, across.w0, across.w1)
        for wa, wb in ((first_a, first_b), (second_a, second_b)):
            value, value_size = _row_rule(frame, kernel, across.swap, u, wu, wa, wb, order, sums)
            scalar += value
            scalar_magnitude += value_size
    return scalar, scalar_magnitude


@njit(cache=True, error_model="numpy", forceinline=True)
def _cut_node(frame, conic, tau, across, ua, ub, order, ju):
    """(u, weight, rows) at node ju of G_order over [ua, ub]: the rows below d = τ, then the two above.

    Each row is (w_a, w_b) within [w0, w1], empty where w_b <= w_a.
    """
    hu = 0.5 * (ub - ua)
    u = 0.5 * (ua + ub) + hu * GAUSS_NODES[order, ju]
    low, high, real = inner_roots_within(frame, conic, tau, u, across.swap, across.w0, across.w1)
    if not real:        # the row lies wholly above
        low, high = np.inf, np.inf
    w0, w1 = across.w0, across.w1
    return (u, hu * GAUSS_WEIGHTS[order, ju],
            ((max(w0, low), min(w1, high)), (w0, min(w1, low)), (max(w0, high), w1)))


@njit(cache=True, error_model="numpy", forceinline=True)
def _cut_rule(frame, kernels, conic, tau, across, ua, ub, order, sums):
    """:func:`_slab_rule` of both slabs of a pixel that one isochrone d = τ cuts, at once.

    The slabs {d <= τ} and {d >= τ} have the same side, so their u-pieces and their inner limits
    at each node are the same roots, found once. ``kernels`` and ``sums`` are pairs (slab below,
    slab above); returns the steps' scalars of both, (∫ a, ∫ |a|) below, then above.
    """
    below, below_size, above, above_size = 0.0, 0.0, 0.0, 0.0
    for ju in range(order):
        u, wu, rows = _cut_node(frame, conic, tau, across, ua, ub, order, ju)
        for row in range(3):
            slab = min(row, 1)
            value, value_size = _row_rule(frame, kernels[slab], across.swap, u, wu, rows[row][0], rows[row][1], order,
                                          sums[slab])
            if slab == 0:
                below += value
                below_size += value_size
            else:
                above += value
                above_size += value_size
    return below, below_size, above, above_size


@njit(cache=True, error_model="numpy", forceinline=True)
def _row_integral(frame, swap, u, wa, wb, order):
    """(∫ a_k, ∫ |a_k|) over [wa, wb] of the line at u by G_order (zeros when the row is empty)."""
    total = 0.0
    size = 0.0
    if not wb > wa:
        return total, size
    for jw in range(order):
        value = _row_node(frame, swap, u, wa, wb, order, jw)[1]
        total += value
        size += abs(value)
    return total, size


@njit(cache=True, error_model="numpy", forceinline=True)
def cut_pieces(frame, conic, tau, sides, u0, u1):
    """The u in (u0, u1) where the side d = τ crosses the pixel's w-edges, in order (inf: none): u-pieces' ends."""
    a, b = crossings(frame, conic, tau, sides.w0, u0, u1, sides.swap)
    c, d = crossings(frame, conic, tau, sides.w1, u0, u1, sides.swap)
    a, b = ordered(a, b)
    c, d = ordered(c, d)
    a, c = ordered(a, c)
    b, d = ordered(b, d)
    b, c = ordered(b, c)
    return a, b, c, d


@njit(cache=True, error_model="numpy", forceinline=True)
def cut_rung(frame, conic, tau, sides, u0, u1, ends, order, above_too):
    """(below, above, below_size, above_size): ∫ a_k and ∫ |a_k| over the pixel's parts d <= τ and d >= τ by
    G_order x G_order on the u-pieces between ``ends`` (:func:`cut_pieces`); ``above_too`` False leaves the part
    above (zeros), saving two rows of three."""
    below, above, below_size, above_size = 0.0, 0.0, 0.0, 0.0
    start = u0
    for stop in (ends[0], ends[1], ends[2], ends[3], u1):
        if not start < stop <= u1:
            continue
        for ju in range(order):
            u, wu, rows = _cut_node(frame, conic, tau, sides, start, stop, order, ju)
            for row in range(3 if above_too else 1):
                value, size = _row_integral(frame, sides.swap, u, rows[row][0], rows[row][1], order)
                if row == 0:
                    below += wu * value
                    below_size += wu * size
                else:
                    above += wu * value
                    above_size += wu * size
        start = stop
    return below, above, below_size, above_size


@njit(cache=True, error_model="numpy")
def single_cut(frame, box, tau, rtol):
    """(below, above, served): ∫ a_k over the pixel's parts d <= τ and d >= τ, when one isochrone cuts it.

    For a step-function S each κ_n is constant on both parts, so a pixel that one breakpoint's
    isochrone d = τ cuts has the entries κ_n(below) ∫_below a_k + κ_n(above) ∫_above a_k. Both
    integrals share the side's u-pieces and its inner roots at each node, as in
    :func:`strip_entries`, and take G_n x G_n for n = :data:`FIRST_RUNG`, ... :data:`LAST_RUNG`,
    each kept when it agrees with G_{n-1} x G_{n-1} within ``rtol`` of itself (beyond the rounding
    of ∫ |a_k|); the kernels are non-negative, so every entry is then within ``rtol``. Scalars only:
    a real call with no array costs no reference count. ``served`` False (zeros) when the side turns
    inside the pixel, τ is below the foci's distance or no rung agrees: the caller integrates the
    pixel its other way.

    Parameters
    ----------
    frame : analytic.kernels.isochrone.Frame
        The pair, in the rectangle's frame.
    box : analytic.kernels.isochrone.PixelBox
        The pixel, metres; clear of the feet and of x* (the caller's test).
    tau : float
        The path length of the only kernel breakpoint inside the pixel's range of d, metres.
    rtol : float
        Relative accuracy of each integral.
    """
    swap, u0, u1, w0, w1 = across(frame, box)
    sides = Across(swap, w0, w1)
    conic = isochrone_conic(frame, tau, swap)
    if conic[2] == 0.0 or turns_inside(conic, u0, u1, w0, w1):
        return 0.0, 0.0, False
    ends = cut_pieces(frame, conic, tau, sides, u0, u1)
    previous_below, previous_above = 0.0, 0.0
    for order in range(FIRST_RUNG - 1, LAST_RUNG + 1):
        below, above, below_size, above_size = cut_rung(frame, conic, tau, sides, u0, u1, ends, order, True)
        if (order >= FIRST_RUNG
                and abs(below - previous_below) <= rtol * abs(below) + 8.0 * ROUNDING * below_size
                and abs(above - previous_above) <= rtol * abs(above) + 8.0 * ROUNDING * above_size):
            return below, above, True
        previous_below, previous_above = below, above
    return 0.0, 0.0, False


@njit(cache=True, error_model="numpy", forceinline=True)
def _slab_kinks(low, high, terms, axis, run, points):
    """Sorted τ in (low, high) where some κ_n has a kink, between low and high; returns the count."""
    points[0] = low
    used = 1
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(terms.starts.size):
            tau = edge - terms.starts[i]
            if terms.kinks[i] and low < tau < high:
                points[used] = tau
                used += 1
    points[used] = high
    used += 1
    points[:used].sort()
    return used


@njit(cache=True, error_model="numpy")
def strip_entries(frame, box, low, high, terms, axis, run, rtol, out, work):
    """Add one (pair, pixel)'s entries to out[:run.bins] by strips; False (out zeroed) when the route does not serve.

    A real call (compiled once for every caller); its cost per call is small beside a cut pair's rules.

    Parameters
    ----------
    frame : analytic.kernels.isochrone.Frame
        The pair, in the rectangle's frame.
    box : analytic.kernels.isochrone.PixelBox
        The pixel, metres; clear of the feet and of x* (the caller's test).
    low, high : float
        The pixel's range of d, metres.
    terms : analytic.waveforms.WaveformTerms
        The waveform's pieces.
    axis : analytic.kernels.bins.TimeAxis
        The pair's bins.
    run : analytic.kernels.bins.BinRun
        The bins the pixel's light reaches.
    rtol : float
        Relative accuracy of each entry.
    out : float64[:]
        Zero on entry, at least ``run.bins`` long.
    work : analytic.kernels.quadrature.Workspace
        Of at least ``run.bins`` components.
    """
    swap, _, _, w0, w1 = across(frame, box)
    sides = Across(swap, w0, w1)
    kinks = 0
    for i in range(terms.starts.size):
        if terms.kinks[i]:
            kinks += 1
    taus = np.empty(2 + kinks * (run.bins + 1))
    slabs = _slab_kinks(low, high, terms, axis, run, taus)
    points = np.empty(10)
    steps = terms.degree == 0
    low_order, magnitude, rounding = work.lower, work.magnitude, work.rounding
    entries = (out, low_order, magnitude, rounding)
    for i in range(run.bins):
        low_order[i] = 0.0
        magnitude[i] = 0.0
        rounding[i] = 0.0
    if slabs == 3:      # one isochrone cuts the pixel: its two slabs share their side
        tau = taus[1]
        below, below_offset = _slab_kernel(terms, axis, run, low, tau)
        above, above_offset = _slab_kernel(terms, axis, run, tau, high)
        if steps:
            below_value, above_value, served = single_cut(frame, box, tau, rtol)
            if served:
                _add_slab(below, 0.5 * (low + tau), below_value, below_offset, out, work)
                _add_slab(above, 0.5 * (tau + high), above_value, above_offset, out, work)
                return True
        conic = isochrone_conic(frame, tau, swap)
        if conic[2] == 0.0:
            return _discard(out, run.bins)
        pieces = _slab_pieces(frame, box, Slab(conic, conic, tau, tau, True, False), swap, points)
        if pieces < 0:
            return _discard(out, run.bins)
        kernels = (below, above)
        sums = np.zeros(6)      # ∫ a_k below and above, by the kept and the judging rule, and ∫ |a_k| (steps)
        kept = (Sums(work.values, work.noise, out[below_offset:], magnitude[below_offset:], rounding[below_offset:],
                     True, steps),
                Sums(work.values, work.noise, out[above_offset:], magnitude[above_offset:], rounding[above_offset:],
                     True, steps))
        judge = (Sums(work.values, work.noise, low_order[below_offset:], magnitude, rounding, False, steps),
                 Sums(work.values, work.noise, low_order[above_offset:], magnitude, rounding, False, steps))
        for piece in range(pieces - 1):
            ua, ub = points[piece], points[piece + 1]
            if not ub > ua:
                continue
            value, value_size, other, other_size = _cut_rule(frame, kernels, conic, tau, sides, ua, ub, HIGH_ORDER,
                                                             kept)
            sums[0] += value
            sums[1] += value_size
            sums[2] += other
            sums[3] += other_size
            value, _, other, _ = _cut_rule(frame, kernels, conic, tau, sides, ua, ub, LOW_ORDER, judge)
            sums[4] += value
            sums[5] += other
        if steps:
            _add_steps(below, 0.5 * (low + tau), (sums[0], sums[4], sums[1]), below_offset, entries, work)
            _add_steps(above, 0.5 * (tau + high), (sums[2], sums[5], sums[3]), above_offset, entries, work)
        return _judged(out, low_order, magnitude, rounding, rtol, run.bins)
    for slab in range(slabs - 1):
        tau_a, tau_b = taus[slab], taus[slab + 1]
        if not tau_b > tau_a:
            continue
        kernel, offset = _slab_kernel(terms, axis, run, tau_a, tau_b)
        if kernel.run.bins <= 0:
            continue
        has_lower, has_upper = slab > 0, slab < slabs - 2
        lower, upper = isochrone_conic(frame, tau_a, swap), isochrone_conic(frame, tau_b, swap)
        if (has_lower and lower[2] == 0.0) or (has_upper and upper[2] == 0.0):
            return _discard(out, run.bins)
        region = Slab(lower, upper, tau_a, tau_b, has_lower, has_upper)
        pieces = _slab_pieces(frame, box, region, swap, points)
        if pieces < 0:
            return _discard(out, run.bins)
        high_sum, low_sum, size = 0.0, 0.0, 0.0       # ∫ a_k over the slab (step-function S)
        for piece in range(pieces - 1):
            ua, ub = points[piece], points[piece + 1]
            if not ub > ua:
                continue
            value, value_size = _slab_rule(frame, kernel, region, sides, ua, ub, HIGH_ORDER,
                                           Sums(work.values, work.noise, out[offset:], magnitude[offset:],
                                                rounding[offset:], True, steps))
            high_sum += value
            size += value_size
            low_sum += _slab_rule(frame, kernel, region, sides, ua, ub, LOW_ORDER,
                                  Sums(work.values, work.noise, low_order[offset:], magnitude, rounding, False,
                                       steps))[0]
        if steps:
            _add_steps(kernel, 0.5 * (tau_a + tau_b), (high_sum, low_sum, size), offset, entries, work)
    return _judged(out, low_order, magnitude, rounding, rtol, run.bins)


@njit(cache=True, error_model="numpy", forceinline=True)
def _slab_kernel(terms, axis, run, tau_a, tau_b):
    """(kernels, offset): the bins light leaving the slab [τ_a, τ_b] reaches (one spare each side), and where they
    start in the run."""
    lo_bin = max(run.first, bin_of(tau_a + terms.lead, axis) - 1)
    hi_bin = min(run.first + run.bins - 1, bin_of(tau_b + terms.duration, axis) + 1)
    return KernelProblem(terms, axis, BinRun(lo_bin, max(hi_bin - lo_bin + 1, 0))), lo_bin - run.first


@njit(cache=True, error_model="numpy", forceinline=True)
def _add_slab(kernel, tau, value, offset, out, work):
    """A step-function S's slab: its kernels (constant there, their value at τ) times value, added to out."""
    kernel_values(kernel, tau, value, work.values, work.noise)
    for i in range(kernel.run.bins):
        out[offset + i] += work.values[i]


@njit(cache=True, error_model="numpy", forceinline=True)
def _add_steps(kernel, tau, integrals, offset, entries, work):
    """A step-function S's slab: κ_n is constant there, its value at τ (the middle) times ∫ a_k by each rule.

    ``integrals``: (∫ a_k by the rule kept, by the rule judging it, ∫ |a_k|); ``entries``: (out, low_order,
    magnitude, rounding), the kept rule's entries and the judging rule's, and their magnitudes and roundings.
    """
    high_sum, low_sum, size = integrals
    out, low_order, magnitude, rounding = entries
    kernel_values(kernel, tau, 1.0, work.values, work.noise)
    for i in range(kernel.run.bins):
        out[offset + i] += work.values[i] * high_sum
        low_order[offset + i] += work.values[i] * low_sum
        magnitude[offset + i] += abs(work.values[i]) * size
        rounding[offset + i] += work.noise[i] * size


@njit(cache=True, error_model="numpy", forceinline=True)
def _judged(out, low_order, magnitude, rounding, rtol, bins):
    """Whether every entry's G_4 x G_4 agrees with G_3 x G_3 within the tolerance (else out zeroed, False)."""
    for i in range(bins):
        if not abs(out[i] - low_order[i]) <= rtol * abs(out[i]) + 4.0 * (rounding[i] + ROUNDING * magnitude[i]):
            return _discard(out, bins)
    return True


@njit(cache=True, error_model="numpy", forceinline=True)
def _discard(out, bins):
    """Zero what a route that did not serve added; returns False."""
    for i in range(bins):
        out[i] = 0.0
    return False
