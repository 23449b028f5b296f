"""Attenuation a_k(x) of DESIGN.md section 2, vectorised over plane points.

| name | a_k(x) |
| lambertian | cos θ_s cos θ_k / (π d_s² d_k²) — physical transport, what Mitsuba renders |
| paper | cos θ_s / (d_s² d_k²) — the paper's eq. (1), without Lambert's outgoing cos θ_k and the BRDF's 1/π |

The two differ pointwise by exactly π / cos θ_k (DESIGN.md section 3.2).
The compiled scalar twin used by the quadrature is
:func:`analytic.isochrone.attenuation_at`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["attenuation"]


def _distances(points, source, sensor):
    points = np.asarray(points, dtype=np.float64)
    x, y = points[..., 0], points[..., 1]
    source = np.asarray(source, dtype=np.float64)
    sensor = np.asarray(sensor, dtype=np.float64)
    d_source = np.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
    d_sensor = np.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2)
    return d_source, d_sensor


def attenuation(points, source, sensor, kind: str = "lambertian") -> np.ndarray:
    """a_k(x) at plane points ``(..., 2)``, 1/m⁴ (per unit source intensity).

    Parameters
    ----------
    points : array_like
        ``(..., 2)`` plane points (x, y), metres.
    source, sensor : array_like
        Positions (x, y, z), metres, z > 0.
    kind : {"lambertian", "paper"}
    """
    d_source, d_sensor = _distances(points, source, sensor)
    cos_source = np.asarray(source, dtype=np.float64)[2] / d_source
    cos_sensor = np.asarray(sensor, dtype=np.float64)[2] / d_sensor
    if kind == "lambertian":
        return cos_source * cos_sensor / (np.pi * d_source**2 * d_sensor**2)
    if kind == "paper":
        return cos_source / (d_source**2 * d_sensor**2)
    raise ValueError(f"attenuation must be 'lambertian' or 'paper', got {kind!r}")
