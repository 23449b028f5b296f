"""A pair's isochrones as conics in a pixel's own axes, in closed form (compiled).

The isochrone d = τ of a pair is the rectangle's section of the prolate
spheroid with foci at the pair's ends: a conic. In a pixel's axes (u, w),
u chosen along the isochrones (:func:`across`), it meets a line of the
pixel at the roots of a quadratic (:func:`inner_roots`, :func:`crossings`),
refined by Newton's method on d itself (:func:`polish`). The slab rules of
:mod:`analytic.kernels.strips` take their limits from here.
"""

from __future__ import annotations

import math

import numpy as np

from .cache import njit

__all__ = ["isochrone_conic", "roots", "polish", "inner_roots", "inner_roots_within",
           "crossings", "turns_inside", "ordered", "across"]


@njit(cache=True, error_model="numpy", forceinline=True)
def isochrone_conic(frame, tau, swap):
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


@njit(cache=True, error_model="numpy", forceinline=True)
def roots(a, b, c):
    """Real roots of a q² + 2 b q + c = 0 (a > 0), sorted: (low, high, True), or (0, 0, False) if none."""
    disc = b * b - a * c
    if disc < 0.0:
        return 0.0, 0.0, False
    t = -(b + math.copysign(math.sqrt(disc), b))
    if t == 0.0:
        return 0.0, 0.0, True
    first, second = t / a, c / t
    return min(first, second), max(first, second), True


@njit(cache=True, error_model="numpy", forceinline=True)
def polish(frame, tau, u, w, swap, along_w):
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


@njit(cache=True, error_model="numpy", forceinline=True)
def inner_roots(frame, conic, tau, u, swap):
    """The w where the isochrone crosses the line at u: (low, high, True), or (0, 0, False) if it does not."""
    return inner_roots_within(frame, conic, tau, u, swap, -np.inf, np.inf)


#: :func:`polish` moves a root by at most two steps of 1e-6 (τ + |u| + |w|): a closed-form root further than
#: this (relative to the same) outside [w0, w1] stays outside.
_POLISH_REACH = 4e-6


@njit(cache=True, error_model="numpy", forceinline=True)
def inner_roots_within(frame, conic, tau, u, swap, w0, w1):
    """:func:`inner_roots` for limits clamped to [w0, w1]: a root that stays outside them is left unpolished.

    Its callers take max(w0, root) or min(w1, root), or an empty row, so they get the same numbers
    as from :func:`inner_roots`, with one Newton refinement (two square roots a step) fewer per root
    outside the pixel (one of the two, for an isochrone much larger than the pixel).
    """
    mu, mw, auu, auw, aww, bu, bw, c = conic
    qu = u - mu
    low, high, real = roots(aww, auw * qu + bw, (auu * qu + 2.0 * bu) * qu + c)
    if not real:
        return 0.0, 0.0, False
    low += mw
    high += mw
    if not low < w0 - _POLISH_REACH * (tau + abs(u) + abs(low)):
        low = polish(frame, tau, u, low, swap, True)
    if not high > w1 + _POLISH_REACH * (tau + abs(u) + abs(high)):
        high = polish(frame, tau, u, high, swap, True)
    return low, high, True


@njit(cache=True, error_model="numpy", forceinline=True)
def crossings(frame, conic, tau, w, lo, hi, swap):
    """The u in (lo, hi) where the isochrone crosses the line at w: two numbers, each inf where there is none."""
    mu, mw, auu, auw, aww, bu, bw, c = conic
    qw = w - mw
    low, high, real = roots(auu, auw * qw + bu, (aww * qw + 2.0 * bw) * qw + c)
    first, second = np.inf, np.inf
    if real:
        u = polish(frame, tau, low + mu, w, swap, False)
        if lo < u < hi:
            first = u
        u = polish(frame, tau, high + mu, w, swap, False)
        if lo < u < hi:
            second = u
    return first, second


@njit(cache=True, error_model="numpy", forceinline=True)
def turns_inside(conic, u0, u1, w0, w1):
    """Whether the isochrone's tangent is along w at a point of the pixel (its inner roots merge there).

    Away from the pixel the merge only slows the rule's convergence near it, which G_3 against G_4
    detects.
    """
    mu, mw, auu, auw, aww, bu, bw, c = conic
    # (A_uw q_u + B_w)² - A_ww (A_uu q_u² + 2 B_u q_u + C) = 0, a quadratic in q_u
    a = auw * auw - aww * auu
    b = auw * bw - aww * bu
    e = bw * bw - aww * c
    low, high, real = roots(-a, -b, -e)         # -a = A_uu A_ww - A_uw² > 0 for an ellipse
    if not real:
        return False
    for q in (low, high):
        if u0 < q + mu < u1 and w0 < mw - (auw * q + bw) / aww < w1:
            return True
    return False


@njit(cache=True, error_model="numpy", forceinline=True)
def ordered(a, b):
    """(a, b) in increasing order (a sorting network's step, on scalars)."""
    return (a, b) if a <= b else (b, a)


@njit(cache=True, error_model="numpy", forceinline=True)
def across(frame, box):
    """(swap, u0, u1, w0, w1): the pixel in (u, w), u along the isochrones (d changes faster across w)."""
    cx, cy = 0.5 * (box.x0 + box.x1), 0.5 * (box.y0 + box.y1)
    ds = math.sqrt((cx - frame.source_x) ** 2 + (cy - frame.source_y) ** 2 + frame.source_height ** 2)
    dk = math.sqrt((cx - frame.sensor_x) ** 2 + (cy - frame.sensor_y) ** 2 + frame.sensor_height ** 2)
    gx = (cx - frame.source_x) / ds + (cx - frame.sensor_x) / dk
    gy = (cy - frame.source_y) / ds + (cy - frame.sensor_y) / dk
    swap = abs(gx) > abs(gy)
    if swap:
        return swap, box.y0, box.y1, box.x0, box.x1
    return swap, box.x0, box.x1, box.y0, box.y1
