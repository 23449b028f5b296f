"""Attenuation a_k(x) of DESIGN.md section 2, once per execution backend.

| name | a_k(x) |
| lambertian | cos θ_s cos θ_k / (π d_s² d_k²) — physical transport, what Mitsuba renders |
| paper | cos θ_s / (d_s² d_k²) — the paper's eq. (1), without Lambert's outgoing cos θ_k and the BRDF's 1/π |

The two differ pointwise by exactly π / cos θ_k (DESIGN.md section 3.2).
:func:`attenuation` is the NumPy form (vectorised over plane points);
:func:`attenuation_at` the compiled scalar form the quadrature calls. The
Dr.Jit form lives with the renderer (``transient``).
"""

from __future__ import annotations

import math

import numpy as np
from .kernel_cache import njit

__all__ = ["attenuation", "attenuation_at", "attenuation_of_distances", "attenuation_code", "LAMBERTIAN",
           "PAPER"]

#: Integer codes of the attenuation kinds for compiled code (``Frame.mode``).
LAMBERTIAN, PAPER = 0, 1

_CODES = {"lambertian": LAMBERTIAN, "paper": PAPER}


def attenuation_code(kind: str) -> int:
    """The compiled code (:data:`LAMBERTIAN` or :data:`PAPER`) of an attenuation name.

    Parameters
    ----------
    kind : {"lambertian", "paper"}
        The scene's ``[model] attenuation``.
    """
    try:
        return _CODES[kind]
    except KeyError:
        raise ValueError(f"attenuation must be 'lambertian' or 'paper', got {kind!r}") from None


def attenuation(points, source, sensor, kind: str = "lambertian") -> np.ndarray:
    """a_k(x) at plane points ``(..., 2)``, 1/m⁴ (per unit source intensity).

    Parameters
    ----------
    points : array_like
        ``(..., 2)`` plane points (x, y), metres.
    source, sensor : array_like
        Positions (x, y, z), metres, z > 0.
    kind : {"lambertian", "paper"}
        Which attenuation (see the module docstring).

    Returns
    -------
    numpy.ndarray
        ``points.shape[:-1]``, 1/m⁴.

    Notes
    -----
    With h_s, h_k the heights, cos θ = h / d, so
    lambertian = h_s h_k / (π d_s³ d_k³) and paper = h_s / (d_s³ d_k²).
    """
    code = attenuation_code(kind)
    points = np.asarray(points, dtype=np.float64)
    x, y = points[..., 0], points[..., 1]
    source = np.asarray(source, dtype=np.float64)
    sensor = np.asarray(sensor, dtype=np.float64)
    d_source = np.sqrt((x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2)
    d_sensor = np.sqrt((x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2)
    cos_source = source[2] / d_source
    cos_sensor = sensor[2] / d_sensor
    if code == LAMBERTIAN:
        return cos_source * cos_sensor / (np.pi * d_source**2 * d_sensor**2)
    return cos_source / (d_source**2 * d_sensor**2)


@njit(cache=True, error_model="numpy")
def attenuation_of_distances(frame, source_squared, sensor_squared):
    """a_k from the squared distances d_s², d_k² of a plane point, 1/m⁴, compiled.

    Parameters
    ----------
    frame : analytic.isochrone.Frame
        The source-sensor pair (heights and attenuation ``mode``).
    source_squared, sensor_squared : float
        d_s², d_k², m².

    Notes
    -----
    lambertian h_s h_k / (π d_s³ d_k³), paper h_s / (d_s³ d_k²): the same
    expressions as :func:`attenuation` with cos θ = h / d.
    """
    ds3 = source_squared * math.sqrt(source_squared)
    if frame.mode == LAMBERTIAN:
        return (frame.source_height * frame.sensor_height
                / (math.pi * ds3 * sensor_squared * math.sqrt(sensor_squared)))
    return frame.source_height / (ds3 * sensor_squared)


@njit(cache=True, error_model="numpy")
def attenuation_at(frame, x, y):
    """a_k(x) at one plane point (x, y), metres, 1/m⁴, compiled.

    Parameters
    ----------
    frame : analytic.isochrone.Frame
        The source-sensor pair (positions, heights and attenuation ``mode``).
    x, y : float
        Plane point, metres.
    """
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    return attenuation_of_distances(frame, ds2, dk2)
