"""Isochrones: the ellipses d(x) = τ on a rectangle's plane, in closed form (compiled).

Everything is in the rectangle's own frame (:mod:`analytic.geometry`):
x and y along its edges, heights along its normal; for the letter's plane
that is the world frame. For a source at height h_s and a sensor at height
h_k whose feet on the plane
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
|∂x/∂φ| / |∇d| (the coarea factor of docs/design.md section 3.1), and stays finite
as τ -> t_min. Area integrals become ∫ dτ ∫ dφ (...) J.

Everything here is scalar and compiled with Numba; a source-sensor pair is a
:class:`Frame` record (see :func:`make_frame`), an isochrone an
:class:`Isochrone`, a pixel a :class:`PixelBox`.

Heights
-------
The attenuation under a source (or sensor) at height h is a peak of width h:
∫ h / (r² + h²)^{3/2} dx = 2π however small h is, so as h -> 0 the response
tends to a finite limit (2 ρ cos θ_k / d_k² from the foot, docs/design.md section
2). Resolving the peak needs h to span many roundings of the plane
coordinates and path lengths, which are as large as the scene:
:data:`analytic.scenes.common.MIN_HEIGHT_FRACTION` of the scene's extent is the
smallest height the model supports (:func:`analytic.scenes.common.check_heights`);
at that height the peak is still ~10⁶ float64 roundings wide.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .cache import njit

from .attenuation import attenuation_at
from .formulas import LAMBERTIAN, PAPER

__all__ = ["Frame", "Isochrone", "PixelBox", "make_frame", "pair_frame", "ellipse", "point_on_ellipse", "jacobian", "path_length_at",
           "first_arrival_point", "segment_minimum", "rectangle_range", "table_ranges", "range_bound",
           "rectangle_crossings",
           "LAMBERTIAN", "PAPER", "attenuation_at"]

class PixelBox(NamedTuple):
    """A pixel (or any axis-aligned rectangle) [x0, x1] x [y0, y1] of the rectangle's frame, metres."""

    x0: float
    x1: float
    y0: float
    y1: float


class Isochrone(NamedTuple):
    """The isochrone d = τ of a pair (:func:`ellipse`), metres.

    x(φ) = centre + a cos φ e + b sin φ e⊥, with Jacobian
    J(τ, φ) = j0 cos φ + j1 cos² φ + j2 sin² φ (m² per m of path per rad).
    """

    centre_x: float
    centre_y: float
    a: float          # semi-axis along e
    b: float          # semi-axis across
    j0: float
    j1: float
    j2: float


class Frame(NamedTuple):
    """A source-sensor pair in the rectangle's frame, as the compiled kernels use it (metres).

    The first eleven fields fix the isochrones and the attenuation; the
    cosine fields are an end's own surface (a relay wall's point): when
    ``source_cosine``, a_k is multiplied by n·(x - p_s) / d_s with
    n·(x - p_s) = source_cosine_0 + source_cosine_u x + source_cosine_v y
    (the same for the sensor).
    """

    source_x: float
    source_y: float
    source_height: float
    sensor_x: float
    sensor_y: float
    sensor_height: float
    axis_x: float           # e, the unit vector from the source's foot to the sensor's
    axis_y: float
    foot_distance: float    # D
    first_arrival: float    # t_min
    mode: int               # attenuation code, analytic.attenuation.LAMBERTIAN or PAPER
    source_cosine: bool
    source_cosine_0: float
    source_cosine_u: float
    source_cosine_v: float
    sensor_cosine: bool
    sensor_cosine_0: float
    sensor_cosine_u: float
    sensor_cosine_v: float


@njit(cache=True, error_model="numpy")
def _frame(source, sensor, mode, source_surface, sensor_surface):
    """The :class:`Frame` of two ends (x, y, height) and their surfaces (has one, (n·(x - p) at 0, ∂u, ∂v))."""
    source_x, source_y, source_height = source
    sensor_x, sensor_y, sensor_height = sensor
    source_cosine, source_form = source_surface
    sensor_cosine, sensor_form = sensor_surface
    dx = sensor_x - source_x
    dy = sensor_y - source_y
    dist = math.hypot(dx, dy)
    if dist > 0.0:
        axis_x, axis_y = dx / dist, dy / dist
    else:  # feet coincide: the isochrones are circles, any axis will do
        axis_x, axis_y = 1.0, 0.0
    return Frame(source_x, source_y, source_height, sensor_x, sensor_y, sensor_height, axis_x, axis_y,
                 dist, math.hypot(dist, source_height + sensor_height), mode, source_cosine, source_form[0],
                 source_form[1], source_form[2], sensor_cosine, sensor_form[0], sensor_form[1], sensor_form[2])


