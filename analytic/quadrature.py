"""Gauss–Kronrod (7, 15) rule and the compiled adaptive integrals built on it.

The 15-point Kronrod rule integrates polynomials of degree 22 exactly and
the embedded 7-point Gauss rule those of degree 13; |K15 - G7| bounds the
error of G7 and overestimates that of K15, which is the value kept. All
integrands here are positive, so a piece accepted with
|K15 - G7| <= rtol * K15 keeps the total relative error below rtol.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .isochrone import attenuation_at, jacobian, point_on_ellipse, rectangle_crossings

__all__ = ["KRONROD_NODES", "KRONROD_WEIGHTS", "GAUSS_WEIGHTS", "isochrone_arc_integral",
           "pixel_isochrone_integral"]

# QUADPACK qk15: nodes x_j (j odd: Gauss nodes), Kronrod weights, Gauss weights.
KRONROD_NODES = np.array([
    0.991455371120812639206854697526329, 0.949107912342758524526189684047851,
    0.864864423359769072789712788640926, 0.741531185599394439863864773280788,
    0.586087235467691130294144845693013, 0.405845151377397166906606412076961,
    0.207784955007898467600689403773245, 0.000000000000000000000000000000000])
KRONROD_WEIGHTS = np.array([
    0.022935322010529224963732008058970, 0.063092092629978553290700663189204,
    0.104790010322250183839876322541518, 0.140653259715525918745189590510238,
    0.169004726639267902826583426598550, 0.190350578064785409913256402421014,
    0.204432940075298892414161999234649, 0.209482141084727828012999174891714])
GAUSS_WEIGHTS = np.array([
    0.129484966168869693270611432679082, 0.279705391489276667901467771423780,
    0.381830050505118944950369775488975, 0.417959183673469387755102040816327])

_STACK = 128        # pieces waiting at once; depth-first bisection needs ~ depth + 1
_MAX_DEPTH_WIDTH = 1e-10  # pieces narrower than this fraction are accepted as they are
_MAX_PIECES = 4000  # rule applications per integral before the rest is accepted as is


@njit(cache=True)
def _arc_rule(frame, cx, cy, a, b, j0, j1, j2, lo, hi):
    """(K15, G7) of a(x(φ)) J(φ) over [lo, hi] on one isochrone."""
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    x, y = point_on_ellipse(frame, cx, cy, a, b, centre)
    value = attenuation_at(frame, x, y) * jacobian(j0, j1, j2, centre)
    kronrod = value * KRONROD_WEIGHTS[7]
    gauss = value * GAUSS_WEIGHTS[3]
    for j in range(7):
        offset = half * KRONROD_NODES[j]
        x, y = point_on_ellipse(frame, cx, cy, a, b, centre - offset)
        left = attenuation_at(frame, x, y) * jacobian(j0, j1, j2, centre - offset)
        x, y = point_on_ellipse(frame, cx, cy, a, b, centre + offset)
        right = attenuation_at(frame, x, y) * jacobian(j0, j1, j2, centre + offset)
        kronrod += KRONROD_WEIGHTS[j] * (left + right)
        if j % 2 == 1:
            gauss += GAUSS_WEIGHTS[j // 2] * (left + right)
    return kronrod * half, gauss * half


@njit(cache=True)
def isochrone_arc_integral(frame, cx, cy, a, b, j0, j1, j2, lo, hi, rtol, stack):
    """∫_lo^hi a(x(τ, φ)) J(τ, φ) dφ by adaptive bisection, m⁻³ (per metre of τ).

    Parameters
    ----------
    frame : float64[12]
        Source-sensor pair.
    cx, cy, a, b, j0, j1, j2 : float
        The isochrone, from :func:`analytic.isochrone.ellipse`.
    lo, hi : float
        Arc, radians.
    rtol : float
        Relative accuracy.
    stack : float64[:, 2]
        Work space.

    Returns
    -------
    value : float
    converged : bool
    """
    total = 0.0
    converged = True
    stack[0, 0] = lo
    stack[0, 1] = hi
    waiting = 1
    applied = 0
    while waiting > 0:
        waiting -= 1
        applied += 1
        left = stack[waiting, 0]
        right = stack[waiting, 1]
        kronrod, gauss = _arc_rule(frame, cx, cy, a, b, j0, j1, j2, left, right)
        stop = ((right - left) <= _MAX_DEPTH_WIDTH * (hi - lo) or waiting + 2 > _STACK
                or applied > _MAX_PIECES)
        # arcs narrower than ~1e-12 rad are below the angles' rounding: keep them
        unresolvable = (right - left) <= 1e-12 * max(1.0, abs(right))
        if abs(kronrod - gauss) <= rtol * abs(kronrod) or stop or unresolvable:
            if not (abs(kronrod - gauss) <= rtol * abs(kronrod) or unresolvable):
                converged = False
            total += kronrod
        else:
            middle = 0.5 * (left + right)
            stack[waiting, 0] = left
            stack[waiting, 1] = middle
            stack[waiting + 1, 0] = middle
            stack[waiting + 1, 1] = right
            waiting += 2
    return total, converged


@njit(cache=True)
def pixel_isochrone_integral(frame, cx, cy, a, b, j0, j1, j2, x0, x1, y0, y1, rtol,
                             angles, stack):
    """G(τ) = ∫_{isochrone ∩ pixel} a J dφ: the pixel's impulse response at τ.

    The isochrone is cut at its crossings with the pixel's edge lines; each
    arc lies wholly inside or outside the pixel and is smooth, so adaptive
    Gauss–Kronrod converges on it geometrically.

    Returns
    -------
    value : float
        Per metre of path length, m⁻³ (lambertian: times sr⁻¹ conventions of
        DESIGN.md; any positive attenuation works).
    converged : bool
    """
    count = rectangle_crossings(frame, cx, cy, a, b, x0, x1, y0, y1, angles)
    two_pi = 2.0 * math.pi
    if count == 0:
        x, y = point_on_ellipse(frame, cx, cy, a, b, 0.0)
        if x0 <= x <= x1 and y0 <= y <= y1:
            return isochrone_arc_integral(frame, cx, cy, a, b, j0, j1, j2, 0.0, two_pi, rtol, stack)
        return 0.0, True
    total = 0.0
    converged = True
    for i in range(count):
        lo = angles[i]
        hi = angles[i + 1] if i + 1 < count else angles[0] + two_pi
        if hi - lo <= 0.0:
            continue
        x, y = point_on_ellipse(frame, cx, cy, a, b, 0.5 * (lo + hi))
        if x0 <= x <= x1 and y0 <= y <= y1:
            value, ok = isochrone_arc_integral(frame, cx, cy, a, b, j0, j1, j2, lo, hi, rtol, stack)
            total += value
            converged = converged and ok
    return total, converged
