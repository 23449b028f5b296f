"""The model's production kernels, evaluated as the tests compare them with NumPy's and Dr.Jit's."""

import numpy as np

from analytic.kernels.bins import BinRun, KernelProblem, TimeAxis, kernel_values


def compiled_kernels(terms, lower, upper) -> np.ndarray:
    """S(upper) - S(lower) by :func:`analytic.kernels.bins.kernel_values` (what assembly runs), one bin each."""
    values, noise = np.empty(1), np.empty(1)
    out = np.empty(len(lower))
    for i, (a, b) in enumerate(zip(lower, upper)):
        kernel_values(KernelProblem(terms, TimeAxis(float(a), float(b) - float(a), 1), BinRun(0, 1)), 0.0, 1.0,
                      values, noise)
        out[i] = values[0]
    return out