@njit(cache=True, error_model="numpy")
def make_frame(source, sensor, mode):
    """A pair of omnidirectional points as a :class:`Frame`.

    Parameters
    ----------
    source, sensor : float64[3]
        Positions in the rectangle's frame (x, y, height), metres, height > 0.
    mode : int
        Attenuation code, :data:`analytic.attenuation.LAMBERTIAN` or ``PAPER``.

    Returns
    -------
    Frame
    """
    none = (False, (1.0, 0.0, 0.0))
    return _frame((source[0], source[1], source[2]), (sensor[0], sensor[1], sensor[2]), mode, none, none)


@njit(cache=True, error_model="numpy")
def pair_frame(pair, mode):
    """The :class:`Frame` of one record of :data:`analytic.geometry.PAIR_DTYPE`."""
    return _frame((pair.source_x, pair.source_y, pair.source_height), (pair.sensor_x, pair.sensor_y,
                                                                       pair.sensor_height), mode,
                  (pair.source_cosine, (pair.source_cosine_0, pair.source_cosine_u, pair.source_cosine_v)),
                  (pair.sensor_cosine, (pair.sensor_cosine_0, pair.sensor_cosine_u, pair.sensor_cosine_v)))


@njit(cache=True, error_model="numpy")
def ellipse(frame, tau):
    """Centre, semi-axes and Jacobian coefficients of the isochrone at τ.

    Parameters
    ----------
    frame : Frame
        From :func:`make_frame`.
    tau : float
        Path length, metres; τ >= t_min.

    Returns
    -------
    Isochrone
        Centre, semi-axes along e and across, and the Jacobian's
        coefficients.
    """
    dist = frame.foot_distance
    hs2 = frame.source_height * frame.source_height
    hk2 = frame.sensor_height * frame.sensor_height
    tmin = frame.first_arrival
    tau2 = tau * tau
    first = max((tau - tmin) * (tau + tmin), 0.0)
    # τ² - D² and τ² - t_2² from τ² - t_min² without cancellation: with low
    # points t_min, t_2 and D agree to many digits.
    den = first + (frame.source_height + frame.sensor_height) ** 2
    second = first + 4.0 * frame.source_height * frame.sensor_height
    q = first * second
    a2 = tau2 * q / (4.0 * den * den)
    b2 = q / (4.0 * den)
    shift = 0.5 * dist * (1.0 + (hs2 - hk2) / den)
    cx = frame.source_x + shift * frame.axis_x
    cy = frame.source_y + shift * frame.axis_y
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
    return Isochrone(cx, cy, a, b, j0, j1, j2)


@njit(cache=True, error_model="numpy")
def point_on_ellipse(frame, curve, phi):
    """The point x(τ, φ) on the isochrone ``curve``, metres."""
    c = math.cos(phi)
    s = math.sin(phi)
    return (curve.centre_x + curve.a * c * frame.axis_x - curve.b * s * frame.axis_y,
            curve.centre_y + curve.a * c * frame.axis_y + curve.b * s * frame.axis_x)


@njit(cache=True, error_model="numpy")
def jacobian(j0, j1, j2, phi):
    """J(τ, φ) = |∂x/∂(τ, φ)|, metres."""
    c = math.cos(phi)
    s = math.sin(phi)
    return abs(j0 * c + j1 * c * c + j2 * s * s)


