"""Isochrones: the ellipses d(x) = τ on the plane, in closed form (compiled).

For a source at height h_s and a sensor at height h_k whose feet on the plane
are D apart, the set {x in z = 0 : |x - p_s| + |x - p_k| = τ} is the plane
section of a prolate spheroid: an ellipse with its major axis along the line
through the two feet. With e the unit vector from the source's foot to the
sensor's and q(τ) = (τ² - t_min²)(τ² - t_2²), t_min² = D² + (h_s + h_k)²,
t_2² = D² + (h_s - h_k)²,

    centre    c(τ) = foot_s + e · D (τ² - D² + h_s² - h_k²) / (2 (τ² - D²))
    semi-axis along e:  a(τ)² = τ² q / (4 (τ² - D²)²)
    semi-axis across:   b(τ)² = q / (4 (τ² - D²)).

t_min is the first arrival: the ellipse is born as a point at
x* = foot_s + e D h_s / (h_s + h_k). The factored q keeps the axes accurate
near t_min and for planes far away.

The map (τ, φ) -> x(τ, φ) = c + a cos φ e + b sin φ e⊥ covers the plane
outside x* once; its Jacobian J(τ, φ) = |∂x/∂τ × ∂x/∂φ| equals
|∂x/∂φ| / |∇d| (the coarea factor of DESIGN.md section 3.1), and stays finite
as τ -> t_min. Area integrals become ∫ dτ ∫ dφ (...) J.

Everything here is scalar and compiled with Numba; ``frame`` arrays hold a
source-sensor pair (see :func:`make_frame`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["make_frame", "ellipse", "point_on_ellipse", "jacobian", "attenuation_at",
           "path_length_at", "first_arrival_point", "LAMBERTIAN", "PAPER"]

LAMBERTIAN, PAPER = 0, 1

# frame layout
SX, SY, HS, KX, KY, HK, E1, E2, DIST, TMIN, T2SQ, MODE = range(12)


@njit(cache=True)
def make_frame(source, sensor, mode):
    """Pack a source-sensor pair for the compiled kernels.

    Parameters
    ----------
    source, sensor : float64[3]
        Positions, metres (z > 0).
    mode : int
        LAMBERTIAN (0) or PAPER (1) attenuation.

    Returns
    -------
    float64[12]
        Feet, heights, unit axis e, foot distance D, t_min, t_2², mode.
    """
    frame = np.empty(12)
    frame[SX], frame[SY], frame[HS] = source[0], source[1], source[2]
    frame[KX], frame[KY], frame[HK] = sensor[0], sensor[1], sensor[2]
    dx = sensor[0] - source[0]
    dy = sensor[1] - source[1]
    dist = math.hypot(dx, dy)
    if dist > 0.0:
        frame[E1], frame[E2] = dx / dist, dy / dist
    else:  # feet coincide: the isochrones are circles, any axis will do
        frame[E1], frame[E2] = 1.0, 0.0
    frame[DIST] = dist
    frame[TMIN] = math.hypot(dist, source[2] + sensor[2])
    frame[T2SQ] = dist * dist + (source[2] - sensor[2]) ** 2
    frame[MODE] = mode
    return frame


@njit(cache=True)
def ellipse(frame, tau):
    """Centre, semi-axes and Jacobian coefficients of the isochrone at τ.

    Parameters
    ----------
    frame : float64[12]
        From :func:`make_frame`.
    tau : float
        Path length, metres; τ >= t_min.

    Returns
    -------
    cx, cy : float
        Centre, metres.
    a, b : float
        Semi-axes along e and across, metres.
    j0, j1, j2 : float
        J(τ, φ) = j0 cos φ + j1 cos² φ + j2 sin² φ, metres (m² per m per rad).
    """
    dist = frame[DIST]
    hs2 = frame[HS] * frame[HS]
    hk2 = frame[HK] * frame[HK]
    tmin = frame[TMIN]
    tau2 = tau * tau
    den = tau2 - dist * dist
    first = (tau - tmin) * (tau + tmin)
    if first < 0.0:
        first = 0.0
    second = tau2 - frame[T2SQ]
    q = first * second
    a2 = tau2 * q / (4.0 * den * den)
    b2 = q / (4.0 * den)
    shift = 0.5 * dist * (1.0 + (hs2 - hk2) / den)
    cx = frame[SX] + shift * frame[E1]
    cy = frame[SY] + shift * frame[E2]
    dq = 2.0 * tau * (second + first)
    da2 = ((2.0 * tau * q + tau2 * dq) * den - 4.0 * tau * tau2 * q) / (4.0 * den * den * den)
    db2 = (dq * den - 2.0 * tau * q) / (4.0 * den * den)
    dshift = -dist * (hs2 - hk2) * tau / (den * den)
    root_den = math.sqrt(den)
    a = math.sqrt(a2)
    b = math.sqrt(b2)
    j0 = b * dshift
    j1 = 0.5 * da2 * root_den / tau        # a' b, written without dividing by a
    j2 = 0.5 * db2 * tau / root_den        # a b', written without dividing by b
    return cx, cy, a, b, j0, j1, j2


@njit(cache=True)
def point_on_ellipse(frame, cx, cy, a, b, phi):
    """The point x(τ, φ) on an isochrone, metres."""
    c = math.cos(phi)
    s = math.sin(phi)
    return (cx + a * c * frame[E1] - b * s * frame[E2],
            cy + a * c * frame[E2] + b * s * frame[E1])


@njit(cache=True)
def jacobian(j0, j1, j2, phi):
    """J(τ, φ) = |∂x/∂(τ, φ)|, metres."""
    c = math.cos(phi)
    s = math.sin(phi)
    return abs(j0 * c + j1 * c * c + j2 * s * s)


@njit(cache=True)
def attenuation_at(frame, x, y):
    """a_k(x) of DESIGN.md section 2 at a plane point, 1/m⁴.

    lambertian: cos θ_s cos θ_k / (π d_s² d_k²) = h_s h_k / (π d_s³ d_k³);
    paper (eq. 1): cos θ_s / (d_s² d_k²) = h_s / (d_s³ d_k²).
    """
    ds2 = (x - frame[SX]) ** 2 + (y - frame[SY]) ** 2 + frame[HS] ** 2
    dk2 = (x - frame[KX]) ** 2 + (y - frame[KY]) ** 2 + frame[HK] ** 2
    if frame[MODE] == LAMBERTIAN:
        return frame[HS] * frame[HK] / (math.pi * ds2 * math.sqrt(ds2) * dk2 * math.sqrt(dk2))
    return frame[HS] / (ds2 * math.sqrt(ds2) * dk2)


@njit(cache=True)
def path_length_at(frame, x, y):
    """d(x) = |x - p_s| + |x - p_k| for a plane point, metres."""
    ds = math.sqrt((x - frame[SX]) ** 2 + (y - frame[SY]) ** 2 + frame[HS] ** 2)
    dk = math.sqrt((x - frame[KX]) ** 2 + (y - frame[KY]) ** 2 + frame[HK] ** 2)
    return ds + dk


@njit(cache=True)
def first_arrival_point(frame):
    """x*, the plane point of shortest path (d(x*) = t_min), metres."""
    ratio = frame[HS] / (frame[HS] + frame[HK])
    return (frame[SX] + frame[E1] * frame[DIST] * ratio,
            frame[SY] + frame[E2] * frame[DIST] * ratio)


@njit(cache=True)
def segment_minimum(frame, x0, y0, x1, y1):
    """Minimum of d on the segment [(x0, y0), (x1, y1)]: (value, inside).

    d restricted to a line is sqrt((u - u_s)² + ρ_s²) + sqrt((u - u_k)² + ρ_k²);
    its minimiser divides [u_s, u_k] in the ratio ρ_s : ρ_k (unfold the
    sensor about the line). ``inside`` says whether it lies strictly inside
    the segment, where it is a tangency of an isochrone with the segment.
    """
    length = math.hypot(x1 - x0, y1 - y0)
    ux = (x1 - x0) / length
    uy = (y1 - y0) / length
    us = (frame[SX] - x0) * ux + (frame[SY] - y0) * uy
    uk = (frame[KX] - x0) * ux + (frame[KY] - y0) * uy
    rho_s = math.sqrt(((frame[SX] - x0) - us * ux) ** 2 + ((frame[SY] - y0) - us * uy) ** 2
                      + frame[HS] ** 2)
    rho_k = math.sqrt(((frame[KX] - x0) - uk * ux) ** 2 + ((frame[KY] - y0) - uk * uy) ** 2
                      + frame[HK] ** 2)
    u = (us * rho_k + uk * rho_s) / (rho_s + rho_k)
    inside = 0.0 < u < length
    if u < 0.0:
        u = 0.0
    elif u > length:
        u = length
    return path_length_at(frame, x0 + u * ux, y0 + u * uy), inside


@njit(cache=True)
def rectangle_range(frame, x0, x1, y0, y1):
    """[min, max] of d over the rectangle [x0, x1] x [y0, y1], metres.

    d is convex, so its maximum is at a corner and its minimum at x* when x*
    is inside, else on an edge.
    """
    xs, ys = first_arrival_point(frame)
    top = max(max(path_length_at(frame, x0, y0), path_length_at(frame, x1, y0)),
              max(path_length_at(frame, x0, y1), path_length_at(frame, x1, y1)))
    if x0 <= xs <= x1 and y0 <= ys <= y1:
        return frame[TMIN], top
    low = segment_minimum(frame, x0, y0, x1, y0)[0]
    low = min(low, segment_minimum(frame, x1, y0, x1, y1)[0])
    low = min(low, segment_minimum(frame, x0, y1, x1, y1)[0])
    low = min(low, segment_minimum(frame, x0, y0, x0, y1)[0])
    return low, top


@njit(cache=True)
def rectangle_crossings(frame, cx, cy, a, b, x0, x1, y0, y1, out):
    """Angles φ where the isochrone crosses the rectangle's four edge lines.

    x1(φ) = cx + R1 cos(φ + ψ1) and x2(φ) = cy + R2 cos(φ - ψ2), so each
    line gives at most two angles. Writes sorted angles in [0, 2π) into
    ``out`` and returns how many.
    """
    e1 = frame[E1]
    e2 = frame[E2]
    r1 = math.hypot(a * e1, b * e2)
    psi1 = math.atan2(b * e2, a * e1)
    r2 = math.hypot(a * e2, b * e1)
    psi2 = math.atan2(b * e1, a * e2)
    count = 0
    two_pi = 2.0 * math.pi
    for line in range(4):
        if line < 2:
            level = x0 if line == 0 else x1
            if r1 <= 0.0:
                continue
            ratio = (level - cx) / r1
            offset = -psi1
        else:
            level = y0 if line == 2 else y1
            if r2 <= 0.0:
                continue
            ratio = (level - cy) / r2
            offset = psi2
        if -1.0 < ratio < 1.0:
            angle = math.acos(ratio)
            for sign in (-1.0, 1.0):
                phi = (offset + sign * angle) % two_pi
                out[count] = phi
                count += 1
    # insertion sort: at most 8 values
    for i in range(1, count):
        value = out[i]
        j = i - 1
        while j >= 0 and out[j] > value:
            out[j + 1] = out[j]
            j -= 1
        out[j + 1] = value
    return count
