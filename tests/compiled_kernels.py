"""The model's production kernels, evaluated as the tests compare them with NumPy's and Dr.Jit's."""

import numpy as np
from numba import njit

from analytic.kernels.bins import BinRun, KernelProblem, TimeAxis, kernel_values
from analytic.kernels.pieces import piece_of, piece_value


@njit(cache=False)
def _cumulative(terms, u, out):
    for i in range(u.size):
        piece = piece_of(terms, u[i])
        out[i] = 0.0 if piece < 0 else terms.constants[piece] + piece_value(terms, piece, u[i])[0]


def compiled_cumulative(terms, u) -> np.ndarray:
    """S(u) = K_i + F_i(u) as the compiled kernels read it (``piece_of`` and ``piece_value``)."""
    u = np.ascontiguousarray(u, dtype=np.float64)
    out = np.empty(u.size)
    _cumulative(terms, u.ravel(), out)
    return out.reshape(u.shape)


def compiled_kernels(terms, lower, upper) -> np.ndarray:
    """S(upper) - S(lower) by :func:`analytic.kernels.bins.kernel_values` (what assembly runs), one bin each."""
    values, noise = np.empty(1), np.empty(1)
    out = np.empty(len(lower))
    for i, (a, b) in enumerate(zip(lower, upper)):
        kernel_values(KernelProblem(terms, TimeAxis(float(a), float(b) - float(a), 1), BinRun(0, 1)), 0.0, 1.0,
                      values, noise)
        out[i] = values[0]
    return out
