"""Quadrature: one adaptive driver, one tensor rule, and the isochrone's arc integral (compiled).

Every integral of the model is built from Gauss–Legendre rules G_n (n nodes,
exact for polynomials of degree 2n - 1) taken as a ladder n = 1, 2, 3, ...:
the difference |G_n - G_{n+1}| estimates the error of G_n, and the first G_n
whose estimate meets the tolerance is the value kept. Keeping G_n (not the
better G_{n+1}) makes the estimate describe the value returned, so the
achieved error follows the requested tolerance instead of lying orders of
magnitude below it: a looser tolerance stops earlier and is faster.

- :func:`integrate` — adaptive bisection of [lo, hi] for a vector-valued
  integrand f(t) (one component per time bin): each piece climbs the ladder
  up to :data:`LADDER_LEVELS`; a piece that does not converge is halved.
- :func:`tensor_integrate` — the tensor ladder G_n x G_n on a rectangle for a
  smooth vector-valued f(x, y), without subdivision: it reports failure
  instead, and the caller falls back to an exact cut quadrature.
- :func:`pixel_isochrone_integral` — G(τ) = ∫_{isochrone ∩ pixel} a J dφ, the
  pixel's own impulse response at path length τ, with :func:`integrate` on
  each arc between the isochrone's crossings of the pixel's edges.

Integrands are compiled functions ``integrand(problem, t, values)`` (or
``(problem, x, y, values)``) that write f into ``values[:size]``; ``problem``
is any tuple they need. Acceptance is per component, relative to
∫ |f| (QUADPACK's ``resabs``), so the relative error of each entry is
bounded even where a waveform's undershoot makes f change sign.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .attenuation import attenuation_at
from .isochrone import jacobian, point_on_ellipse, rectangle_crossings

__all__ = ["Workspace", "make_workspace", "integrate", "tensor_integrate", "arc_integrand",
           "pixel_isochrone_integral", "GAUSS_NODES", "GAUSS_WEIGHTS", "LADDER_LEVELS", "TENSOR_LEVELS"]

#: Largest Gauss–Legendre order tabulated.
MAX_ORDER = 12
#: Highest rung of the 1-D ladder before a piece is halved (G_1 ... G_6, 21 nodes).
LADDER_LEVELS = 6
#: Highest rung of the tensor ladder before the caller falls back (G_7 x G_7).
TENSOR_LEVELS = 7

_STACK = 96                 # pieces waiting at once; depth-first bisection needs ~ depth + 1
_MIN_WIDTH = 1e-13          # pieces narrower than this fraction of [lo, hi] are kept as they are
_MAX_PIECES = 3000          # rule applications per integral before the rest is kept as is


def _gauss_table():
    nodes = np.zeros((MAX_ORDER + 1, MAX_ORDER))
    weights = np.zeros((MAX_ORDER + 1, MAX_ORDER))
    for n in range(1, MAX_ORDER + 1):
        x, w = np.polynomial.legendre.leggauss(n)
        nodes[n, :n] = x
        weights[n, :n] = w
    return nodes, weights


#: Gauss–Legendre rules on [-1, 1]: row n holds the n nodes (and weights) of G_n.
GAUSS_NODES, GAUSS_WEIGHTS = _gauss_table()


class Workspace(NamedTuple):
    """Scratch arrays of one integration level (compiled code cannot allocate cheaply)."""

    stack: np.ndarray       # (_STACK, 2) pieces waiting
    values: np.ndarray      # f at one node
    lower: np.ndarray       # G_n of the current piece
    upper: np.ndarray       # G_{n+1}
    magnitude: np.ndarray   # ∫ |f| by G_{n+1}
    previous: np.ndarray    # δ_{n-1} = |G_{n-1} - G_n|
    before: np.ndarray      # δ_{n-2}
    result: np.ndarray      # an accumulator for the caller (integrate never touches it)
    failures: np.ndarray    # int64[1]: pieces kept without meeting the tolerance


@njit(cache=True, error_model="numpy")
def make_workspace(size):
    """A :class:`Workspace` for integrands of up to ``size`` components."""
    size = max(size, 1)
    return Workspace(np.empty((_STACK, 2)), np.empty(size), np.empty(size), np.empty(size),
                     np.empty(size), np.empty(size), np.empty(size), np.zeros(size),
                     np.zeros(1, dtype=np.int64))


@njit(cache=True, error_model="numpy", inline="always")
def _gauss(integrand, problem, lo, hi, order, size, work, out, magnitude):
    """G_order of f on [lo, hi] into out[:size], and of |f| into magnitude[:size]."""
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    values = work.values
    for i in range(size):
        out[i] = 0.0
        magnitude[i] = 0.0
    for j in range(order):
        integrand(problem, centre + half * GAUSS_NODES[order, j], values)
        weight = half * GAUSS_WEIGHTS[order, j]
        for i in range(size):
            out[i] += weight * values[i]
            magnitude[i] += weight * abs(values[i])


@njit(cache=True, error_model="numpy")
def _judge(work, size, rtol, rung):
    """With G_rung in work.lower and G_{rung+1} in work.upper: is G_rung within the tolerance?

    E_n = max(δ_n, δ_{n-1} min(1, δ_{n-1} / δ_{n-2})), δ_n = |G_n - G_{n+1}|,
    δ_0 = ∫ |f|: the last difference, or the error the previous rungs' rate
    of convergence predicts if that is larger (two rules can agree by
    accident; a trend of three cannot). Needs rung >= 2. When G_rung is
    refused, the history moves one rung up and work.lower takes G_{rung+1}.
    """
    accepted = rung >= 2
    if accepted:
        for i in range(size):
            delta = abs(work.lower[i] - work.upper[i])
            previous = work.previous[i]
            trend = previous * min(1.0, previous / work.before[i]) if work.before[i] > 0.0 else previous
            if not max(delta, trend) <= rtol * work.magnitude[i]:
                accepted = False
                break
    if accepted:
        return True
    for i in range(size):
        work.before[i] = work.magnitude[i] if rung == 1 else work.previous[i]
        work.previous[i] = abs(work.lower[i] - work.upper[i])
        work.lower[i] = work.upper[i]
    return False


@njit(cache=True, error_model="numpy", inline="always")
def _ladder(integrand, problem, lo, hi, rtol, size, work):
    """Climb G_1, G_2, ... on [lo, hi]; True with the kept G_n in work.lower when converged.

    When it does not converge, work.lower holds the best (highest) rung.
    """
    _gauss(integrand, problem, lo, hi, 1, size, work, work.lower, work.magnitude)
    for order in range(2, LADDER_LEVELS + 1):
        _gauss(integrand, problem, lo, hi, order, size, work, work.upper, work.magnitude)
        if _judge(work, size, rtol, order - 1):
            return True
    return False


@njit(cache=True, error_model="numpy", inline="always")
def integrate(integrand, problem, lo, hi, rtol, size, total, work, resolution):
    """Add ∫_lo^hi f(t) dt to total[:size] by adaptive bisection with the Gauss ladder.

    Parameters
    ----------
    integrand : compiled function
        ``integrand(problem, t, values)`` writes f(t) into ``values[:size]``.
    problem : tuple
        Passed to ``integrand``.
    lo, hi : float
        Interval, in the integration variable's units.
    rtol : float
        Relative accuracy of each component (relative to ∫ |f|).
    size : int
        Number of components.
    total : float64[:]
        Accumulator.
    work : Workspace
        This level's scratch (a nested integral needs its own).
    resolution : float
        Pieces narrower than this are kept at their best rung without
        counting as failures: the integrand itself is not resolved finer
        (its inputs round), so refining them would only chase rounding.

    Returns
    -------
    int
        Pieces kept without meeting the tolerance (0 when converged); also
        added to ``work.failures[0]``.

    Notes
    -----
    Depth first; a piece narrower than 1e-13 of [lo, hi], or the 3000th,
    is kept at its best rung and counted as a failure, unless it is below
    ``resolution`` or only a few roundings wide (its nodes coincide).
    """
    failures = 0
    work.stack[0, 0] = lo
    work.stack[0, 1] = hi
    waiting = 1
    applied = 0
    while waiting > 0:
        waiting -= 1
        applied += 1
        left = work.stack[waiting, 0]
        right = work.stack[waiting, 1]
        if _ladder(integrand, problem, left, right, rtol, size, work):
            for i in range(size):
                total[i] += work.lower[i]
            continue
        unresolvable = (right - left) <= max(resolution, 64.0 * 2.2e-16 * max(abs(left), abs(right)))
        stop = ((right - left) <= _MIN_WIDTH * (hi - lo) or waiting + 2 > _STACK
                or applied >= _MAX_PIECES)
        if unresolvable or stop:
            if not unresolvable:
                failures += 1
            for i in range(size):
                total[i] += work.lower[i]
            continue
        middle = 0.5 * (left + right)
        work.stack[waiting, 0] = middle
        work.stack[waiting, 1] = right
        work.stack[waiting + 1, 0] = left
        work.stack[waiting + 1, 1] = middle
        waiting += 2
    work.failures[0] += failures
    return failures


@njit(cache=True, error_model="numpy", inline="always")
def tensor_integrate(integrand, problem, x0, x1, y0, y1, rtol, size, total, work):
    """Add ∫∫ f(x, y) over [x0, x1] x [y0, y1] to total[:size] by the tensor Gauss ladder.

    Rungs G_n x G_n, n = 1 ... :data:`TENSOR_LEVELS`, each checked against the
    next like :func:`integrate`'s, without subdivision.

    Parameters
    ----------
    integrand : compiled function
        ``integrand(problem, x, y, values)`` writes f(x, y) into ``values[:size]``.
    problem : tuple
    x0, x1, y0, y1 : float
        Rectangle, metres.
    rtol : float
        Relative accuracy of each component (relative to ∫∫ |f|).
    size : int
    total : float64[:]
        Accumulator, untouched unless converged.
    work : Workspace

    Returns
    -------
    bool
        Whether a rung met the tolerance (then total holds the result).
    """
    cx = 0.5 * (x0 + x1)
    hx = 0.5 * (x1 - x0)
    cy = 0.5 * (y0 + y1)
    hy = 0.5 * (y1 - y0)
    values = work.values
    for order in range(1, TENSOR_LEVELS + 1):
        target = work.lower if order == 1 else work.upper
        for i in range(size):
            target[i] = 0.0
            work.magnitude[i] = 0.0
        for jx in range(order):
            x = cx + hx * GAUSS_NODES[order, jx]
            wx = hx * GAUSS_WEIGHTS[order, jx]
            for jy in range(order):
                integrand(problem, x, cy + hy * GAUSS_NODES[order, jy], values)
                weight = wx * hy * GAUSS_WEIGHTS[order, jy]
                for i in range(size):
                    target[i] += weight * values[i]
                    work.magnitude[i] += weight * abs(values[i])
        if order > 1 and _judge(work, size, rtol, order - 1):
            for i in range(size):
                total[i] += work.lower[i]
            return True
    return False


@njit(cache=True, error_model="numpy")
def arc_integrand(problem, phi, values):
    """a(x(τ, φ)) J(τ, φ) on one isochrone (``problem`` = frame and its ellipse), m⁻³ per rad."""
    frame, cx, cy, a, b, j0, j1, j2 = problem
    x, y = point_on_ellipse(frame, cx, cy, a, b, phi)
    values[0] = attenuation_at(frame, x, y) * jacobian(j0, j1, j2, phi)


@njit(cache=True, error_model="numpy")
def pixel_isochrone_integral(frame, cx, cy, a, b, j0, j1, j2, x0, x1, y0, y1, rtol, angles, work):
    """G(τ) = ∫_{isochrone ∩ pixel} a J dφ: the pixel's impulse response at τ, m⁻³.

    The isochrone is cut at its crossings with the pixel's edge lines; each
    arc lies wholly inside or outside the pixel and is smooth, so the ladder
    converges on it geometrically.

    Parameters
    ----------
    frame : Frame
    cx, cy, a, b, j0, j1, j2 : float
        The isochrone, from :func:`analytic.isochrone.ellipse`.
    x0, x1, y0, y1 : float
        Pixel, metres.
    rtol : float
        Relative accuracy.
    angles : float64[8]
        Scratch for the crossings.
    work : Workspace
        Scratch of size >= 1 (its ``result`` too); failures are counted in
        ``work.failures``.

    Returns
    -------
    float
        Per metre of path length, m⁻³ (any positive attenuation works).
    """
    count = rectangle_crossings(frame, cx, cy, a, b, x0, x1, y0, y1, angles)
    problem = (frame, cx, cy, a, b, j0, j1, j2)
    total = work.result
    total[0] = 0.0
    two_pi = 2.0 * math.pi
    if count == 0:
        x, y = point_on_ellipse(frame, cx, cy, a, b, 0.0)
        if x0 <= x <= x1 and y0 <= y <= y1:
            integrate(arc_integrand, problem, 0.0, two_pi, rtol, 1, total, work, 0.0)
        return total[0]
    for i in range(count):
        lo = angles[i]
        hi = angles[i + 1] if i + 1 < count else angles[0] + two_pi
        if not hi - lo > 0.0:
            continue
        x, y = point_on_ellipse(frame, cx, cy, a, b, 0.5 * (lo + hi))
        if x0 <= x <= x1 and y0 <= y <= y1:
            integrate(arc_integrand, problem, lo, hi, rtol, 1, total, work, 0.0)
    return total[0]
