"""Scalar values of scene tables, checked: a finite number (a length within range), a whole number.

Each helper raises :class:`~analytic.errors.SceneError` naming the key, so
every table's dataclass (:mod:`analytic.scene`, :mod:`analytic.detector`,
:mod:`analytic.relay_wall`) says what is wrong the same way.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import SceneError

__all__ = ["MAX_LENGTH", "MIN_LENGTH"]

#: Largest |length| or |coordinate| accepted, metres.
MAX_LENGTH = 1e12
#: Smallest positive length accepted (plane size, bin width), metres.
MIN_LENGTH = 1e-9


def _number(key: str, value: Any, *, positive: bool = False, nonnegative: bool = False,
            length: bool = False) -> float:
    """A finite float; ``length``: within ±MAX_LENGTH and, if positive, at least MIN_LENGTH."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SceneError(key, f"expected a number, got {value!r}")
    try:
        value = float(value)
    except OverflowError:
        raise SceneError(key, f"{value} is beyond the range of a float64") from None
    if not math.isfinite(value):
        raise SceneError(key, f"must be finite, got {value}")
    if positive and not value > 0.0:
        raise SceneError(key, f"must be > 0, got {value}")
    if nonnegative and not value >= 0.0:
        raise SceneError(key, f"must be >= 0, got {value}")
    if length:
        if abs(value) > MAX_LENGTH:
            raise SceneError(key, f"{value} m is beyond the ±{MAX_LENGTH:g} m this tool resolves in float64")
        if positive and value < MIN_LENGTH:
            raise SceneError(key, f"{value} m is below the smallest length supported, {MIN_LENGTH:g} m")
    return value


def _integer(key: str, value: Any, *, minimum: int = 1, maximum: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        else:
            raise SceneError(key, f"expected a whole number, got {value!r}")
    value = int(value)
    if value < minimum:
        raise SceneError(key, f"must be >= {minimum}, got {value}")
    if maximum is not None and value > maximum:
        raise SceneError(key, f"must be <= {maximum}, got {value}")
    return value
