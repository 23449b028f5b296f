"""Derivatives of the model's samples y with respect to the geometry: where exact derivatives will live.

For now every derivative is a finite difference of the exact model
(Richardson-extrapolated central differences, the model assembled at
tolerance :data:`TOLERANCE`), through the geometry door of
:mod:`analytic.geometry`: a parameter moves the rectangle or the points of
its pairs, and :func:`analytic.operator.system.rectangle_matrix` assembles A again.
An exact (analytic) derivative of a parameter replaces its entry in
:data:`PARAMETERS` without changing the callers; the finite differences then
become its test.

Parameters (what :func:`derivative` takes), each in metres or radians:

- ``source.position[i]``: the source's coordinate i (0, 1, 2: x, y, z);
- ``sensors.positions[k][i]``: sensor k's coordinate i;
- ``plane.translation[i]``: the plane moved rigidly along axis i;
- ``plane.rotation[i]``: the plane turned rigidly about the world axis i
  through its centre.
"""

from __future__ import annotations

import re

import numpy as np

from ..geometry import PointPairs, Rectangle, plane_geometry
from .system import rectangle_matrix
from ..waveforms import make_waveform

__all__ = ["derivative", "PARAMETERS", "TOLERANCE", "STEP"]

#: The model's tolerance inside the differences: its error over the step bounds the derivative's.
TOLERANCE = 1e-9
#: The first step of the differences, as a fraction of the scene's extent (halved for Richardson).
STEP = 1e-3

#: Parameter names (patterns) this module differentiates.
PARAMETERS = (r"source\.position\[[012]\]", r"sensors\.positions\[\d+\]\[[012]\]",
              r"plane\.translation\[[012]\]", r"plane\.rotation\[[012]\]")


def _rotation(axis: int, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    matrix = np.eye(3)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    matrix[i, i], matrix[i, j], matrix[j, i], matrix[j, j] = c, -s, s, c
    return matrix


def _moved(scene, parameter: str, amount: float) -> tuple[Rectangle, PointPairs]:
    """The scene's rectangle and pairs with one parameter changed by ``amount`` (metres or radians)."""
    rectangle, pairs = plane_geometry(scene)
    sources, sensors = np.array(pairs.sources), np.array(pairs.sensors)
    corner, u, v = rectangle.corner.copy(), rectangle.u.copy(), rectangle.v.copy()
    indices = [int(i) for i in re.findall(r"\[(\d+)\]", parameter)]
    if parameter.startswith("source."):
        sources[:, indices[0]] += amount
    elif parameter.startswith("sensors."):
        k, i = indices
        if not 0 <= k < len(sensors):
            raise ValueError(f"{parameter}: the scene has {len(sensors)} sensors")
        sensors[k, i] += amount
    elif parameter.startswith("plane.translation"):
        corner[indices[0]] += amount
    else:
        centre = corner + 0.5 * (u + v)
        turn = _rotation(indices[0], amount)
        corner, u, v = centre + turn @ (corner - centre), turn @ u, turn @ v
    return (Rectangle(corner, u, v, rectangle.pixels),
            PointPairs(sources, sensors, scales=pairs.scales, attenuation=pairs.attenuation))


def _samples(scene, parameter: str, amount: float) -> np.ndarray:
    rectangle, pairs = _moved(scene, parameter, amount)
    matrix = rectangle_matrix(rectangle, pairs, scene.sampling,
                              make_waveform(scene.illumination, scene.sampling.bin_width_opl), tolerance=TOLERANCE)
    return (matrix @ scene.reflectance.ravel()).reshape(scene.sensor_count, scene.sampling.count)


def derivative(scene, parameter: str, *, step: float | None = None) -> np.ndarray:
    """∂y/∂θ for one geometric parameter θ, by Richardson-extrapolated central differences.

    Parameters
    ----------
    scene : analytic.Scene
        The plane scene.
    parameter : str
        One of :data:`PARAMETERS` (e.g. ``"source.position[2]"``).
    step : float, optional
        First step h, metres (or radians); default :data:`STEP` x the
        scene's extent (or :data:`STEP` radians).

    Returns
    -------
    numpy.ndarray
        ``(K, N)``: units of y per metre (or per radian).

    Notes
    -----
    D(h) = (y(θ + h) - y(θ - h)) / 2h has error c₂ h² + c₄ h⁴ + ...; the
    extrapolation (4 D(h/2) - D(h)) / 3 removes the h² term. Its error is
    O(h⁴) from the differences plus ~tolerance x |y| / h from the model.
    A step that carries a bin edge across a pixel's range makes y jump
    in h's smooth expansion only as much as the entries change, which the
    model follows exactly: the derivative is that of the binned samples.
    """
    if not any(re.fullmatch(pattern, parameter) for pattern in PARAMETERS):
        raise ValueError(f"parameter: expected one of {', '.join(PARAMETERS)} (as patterns), got {parameter!r}")
    if step is None:
        extent = max(float(scene.size), float(np.max(np.abs(scene.sensors))), float(np.max(np.abs(scene.source))))
        step = STEP * (1.0 if parameter.startswith("plane.rotation") else extent)

    def central(h):
        return (_samples(scene, parameter, h) - _samples(scene, parameter, -h)) / (2.0 * h)

    return (4.0 * central(step / 2.0) - central(step)) / 3.0
