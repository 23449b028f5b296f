"""Derivatives of the model's samples y with respect to the scene's parameters (docs/design.md section 9).

:func:`jacobian` returns ∂y/∂θ for parameters named by scene-file keys
(:mod:`.parameters`). Two parameters are exact by linearity: a reflectance
scale (∂y/∂s = y) and the source's intensity (∂y/∂I = y / I). The others
are, for now, Richardson-extrapolated central differences of the model
assembled at tolerance :data:`TOLERANCE` (``route="differences"``); the
exact route (interior and bin-edge terms) replaces them without changing
the callers.
"""

from __future__ import annotations

import numpy as np

from ..errors import OptionError
from ..scenes.scene_file import scene_of
from .parameters import Parameter, parameter, parameters, value_of, with_values
from .matrix_free import forward

__all__ = ["jacobian", "derivative", "TOLERANCE", "STEP"]

#: The model's tolerance inside the differences: its error over the step bounds the derivative's.
TOLERANCE = 1e-10
#: The first step of the differences, as a fraction of the parameter's scale (halved for Richardson).
STEP = 1e-3


def _scale(scene, item: Parameter) -> float:
    """The size against which a parameter's step is taken: the scene's extent, 1 rad, or the value."""
    if item.unit == "rad":
        return 1.0
    if item.stem.startswith("illumination.") or item.stem == "plane.size":
        return abs(value_of(scene, item))
    if scene.kind == "plane":
        points = np.vstack([np.asarray(scene.source)[None, :], np.asarray(scene.sensors)])
        return max(float(scene.size), float(np.max(np.abs(points))))
    return max(float(np.max(scene.wall_size)), float(np.linalg.norm(scene.center)))


def _differences(scene, item: Parameter, step: float) -> np.ndarray:
    tight = scene.replace(tolerance=min(TOLERANCE, scene.tolerance))
    start = value_of(scene, item)

    def central(h):
        return (forward(with_values(tight, {item.key: start + h}))
                - forward(with_values(tight, {item.key: start - h}))) / (2.0 * h)

    return (4.0 * central(step / 2.0) - central(step)) / 3.0


def jacobian(scene, keys, *, step: float | None = None) -> np.ndarray:
    """∂y/∂θ for each named parameter θ.

    Parameters
    ----------
    scene : SceneKind, str or Path
        A plane or relay-wall scene, or its file.
    keys : sequence of str
        Parameter keys of docs/design.md section 9 (``source.position.x``,
        ``sensors.positions.3.z``, ``sampling.start``, ...).
    step : float, optional
        The differences' first step as a fraction of each parameter's scale
        (default :data:`STEP`).

    Returns
    -------
    numpy.ndarray
        ``(K, N, P)`` float64: y's units per unit of each parameter (per
        metre, per radian, per W/sr, or per unit scale), K sensors (pairs
        for a relay wall), N bins, P keys in the order given.
    """
    scene = scene_of(scene)
    if isinstance(keys, str):
        keys = [keys]
    items = parameters(scene, list(keys))
    fraction = STEP if step is None else float(step)
    if not np.isfinite(fraction) or fraction <= 0.0:
        raise OptionError(f"step: expected a positive fraction, got {step!r}")
    y = None
    columns = []
    for item in items:
        if item.stem.endswith(".reflectance") or item.unit == "W/sr":
            y = forward(scene) if y is None else y
            columns.append(y if item.unit == "1" else y / value_of(scene, item))
        else:
            columns.append(_differences(scene, item, fraction * _scale(scene, item)))
    return np.stack(columns, axis=-1)


def derivative(scene, key: str, *, step: float | None = None) -> np.ndarray:
    """∂y/∂θ for one parameter: ``jacobian(scene, [key])[..., 0]``, ``(K, N)``."""
    return jacobian(scene, [key], step=step)[..., 0]