@njit(cache=True, error_model="numpy")
def path_length_at(frame, x, y):
    """d(x) = |x - p_s| + |x - p_k| for a plane point, metres."""
    ds = math.sqrt((x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2)
    dk = math.sqrt((x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2)
    return ds + dk


@njit(cache=True, error_model="numpy")
def first_arrival_point(frame):
    """x*, the plane point of shortest path (d(x*) = t_min), metres."""
    ratio = frame.source_height / (frame.source_height + frame.sensor_height)
    return (frame.source_x + frame.axis_x * frame.foot_distance * ratio,
            frame.source_y + frame.axis_y * frame.foot_distance * ratio)


@njit(cache=True, error_model="numpy")
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
    us = (frame.source_x - x0) * ux + (frame.source_y - y0) * uy
    uk = (frame.sensor_x - x0) * ux + (frame.sensor_y - y0) * uy
    rho_s = math.sqrt(((frame.source_x - x0) - us * ux) ** 2 + ((frame.source_y - y0) - us * uy) ** 2
                      + frame.source_height ** 2)
    rho_k = math.sqrt(((frame.sensor_x - x0) - uk * ux) ** 2 + ((frame.sensor_y - y0) - uk * uy) ** 2
                      + frame.sensor_height ** 2)
    u = (us * rho_k + uk * rho_s) / (rho_s + rho_k)
    inside = 0.0 < u < length
    if u < 0.0:
        u = 0.0
    elif u > length:
        u = length
    return path_length_at(frame, x0 + u * ux, y0 + u * uy), inside


@njit(cache=True, error_model="numpy")
def rectangle_range(frame, box):
    """[min, max] of d over the :class:`PixelBox` ``box``, metres.

    d is convex, so its maximum is at a corner and its minimum at x* when x*
    is inside, else on an edge.
    """
    x0, x1, y0, y1 = box
    xs, ys = first_arrival_point(frame)
    top = max(max(path_length_at(frame, x0, y0), path_length_at(frame, x1, y0)),
              max(path_length_at(frame, x0, y1), path_length_at(frame, x1, y1)))
    if x0 <= xs <= x1 and y0 <= ys <= y1:
        return frame.first_arrival, top
    low = segment_minimum(frame, x0, y0, x1, y0)[0]
    low = min(low, segment_minimum(frame, x1, y0, x1, y1)[0])
    low = min(low, segment_minimum(frame, x0, y1, x1, y1)[0])
    low = min(low, segment_minimum(frame, x0, y0, x0, y1)[0])
    return low, top



@njit(cache=True, error_model="numpy")
def table_ranges(table, boxes, mode):
    """``(P, B, 2)`` [min, max] of d over each box for each pair of a pair table, metres (offsets not added).

    The loop over :func:`pair_frame` and :func:`rectangle_range` compiled whole: a :class:`Frame` boxed for
    Python calls Python's NamedTuple constructor from compiled code, and a KeyboardInterrupt raised there
    crashed the process.

    Parameters
    ----------
    table : numpy.ndarray
        ``(P,)`` records of :data:`analytic.geometry.PAIR_DTYPE`.
    boxes : numpy.ndarray
        ``(B, 4)`` boxes, rows (x0, x1, y0, y1) as :class:`PixelBox`, metres.
    mode : int
        Attenuation code, :data:`LAMBERTIAN` or :data:`PAPER`.
    """
    out = np.empty((table.shape[0], boxes.shape[0], 2))
    for p in range(table.shape[0]):
        frame = pair_frame(table[p], mode)
        for b in range(boxes.shape[0]):
            low, high = rectangle_range(frame, PixelBox(boxes[b, 0], boxes[b, 1], boxes[b, 2], boxes[b, 3]))
            out[p, b, 0] = low
            out[p, b, 1] = high
    return out


#: Relative slack of :func:`range_bound` over the rounding of d (a few dozen roundings of a path length).
_BOUND_SLACK = 1e-14


@njit(cache=True, error_model="numpy")
def range_bound(frame, centre_x, centre_y, half_x, half_y):
    """An interval of path length holding d over the box centre ± half, metres, from d and ∇d at its centre.

    d is convex, so d >= d(c) + ∇d(c)·δ over the box; its Hessian along the plane is at
    most 1/d_s + 1/d_k (each distance's is (I - u uᵀ)/d), so d <= d(c) + ∇d(c)·δ + |δ|²/2
    (1/d_s + 1/d_k) with each distance at least its value at the centre less |δ| (and its
    height). For a pixel far smaller than its distances the interval exceeds
    :func:`rectangle_range` by ~|δ|²/d: two square roots instead of a dozen. The slack
    covers both computations' rounding, so the interval holds :func:`rectangle_range`'s
    floating-point ends too.
    """
    sx = centre_x - frame.source_x
    sy = centre_y - frame.source_y
    kx = centre_x - frame.sensor_x
    ky = centre_y - frame.sensor_y
    ds = math.sqrt(sx * sx + sy * sy + frame.source_height ** 2)
    dk = math.sqrt(kx * kx + ky * ky + frame.sensor_height ** 2)
    linear = abs(sx / ds + kx / dk) * half_x + abs(sy / ds + ky / dk) * half_y
    radius2 = half_x * half_x + half_y * half_y
    radius = math.sqrt(radius2)
    curvature = 0.5 * radius2 * (1.0 / max(ds - radius, frame.source_height)
                                 + 1.0 / max(dk - radius, frame.sensor_height))
    d = ds + dk
    slack = _BOUND_SLACK * (d + linear + curvature)
    return d - linear - slack, d + linear + curvature + slack


@njit(cache=True, error_model="numpy")
def rectangle_crossings(frame, curve, box, out):
    """Angles φ where the isochrone ``curve`` crosses the four edge lines of the :class:`PixelBox` ``box``.

    x1(φ) = cx + R1 cos(φ + ψ1) and x2(φ) = cy + R2 cos(φ - ψ2), so each
    line gives at most two angles. Writes sorted angles in [0, 2π) into
    ``out`` and returns how many.
    """
    cx, cy, a, b = curve.centre_x, curve.centre_y, curve.a, curve.b
    x0, x1, y0, y1 = box
    e1 = frame.axis_x
    e2 = frame.axis_y
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
