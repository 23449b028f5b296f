"""The renderer's production deposit, evaluated as the tests compare it with NumPy's and Numba's kernels."""

import numpy as np


def deposited_kernels(mitsuba, terms, lower, width: float) -> np.ndarray:
    """S(lower + width) - S(lower) per path, by :func:`transient.common.deposit` (what the plugins run).

    Each path gets a row of one bin [0, width) and the path length -lower, so that the bin's kernel is
    S(width + lower) - S(lower) (κ_0(τ) = S(t_1 - τ) - S(t_0 - τ)).
    """
    import drjit as dr

    from transient.common import deposit, reduce_mode

    lower = np.asarray(lower, dtype=np.float64)
    histogram = dr.zeros(mitsuba.Float64, lower.size)
    deposit(histogram, mitsuba.UInt32(np.arange(lower.size, dtype=np.uint32)), mitsuba.Float64(1.0),
            mitsuba.Float64(-lower), mitsuba.Bool(True), bins=1, start_opl=0.0, bin_width_opl=float(width),
            terms=terms, taps=1, mode=reduce_mode())
    return np.array(histogram, dtype=np.float64)


def traced_cumulative(mitsuba, terms, u) -> np.ndarray:
    """S(u) = K_i + F_i(u) as the deposit reads it (:func:`transient.common.constant_and_form`)."""
    from transient.common import constant_and_form

    constant, form = constant_and_form(terms, mitsuba.Float64(np.asarray(u, dtype=np.float64)))
    return np.array(constant + form, dtype=np.float64)
