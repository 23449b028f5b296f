"""Formulas written once for the three backends: NumPy, compiled code (Numba) and the renderer (Dr.Jit).

Each is a plain function of its inputs and of the array module's functions
(``sqrt``, ``exp``), with no import of its own, so that one expression
serves every backend: :func:`bin_formula` (the bin of a path length),
:func:`attenuation_formula` (a_k of docs/design.md section 2) and the scaled complementary error function's three ranges
(:func:`small`, :func:`middle`, :func:`large`), which the Gaussian and EMG
pulses' cumulatives are made of. NumPy's forms are here too
(:func:`erfcx_array`); the compiled ones are in :mod:`.special` and
:mod:`.attenuation`, the renderer's in :mod:`transient.common`.

The scaled complementary error function erfcx(v) = e^{v²} erfc(v), v >= 0:
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
(:func:`analytic.kernels.special.erfcx_scalar` by branches in compiled code, :func:`erfcx_array`
with ``numpy.where``, the renderer with ``drjit.select``).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["bin_formula", "attenuation_formula", "LAMBERTIAN", "PAPER", "small", "middle", "large", "erfcx_array", "SMALL",
           "LARGE", "RECIPROCAL_SQRT_PI"]

def bin_formula(floor):
    """The bin of a path length, for an array module's ``floor``: the one binning of the model and renderers.

    Parameters
    ----------
    floor : callable
        ``numpy.floor`` (NumPy and compiled code) or ``drjit.floor``.

    Returns
    -------
    callable
        ``bin(length_opl, start_opl, bin_width_opl)`` = ⌊(length_opl -
        start_opl) / bin_width_opl⌋ as a float of the input's type: bin n
        covers [start_opl + n T, start_opl + (n + 1) T), metres (the
        quotient, not a product by 1/T, so that a length on an edge falls
        in the bin the edge starts).
    """
    def position(length_opl, start_opl, bin_width_opl):
        return floor((length_opl - start_opl) / bin_width_opl)
    return position


#: Integer codes of the attenuation kinds for compiled code (``Frame.mode``).
LAMBERTIAN, PAPER = 0, 1


def attenuation_formula(sqrt):
    """a_k from heights and squared distances, for an array module's ``sqrt``.

    Parameters
    ----------
    sqrt : callable
        ``math.sqrt`` (compiled code), ``numpy.sqrt`` or ``drjit.sqrt``.

    Returns
    -------
    callable
        ``a(mode, source_height, source_squared, sensor_height,
        sensor_squared)``: heights h_s, h_k in metres, squared distances
        d_s², d_k² in m², ``mode`` :data:`LAMBERTIAN` or :data:`PAPER`
        (a Python int: a branch at trace time for Dr.Jit); 1/m⁴.

    Notes
    -----
    lambertian h_s h_k / (π d_s³ d_k³), paper h_s / (d_s³ d_k²).
    """
    def formula(mode, source_height, source_squared, sensor_height, sensor_squared):
        source_cube = source_squared * sqrt(source_squared)
        if mode == LAMBERTIAN:
            return source_height * sensor_height / (math.pi * source_cube * sensor_squared * sqrt(sensor_squared))
        return source_height / (source_cube * sensor_squared)
    return formula


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


def erfcx_array(v) -> np.ndarray:
    """erfcx(v) elementwise for v >= 0 (NumPy; v < 0 is clamped to 0)."""
    v = np.maximum(np.asarray(v, dtype=np.float64), 0.0)
    low = small(np.minimum(v, SMALL), np.exp)
    mid = middle(np.clip(v, SMALL, LARGE), np.exp)
    with np.errstate(divide="ignore", invalid="ignore"):
        high = large(np.maximum(v, LARGE), np.exp)
    return np.where(v <= SMALL, low, np.where(v <= LARGE, mid, high))
