"""Attenuation a_k(x) of docs/design.md section 2, written once for NumPy, Numba and Dr.Jit.

| name | a_k(x) |
| lambertian | cos θ_s cos θ_k / (π d_s² d_k²) — physical transport, what Mitsuba renders |
| paper | cos θ_s / (d_s² d_k²) — the paper's eq. (1), without Lambert's outgoing cos θ_k and the BRDF's 1/π |

The two differ pointwise by exactly π / cos θ_k (docs/design.md section 3.2).
With h the heights of the two ends above the rectangle, cos θ = h / d:
:func:`attenuation_formula` writes a_k from the heights and squared
distances with the array module's square root as its one argument, so the
NumPy form (:func:`attenuation`), the compiled scalar form the quadrature
calls (:mod:`analytic.kernels.attenuation`) and the
renderer's Dr.Jit form (``attenuation_formula(drjit.sqrt)``) are one
expression. Where an end has a surface of its own (a relay wall's point),
its cosine n·(x - p) / d multiplies a_k (:func:`attenuation_at`).
"""

from __future__ import annotations

import numpy as np

from .geometry import ATTENUATIONS
from .kernels.formulas import LAMBERTIAN, PAPER, attenuation_formula

__all__ = ["attenuation", "attenuation_formula", "attenuation_code", "ATTENUATIONS", "LAMBERTIAN", "PAPER"]

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


_numpy_formula = attenuation_formula(np.sqrt)

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
