"""Scalar values of scene tables, checked: a finite number (a length within range), a whole number.

Each helper raises :class:`~analytic.errors.SceneError` naming the key, so
every table's dataclass (:mod:`analytic.scenes.common`, :mod:`analytic.measurement.detector`,
:mod:`analytic.scenes.relay_wall`) says what is wrong the same way.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import SceneError

__all__ = ["MAX_LENGTH", "MIN_LENGTH", "exact", "huge_integer"]

#: Largest |length| or |coordinate| accepted, metres.
MAX_LENGTH = 1e12
#: Smallest positive length accepted (plane size, bin width), metres.
MIN_LENGTH = 1e-9


def exact(value: float) -> str:
    """A number as the shortest text that reads back as the same float64 (Python's ``repr``).

    For the value a message compares with a bound: ``f"{x:g}"`` of 9.999999999999999e-05 is "0.0001", which
    would hide why it is below 1e-4. NumPy scalars are shown as plain numbers ("1e-05", not "np.float64(1e-05)"),
    and whole numbers below 2^53 without a decimal point ("5", not "5.0").
    """
    value = float(value)
    if value.is_integer() and abs(value) < 2.0**53:
        return str(int(value))
    return repr(value)


def huge_integer(value: int) -> str:
    """The problem with a whole number past float64's range, without writing out its digits."""
    # str() of an int past Python's digit limit (4300) raises; its bit length tells its size
    return f"a whole number of about {int(abs(int(value)).bit_length() * math.log10(2)) + 1} digits is beyond " \
           f"the range of a float64"


def _number(key: str, value: Any, *, positive: bool = False, nonnegative: bool = False,
            length: bool = False) -> float:
    """A finite float; ``length``: within ±MAX_LENGTH and, if positive, at least MIN_LENGTH."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise SceneError(key, f"expected a number, got {value!r}")
    try:
        value = float(value)
    except OverflowError:
        raise SceneError(key, huge_integer(value)) from None
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
