"""Quadrature: one adaptive driver and its rules (compiled).

Every integral of the model is built from Gauss–Legendre rules G_n (n nodes,
exact for polynomials of degree 2n - 1) taken as a ladder n = 1, 2, 3, ...:
the difference |G_n - G_{n+1}| estimates the error of G_n, and the first G_n
whose estimate meets the tolerance is the value kept (:func:`judge` also
asks the previous rungs' rate of convergence, so that two rules agreeing by
accident are not believed). Keeping G_n (not the better G_{n+1}) makes the
estimate describe the value returned, so the achieved error follows the
requested tolerance instead of lying orders of magnitude below it: a looser
tolerance stops earlier and is faster.

- :func:`adapt` — the one adaptive driver: bisection of [lo, hi], depth
  first, with a *rule* applied to each piece (a rule climbs its ladder and
  says whether it converged).
- :func:`ladder_rule` — the 1-D ladder of an integrand f(t); with
  :func:`adapt` it is :func:`integrate`.
- :func:`tensor_integrate` — the tensor ladder G_n x G_n on a rectangle for a
  smooth f(x, y), without subdivision: it reports failure instead, and the
  caller falls back to the exact cut quadrature.
- :func:`rule` — the rule :func:`adapt` climbs for a problem: its record's
  own (:func:`rule_for`; the isochrone's tensor rule of :mod:`.arcs`) or
  :func:`ladder_rule`.

The isochrone's integrals (its arcs in a pixel, G(τ), the (τ, φ) tensor
rule) are :mod:`.arcs`.

Integrands are compiled functions ``f(problem, t, values, noise)`` (or
``(problem, x, y, values, noise)``) that write a vector f (one component
per time bin) into ``values[:size]`` and a bound on its rounding into
``noise[:size]``; ``problem`` is a record (a NamedTuple) of what they need,
and its type chooses the integrand: each module registers its own with
:func:`implements` for :func:`integrand`, :func:`surface_integrand` or
:func:`time_weight`, and the drivers call those names. The choice is made
when a driver is compiled for a problem type, so no compiled function is
passed as a value (which Numba could neither cache nor compile once). Acceptance is per
component, relative to ∫ |f| (QUADPACK's ``resabs``), so the relative error
of each entry is bounded even where a waveform's undershoot makes f change
sign; a component whose ∫ |f| is below its own integrated rounding (a time
kernel that is the difference of two nearly equal values of S) is held to
that rounding instead, which no rung could beat.

Compiled with ``error_model="numpy"`` (a division by zero gives inf or NaN
instead of raising).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.extending import overload

from .cache import njit

__all__ = ["Workspace", "make_workspace", "adapt", "ladder_rule", "integrate", "integrand", "surface_integrand",
           "time_weight", "implements", "rule", "rule_for", "tensor_integrate", "judge", "GAUSS_NODES", "GAUSS_WEIGHTS",
           "LADDER_LEVELS", "TENSOR_LEVELS", "MAX_PIECES"]

#: Largest Gauss–Legendre order tabulated.
MAX_ORDER = 12
#: Highest rung of a rule before :func:`adapt` halves the piece (G_6: 21 nodes in 1-D).
LADDER_LEVELS = 6
#: Highest rung of :func:`tensor_integrate` before the caller falls back (G_7 x G_7).
TENSOR_LEVELS = 7

_STACK = 96                 # pieces waiting at once; depth-first bisection needs ~ depth + 1
_MIN_WIDTH = 1e-13          # pieces narrower than this fraction of [lo, hi] are kept as they are
#: Rule applications per integral of :func:`integrate` before the rest is kept as it is.
MAX_PIECES = 3000


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
    noise: np.ndarray       # bound on the rounding of f at that node
    lower: np.ndarray       # G_n of the current piece
    upper: np.ndarray       # G_{n+1}
    magnitude: np.ndarray   # ∫ |f| by G_{n+1}
    rounding: np.ndarray    # ∫ (rounding of f) by G_{n+1}
    previous: np.ndarray    # δ_{n-1} = |G_{n-1} - G_n|
    before: np.ndarray      # δ_{n-2}
    floor: np.ndarray       # absolute error each component may have on the current piece
    density: np.ndarray     # ∫ |f| per unit length over the whole interval (adapt's first look)
    result: np.ndarray      # an accumulator for the caller (integrate never touches it)
    failures: np.ndarray    # int64[1]: pieces kept without meeting the tolerance


@njit(cache=True, error_model="numpy")
def make_workspace(size):
    """A :class:`Workspace` for integrands of up to ``size`` components."""
    size = max(size, 1)
    return Workspace(np.empty((_STACK, 2)), np.empty(size), np.zeros(size), np.empty(size), np.empty(size),
                     np.empty(size), np.zeros(size), np.empty(size), np.empty(size), np.zeros(size),
                     np.zeros(size), np.zeros(size), np.zeros(1, dtype=np.int64))


# -- integrands, chosen by their problem's type ---------------------------------------------------------------


def integrand(problem, t, values, noise):
    """f(t) of a 1-D integral into ``values[:size]``, its rounding into ``noise[:size]`` (compiled code only).

    The implementation is the one registered for ``problem``'s record type (:func:`implements`).
    """
    raise TypeError("integrand is called from compiled code, with a registered problem record")


def surface_integrand(problem, x, y, values, noise):
    """f(x, y) of a 2-D integral over a rectangle, as :func:`integrand` (compiled code only)."""
    raise TypeError("surface_integrand is called from compiled code, with a registered problem record")


def time_weight(problem, tau, scale, values, noise):
    """scale w(τ): a cut piece's time weight (the bins' kernels, or the powers of τ), as :func:`integrand`."""
    raise TypeError("time_weight is called from compiled code, with a registered problem record")


def implements(stub, record):
    """Decorator: the compiled function is ``stub``'s implementation for problems of type ``record``.

    The dispatch is inlined where a driver calls the stub (Numba's overload, resolved when the driver is
    compiled for that problem type), so it adds no compiled function of its own.

    Parameters
    ----------
    stub : {integrand, surface_integrand, time_weight}
    record : type
        A NamedTuple class; its instances are the first argument.
    """
    def register(kernel):
        def chosen(problem):
            return getattr(problem, "instance_class", None) is record

        if stub is integrand:
            @overload(integrand, jit_options={"error_model": "numpy"}, inline="always")
            def _typed(problem, t, values, noise):
                if chosen(problem):
                    return lambda problem, t, values, noise: kernel(problem, t, values, noise)
                return None
        elif stub is surface_integrand:
            @overload(surface_integrand, jit_options={"error_model": "numpy"}, inline="always")
            def _typed(problem, x, y, values, noise):
                if chosen(problem):
                    return lambda problem, x, y, values, noise: kernel(problem, x, y, values, noise)
                return None
        elif stub is time_weight:
            @overload(time_weight, jit_options={"error_model": "numpy"}, inline="always")
            def _typed(problem, tau, scale, values, noise):
                if chosen(problem):
                    return lambda problem, tau, scale, values, noise: kernel(problem, tau, scale, values, noise)
                return None
        else:
            raise ValueError(f"implements: {stub!r} is not one of integrand, surface_integrand, time_weight")
        return kernel
    return register


@njit(cache=True, error_model="numpy", inline="always")
def _gauss(problem, lo, hi, order, size, work, out):
    """G_order of f on [lo, hi] into out[:size]; of |f| and of f's rounding into work.magnitude, work.rounding."""
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    for i in range(size):
        out[i] = 0.0
        work.magnitude[i] = 0.0
        work.rounding[i] = 0.0
    for j in range(order):
        integrand(problem, centre + half * GAUSS_NODES[order, j], work.values, work.noise)
        weight = half * GAUSS_WEIGHTS[order, j]
        for i in range(size):
            out[i] += weight * work.values[i]
            work.magnitude[i] += weight * abs(work.values[i])
            work.rounding[i] += weight * work.noise[i]


