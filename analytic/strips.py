"""A cut pixel by strips: the pixel's share of each slab between two isochrones, in closed-form limits (compiled).

A bin edge (or another kink of the kernels) that crosses a pixel splits it
into slabs {τ_a <= d <= τ_b}; on each slab every kernel κ_n(d) is smooth,
so the entries are smooth integrals over a region with curved sides. The
sides are conics: the isochrone d = τ is the rectangle's section of the
prolate spheroid with foci at the pair's ends, so along a line of the
pixel it is a quadratic with closed-form roots. With the outer variable u
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
integrated together, its roots found once per node.
"""

from __future__ import annotations

import math

import numpy as np

from .attenuation import attenuation_of_distances
from .bins import BinRun, KernelProblem, bin_edge, bin_of, kernel_values
from .kernel_cache import njit
from .quadrature import GAUSS_NODES, GAUSS_WEIGHTS
from .waveforms.pieces import ROUNDING

__all__ = ["strip_entries", "HIGH_ORDER", "LOW_ORDER"]

#: The rule kept (G_n in each variable) and the one that judges it.
HIGH_ORDER = 4
LOW_ORDER = 3


@njit(cache=True, error_model="numpy", inline="always")
def _conic(frame, tau, swap):
    """The isochrone d = τ as a conic in the pixel's (u, w) about the foci's midpoint.

    Q(q) = A_uu q_u² + 2 A_uw q_u q_w + A_ww q_w² + 2 B_u q_u + 2 B_w q_w + C, q = (u, w) - m,
    is zero on the isochrone and negative inside it (d < τ). Returns (m_u, m_w, A_uu, A_uw, A_ww,
    B_u, B_w, C), or all zeros with A_uu = 0 when τ does not exceed the foci's distance.
    """
    sx, sy, kx, ky = frame.source_x, frame.source_y, frame.sensor_x, frame.sensor_y
    if swap:
        sx, sy, kx, ky = sy, sx, ky, kx
    dx, dy, dz = kx - sx, ky - sy, frame.sensor_height - frame.source_height
    focal = math.sqrt(dx * dx + dy * dy + dz * dz)
    if not tau > focal:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    mu, mw, mz = 0.5 * (sx + kx), 0.5 * (sy + ky), 0.5 * (frame.source_height + frame.sensor_height)
    eu, ew, ez = (dx / focal, dy / focal, dz / focal) if focal > 0.0 else (0.0, 0.0, 0.0)
    ratio = (focal / tau) ** 2                      # (c / a)²
    minor = 0.25 * (tau - focal) * (tau + focal)    # b², without the cancellation of a² - c²
    pz = -mz * ez                                   # the plane's q_z = -m_z, projected on the axis
    # |q|² - (c/a)² (q·e)² - b², expanded with q = (q_u, q_w, -m_z)
    return (mu, mw, 1.0 - ratio * eu * eu, -ratio * eu * ew, 1.0 - ratio * ew * ew, -ratio * eu * pz,
            -ratio * ew * pz, mz * mz - ratio * pz * pz - minor)


@njit(cache=True, error_model="numpy", inline="always")
def _roots(a, b, c):
    """Real roots of a q² + 2 b q + c = 0 (a > 0), sorted: (low, high, True), or (0, 0, False) if none."""
    disc = b * b - a * c
    if disc < 0.0:
        return 0.0, 0.0, False
    t = -(b + math.copysign(math.sqrt(disc), b))
    if t == 0.0:
        return 0.0, 0.0, True
    first, second = t / a, c / t
    return min(first, second), max(first, second), True


