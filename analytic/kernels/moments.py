"""Entries through moments: a pixel's moments of path length, and the entries they give (compiled).

Over a range of path lengths that no kink of the waveform crosses, every
bin kernel is a short Taylor polynomial in τ - c (:mod:`analytic.kernels.taylor`),
so a pixel's entries for every bin it reaches are Σ_j c_{n,j} m_j with the
*moments* m_j = ∫_pixel a(x) (d(x) - c)^j dx: a few scalars, one quadrature
for all the bins. This module computes a whole pixel's moments (the smooth
route of :mod:`analytic.operator.system`) and turns moments into entries; the cut
route's τ-pieces use the same :func:`bin_moments` with moments of their
own (:mod:`analytic.kernels`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from .attenuation import attenuation_of_distances
from .cache import njit
from .quadrature import GAUSS_NODES, GAUSS_WEIGHTS, TENSOR_LEVELS, implements, time_weight
from .taylor import cancels, entries_from_moments, kernel_taylor
from .pieces import ROUNDING

__all__ = ["MomentProblem", "moment_weight", "pixel_moments", "pixel_integral", "smooth_by_moments", "bin_moments"]


class MomentProblem(NamedTuple):
    """Powers (τ - centre)^j, j < count, of the path length: the moments' weights (:mod:`analytic.kernels.taylor`)."""

    centre: float
    count: int


@implements(time_weight, MomentProblem)
@njit(cache=True, error_model="numpy", forceinline=True)
def moment_weight(problem, tau, scale, values, noise):
    """values[j] = scale (τ - centre)^j, j < count: the moments' weights (their rounding is negligible)."""
    offset = tau - problem.centre
    power = scale
    for j in range(problem.count):
        values[j] = power
        noise[j] = 0.0
        power *= offset


@njit(cache=True, error_model="numpy", forceinline=True)
def _node(frame, cx, hx, cy, hy, order, jx, jy):
    """(weight x a_k, d_s², d_k²) at node (jx, jy) of G_order x G_order on the box centre ± half (metres)."""
    x = cx + hx * GAUSS_NODES[order, jx]
    y = cy + hy * GAUSS_NODES[order, jy]
    ds2 = (x - frame.source_x) ** 2 + frame.source_height ** 2 + (y - frame.source_y) ** 2
    dk2 = (x - frame.sensor_x) ** 2 + frame.sensor_height ** 2 + (y - frame.sensor_y) ** 2
    weight = hx * GAUSS_WEIGHTS[order, jx] * hy * GAUSS_WEIGHTS[order, jy]
    return weight * attenuation_of_distances(frame, x, y, ds2, dk2), ds2, dk2


@njit(cache=True, error_model="numpy", forceinline=True)
def pixel_moments(frame, box, centre, count, rtol, moments):
    """m_j = ∫_pixel a(x) (d(x) - centre)^j dx, j < count, by the tensor Gauss ladder; True when converged.

    The rule and its judgement are :func:`analytic.kernels.quadrature.tensor_integrate`'s (rung n is
    G_n x G_n, its error the next rung's difference or the previous rungs' trend, G_1 trusted
    for an integrand analytic around the pixel), written for the few scalar moments of one
    pixel: a generic vector of components would cost more than the arithmetic itself.
    ``moments`` is a Workspace of at least ``count`` components; the result is in its
    ``result``.
    """
    lower, upper, magnitude = moments.lower, moments.upper, moments.magnitude
    previous, before, result = moments.previous, moments.before, moments.result
    cx = 0.5 * (box.x0 + box.x1)
    hx = 0.5 * (box.x1 - box.x0)
    cy = 0.5 * (box.y0 + box.y1)
    hy = 0.5 * (box.y1 - box.y0)
    for order in range(1, TENSOR_LEVELS + 1):
        target = lower if order == 1 else upper
        for j in range(count):
            target[j] = 0.0
            magnitude[j] = 0.0
        for jx in range(order):
            for jy in range(order):
                value, ds2, dk2 = _node(frame, cx, hx, cy, hy, order, jx, jy)
                offset = math.sqrt(ds2) + math.sqrt(dk2) - centre
                for j in range(count):
                    target[j] += value
                    magnitude[j] += abs(value)
                    value *= offset
        if order == 1:
            continue
        rung = order - 1            # is G_rung (in lower) within the tolerance, by G_{rung+1} (in upper)?
        accepted = True
        for j in range(count):
            delta = abs(lower[j] - upper[j])
            estimate = delta
            if rung >= 2:
                estimate = max(delta, previous[j] * min(1.0, previous[j] / before[j]) if before[j] > 0.0
                               else previous[j])
            if not estimate <= max(rtol, ROUNDING) * magnitude[j]:
                accepted = False
                break
        if accepted:
            for j in range(count):
                result[j] = lower[j]
            return True
        for j in range(count):
            before[j] = magnitude[j] if rung == 1 else previous[j]
            previous[j] = abs(lower[j] - upper[j])
            lower[j] = upper[j]
    return False