@njit(cache=True, error_model="numpy")
def judge(work, size, rtol, rung, first):
    """With G_rung in work.lower and G_{rung+1} in work.upper: is G_rung within the tolerance?

    E_n = max(δ_n, δ_{n-1} min(1, δ_{n-1} / δ_{n-2})), δ_n = |G_n - G_{n+1}|,
    δ_0 = ∫ |f|: the last difference, or the error the previous rungs' rate
    of convergence predicts if that is larger (two rules can agree by
    accident; a trend of three rarely does). E_1 = δ_1, trusted only where
    the integrand is known analytic around the domain (``first`` = 1);
    ``first`` = 2 refuses G_1 outright. The bound is rtol ∫|f| over the
    piece, or ``work.floor``, or the integrated rounding of f, whichever is
    largest. When G_rung is refused, the
    history moves one rung up and work.lower takes G_{rung+1}.
    """
    accepted = rung >= first
    for i in range(size if accepted else 0):
        delta = abs(work.lower[i] - work.upper[i])
        estimate = delta
        if rung >= 2:
            previous = work.previous[i]
            estimate = max(delta, previous * min(1.0, previous / work.before[i]) if work.before[i] > 0.0
                           else previous)
        if not estimate <= max(rtol * work.magnitude[i], work.floor[i], work.rounding[i]):
            accepted = False
            break
    if accepted:
        return True
    for i in range(size):
        work.before[i] = work.magnitude[i] if rung == 1 else work.previous[i]
        work.previous[i] = abs(work.lower[i] - work.upper[i])
        work.lower[i] = work.upper[i]
    return False