@njit(cache=True, error_model="numpy", inline="always")
def _polish(frame, tau, u, w, swap, along_w):
    """A root of d = τ on the line through (u, w) along w (or u), refined by Newton's method on d itself.

    The conic's coefficients are taken about the foci's midpoint: with a focus far away its
    constant term is a difference of large numbers, and a root can be off by eps |q|² / |∇Q|,
    enough to move a slab's edge by more than the tolerance. d - τ has no such cancellation.
    """
    for _ in range(2):
        x, y = (w, u) if swap else (u, w)
        ds = math.sqrt((x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2)
        dk = math.sqrt((x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2)
        if along_w != swap:      # the derivative along y
            slope = (y - frame.source_y) / ds + (y - frame.sensor_y) / dk
        else:
            slope = (x - frame.source_x) / ds + (x - frame.sensor_x) / dk
        if slope == 0.0:
            break
        step = (ds + dk - tau) / slope
        # the closed form is off by rounding only: a larger step is a near-tangent line, left alone
        if not abs(step) <= 1e-6 * (tau + abs(u) + abs(w)):
            break
        if along_w:
            w -= step
        else:
            u -= step
        # Newton converges quadratically: after a step this small the next is below rounding
        if abs(step) <= 1e-14 * (tau + abs(u) + abs(w)):
            break
    return w if along_w else u


@njit(cache=True, error_model="numpy", inline="always")
def _inner_roots(frame, conic, tau, u, swap):
    """The w where the isochrone crosses the line at u: (low, high, True), or (0, 0, False) if it does not."""
    mu, mw, auu, auw, aww, bu, bw, c = conic
    qu = u - mu
    low, high, real = _roots(aww, auw * qu + bw, (auu * qu + 2.0 * bu) * qu + c)
    if not real:
        return 0.0, 0.0, False
    return (_polish(frame, tau, u, low + mw, swap, True), _polish(frame, tau, u, high + mw, swap, True), True)


@njit(cache=True, error_model="numpy", inline="always")
def _add_crossings(frame, conic, tau, w, lo, hi, swap, points, used):
    """Append the u in (lo, hi) where the isochrone crosses the line at w; returns the new count."""
    mu, mw, auu, auw, aww, bu, bw, c = conic
    qw = w - mw
    low, high, real = _roots(auu, auw * qw + bu, (aww * qw + 2.0 * bw) * qw + c)
    if real:
        for q in (low, high):
            u = _polish(frame, tau, q + mu, w, swap, False)
            if lo < u < hi:
                points[used] = u
                used += 1
    return used


@njit(cache=True, error_model="numpy", inline="always")
def _turns_inside(conic, u0, u1, w0, w1):
    """Whether the isochrone's tangent is along w at a point of the pixel (its inner roots merge there).

    Away from the pixel the merge only slows the rule's convergence near it, which G_3 against G_4
    detects.
    """
    mu, mw, auu, auw, aww, bu, bw, c = conic
    # (A_uw q_u + B_w)² - A_ww (A_uu q_u² + 2 B_u q_u + C) = 0, a quadratic in q_u
    a = auw * auw - aww * auu
    b = auw * bw - aww * bu
    e = bw * bw - aww * c
    low, high, real = _roots(-a, -b, -e)         # -a = A_uu A_ww - A_uw² > 0 for an ellipse
    if not real:
        return False
    for q in (low, high):
        if u0 < q + mu < u1 and w0 < mw - (auw * q + bw) / aww < w1:
            return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def _slab_pieces(frame, box, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, points):
    """Sorted u-breakpoints of the slab's region (the pixel's u-edges and the sides' crossings of its w-edges).

    Returns the count, or -1 when a side turns inside the pixel (the route does not apply).
    """
    u0, u1, w0, w1 = (box.y0, box.y1, box.x0, box.x1) if swap else (box.x0, box.x1, box.y0, box.y1)
    points[0] = u0
    used = 1
    for present, conic, tau in ((has_lower, lower, tau_a), (has_upper, upper, tau_b)):
        if present:
            if _turns_inside(conic, u0, u1, w0, w1):
                return -1
            used = _add_crossings(frame, conic, tau, w0, u0, u1, swap, points, used)
            used = _add_crossings(frame, conic, tau, w1, u0, u1, swap, points, used)
    points[used] = u1
    used += 1
    points[:used].sort()
    return used


@njit(cache=True, error_model="numpy", inline="always")
def _region_rows(frame, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, u, w0, w1):
    """The inner intervals of the slab's region on the line at u: up to two (w_a, w_b), as four numbers.

    {d <= τ_b} is one interval on the line (d is convex), {d >= τ_a} the complement of one.
    """
    below_low, below_high = -np.inf, np.inf          # {d <= τ_b}
    if has_upper:
        below_low, below_high, real = _inner_roots(frame, upper, tau_b, u, swap)
        if not real:
            return 0.0, 0.0, 0.0, 0.0
    hole_low, hole_high = np.inf, np.inf              # {d < τ_a}: removed
    if has_lower:
        low, high, real = _inner_roots(frame, lower, tau_a, u, swap)
        if real:
            hole_low, hole_high = low, high
    start, stop = max(w0, below_low), min(w1, below_high)
    return start, min(stop, hole_low), max(start, hole_high), stop


@njit(cache=True, error_model="numpy", inline="always")
def _row_rule(frame, kernel, swap, u, wu, wa, wb, order, values, noise, total, magnitude, rounding, judged, steps):
    """G_order in w over [wa, wb] of the row at u (weight ``wu``), added as :func:`_slab_rule` says."""
    scalar = 0.0
    scalar_magnitude = 0.0
    if not wb > wa:
        return scalar, scalar_magnitude
    cw = 0.5 * (wa + wb)
    hw = 0.5 * (wb - wa)
    for jw in range(order):
        w = cw + hw * GAUSS_NODES[order, jw]
        x, y = (w, u) if swap else (u, w)
        ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
        dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
        weight = wu * hw * GAUSS_WEIGHTS[order, jw] * attenuation_of_distances(frame, x, y, ds2, dk2)
        if steps:
            scalar += weight
            scalar_magnitude += abs(weight)
            continue
        kernel_values(kernel, math.sqrt(ds2) + math.sqrt(dk2), weight, values, noise)
        for i in range(kernel.run.bins):
            total[i] += values[i]
        if judged:
            for i in range(kernel.run.bins):
                magnitude[i] += abs(values[i])
                rounding[i] += noise[i]
    return scalar, scalar_magnitude


@njit(cache=True, error_model="numpy", inline="always")
def _slab_rule(frame, kernel, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, ua, ub, w0, w1, order,
               values, noise, total, magnitude, rounding, judged, steps):
    """G_order x G_order of a_k κ_n(d) over the slab's region for u in [ua, ub], added to total (per bin).

    ``judged``: also add ∫ |f| and f's rounding to magnitude and rounding (the rule that is kept;
    the rule that only judges it needs neither). ``steps``: the kernels are constant on the slab
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
        first_a, first_b, second_a, second_b = _region_rows(frame, lower, upper, tau_a, tau_b, has_lower, has_upper,
                                                            swap, u, w0, w1)
        for wa, wb in ((first_a, first_b), (second_a, second_b)):
            value, value_size = _row_rule(frame, kernel, swap, u, wu, wa, wb, order, values, noise, total, magnitude,
                                          rounding, judged, steps)
            scalar += value
            scalar_magnitude += value_size
    return scalar, scalar_magnitude


@njit(cache=True, error_model="numpy", inline="always")
def _cut_rule(frame, kernels, conic, tau, swap, ua, ub, w0, w1, order, values, noise, totals, magnitudes, roundings,
              judged, steps):
    """:func:`_slab_rule` of both slabs of a pixel that one isochrone d = τ cuts, at once.

    The slabs {d <= τ} and {d >= τ} have the same side, so their u-pieces and their inner limits
    at each node are the same roots, found once. ``kernels``, ``totals``, ``magnitudes`` and
    ``roundings`` are pairs (slab below, slab above); returns the steps' scalars of both,
    (∫ a, ∫ |a|) below, then above.
    """
    cu = 0.5 * (ua + ub)
    hu = 0.5 * (ub - ua)
    below, below_size, above, above_size = 0.0, 0.0, 0.0, 0.0
    for ju in range(order):
        u = cu + hu * GAUSS_NODES[order, ju]
        wu = hu * GAUSS_WEIGHTS[order, ju]
        low, high, real = _inner_roots(frame, conic, tau, u, swap)
        if not real:        # the row lies wholly above
            low, high = np.inf, np.inf
        rows = ((max(w0, low), min(w1, high)), (w0, min(w1, low)), (max(w0, high), w1))
        for row in range(3):
            slab = min(row, 1)
            value, value_size = _row_rule(frame, kernels[slab], swap, u, wu, rows[row][0], rows[row][1], order,
                                          values, noise, totals[slab], magnitudes[slab], roundings[slab], judged,
                                          steps)
            if slab == 0:
                below += value
                below_size += value_size
            else:
                above += value
                above_size += value_size
    return below, below_size, above, above_size


@njit(cache=True, error_model="numpy", inline="always")
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
    frame : analytic.isochrone.Frame
        The pair, in the rectangle's frame.
    box : analytic.isochrone.PixelBox
        The pixel, metres; clear of the feet and of x* (the caller's test).
    low, high : float
        The pixel's range of d, metres.
    terms : analytic.waveforms.WaveformTerms
        The waveform's pieces.
    axis : analytic.bins.TimeAxis
        The pair's bins.
    run : analytic.bins.BinRun
        The bins the pixel's light reaches.
    rtol : float
        Relative accuracy of each entry.
    out : float64[:]
        Zero on entry, at least ``run.bins`` long.
    work : analytic.quadrature.Workspace
        Of at least ``run.bins`` components.
    """
    # the u-axis along the isochrones: d changes faster across w
    cx, cy = 0.5 * (box.x0 + box.x1), 0.5 * (box.y0 + box.y1)
    ds = math.sqrt((cx - frame.source_x) ** 2 + (cy - frame.source_y) ** 2 + frame.source_height ** 2)
    dk = math.sqrt((cx - frame.sensor_x) ** 2 + (cy - frame.sensor_y) ** 2 + frame.sensor_height ** 2)
    gx = (cx - frame.source_x) / ds + (cx - frame.sensor_x) / dk
    gy = (cy - frame.source_y) / ds + (cy - frame.sensor_y) / dk
    swap = abs(gx) > abs(gy)
    w0, w1 = (box.x0, box.x1) if swap else (box.y0, box.y1)
    kinks = 0
    for i in range(terms.starts.size):
        if terms.kinks[i]:
            kinks += 1
    taus = np.empty(2 + kinks * (run.bins + 1))
    slabs = _slab_kinks(low, high, terms, axis, run, taus)
    points = np.empty(10)
    steps = terms.degree == 0
    low_order, magnitude, rounding = work.lower, work.magnitude, work.rounding
    for i in range(run.bins):
        low_order[i] = 0.0
        magnitude[i] = 0.0
        rounding[i] = 0.0
    if slabs == 3:      # one isochrone cuts the pixel: its two slabs share their side
        tau = taus[1]
        below, below_offset = _slab_kernel(terms, axis, run, low, tau)
        above, above_offset = _slab_kernel(terms, axis, run, tau, high)
        conic = _conic(frame, tau, swap)
        if conic[2] == 0.0:
            return _discard(out, run.bins)
        pieces = _slab_pieces(frame, box, conic, conic, tau, tau, True, False, swap, points)
        if pieces < 0:
            return _discard(out, run.bins)
        kernels = (below, above)
        sums = np.zeros(6)      # ∫ a_k below and above, by the kept and the judging rule, and ∫ |a_k| (steps)
        for piece in range(pieces - 1):
            ua, ub = points[piece], points[piece + 1]
            if not ub > ua:
                continue
            value, value_size, other, other_size = _cut_rule(
                frame, kernels, conic, tau, swap, ua, ub, w0, w1, HIGH_ORDER, work.values, work.noise,
                (out[below_offset:], out[above_offset:]), (magnitude[below_offset:], magnitude[above_offset:]),
                (rounding[below_offset:], rounding[above_offset:]), True, steps)
            sums[0] += value
            sums[1] += value_size
            sums[2] += other
            sums[3] += other_size
            value, _, other, _ = _cut_rule(
                frame, kernels, conic, tau, swap, ua, ub, w0, w1, LOW_ORDER, work.values, work.noise,
                (low_order[below_offset:], low_order[above_offset:]), (magnitude, magnitude), (rounding, rounding),
                False, steps)
            sums[4] += value
            sums[5] += other
        if steps:
            _add_steps(below, 0.5 * (low + tau), sums[0], sums[4], sums[1], below_offset, out, low_order, magnitude,
                       rounding, work)
            _add_steps(above, 0.5 * (tau + high), sums[2], sums[5], sums[3], above_offset, out, low_order,
                       magnitude, rounding, work)
        return _judged(out, low_order, magnitude, rounding, rtol, run.bins)
    for slab in range(slabs - 1):
        tau_a, tau_b = taus[slab], taus[slab + 1]
        if not tau_b > tau_a:
            continue
        kernel, offset = _slab_kernel(terms, axis, run, tau_a, tau_b)
        if kernel.run.bins <= 0:
            continue
        has_lower, has_upper = slab > 0, slab < slabs - 2
        lower, upper = _conic(frame, tau_a, swap), _conic(frame, tau_b, swap)
        if (has_lower and lower[2] == 0.0) or (has_upper and upper[2] == 0.0):
            return _discard(out, run.bins)
        pieces = _slab_pieces(frame, box, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, points)
        if pieces < 0:
            return _discard(out, run.bins)
        high_sum, low_sum, size = 0.0, 0.0, 0.0       # ∫ a_k over the slab (step-function S)
        for piece in range(pieces - 1):
            ua, ub = points[piece], points[piece + 1]
            if not ub > ua:
                continue
            value, value_size = _slab_rule(frame, kernel, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, ua,
                                           ub, w0, w1, HIGH_ORDER, work.values, work.noise, out[offset:],
                                           magnitude[offset:], rounding[offset:], True, steps)
            high_sum += value
            size += value_size
            low_sum += _slab_rule(frame, kernel, lower, upper, tau_a, tau_b, has_lower, has_upper, swap, ua, ub, w0,
                                  w1, LOW_ORDER, work.values, work.noise, low_order[offset:], magnitude, rounding,
                                  False, steps)[0]
        if steps:
            _add_steps(kernel, 0.5 * (tau_a + tau_b), high_sum, low_sum, size, offset, out, low_order, magnitude,
                       rounding, work)
    return _judged(out, low_order, magnitude, rounding, rtol, run.bins)


@njit(cache=True, error_model="numpy", inline="always")
def _slab_kernel(terms, axis, run, tau_a, tau_b):
    """(kernels, offset): the bins light leaving the slab [τ_a, τ_b] reaches (one spare each side), and where they
    start in the run."""
    lo_bin = max(run.first, bin_of(tau_a + terms.lead, axis) - 1)
    hi_bin = min(run.first + run.bins - 1, bin_of(tau_b + terms.duration, axis) + 1)
    return KernelProblem(terms, axis, BinRun(lo_bin, max(hi_bin - lo_bin + 1, 0))), lo_bin - run.first


@njit(cache=True, error_model="numpy", inline="always")
def _add_steps(kernel, tau, high_sum, low_sum, size, offset, out, low_order, magnitude, rounding, work):
    """A step-function S's slab: κ_n is constant there, its value at τ (the middle) times ∫ a_k by each rule."""
    kernel_values(kernel, tau, 1.0, work.values, work.noise)
    for i in range(kernel.run.bins):
        out[offset + i] += work.values[i] * high_sum
        low_order[offset + i] += work.values[i] * low_sum
        magnitude[offset + i] += abs(work.values[i]) * size
        rounding[offset + i] += work.noise[i] * size


@njit(cache=True, error_model="numpy", inline="always")
def _judged(out, low_order, magnitude, rounding, rtol, bins):
    """Whether every entry's G_4 x G_4 agrees with G_3 x G_3 within the tolerance (else out zeroed, False)."""
    for i in range(bins):
        if not abs(out[i] - low_order[i]) <= rtol * abs(out[i]) + 4.0 * (rounding[i] + ROUNDING * magnitude[i]):
            return _discard(out, bins)
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _discard(out, bins):
    """Zero what a route that did not serve added; returns False."""
    for i in range(bins):
        out[i] = 0.0
    return False