@njit(cache=True, error_model="numpy")
def pixel_integral(frame, box, rtol):
    """(m_0, converged): :func:`pixel_moments` of one moment, ∫_pixel a(x) dx, in scalars.

    The same nodes, sums in the same order and the same judgement as ``pixel_moments(..., count=1)``,
    so the same value; without the workspace's arrays, whose reference counts cost more than the
    few nodes a small pixel needs (a regular call: small enough for LLVM to inline).
    """
    cx = 0.5 * (box.x0 + box.x1)
    hx = 0.5 * (box.x1 - box.x0)
    cy = 0.5 * (box.y0 + box.y1)
    hy = 0.5 * (box.y1 - box.y0)
    lower = 0.0
    previous = 0.0
    before = 0.0
    for order in range(1, TENSOR_LEVELS + 1):
        total = 0.0
        magnitude = 0.0
        for jx in range(order):
            for jy in range(order):
                value = _node(frame, cx, hx, cy, hy, order, jx, jy)[0]
                total += value
                magnitude += abs(value)
        if order == 1:
            lower = total
            continue
        rung = order - 1            # is G_rung (lower) within the tolerance, by G_{rung+1} (total)?
        delta = abs(lower - total)
        estimate = delta
        if rung >= 2:
            estimate = max(delta, previous * min(1.0, previous / before) if before > 0.0 else previous)
        if estimate <= max(rtol, ROUNDING) * magnitude:
            return lower, True
        before = magnitude if rung == 1 else previous
        previous = delta
        lower = total
    return 0.0, False


@njit(cache=True, error_model="numpy", forceinline=True)
def smooth_by_moments(frame, box, low, high, terms, axis, run, rtol, out, scratch):
    """Add a smooth pixel's entries to out[:run.bins] through its moments; False (nothing added) when it cannot.

    ``low``, ``high``: a range of path length holding the pixel's (the exact one, or a bound
    around it: the Taylor remainders and the moments' magnitudes are then bounded over the
    wider range, which only costs terms), with no kernel breakpoint inside. It does not serve
    when a kernel needs more than MAX_TERMS Taylor terms over the range, when the moments'
    tensor rule does not converge, or when an entry's terms cancel.
    """
    centre = 0.5 * (low + high)
    half = 0.5 * (high - low)
    count = kernel_taylor(terms, axis, run, centre, half, rtol, scratch.coefficients, scratch.lower_edge,
                          scratch.upper_edge)
    if count == 0:
        return False
    if not pixel_moments(frame, box, centre, count, rtol, scratch.moments):
        return False
    return bin_moments(scratch, count, run.bins, half, out)


@njit(cache=True, error_model="numpy", forceinline=True)
def bin_moments(scratch, count, bins, half, out):
    """Add Σ_j c_{n,j} m_j to out[:bins], unless an entry's terms cancel (then False and nothing added).

    The moments are in ``scratch.moments.result``, the Taylor coefficients in
    ``scratch.coefficients``, taken about the centre of a range of half-width ``half``. The
    response is never negative, so M_j = ∫ |τ - c|^j G <= half^j m_0 bounds each moment's magnitude.
    """
    moments = scratch.moments.result
    magnitudes = scratch.moments.floor      # free here: the quadrature is over
    power = 1.0
    for j in range(count):
        magnitudes[j] = power * abs(moments[0])
        power *= half
    if cancels(scratch.coefficients, count, bins, moments, magnitudes):
        return False
    entries_from_moments(scratch.coefficients, count, bins, moments, out)
    return True
