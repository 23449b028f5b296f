"""How the ``transient_opl`` integrator draws its plane points: the sampling techniques and their densities.

A technique draws x on the rectangle [0, a] x [0, b] (the plane's frame,
metres) either uniformly by area, or by the solid angle a point (the source
or a sensor) sees it under (:mod:`transient.spherical_rectangle`), with
p(x) = h / (Ω d³). :func:`sampling_kind` picks area where the solid angle's
density varies too little to pay for its map; :func:`peak_ratio` says how
heavy-tailed a sensor's weights would be with points drawn for the source;
:func:`block_bounds` deals a replica's samples out to the techniques;
:func:`warp` maps each sample's (u, v) to x by its technique and
:func:`mixture_density` gives the density of all of them together, the
balance heuristic's denominator. Which techniques a scene gets is the
integrator's choice (:func:`transient.plane.techniques`).

Import only after :func:`transient.backend.select_variant`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi
import numpy as np

from . import spherical_rectangle
from .common import height_over_cube

__all__ = ["Technique", "AREA", "SOLID_ANGLE", "AREA_SAMPLING_RATIO", "sampling_kind", "peak_ratio",
           "block_bounds", "warp", "mixture_density"]

#: A point whose density h / d³ varies by less than this factor r over the
#: rectangle is sampled by area: the variance of area sampling is then
#: within (1 + r)² / (4 r) = 4/3 of the solid angle's (Kantorovich's
#: bound), while the solid angle's map costs more per sample (docs/benchmarks.md).
AREA_SAMPLING_RATIO = 3.0

#: Technique kinds: uniform by area, or by the solid angle from a point.
AREA, SOLID_ANGLE = 0, 1


class Technique(NamedTuple):
    """One way of drawing plane points, and its share of each replica.

    Attributes
    ----------
    kind : int
        ``AREA`` (uniform, p = 1 / (a b)) or ``SOLID_ANGLE`` (p = h / (Ω d³)
        from ``point``).
    point : (float, float, float)
        (x, y, h) in the plane's frame, metres: the source or a sensor.
    share : float
        Fraction of each replica's samples drawn this way.
    rectangle : SphericalRectangle or None
        The constants of the solid-angle map (``SOLID_ANGLE`` only).
    """

    kind: int
    point: tuple
    share: float
    rectangle: object


def peak_ratio(source: Technique, sensor, width: float, height: float) -> float:
    """max over x of cos θ_k / d_k² / p_s(x), over its mean ∫ cos θ_s cos θ_k / (d_s² d_k²) dx.

    The mean comes from a fixed 64 x 64 stratified estimate by the
    sensor's own solid angle (the integrand's peak), which is accurate to
    far better than the factor this ratio is compared with.
    """
    if sampling_kind(sensor, width, height) == AREA:
        # its h / d³ varies under AREA_SAMPLING_RATIO over the rectangle: no peak to tame (and a
        # rectangle it sees under an unresolvably small solid angle has no spherical set-up)
        return 1.0
    sx, sy, sh = source.point
    kx, ky, kh = sensor
    nearest = math.hypot(max(0.0, -kx, kx - width), max(0.0, -ky, ky - height))
    closest = math.sqrt(nearest**2 + kh**2)
    if source.kind == SOLID_ANGLE:
        peak = source.rectangle.solid_angle * kh / closest**3
    else:
        source_nearest = math.hypot(max(0.0, -sx, sx - width), max(0.0, -sy, sy - height))
        peak = width * height * sh / math.hypot(source_nearest, sh) ** 3 * kh / closest**3
    own = spherical_rectangle.setup(sensor, width, height)
    cells = (np.arange(64) + 0.5) / 64
    u, v = np.meshgrid(cells, cells)
    x, y = (np.array(c, dtype=np.float64) for c in
            spherical_rectangle.sample(own, mi.Float64(u.ravel()), mi.Float64(v.ravel())))
    source_squared = (x - sx) ** 2 + (y - sy) ** 2 + sh * sh
    # ∫ (h_s / d_s³)(h_k / d_k³) dA by the sensor's own solid angle: the sensor factor is Ω_k p_k.
    mean = own.solid_angle * float(np.mean(sh / (source_squared * np.sqrt(source_squared))))
    return peak / mean


def sampling_kind(point, width: float, height: float) -> int:
    """``AREA`` where h / d³ varies by less than :data:`AREA_SAMPLING_RATIO` over the rectangle."""
    x, y, h = point
    nearest = math.hypot(max(0.0, -x, x - width), max(0.0, -y, y - height))
    farthest = math.hypot(max(abs(x), abs(x - width)), max(abs(y), abs(y - height)))
    ratio = (math.hypot(farthest, h) / math.hypot(nearest, h)) ** 3
    return AREA if ratio < AREA_SAMPLING_RATIO else SOLID_ANGLE


def block_bounds(shares, replica_size: int) -> list[int]:
    """First sample index of each technique's block in a replica, and n at the end.

    Block t holds round(n Σ_{s<t} share_s) ... : every technique with a
    positive share gets at least one sample when n >= number of techniques.
    """
    cumulative = np.concatenate([[0.0], np.cumsum(shares)])
    bounds = [int(round(c * replica_size)) for c in cumulative[:-1]] + [int(replica_size)]
    for t in range(1, len(bounds) - 1):      # never an empty block when n allows
        bounds[t] = min(max(bounds[t], bounds[t - 1] + 1), replica_size - (len(bounds) - 1 - t))
    return bounds


def warp(plan, technique, u, v, width: float, height: float):
    """The plane point (x, y) of (u, v) ∈ [0, 1)² under each sample's technique.

    Parameters
    ----------
    plan : list of Technique
    technique : mitsuba.UInt32
        Each sample's index into ``plan``.
    u, v : mitsuba.Float64
        Each sample's point of the unit square.
    width, height : float
        The rectangle's sides a, b, metres.

    Returns
    -------
    x, y : mitsuba.Float64
        Plane coordinates, metres.
    """
    area = (u * width, v * height)
    kinds = {t.kind for t in plan}
    if kinds == {AREA}:
        return area
    solid = [t for t in plan if t.kind == SOLID_ANGLE]
    if len(solid) == 1:
        rectangle = solid[0].rectangle
    else:
        # Gather each sample's constants (area techniques read a solid-angle one, unused).
        order = [t if t.kind == SOLID_ANGLE else solid[0] for t in plan]
        fields = spherical_rectangle.SphericalRectangle._fields
        gathered = {}
        for name in fields:
            if name == "point":
                continue
            table = mi.Float64([getattr(t.rectangle, name) for t in order])
            gathered[name] = dr.gather(mi.Float64, table, technique)
        points = [mi.Float64([t.rectangle.point[i] for t in order]) for i in range(3)]
        gathered["point"] = tuple(dr.gather(mi.Float64, p, technique) for p in points)
        rectangle = spherical_rectangle.SphericalRectangle(**gathered)
    x, y = spherical_rectangle.sample(rectangle, u, v)
    if kinds == {SOLID_ANGLE}:
        return x, y
    is_area = dr.gather(mi.Bool, mi.Bool([t.kind == AREA for t in plan]), technique)
    return dr.select(is_area, area[0], x), dr.select(is_area, area[1], y)


def mixture_density(plan, shares, x, y, width: float, height: float):
    """p(x) = Σ_t share_t p_t(x), per square metre: the density of the whole replica's points.

    Parameters
    ----------
    plan : list of Technique
    shares : list of mitsuba.Float64
        Each technique's share of the replica's samples.
    x, y : mitsuba.Float64
        Plane coordinates, metres.
    width, height : float
        The rectangle's sides a, b, metres.
    """
    total = mi.Float64(0.0)
    for technique, share in zip(plan, shares):
        if technique.kind == AREA:
            total += share / (width * height)
        else:
            total += share * height_over_cube(x, y, technique.point) / technique.rectangle.solid_angle
    return total
