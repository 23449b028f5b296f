"""Exact ∂y/∂θ of a relay-wall capture for the laser's and the sensor's positions (docs/derivatives.md).

The model counts the third bounce laser -> l -> x -> s -> sensor and gives each pair (l, s) the
constant factor of its laser leg (:meth:`analytic.scenes.relay_wall.RelayWallScene.laser_leg`),

    c_l = I (ρ_w / π)² n·(o - l) / |o - l|³ ,

o the laser's position and n the wall's normal. Unless the first and last legs are counted in the
path lengths (``scan.account_first_and_last_bounces``: then o and the sensor's position also shift
every pair's time axis), the laser's position enters y only through c_l and the sensor's position not
at all, so

    ∂y_p/∂o = y_p ∂ln c_l/∂o = y_p [n / n·(o - l) - 3 (o - l) / |o - l|²],     ∂y/∂o_s = 0,

exact to the model's own precision at the cost of one forward (none for the sensor).
"""

from __future__ import annotations

import numpy as np

from ..scenes.relay_wall import WALL_NORMAL

__all__ = ["supports_leg", "leg_column"]

_STEMS = ("laser.position", "sensor.position")


def supports_leg(scene, stem: str) -> bool:
    """Whether :func:`leg_column` gives ``stem``'s column: a relay wall whose end legs are not counted."""
    return (scene.kind == "relay_wall" and stem in _STEMS
            and not bool(scene.scan.account_first_and_last_bounces))


def leg_column(scene, stem: str, axis: int, y: np.ndarray) -> np.ndarray:
    """∂y/∂(``stem``'s ``axis`` component), ``(P, N)``, from the model's samples ``y`` (``(P, N)``).

    Parameters
    ----------
    scene : RelayWallScene
        A capture :func:`supports_leg` accepts.
    stem : {"laser.position", "sensor.position"}
    axis : int
        0, 1, 2 for x, y, z.
    y : numpy.ndarray
        The model's samples of ``scene``, y's units.

    Returns
    -------
    numpy.ndarray
        y's units per metre.
    """
    if stem == "sensor.position":
        return np.zeros_like(y)
    lit, _ = scene.pair_points
    toward = np.asarray(scene.laser_position, dtype=np.float64) - lit
    along = toward @ WALL_NORMAL
    rate = WALL_NORMAL[axis] / along - 3.0 * toward[:, axis] / np.einsum("pj,pj->p", toward, toward)
    return y * rate[:, None]
