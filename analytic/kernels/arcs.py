"""The isochrone's integrals over a pixel (compiled): its arcs, G(τ), and the (τ, φ) tensor rule.

- :func:`pixel_arcs` — the arcs of an isochrone (an ellipse of the plane)
  inside a pixel, between its crossings of the pixel's edges.
- :func:`pixel_isochrone_integral` — G(τ) = ∫_{isochrone ∩ pixel} a J dφ
  with :func:`analytic.kernels.quadrature.integrate` on each arc.
- :func:`isochrone_rule` — the tensor ladder in (τ, φ) of ∫ w(τ) G(τ) dτ over
  part of a τ-piece. Bisection in τ cannot refine φ, so its caller gives it a
  small ``max_pieces`` and falls back to adaptive φ-integrals
  (:func:`pixel_isochrone_integral`) when it fails. It is the rule
  :func:`analytic.kernels.quadrature.adapt` climbs for an
  :class:`IsochronePiece` (:func:`analytic.kernels.quadrature.rule_for`).
- :func:`piece_map` — τ(v) on a τ-piece, smoothing its square-root ends.

Compiled with ``error_model="numpy"``, as the drivers.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .attenuation import attenuation_at
from .cache import njit
from .isochrone import Frame, Isochrone, PixelBox, ellipse, make_frame, point_on_ellipse, rectangle_crossings
from .quadrature import (GAUSS_NODES, GAUSS_WEIGHTS, LADDER_LEVELS, implements, integrand, integrate, judge,
                         make_workspace, rule_for, time_weight)

__all__ = ["ArcProblem", "IsochronePiece", "arc_value", "arc_integrand", "pixel_arcs", "pixel_isochrone_integral",
           "nested_integral_arguments", "piece_map", "isochrone_rule", "LINEAR", "ROOT_START", "ROOT_END",
           "ROOT_BOTH"]


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


@rule_for(IsochronePiece)
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
        if order > 1 and judge(work, size, rtol, order - 1, 2):
            return True
    return False
