"""a_k(x) at points of a rectangle, compiled: :func:`.formulas.attenuation_formula` and the relay wall's cosines."""

from __future__ import annotations

import math

from .cache import njit
from .formulas import attenuation_formula

__all__ = ["attenuation_at", "attenuation_of_distances"]

#: The formula compiled (scalars, ``math.sqrt``).
_compiled_formula = njit(cache=True, error_model="numpy")(attenuation_formula(math.sqrt))


@njit(cache=True, error_model="numpy")
def attenuation_of_distances(frame, x, y, source_squared, sensor_squared):
    """a_k at the rectangle point (x, y) with squared distances d_s², d_k² (m²) to the pair's ends, 1/m⁴.

    Parameters
    ----------
    frame : analytic.kernels.isochrone.Frame
        The pair (heights, attenuation ``mode``, end cosines).
    x, y : float
        The point in the rectangle's frame, metres.
    source_squared, sensor_squared : float
        d_s², d_k², m².

    Notes
    -----
    :func:`.formulas.attenuation_formula`, times n·(x - p) / d at each end that has
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
    frame : analytic.kernels.isochrone.Frame
        The pair (positions, heights, attenuation ``mode``, end cosines).
    x, y : float
        The point in the rectangle's frame, metres.
    """
    ds2 = (x - frame.source_x) ** 2 + (y - frame.source_y) ** 2 + frame.source_height ** 2
    dk2 = (x - frame.sensor_x) ** 2 + (y - frame.sensor_y) ** 2 + frame.sensor_height ** 2
    return attenuation_of_distances(frame, x, y, ds2, dk2)
