"""Quadrature: one adaptive driver, its rules, and the isochrone's integrals (compiled).

Every integral of the model is built from Gauss–Legendre rules G_n (n nodes,
exact for polynomials of degree 2n - 1) taken as a ladder n = 1, 2, 3, ...:
the difference |G_n - G_{n+1}| estimates the error of G_n, and the first G_n
whose estimate meets the tolerance is the value kept (:func:`_judge` also
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
- :func:`isochrone_rule` — the tensor ladder in (τ, φ) of ∫ w(τ) G(τ) dτ over
  part of a τ-piece, G(τ) = ∫_{isochrone ∩ pixel} a J dφ. Bisection in τ
  cannot refine φ, so its caller gives it a small ``max_pieces`` and falls
  back to adaptive φ-integrals (:func:`pixel_isochrone_integral`) when it
  fails.
- :func:`tensor_integrate` — the tensor ladder G_n x G_n on a rectangle for a
  smooth f(x, y), without subdivision: it reports failure instead, and the
  caller falls back to the exact cut quadrature.
- :func:`pixel_isochrone_integral` — G(τ) with :func:`integrate` on each arc
  between the isochrone's crossings of the pixel's edges.

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

import math
from typing import NamedTuple

import numpy as np
from numba.extending import overload

from .attenuation import attenuation_at
from .cache import njit
from .isochrone import Frame, Isochrone, PixelBox, ellipse, make_frame, point_on_ellipse, rectangle_crossings

__all__ = ["Workspace", "ArcProblem", "IsochronePiece", "make_workspace", "adapt", "ladder_rule", "integrate",
           "isochrone_rule", "integrand", "surface_integrand", "time_weight", "implements", "nested_integral_arguments",
           "tensor_integrate", "arc_value", "arc_integrand", "pixel_arcs", "pixel_isochrone_integral",
           "piece_map", "LINEAR", "ROOT_START", "ROOT_END", "ROOT_BOTH", "GAUSS_NODES", "GAUSS_WEIGHTS",
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
def _judge(work, size, rtol, rung, first):
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
        if _judge(work, size, rtol, order - 1, 2):
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
        if order > 1 and _judge(work, size, rtol, order - 1, 1):
            lower = work.lower
            for i in range(size):
                total[i] += lower[i]
            return True
    return False


class ArcProblem(NamedTuple):
    """What :func:`arc_integrand` needs: the pair and one of its isochrones."""

    frame: Frame
    curve: Isochrone


@njit(cache=True, error_model="numpy")
def arc_value(frame, curve, phi):
    """a(x(τ, φ)) J(τ, φ) on one isochrone, m⁻³ per rad (one cosine and sine for both factors)."""
    c = math.cos(phi)
    s = math.sin(phi)
    x = curve.centre_x + curve.a * c * frame.axis_x - curve.b * s * frame.axis_y
    y = curve.centre_y + curve.a * c * frame.axis_y + curve.b * s * frame.axis_x
    return attenuation_at(frame, x, y) * abs(curve.j0 * c + curve.j1 * c * c + curve.j2 * s * s)


@implements(integrand, ArcProblem)
@njit(cache=True, error_model="numpy")
def arc_integrand(problem, phi, values, noise):
    """:func:`arc_value` as an integrand of :func:`integrate` (``problem``: an :class:`ArcProblem`).

    A product of well-conditioned factors: its rounding is negligible (0).
    """
    values[0] = arc_value(problem.frame, problem.curve, phi)
    noise[0] = 0.0


@njit(cache=True, error_model="numpy")
def pixel_arcs(frame, curve, box, angles, arcs):
    """The arcs [φ_lo, φ_hi] of an isochrone inside a pixel; returns how many (at most 4).

    The isochrone is cut at its crossings with the pixel's edge lines; each
    arc between crossings lies wholly inside or outside the pixel. With no
    crossing the whole ellipse is inside or outside.

    Parameters
    ----------
    frame : Frame
    curve : Isochrone
        From :func:`analytic.kernels.isochrone.ellipse`, metres.
    box : PixelBox
        The pixel, metres.
    angles : float64[8]
        Scratch for the crossings.
    arcs : float64[4, 2]
        Output, radians.
    """
    count = rectangle_crossings(frame, curve, box, angles)
    two_pi = 2.0 * math.pi
    if count == 0:
        x, y = point_on_ellipse(frame, curve, 0.0)
        if box.x0 <= x <= box.x1 and box.y0 <= y <= box.y1:
            arcs[0, 0] = 0.0
            arcs[0, 1] = two_pi
            return 1
        return 0
    inside = 0
    for i in range(count):
        lo = angles[i]
        hi = angles[i + 1] if i + 1 < count else angles[0] + two_pi
        if not hi - lo > 0.0:
            continue
        x, y = point_on_ellipse(frame, curve, 0.5 * (lo + hi))
        if box.x0 <= x <= box.x1 and box.y0 <= y <= box.y1 and inside < arcs.shape[0]:
            arcs[inside, 0] = lo
            arcs[inside, 1] = hi
            inside += 1
    return inside


@njit(cache=True, error_model="numpy")
def pixel_isochrone_integral(frame, curve, box, rtol, angles, arcs, work):
    """G(τ) = ∫_{isochrone ∩ pixel} a J dφ: the pixel's impulse response at τ, m⁻³.

    Each arc of :func:`pixel_arcs` is smooth, so the adaptive ladder
    converges on it geometrically.

    Parameters
    ----------
    frame : Frame
    curve : Isochrone
        From :func:`analytic.kernels.isochrone.ellipse`.
    box : PixelBox
        The pixel, metres.
    rtol : float
        Relative accuracy.
    angles, arcs : float64[8], float64[4, 2]
        Scratch.
    work : Workspace
        Scratch of size >= 1 (its ``result`` too); failures are counted in
        ``work.failures``.

    Returns
    -------
    float
        Per metre of path length, m⁻³ (any positive attenuation works).
    """
    count = pixel_arcs(frame, curve, box, angles, arcs)
    problem = ArcProblem(frame, curve)
    total = work.result
    total[0] = 0.0
    for i in range(count):
        integrate(problem, arcs[i, 0], arcs[i, 1], rtol, 1, total, work, 0.0)
    return total[0]


def nested_integral_arguments():
    """Arguments of :func:`pixel_isochrone_integral` (any values of the right types).

    The cut routes integrate over τ with integrands that integrate over φ by the same drivers
    (:func:`integrate` inside :func:`integrate`). Numba links such a nested specialisation only if it
    was compiled before the outer one (otherwise the call aborts at run time on an unresolved symbol),
    so the Python side compiles :func:`pixel_isochrone_integral` for these types first
    (:func:`analytic.kernels.cache.compiled`).
    """
    frame = make_frame((0.5, 0.5, 1.0), (0.5, 0.5, 1.0), 0)
    return (frame, ellipse(frame, 2.5), PixelBox(0.0, 1.0, 0.0, 1.0), 1e-6, np.empty(8), np.empty((4, 2)),
            make_workspace(1))


#: How :func:`piece_map` maps v in [0, 1] onto a τ-piece, by which ends have a
#: square-root behaviour (an isochrone touching an edge, or born at x*).
LINEAR, ROOT_START, ROOT_END, ROOT_BOTH = 0, 1, 2, 3


@njit(cache=True, error_model="numpy")
def piece_map(kind, tau_a, span, v):
    """τ(v) on [τ_a, τ_a + span] and dτ/dv, for v in [0, 1].

    LINEAR: τ_a + span v, for ends where the integrand is analytic (a pixel
    corner starts or ends it linearly; a kernel breakpoint cuts an analytic
    function). ROOT_START: τ_a + span v², so sqrt(τ - τ_a) = v sqrt(span);
    ROOT_END the mirror; ROOT_BOTH: τ_a + span sin²(πv/2), so that
    sqrt(τ - τ_a) = sqrt(span) sin(πv/2) and sqrt(τ_b - τ) = sqrt(span)
    cos(πv/2). Each turns a square-root end into an entire function of v,
    without adding a singularity where the end was regular.
    """
    if kind == LINEAR:
        return tau_a + span * v, span
    if kind == ROOT_START:
        return tau_a + span * v * v, 2.0 * span * v
    if kind == ROOT_END:
        w = 1.0 - v
        return tau_a + span * (1.0 - w * w), 2.0 * span * w
    s = math.sin(0.5 * math.pi * v)
    return tau_a + span * s * s, 0.5 * math.pi * span * math.sin(math.pi * v)


class IsochronePiece(NamedTuple):
    """What :func:`isochrone_rule` needs: the time weight's own problem, the pair, the pixel, the τ-piece.

    ``kind``, ``tau_a`` and ``span`` define τ(v) (:func:`piece_map`);
    ``angles`` and ``arcs`` are scratch (float64[8], float64[4, 2]).
    """

    weight_problem: tuple
    frame: Frame
    box: PixelBox
    kind: int
    tau_a: float
    span: float
    angles: np.ndarray
    arcs: np.ndarray


@njit(cache=True, error_model="numpy")
def isochrone_rule(problem, lo, hi, rtol, size, work):
    """Tensor ladder in (v, φ) of w(τ) G(τ) dτ/dv over [lo, hi] ⊂ [0, 1] (a rule for :func:`adapt`).

    G(τ) = ∫_{isochrone ∩ pixel} a J dφ as in :func:`pixel_isochrone_integral`,
    τ = :func:`piece_map` (v) over the whole τ-piece; rung n takes n nodes
    in v and n on every arc. Valid on a τ-piece with no corner, tangency or
    first arrival strictly inside (the arcs' end angles are then smooth in
    τ) and a pixel whose attenuation is smooth along the arcs.

    Parameters
    ----------
    problem : IsochronePiece
        Its ``weight_problem``'s :func:`time_weight` writes scale w(τ) into
        ``values[:size]`` (the time kernels, or powers of τ) and its rounding
        into ``noise[:size]``.
    lo, hi, rtol, size, work
        As for any rule of :func:`adapt`.
    """
    frame = problem.frame
    angles = problem.angles
    arcs = problem.arcs
    centre_v = 0.5 * (lo + hi)
    half_v = 0.5 * (hi - lo)
    for order in range(1, LADDER_LEVELS + 1):
        target = work.lower if order == 1 else work.upper
        for i in range(size):
            target[i] = 0.0
            work.magnitude[i] = 0.0
            work.rounding[i] = 0.0
        for jv in range(order):
            tau, slope = piece_map(problem.kind, problem.tau_a, problem.span,
                                   centre_v + half_v * GAUSS_NODES[order, jv])
            curve = ellipse(frame, tau)
            count = pixel_arcs(frame, curve, problem.box, angles, arcs)
            response = 0.0
            for arc in range(count):
                centre = 0.5 * (arcs[arc, 0] + arcs[arc, 1])
                half = 0.5 * (arcs[arc, 1] - arcs[arc, 0])
                for jphi in range(order):
                    phi = centre + half * GAUSS_NODES[order, jphi]
                    response += half * GAUSS_WEIGHTS[order, jphi] * arc_value(frame, curve, phi)
            scale = half_v * GAUSS_WEIGHTS[order, jv] * slope * response
            if scale == 0.0:
                continue
            time_weight(problem.weight_problem, tau, scale, work.values, work.noise)
            for i in range(size):
                target[i] += work.values[i]
                work.magnitude[i] += abs(work.values[i])
                work.rounding[i] += work.noise[i]
        if order > 1 and _judge(work, size, rtol, order - 1, 2):
            return True
    return False


def rule(problem, lo, hi, rtol, size, work):
    """The rule :func:`adapt` climbs on [lo, hi] for ``problem`` (compiled code only)."""
    raise TypeError("rule is called from compiled code")


@overload(rule, jit_options={"error_model": "numpy"}, inline="always")
def _rule_of(problem, lo, hi, rtol, size, work):
    if getattr(problem, "instance_class", None) is IsochronePiece:
        return lambda problem, lo, hi, rtol, size, work: isochrone_rule(problem, lo, hi, rtol, size, work)
    return lambda problem, lo, hi, rtol, size, work: ladder_rule(problem, lo, hi, rtol, size, work)
