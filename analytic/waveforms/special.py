"""The scaled complementary error function erfcx(v) = e^{v²} erfc(v) for v >= 0, one formula for three backends.

The Gaussian and exponentially modified Gaussian pulses' cumulatives are
sums of e^{E(u)} erfcx(v(u)) with v >= 0 (:mod:`analytic.waveforms.pieces`,
family ``ERRORFUNCTIONS``): erfcx is bounded by 1 there and never
overflows, and e^{-v²} erfcx(v) = erfc(v) keeps erfc's relative accuracy
far in a tail, where 1 - erf(v) would keep only rounding. Dr.Jit has
``erf`` but neither erfc nor erfcx, and Numba has no erfcx, so it is
written here once, as W. J. Cody's rational Chebyshev approximations
(Math. Comp. 23 (1969) 631-637; the coefficients of SPECFUN's CALERF,
public domain), relative accuracy ~1e-16 for every v >= 0:

======================= ==============================================
v <= 0.46875            e^{v²} (1 - v R_1(v²)) (erf's approximation)
0.46875 < v <= 4        R_2(v)
v > 4                   (1/√π - R_3(1/v²) / v²) / v (asymptotic form)
======================= ==============================================

Each range is one function of the array module's ``exp`` (:func:`small`,
:func:`middle`, :func:`large`); the backends only choose between them
(:func:`erfcx_scalar` by branches in compiled code, :func:`erfcx_array`
with ``numpy.where``, the renderer with ``drjit.select``).

:func:`erfcx_taylor` gives erfcx's Taylor coefficients at v, which the
model's moments route needs: erfcx^(k)(v) / k! = (-2)^k e^{v²} i^k erfc(v),
with the repeated integrals i^k erfc the minimal solution of
2k c_k = c_{k-2} - 2v c_{k-1} (c_k = e^{v²} i^k erfc(v), c_{-1} = 2/√π),
so they are computed by Miller's backward recurrence (forward it loses
(2v²)^k / k! of its digits: all of them at v = 6, k = 11).
"""

from __future__ import annotations

import math

import numpy as np

from ..kernel_cache import njit

__all__ = ["erfcx_scalar", "erfcx_array", "erfcx_taylor", "small", "middle", "large", "SMALL", "LARGE",
           "RECIPROCAL_SQRT_PI"]

#: Where Cody's first range ends and his asymptotic range begins.
SMALL, LARGE = 0.46875, 4.0
RECIPROCAL_SQRT_PI = 0.56418958354775628695

_A = (3.16112374387056560e00, 1.13864154151050156e02, 3.77485237685302021e02, 3.20937758913846947e03,
      1.85777706184603153e-1)
_B = (2.36012909523441209e01, 2.44024637934444173e02, 1.28261652607737228e03, 2.84423683343917062e03)
_C = (5.64188496988670089e-1, 8.88314979438837594e00, 6.61191906371416295e01, 2.98635138197400131e02,
      8.81952221241769090e02, 1.71204761263407058e03, 2.05107837782607147e03, 1.23033935479799725e03,
      2.15311535474403846e-8)
_D = (1.57449261107098347e01, 1.17693950891312499e02, 5.37181101862009858e02, 1.62138957456669019e03,
      3.29079923573345963e03, 4.36261909014324716e03, 3.43936767414372164e03, 1.23033935480374942e03)
_P = (3.05326634961232344e-1, 3.60344899949804439e-1, 1.25781726111229246e-1, 1.60837851487422766e-2,
      6.58749161529837803e-4, 1.63153871373020978e-2)
_Q = (2.56852019228982242e00, 1.87295284992346047e00, 5.27905102951428412e-1, 6.05183413124413191e-2,
      2.33520497626869185e-3)


def small(v, exp):
    """erfcx(v) for 0 <= v <= SMALL: e^{v²} (1 - erf v), erf by Cody's R_1 (any array type, its ``exp``)."""
    z = v * v
    numerator = _A[4] * z
    denominator = z
    for a, b in zip(_A[:3], _B[:3]):
        numerator = (numerator + a) * z
        denominator = (denominator + b) * z
    return exp(z) * (1.0 - v * (numerator + _A[3]) / (denominator + _B[3]))


def middle(v, exp):
    """erfcx(v) for SMALL < v <= LARGE: Cody's R_2 (``exp`` unused; one signature for the three ranges)."""
    numerator = _C[8] * v
    denominator = v
    for c, d in zip(_C[:7], _D[:7]):
        numerator = (numerator + c) * v
        denominator = (denominator + d) * v
    return (numerator + _C[7]) / (denominator + _D[7])


def large(v, exp):
    """erfcx(v) for v > LARGE: (1/√π - R_3(1/v²)/v²) / v (``exp`` unused)."""
    z = 1.0 / (v * v)
    numerator = _P[5] * z
    denominator = z
    for p, q in zip(_P[:4], _Q[:4]):
        numerator = (numerator + p) * z
        denominator = (denominator + q) * z
    return (RECIPROCAL_SQRT_PI - z * (numerator + _P[4]) / (denominator + _Q[4])) / v


_small = njit(cache=True, error_model="numpy", inline="always")(small)
_middle = njit(cache=True, error_model="numpy", inline="always")(middle)
_large = njit(cache=True, error_model="numpy", inline="always")(large)


@njit(cache=True, error_model="numpy")
def erfcx_scalar(v):
    """erfcx(v) = e^{v²} erfc(v) for one v >= 0 (compiled); 1 for v <= 0 is not defined here (v < 0 is clamped)."""
    if v <= SMALL:
        return _small(max(v, 0.0), math.exp)
    if v <= LARGE:
        return _middle(v, math.exp)
    return _large(v, math.exp)


def erfcx_array(v) -> np.ndarray:
    """erfcx(v) elementwise for v >= 0 (NumPy; v < 0 is clamped to 0)."""
    v = np.maximum(np.asarray(v, dtype=np.float64), 0.0)
    low = small(np.minimum(v, SMALL), np.exp)
    mid = middle(np.clip(v, SMALL, LARGE), np.exp)
    with np.errstate(divide="ignore", invalid="ignore"):
        high = large(np.maximum(v, LARGE), np.exp)
    return np.where(v <= SMALL, low, np.where(v <= LARGE, mid, high))


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
