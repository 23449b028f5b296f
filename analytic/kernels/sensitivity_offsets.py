"""Exact derivatives of a relay wall's samples pixel by pixel: the offset route's runs (compiled).

Where a capture's pairs are translates of a few by whole pixels (:mod:`analytic.operator.offsets`), the
derivatives' integrals of (pair, pixel) depend only on their offset, as A's entries do: each group's first
pair is integrated over every pixel of a virtual rectangle once, and each pixel's integrals kept as a run of
bins, read like A's (:func:`analytic.kernels.offsets.offset_product`). A pixel's integrals at the bin
edges are :func:`.sensitivity.pair_sums` over its own cells and the edges of its window (the last edge at
or below its nearest path, where F is 0, to the first beyond its deepest, where F is the whole pixel's),
turned into the :data:`OUTPUTS` per bin there; for any other waveform,
:func:`.sensitivity_waveform.waveform_pair_sums` over its cells on the axis of its window's bins
(:func:`waveform_window_sums`).
"""

from __future__ import annotations

import numpy as np

from .bins import TimeAxis
from .cache import njit
from .offsets import _run
from .sensitivity import RELAY_AMPLITUDES, pair_sums
from .sensitivity_waveform import waveform_pair_sums

__all__ = ["OUTPUTS", "window_sums", "waveform_window_sums", "window_products"]

#: y, ∂y/∂l (x, y, z), ∂y/∂s (x, y, z), ∂y/∂t_0, ∂y/∂n (x, y, z), the stretch's moments (x, y): per bin,
#: each the interior term plus the bin-edge term (:func:`analytic.operator.relay_wall_sensitivity.relay_edge_columns`).
OUTPUTS = 13


@njit(cache=True, error_model="numpy", inline="always")
def _bin(F, H, i, out):
    """The :data:`OUTPUTS` of the bin between window edges i and i + 1 from F and H there."""
    out[0] = F[i + 1, 0] - F[i, 0]
    for j in range(3):
        out[1 + j] = F[i + 1, 1 + j] - F[i, 1 + j] + H[i, 7 + j] - H[i + 1, 7 + j]
        out[4 + j] = F[i + 1, 4 + j] - F[i, 4 + j] + H[i, 10 + j] - H[i + 1, 10 + j]
        out[8 + j] = F[i + 1, 13 + j] - F[i, 13 + j]
    out[7] = H[i + 1, 0] - H[i, 0]
    for j in range(2):
        out[11 + j] = F[i + 1, 16 + j] - F[i, 16 + j] + H[i, 18 + j] - H[i + 1, 18 + j]


@njit(cache=True, error_model="numpy", nogil=True)
def window_sums(g, cells, bounds, windows, edges, rtol, starts, first, last, values):
    """The runs of pixels first ... last - 1 into ``values[starts[j]:starts[j + 1]]`` (rows: bins).

    Parameters
    ----------
    g : PairGeometry
        The group's pair in the virtual rectangle's frame, with ``surfaces``.
    cells : float64[C, 5]
        Every pixel's cells (x0, x1, y0, y1, f = 1), pixel j's rows ``bounds[j]:bounds[j + 1]``.
    bounds : int64[J + 1]
    windows : int64[J, 2]
        Each pixel's first and last edge; its run is the bins between them.
    edges : float64[E]
        The pair's bin edges, metres of path length.
    rtol : float
    starts : int64[J + 1]
    first, last : int
    values : float64[R, 13]
        Outputs, m⁻² and m⁻³ times the amplitudes' units (as :func:`.sensitivity.pair_sums`' differences).

    Returns
    -------
    int
        Cell integrals kept before meeting ``rtol`` (0 normally).
    """
    failures = 0
    for j in range(first, last):
        low, high = windows[j, 0], windows[j, 1]
        if high <= low:
            continue
        F = np.zeros((high - low + 1, RELAY_AMPLITUDES))
        H = np.zeros((high - low + 1, RELAY_AMPLITUDES))
        failures += pair_sums(g, cells[bounds[j]:bounds[j + 1]], edges[low:high + 1], rtol, F, H)
        for i in range(high - low):
            _bin(F, H, i, values[starts[j] + i])
    return failures


@njit(cache=True, error_model="numpy", nogil=True)
def waveform_window_sums(g, pixels, terms, axis, scales, rtol, span, values):
    """:func:`window_sums` for a waveform other than the impulse: each pixel's run is
    :func:`.sensitivity_waveform.waveform_pair_sums` over its cells on the axis of bins
    ``windows[j, 0]`` ... ``windows[j, 1] - 1`` of ``axis``.

    ``pixels`` = (cells, bounds, windows, starts) as :func:`window_sums` takes them; ``span`` = (first,
    last) the pixels; ``values``: float64[R, C], the waveform route's outputs per bin. Returns the cell
    integrals kept before meeting ``rtol``.
    """
    cells, bounds, windows, starts = pixels
    failures = 0
    for j in range(span[0], span[1]):
        low, high = windows[j, 0], windows[j, 1]
        if high <= low:
            continue
        window = TimeAxis(axis.start_opl + axis.bin_width_opl * low, axis.bin_width_opl, high - low)
        failures += waveform_pair_sums(g, cells[bounds[j]:bounds[j + 1]], terms, window, scales, rtol,
                                       values[starts[j]:starts[j + 1]])
    return failures


@njit(cache=True, error_model="numpy", nogil=True)
def window_products(runs, shape, mapping, scales, image, out):
    """Every output's Σ_p scale_k value f_p of every pair k into ``out[k, n, :]`` (zeroed by the caller): what
    :func:`analytic.kernels.offsets.offset_product` makes of one output, for all of them in one sweep.

    ``runs`` = (starts, firsts, values ``(R, C)``); ``shape`` = (M, Mv, N); ``mapping`` = (groups, shift_c,
    shift_r) per pair; ``image`` the M² reflectances (row from the top).
    """
    starts, firsts, values = runs
    pixels, virtual, bins = shape
    groups, shift_c, shift_r = mapping
    for k in range(out.shape[0]):
        scale = scales[k]
        for p in range(pixels * pixels):
            weight = scale * image[p]
            if weight == 0.0:
                continue
            j = _run(k, p, pixels, virtual, groups, shift_c, shift_r)
            base = firsts[j] - starts[j]
            for i in range(starts[j], starts[j + 1]):
                n = base + i
                if 0 <= n < bins:
                    for c in range(values.shape[1]):
                        out[k, n, c] += weight * values[i, c]
    return 0
