"""A user's numbers, checked: real, finite float64 arrays of the shape a call needs, or one line saying why not.

Every public call of :mod:`validation` that takes arrays (``compare_transients``,
``check_transient``, ``assert_agrees``) reads them through :func:`real_array`
and its options through :func:`false_alarm_rate` and :func:`whole_number`, so
that a Python caller gets the command line's refusals as the library's own
exceptions (:class:`~analytic.errors.DataError`,
:class:`~analytic.errors.OptionError`), never NumPy's ``ValueError`` or a
``ComplexWarning`` and a silently dropped imaginary part.
"""

from __future__ import annotations

import math
import numbers

import numpy as np

from analytic.errors import DataError, OptionError

__all__ = ["real_array", "false_alarm_rate", "whole_number", "MIN_FALSE_ALARM", "MAX_FALSE_ALARM"]

#: Smallest false-alarm rate: the limits' tails must stay finite normal quantiles.
MIN_FALSE_ALARM = 1e-12

#: Largest false-alarm rate: beyond it a check would reject correct data more often than not.
MAX_FALSE_ALARM = 0.5


def real_array(name: str, value, *, finite: bool = True) -> np.ndarray:
    """``value`` as a float64 array, refused in one line when it is not an array of real numbers.

    Parameters
    ----------
    name : str
        What it is, for the message (``"data"``, ``"stderr"``).
    value : array_like
        Numbers (an array, nested lists, a number).
    finite : bool
        Refuse NaN and infinity too.

    Raises
    ------
    DataError
        Complex numbers (refused, as the command line refuses a complex
        ``.npy``, rather than cast with a warning), text, objects, ragged
        lists, NaN or infinity.
    """
    try:
        array = np.asarray(value)
    except ValueError:          # ragged nested lists
        raise DataError(f"{name}: not an array of numbers (lists of different lengths?); give a NumPy array") from None
    if np.iscomplexobj(array):
        raise DataError(f"{name}: complex numbers; give real values (the transient itself, not a spectrum)")
    if array.dtype.kind in "US":
        raise DataError(f"{name}: text, not numbers; a file is read by validation.read_data(path, scene) and judged "
                        f"by validation.check_transient(scene, path)")
    if array.dtype.kind not in "biuf":
        raise DataError(f"{name}: an array of {array.dtype} values, not numbers; give a float array")
    array = array.astype(np.float64, copy=False)
    if finite and not np.all(np.isfinite(array)):
        raise DataError(f"{name}: {int(np.sum(~np.isfinite(array)))} value(s) are NaN or infinite; give "
                        f"finite values")
    return array


def false_alarm_rate(value) -> float:
    """α checked: a number in [:data:`MIN_FALSE_ALARM`, :data:`MAX_FALSE_ALARM`].

    Raises
    ------
    OptionError
        Not a number, or outside that range (α = 0 would accept anything,
        α near 1 would reject correct data).
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
        raise OptionError(f"false_alarm: expected a number, got {value!r}")
    if not MIN_FALSE_ALARM <= float(value) <= MAX_FALSE_ALARM:
        raise OptionError(f"false_alarm: must be in [{MIN_FALSE_ALARM:g}, {MAX_FALSE_ALARM:g}] (the probability "
                          f"that correct data fail), got {value!r}")
    return float(value)


def whole_number(name: str, value, *, smallest: int) -> int:
    """``value`` as an int >= ``smallest``; OptionError naming ``name`` otherwise (a bool is not a number)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < smallest:
        raise OptionError(f"{name}: must be a whole number >= {smallest}, got {value!r}")
    return int(value)
