"""Points on a rectangle distributed by the solid angle they subtend from a point above it.

Ureña, Fajardo and King, "An area-preserving parametrization for spherical
rectangles", Computer Graphics Forum 32(4), 2013. Seen from a point p at
height h above the rectangle [0, a] x [0, b] (in the rectangle's own frame),
the rectangle subtends the solid angle Ω; the map (u, v) ∈ [0, 1)² -> x
below sends the uniform distribution to the density

    p(x) = cos θ / (Ω d²) = h / (Ω d³)      per unit area, d = |x - p|,

which is exactly the shape of a point source's irradiance cos θ_s / d_s²
(or of a point sensor's cos θ_k / d_k²). Sampling by it leaves a bounded
weight where area sampling has a 1/d² spike below a low point.

:func:`setup` computes the constants of one point on the host (float64,
NumPy); :func:`sample` maps (u, v) in a Dr.Jit kernel. Both are float64
throughout, with true divisions and square roots (no approximate
reciprocals, which CUDA would otherwise use). The solid angle comes from four angles that add up to 2π + Ω,
so its absolute rounding error is a few 1e-16: relative 1e-10 at Ω = 1e-6
(a 1 m plane 1 km away). :func:`transient.plane.techniques` uses area
sampling instead where the density varies by less than a factor 3 over
the rectangle, so far points never reach that regime.

Import :func:`sample` only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = ["SphericalRectangle", "setup", "density", "sample"]


class SphericalRectangle(NamedTuple):
    """The constants of the map for one point (metres and radians).

    Attributes
    ----------
    point : (float, float, float)
        (p_x, p_y, h) in the rectangle's frame, h > 0.
    x0, x1, y0, y1 : float
        The rectangle relative to the point's foot: [x0, x1] x [y0, y1].
    z0 : float
        -h.
    b0, b1 : float
        z components of the normals of the planes through p and the edges
        y = y0 and y = y1.
    k : float
        2π - γ2 - γ3, the azimuth offset.
    solid_angle : float
        Ω, steradians.
    """

    point: tuple
    x0: float
    x1: float
    y0: float
    y1: float
    z0: float
    b0: float
    b1: float
    k: float
    solid_angle: float


def setup(point, width: float, height: float) -> SphericalRectangle:
    """The constants for a point above the rectangle [0, width] x [0, height] (its own frame).

    Parameters
    ----------
    point : array_like
        (p_x, p_y, h), metres, h > 0.
    width, height : float
        Rectangle sides a, b, metres.

    Returns
    -------
    SphericalRectangle
    """
    px, py, h = (float(v) for v in point)
    if not h > 0.0:
        raise ValueError(f"the point must lie above the rectangle (height > 0), got {h}")
    x0, y0, z0 = -px, -py, -h
    x1, y1 = x0 + float(width), y0 + float(height)
    # Normals of the four planes through p and an edge (inward), in closed form.
    n0 = np.array([0.0, z0, -y0]) / math.hypot(z0, y0)
    n1 = np.array([-z0, 0.0, x1]) / math.hypot(z0, x1)
    n2 = np.array([0.0, -z0, y1]) / math.hypot(z0, y1)
    n3 = np.array([z0, 0.0, -x0]) / math.hypot(z0, x0)
    g0 = math.acos(float(np.clip(-n0 @ n1, -1.0, 1.0)))
    g1 = math.acos(float(np.clip(-n1 @ n2, -1.0, 1.0)))
    g2 = math.acos(float(np.clip(-n2 @ n3, -1.0, 1.0)))
    g3 = math.acos(float(np.clip(-n3 @ n0, -1.0, 1.0)))
    k = 2.0 * math.pi - g2 - g3
    solid_angle = g0 + g1 - k
    if not solid_angle > 0.0:
        raise ValueError(f"the rectangle subtends no resolvable solid angle from {point} ({solid_angle})")
    return SphericalRectangle((px, py, h), x0, x1, y0, y1, z0, float(n0[2]), float(n2[2]), k, solid_angle)


def density(rectangle: SphericalRectangle, x, y) -> np.ndarray:
    """p(x) = h / (Ω d³), per square metre, at plane points (NumPy)."""
    px, py, h = rectangle.point
    squared = (np.asarray(x) - px) ** 2 + (np.asarray(y) - py) ** 2 + h * h
    return h / (rectangle.solid_angle * squared * np.sqrt(squared))


def sample(rectangle, u, v):
    """The plane point of (u, v) ∈ [0, 1)² (Dr.Jit Float64).

    Parameters
    ----------
    rectangle : SphericalRectangle
        Constants as Python floats, or a record of the same fields holding
        ``mi.Float64`` (gathered per sample when techniques differ).
    u, v : mi.Float64

    Returns
    -------
    x, y : mi.Float64
        The point in the rectangle's frame, metres, inside the rectangle.

    Notes
    -----
    u fixes the azimuth of the sampled direction around the point's foot
    (a sub-solid-angle u Ω, solved in closed form for the abscissa x_u), v
    the height along the resulting segment of constant x, uniform in
    solid angle (Ureña et al., Algorithm 1).
    """
    import drjit as dr
    import mitsuba as mi

    px, py, _ = rectangle.point
    z0, b0, b1 = rectangle.z0, rectangle.b0, rectangle.b1
    azimuth = u * rectangle.solid_angle + rectangle.k
    tangent = (dr.cos(azimuth) * b0 - b1) / dr.sin(azimuth)
    cosine = dr.clip(dr.copysign(1.0, tangent) / dr.sqrt(dr.square(tangent) + b0 * b0), -1.0, 1.0)
    along_x = -(cosine * z0) / dr.sqrt(dr.maximum(1.0 - dr.square(cosine), 1e-300))
    along_x = dr.clip(along_x, rectangle.x0, rectangle.x1)
    # sin(azimuth) = 0 lies on the plane through the foot: x_u = 0 there.
    along_x = dr.select(dr.isfinite(along_x), along_x, mi.Float64(0.0))
    distance = dr.sqrt(dr.square(along_x) + z0 * z0)
    low = rectangle.y0 / dr.sqrt(dr.square(distance) + rectangle.y0 ** 2)
    high = rectangle.y1 / dr.sqrt(dr.square(distance) + rectangle.y1 ** 2)
    heights = low + v * (high - low)
    squared = dr.square(heights)
    along_y = dr.select(squared < 1.0 - 1e-15,
                        heights * distance / dr.sqrt(dr.maximum(1.0 - squared, 1e-300)),
                        mi.Float64(rectangle.y1))
    along_y = dr.clip(along_y, rectangle.y0, rectangle.y1)
    width, height = rectangle.x1 - rectangle.x0, rectangle.y1 - rectangle.y0
    return dr.clip(px + along_x, 0.0, width), dr.clip(py + along_y, 0.0, height)
