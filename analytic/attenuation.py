"""Attenuation a_k(x) of docs/design.md section 2, written once for NumPy, Numba and Dr.Jit.

| name | a_k(x) |
| lambertian | cos θ_s cos θ_k / (π d_s² d_k²) — physical transport, what Mitsuba renders |
| paper | cos θ_s / (d_s² d_k²) — the paper's eq. (1), without Lambert's outgoing cos θ_k and the BRDF's 1/π |

The two differ pointwise by exactly π / cos θ_k (docs/design.md section 3.2).
With h the heights of the two ends above the rectangle, cos θ = h / d:
:func:`attenuation_formula` writes a_k from the heights and squared
distances with the array module's square root as its one argument, so the
NumPy form (:func:`attenuation`), the compiled scalar form the quadrature
calls (:func:`attenuation_of_distances`, :func:`attenuation_at`) and the
renderer's Dr.Jit form (``attenuation_formula(drjit.sqrt)``) are one
expression. Where an end has a surface of its own (a relay wall's point),
its cosine n·(x - p) / d multiplies a_k (:func:`attenuation_at`).
"""

from __future__ import annotations

import math

import numpy as np

from .geometry import ATTENUATIONS
from .kernel_cache import njit

__all__ = ["attenuation", "attenuation_formula", "attenuation_at", "attenuation_of_distances",
           "attenuation_code", "ATTENUATIONS", "LAMBERTIAN", "PAPER"]

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


def attenuation_formula(sqrt):
    """a_k from heights and squared distances, for an array module's ``sqrt``.

    Parameters
    ----------
    sqrt : callable
        ``math.sqrt`` (compiled code), ``numpy.sqrt`` or ``drjit.sqrt``.

    Returns
    -------
    callable
        ``a(mode, source_height, source_squared, sensor_height,
        sensor_squared)``: heights h_s, h_k in metres, squared distances
        d_s², d_k² in m², ``mode`` :data:`LAMBERTIAN` or :data:`PAPER`
        (a Python int: a branch at trace time for Dr.Jit); 1/m⁴.

    Notes
    -----
    lambertian h_s h_k / (π d_s³ d_k³), paper h_s / (d_s³ d_k²).
    """
    def formula(mode, source_height, source_squared, sensor_height, sensor_squared):
        source_cube = source_squared * sqrt(source_squared)
        if mode == LAMBERTIAN:
            return source_height * sensor_height / (math.pi * source_cube * sensor_squared * sqrt(sensor_squared))
        return source_height / (source_cube * sensor_squared)
    return formula


_numpy_formula = attenuation_formula(np.sqrt)

#: The formula compiled (scalars, ``math.sqrt``).
_compiled_formula = njit(cache=True, error_model="numpy")(attenuation_formula(math.sqrt))


def attenuation(points, source, sensor, kind: str = "lambertian") -> np.ndarray:
    """a_k(x) at plane points ``(..., 2)`` of the z = 0 plane, 1/m⁴ (per unit source intensity).

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
    """
    code = attenuation_code(kind)
    points = np.asarray(points, dtype=np.float64)
    x, y = points[..., 0], points[..., 1]
    source = np.asarray(source, dtype=np.float64)
    sensor = np.asarray(sensor, dtype=np.float64)
    source_squared = (x - source[0]) ** 2 + (y - source[1]) ** 2 + source[2] ** 2
    sensor_squared = (x - sensor[0]) ** 2 + (y - sensor[1]) ** 2 + sensor[2] ** 2
    return _numpy_formula(code, source[2], source_squared, sensor[2], sensor_squared)


@njit(cache=True, error_model="numpy")
def attenuation_of_distances(frame, x, y, source_squared, sensor_squared):
    """a_k at the rectangle point (x, y) with squared distances d_s², d_k² (m²) to the pair's ends, 1/m⁴.

    Parameters
    ----------
    frame : analytic.isochrone.Frame
        The pair (heights, attenuation ``mode``, end cosines).
    x, y : float
        The point in the rectangle's frame, metres.
    source_squared, sensor_squared : float
        d_s², d_k², m².

    Notes
    -----
    :func:`attenuation_formula`, times n·(x - p) / d at each end that has
    a surface (``frame.source_cosine``, ``frame.sensor_cosine``).
    """
    value = _compiled_formula(frame.mode, frame.source_height, source_squared, frame.sensor_height,
                              sensor_squared)
    if frame.source_cosine:
        value *= (frame.source_cosine_0 + frame.source_cosine_u * x + frame.source_cosine_v * y) / math.sqrt(
            source_squared)
    if frame.sensor_cosine:
        value *= (frame.sensor_cosine_0 + frame.sensor_cosine_u * x + frame.sensor_cosine_v * y) / math.sqrt(
            sensor_squared)
    return value


@njit(cache=True, error_model="numpy")
def attenuation_at(frame, x, y):
    """a_k(x) at one rectangle point (x, y), metres, 1/m⁴, compiled.

    Parameters
    ----------
    frame : analytic.isochrone.Frame
        The pair (positions, heights, attenuation ``mode``, end cosines).
    x, y : float
        The point in the rectangle's frame, metres.
    """
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    return attenuation_of_distances(frame, x, y, ds2, dk2)
