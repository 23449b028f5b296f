"""A's entries from the entries of one pixel offset each: a translation-invariant capture's product and CSR.

When every pair is a translate of one of a few representatives by whole pixels (a hidden rectangle
parallel to a relay wall scanned on a grid commensurate with its pixels: :mod:`analytic.operator.offsets`),
the entries of (pair k, pixel p) are those of (its representative g_k, the virtual pixel p shifted by
the pair's shift). Those are computed once, as a run of bins per (representative, virtual pixel):
``starts[j]``, ``firsts[j]`` and ``values[starts[j]:starts[j + 1]]`` for j = g Mv² + pv. These kernels
read them for a range of pairs: y = A f without A (:func:`offset_product`), or A in CSR
(:func:`offset_entries`); each entry is the pair's scale times the run's value, summed
in column order as a CSR product sums it.
"""

from __future__ import annotations

from .cache import njit

__all__ = ["offset_product", "offset_entries"]


@njit(cache=True, error_model="numpy", forceinline=True)
def _run(k, p, pixels, virtual, groups, shift_c, shift_r):
    """The run index j = g Mv² + pv of pair k's pixel p = r M + c (row r from the top)."""
    r = p // pixels
    c = p - r * pixels
    # rows count from the top, frame rows from the bottom: the shift is along the frame's rows
    row = r + (virtual - pixels) - shift_r[k]
    return groups[k] * virtual * virtual + row * virtual + c + shift_c[k]


@njit(cache=True, error_model="numpy", nogil=True)
def offset_product(runs, shape, mapping, scales, image, first, last, out):
    """y for pairs first ... last - 1 into ``out[k - first, :]`` (bins): Σ_p scale_k value f_p, column order.

    ``runs`` = (starts, firsts, values); ``shape`` = (M, Mv, N); ``mapping`` = (groups, shift_c, shift_r)
    per pair. Returns the entries of A those rows hold (its non-zeros).
    """
    starts, firsts, values = runs
    pixels, virtual, bins = shape
    groups, shift_c, shift_r = mapping
    nonzeros = 0
    for k in range(first, last):
        row = out[k - first]
        scale = scales[k]
        for p in range(pixels * pixels):
            j = _run(k, p, pixels, virtual, groups, shift_c, shift_r)
            begin, end = starts[j], starts[j + 1]
            weight = image[p]
            base = firsts[j] - begin
            for i in range(begin, end):
                entry = scale * values[i]
                if entry != 0.0:
                    n = base + i
                    if 0 <= n < bins:
                        row[n] += entry * weight
                        nonzeros += 1
    return nonzeros


@njit(cache=True, error_model="numpy", nogil=True)
def offset_entries(runs, shape, mapping, scales, first, last, cursors, indices, data, fill):
    """A's entries of pairs first ... last - 1: counted per row into ``cursors[(k - first) N + n]`` (``fill``
    False), or written into CSR slots, columns ascending in each row, each cursor starting at its row's first
    slot and ending past its last (``fill`` True)."""
    starts, firsts, values = runs
    pixels, virtual, bins = shape
    groups, shift_c, shift_r = mapping
    for k in range(first, last):
        scale = scales[k]
        for p in range(pixels * pixels):
            j = _run(k, p, pixels, virtual, groups, shift_c, shift_r)
            base = firsts[j] - starts[j]
            for i in range(starts[j], starts[j + 1]):
                entry = scale * values[i]
                n = base + i
                if entry != 0.0 and 0 <= n < bins:
                    row = (k - first) * bins + n
                    if fill:
                        slot = cursors[row]
                        indices[slot] = p
                        data[slot] = entry
                    cursors[row] += 1
    return 0
