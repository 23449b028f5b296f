"""erfcx(v) = e^{v²} erfc(v) and its Taylor coefficients, compiled (:mod:`.formulas` holds the formula).

:func:`erfcx_taylor` gives erfcx's Taylor coefficients at v, which the
model's moments route needs: erfcx^(k)(v) / k! = (-2)^k e^{v²} i^k erfc(v),
with the repeated integrals i^k erfc the minimal solution of
2k c_k = c_{k-2} - 2v c_{k-1} (c_k = e^{v²} i^k erfc(v), c_{-1} = 2/√π),
so they are computed by Miller's backward recurrence (forward it loses
(2v²)^k / k! of its digits: all of them at v = 6, k = 11).
"""

from __future__ import annotations

import math

from .cache import njit
from .formulas import LARGE, RECIPROCAL_SQRT_PI, SMALL, large, middle, small

__all__ = ["erfcx_scalar", "erfcx_taylor"]

_small = njit(cache=True, error_model="numpy")(small)
_middle = njit(cache=True, error_model="numpy")(middle)
_large = njit(cache=True, error_model="numpy")(large)


@njit(cache=True, error_model="numpy")
def erfcx_scalar(v):
    """erfcx(v) = e^{v²} erfc(v) for one v >= 0 (compiled); 1 for v <= 0 is not defined here (v < 0 is clamped)."""
    if v <= SMALL:
        return _small(max(v, 0.0), math.exp)
    if v <= LARGE:
        return _middle(v, math.exp)
    return _large(v, math.exp)


# Miller's recurrence starts 40 + 320 / v² orders above the highest one asked for (at most 13): the
# dominant solution's share has decayed below 1e-15 by then (measured against mpmath, v in (1, 1e6]).
# For v <= 1 the forward recurrence loses at most (2v²)^k / k! <= 2 of its digits and is used instead.
_MILLER_START = 40.0
_MILLER_SLOW = 320.0
# Rescale the backward recurrence when its values pass this size (they grow like (2v)^k).
_RESCALE = 1e150


@njit(cache=True, error_model="numpy")
def erfcx_taylor(v, count, out):
    """out[k] = erfcx^(k)(v) / k! for k < count, v >= 0 (compiled).

    Notes
    -----
    erfcx^(k)(v) / k! = (-2)^k c_k with c_k = e^{v²} i^k erfc(v), the
    minimal solution of c_{k-2} = 2k c_k + 2v c_{k-1} for v > 1; Miller's
    algorithm runs it downward from c_{N+1} = 0, c_N = 1 and scales the
    result so that c_{-1} = 2/√π (see the module docstring). For v <= 1,
    where the two solutions barely separate, it runs forward from
    c_{-1} = 2/√π and c_0 = erfcx(v).
    """
    v = max(v, 0.0)
    if v <= 1.0:
        before = 2.0 * RECIPROCAL_SQRT_PI      # c_{k-2}
        current = erfcx_scalar(v)              # c_{k-1}
        factor = 1.0
        for k in range(count):
            if k > 0:
                before, current = current, (before - 2.0 * v * current) / (2.0 * k)
            out[k] = current * factor
            factor *= -2.0
        return
    top = count + int(_MILLER_START + _MILLER_SLOW / (v * v))
    upper = 0.0            # c_{k+1}
    current = 1e-300       # c_k, from k = top down
    for k in range(top, -1, -1):
        if k < count:
            out[k] = current
        lower = 2.0 * (k + 1) * upper + 2.0 * v * current     # c_{k-1}
        upper, current = current, lower
        if abs(current) > _RESCALE:
            for j in range(min(k, count), count):
                out[j] /= _RESCALE
            upper /= _RESCALE
            current /= _RESCALE
    # current is now c_{-1}
    scale = 2.0 * RECIPROCAL_SQRT_PI / current
    factor = 1.0
    for k in range(count):
        out[k] *= scale * factor
        factor *= -2.0
