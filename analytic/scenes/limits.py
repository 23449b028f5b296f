"""The scene's numeric limits that float64 sets: the smallest height above the plane and the model's tolerance.

Every length is in metres (docs/design.md section 1); :mod:`analytic.scenes.common`
re-exports these names and checks heights with them (:func:`analytic.scenes.common.check_heights`).
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from ..values import _number, exact

__all__ = ["MAX_INTENSITY", "MIN_INTENSITY", "check_intensity", "MIN_HEIGHT_FRACTION", "MIN_TOLERANCE", "MAX_TOLERANCE", "scene_extent", "minimum_height",
           "check_tolerance"]

#: Smallest height of the source or a sensor, as a fraction of the scene's extent
#: (:func:`analytic.scenes.common.check_heights`).
MIN_HEIGHT_FRACTION = 1e-9
#: Relative accuracy of A's entries: below MIN_TOLERANCE float64 quadrature stops converging.
MIN_TOLERANCE = 1e-10
MAX_TOLERANCE = 0.1

#: Largest source intensity, W/sr: y (and the squares the λ rules form) stay finite.
MAX_INTENSITY = 1e30
#: Smallest source intensity, W/sr: below it y leaves float64's normal range (a 1e-320 W/sr source gave
#: all-zero or two-digit subnormal transients); at it, y ∝ I holds to 1e-6 for scenes of a few metres
#: (tests/cli/probe/test_numbers.py, "intensity law", a slow case). Far scenes reach subnormal y sooner: scale I up
#: and y down.
MIN_INTENSITY = 1e-300


def scene_extent(size: float, source, sensors) -> float:
    """The scene's length scale: the largest of the plane's side and every coordinate's magnitude, metres.

    Plane coordinates and path lengths are as large as this, so it sets the
    float64 rounding of everything the model computes.
    """
    points = np.vstack([np.reshape(np.asarray(source, dtype=np.float64), (1, 3)),
                        np.reshape(np.asarray(sensors, dtype=np.float64), (-1, 3))])
    return float(max(abs(float(size)), float(np.max(np.abs(points)))))


def minimum_height(size: float, source, sensors) -> float:
    """Smallest supported height of the source and the sensors, metres: MIN_HEIGHT_FRACTION x extent."""
    return MIN_HEIGHT_FRACTION * scene_extent(size, source, sensors)


def check_tolerance(tolerance: float) -> float:
    """The tolerance as a float, or SceneError("model.tolerance") outside [MIN_TOLERANCE, MAX_TOLERANCE)."""
    tolerance = _number("model.tolerance", tolerance, positive=True)
    if not MIN_TOLERANCE <= tolerance < MAX_TOLERANCE:
        raise SceneError("model.tolerance", f"must be in [{MIN_TOLERANCE:g}, {MAX_TOLERANCE:g}), got "
                         f"{exact(tolerance)}: below {MIN_TOLERANCE:g} float64 quadrature stops converging "
                         f"(1e-12 already takes ~60 times as long as the default 1e-6)")
    return tolerance


def check_intensity(key: str, value) -> float:
    """A source's radiant intensity, W/sr, in [MIN_INTENSITY, MAX_INTENSITY], else a SceneError naming ``key``."""
    intensity = _number(key, value, positive=True)
    if intensity > MAX_INTENSITY:
        raise SceneError(key, f"{exact(intensity)} W/sr is beyond the {MAX_INTENSITY:g} W/sr supported (y and "
                              f"its squares must stay finite)")
    if intensity < MIN_INTENSITY:
        raise SceneError(key, f"{exact(intensity)} W/sr is below the {MIN_INTENSITY:g} W/sr supported, where y "
                              f"would leave float64's normal range and lose its digits; y is linear in the "
                              f"intensity: model a larger one and scale the result")
    return intensity
