"""The one binning function, shared by the analytic model and the renderer.

Bin ``n`` covers path lengths ``[start_opl + n * bin_width_opl,
start_opl + (n + 1) * bin_width_opl)`` (metres, c = 1). If the renderers and the
model binned differently, the cross-check would compare different things, so
the formula is written once (:func:`analytic.kernels.formulas.bin_formula`):
the compiled kernels use it through :func:`analytic.kernels.bins.bin_of`, the
renderers and NumPy callers through :func:`bin_index`.
"""

from __future__ import annotations

import numpy as np

from .kernels.formulas import bin_formula

__all__ = ["bin_index"]


def bin_index(length_opl, start_opl: float, bin_width_opl: float, count: int, floor=np.floor):
    """Bin of each path length, with the mask of those inside the window.

    Parameters
    ----------
    length_opl : array_like
        Optical path lengths, metres (c = 1). NumPy or Dr.Jit arrays.
    start_opl : float
        Lower edge of bin 0, metres.
    bin_width_opl : float
        Bin width T, metres.
    count : int
        Number of bins N.
    floor : callable
        The array module's floor (``numpy.floor`` or ``drjit.floor``).

    Returns
    -------
    index : array
        :func:`~analytic.kernels.formulas.bin_formula`: ``floor((length_opl -
        start_opl) / bin_width_opl)``, as floats of the
        input's type, unmasked (negative before the window).
    inside : array of bool
        ``0 <= index < count``.
    """
    index = bin_formula(floor)(length_opl, start_opl, bin_width_opl)
    inside = (index >= 0) & (index < count)
    return index, inside