@njit(cache=True, error_model="numpy")
def ladder_rule(problem, lo, hi, rtol, size, work):
    """The 1-D ladder G_1, G_2, ... of an integrand on [lo, hi] (a rule for :func:`adapt`).

    Returns True when a rung converged, with it in ``work.lower``; else
    ``work.lower`` holds the highest rung.
    """
    _gauss(problem, lo, hi, 1, size, work, work.lower)
    for order in range(2, LADDER_LEVELS + 1):
        _gauss(problem, lo, hi, order, size, work, work.upper)
        if judge(work, size, rtol, order - 1, 2):
            return True
    return False


@njit(cache=True, error_model="numpy")
def adapt(problem, lo, hi, rtol, size, total, work, resolution, max_pieces):
    """Add ∫_lo^hi of a vector integrand to total[:size] by adaptive bisection.

    Parameters
    ----------
    problem : tuple
        The integrand's record; its type chooses the rule that climbs a ladder
        on each piece (:func:`rule`: :func:`isochrone_rule` for an
        :class:`IsochronePiece`, :func:`ladder_rule` of its :func:`integrand`
        otherwise).
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
    max_pieces : int
        Rule applications before the remaining pieces are kept as they are
        (each counted as a failure).

    Returns
    -------
    int
        Pieces kept without meeting the tolerance (0 when converged); also
        added to ``work.failures[0]``.

    Notes
    -----
    A piece is accepted when its error estimate is within rtol of its own
    ∫ |f|, or of its share (by length) of the whole interval's ∫ |f| as
    first estimated: the total error stays within ~2 rtol ∫ |f| over
    [lo, hi], and pieces whose contribution is negligible (or rounding
    noise) are not refined for nothing. Depth first; a piece narrower than
    1e-13 of [lo, hi], or the 3000th, is kept at its best rung and counted
    as a failure, unless it is below ``resolution`` or only a few roundings
    wide (its nodes coincide).
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
        # a piece may hold its share (by length) of the whole interval's error budget
        for i in range(size):
            work.floor[i] = 0.0 if applied == 1 else rtol * work.density[i] * (right - left)
        converged = rule(problem, left, right, rtol, size, work)
        if applied == 1:
            for i in range(size):
                work.density[i] = work.magnitude[i] / (hi - lo)
        unresolvable = (right - left) <= max(resolution, 64.0 * 2.2e-16 * max(abs(left), abs(right)))
        stop = ((right - left) <= _MIN_WIDTH * (hi - lo) or waiting + 2 > _STACK
                or applied >= max_pieces)
        if converged or unresolvable or stop:
            if not (converged or unresolvable):
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
def integrate(problem, lo, hi, rtol, size, total, work, resolution):
    """Add ∫_lo^hi f(t) dt to total[:size]: :func:`adapt` with :func:`ladder_rule` of ``problem``'s :func:`integrand`.

    The arguments and the return value are :func:`adapt`'s.
    """
    return adapt(problem, lo, hi, rtol, size, total, work, resolution, MAX_PIECES)


@njit(cache=True, error_model="numpy")
def tensor_integrate(problem, box, rtol, size, total, work):
    """Add ∫∫ f(x, y) over [x0, x1] x [y0, y1] to total[:size] by the tensor Gauss ladder.

    Rungs G_n x G_n, n = 1 ... :data:`TENSOR_LEVELS`, each checked against the
    next like :func:`integrate`'s, without subdivision.

    Parameters
    ----------
    problem : tuple
        The record of a registered :func:`surface_integrand`.
    box : analytic.kernels.isochrone.PixelBox
        The rectangle, metres.
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
    cx = 0.5 * (box.x0 + box.x1)
    hx = 0.5 * (box.x1 - box.x0)
    cy = 0.5 * (box.y0 + box.y1)
    hy = 0.5 * (box.y1 - box.y0)
    # the workspace's arrays held in locals: each attribute read of a record of arrays costs a reference count
    values, noise, magnitude, rounding, floor = work.values, work.noise, work.magnitude, work.rounding, work.floor
    for i in range(size):
        floor[i] = 0.0
    for order in range(1, TENSOR_LEVELS + 1):
        target = work.lower if order == 1 else work.upper
        for i in range(size):
            target[i] = 0.0
            magnitude[i] = 0.0
            rounding[i] = 0.0
        for jx in range(order):
            x = cx + hx * GAUSS_NODES[order, jx]
            wx = hx * GAUSS_WEIGHTS[order, jx]
            for jy in range(order):
                surface_integrand(problem, x, cy + hy * GAUSS_NODES[order, jy], values, noise)
                weight = wx * hy * GAUSS_WEIGHTS[order, jy]
                for i in range(size):
                    target[i] += weight * values[i]
                    magnitude[i] += weight * abs(values[i])
                    rounding[i] += weight * noise[i]
        if order > 1 and judge(work, size, rtol, order - 1, 1):
            lower = work.lower
            for i in range(size):
                total[i] += lower[i]
            return True
    return False


def rule(problem, lo, hi, rtol, size, work):
    """The rule :func:`adapt` climbs on [lo, hi] for ``problem`` (compiled code only)."""
    raise TypeError("rule is called from compiled code")


#: Record types with a rule of their own (:func:`rule_for`); every other problem climbs :func:`ladder_rule`.
_OWN_RULES = {}


def rule_for(record):
    """Decorator: the compiled function is the rule :func:`adapt` climbs for problems of type ``record``.

    Parameters
    ----------
    record : type
        A NamedTuple class (:class:`analytic.kernels.arcs.IsochronePiece`).
    """
    def register(kernel):
        _OWN_RULES[record] = kernel
        return kernel
    return register


@overload(rule, jit_options={"error_model": "numpy"}, inline="always")
def _rule_of(problem, lo, hi, rtol, size, work):
    own = _OWN_RULES.get(getattr(problem, "instance_class", None))
    if own is not None:
        return lambda problem, lo, hi, rtol, size, work: own(problem, lo, hi, rtol, size, work)
    return lambda problem, lo, hi, rtol, size, work: ladder_rule(problem, lo, hi, rtol, size, work)
