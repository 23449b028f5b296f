"""A pixel that breakpoints' isochrones cut, for a step-function S: its slabs from the parts below each (compiled).

For the impulse every κ_n is constant between two consecutive breakpoint isochrones
d = τ_1 < ... < d = τ_m that cross a pixel, so its entries are the kernels' values on
each slab times the slab's ∫ a_k. Where the bins are short against the pixels (a
relay wall's or a plane's 5 mm bins over 15 mm pixels: two to six isochrones per
pixel) the slabs are many; each with two curved sides, the general strip rule
(:func:`analytic.kernels.strips.strip_entries`, G_4 x G_4 judged by G_3 x G_3 per slab,
both sides' roots at every node) took nine tenths of A's build. Here each isochrone
is integrated once, as :func:`analytic.kernels.strips.single_cut` does for one: the part
of the pixel below it, F_i = ∫_{d <= τ_i} a_k, by the ladder G_n x G_n from
:data:`~analytic.kernels.strips.FIRST_RUNG` (one side, one root pair per node, one row
below it), and the last one's part above too. The slabs are F_1, F_{i+1} - F_i and the
part above τ_m. Each F_i's error is estimated by its rung below (as single_cut's), and
a slab between two isochrones is accepted when the sum of both estimates is within the
tolerance of the slab itself (beyond the rounding of ∫ |a_k|): the difference's error
is at most that sum, so a thin slab asks its sides for more rungs, not less. An
isochrone whose slab fails climbs a rung; past :data:`~analytic.kernels.strips.LAST_RUNG`,
or where a side turns inside the pixel, nothing is kept and the caller integrates the
pixel its other way. With one isochrone this is single_cut's arithmetic, number for number.
"""

from __future__ import annotations

import numpy as np

from .bins import bin_edge, step_kernels
from .cache import njit
from .conics import across, isochrone_conic, turns_inside
from .pieces import ROUNDING
from .routes import clear_of_birth, clear_of_feet
from .strips import FIRST_RUNG, LAST_RUNG, Across, cut_pieces, cut_rung

__all__ = ["multi_cut", "cut_entries", "cut_table", "CUT_COLUMNS", "TAU", "PART"]

# Columns of :func:`multi_cut`'s table, one row per isochrone: its τ (the caller's), the conic (8) and the
# u-pieces' ends (4), its parts below and above, their ∫ |a_k|, their error estimates, its rung, whether it
# climbs next, and the slab below it (``PART``; row m holds the part above the last).
TAU, _CONIC, _ENDS, _BELOW, _ABOVE, _BELOW_SIZE, _ABOVE_SIZE, _BELOW_ERROR, _ABOVE_ERROR, _RUNG, _CLIMB, PART = (
    0, 1, 9, 13, 14, 15, 16, 17, 18, 19, 20, 21)
#: Columns of the table :func:`multi_cut` takes.
CUT_COLUMNS = 22


@njit(cache=True, error_model="numpy", forceinline=True)
def _conic_of(cuts, i):
    row = cuts[i]
    return (row[_CONIC], row[_CONIC + 1], row[_CONIC + 2], row[_CONIC + 3], row[_CONIC + 4], row[_CONIC + 5],
            row[_CONIC + 6], row[_CONIC + 7])


@njit(cache=True, error_model="numpy", forceinline=True)
def _climb(frame, cuts, i, count, sides, u0, u1):
    """Isochrone i's parts by its next rung: the new values and their change from the last as error estimates."""
    row = cuts[i]
    order = int(row[_RUNG]) + 1
    ends = (row[_ENDS], row[_ENDS + 1], row[_ENDS + 2], row[_ENDS + 3])
    below, above, below_size, above_size = cut_rung(frame, _conic_of(cuts, i), row[TAU], sides, u0, u1, ends, order,
                                                    i == count - 1)
    row[_BELOW_ERROR] = abs(below - row[_BELOW])
    row[_ABOVE_ERROR] = abs(above - row[_ABOVE])
    row[_BELOW], row[_ABOVE], row[_BELOW_SIZE], row[_ABOVE_SIZE] = below, above, below_size, above_size
    row[_RUNG] = order
    row[_CLIMB] = 0.0


@njit(cache=True, error_model="numpy")
def multi_cut(frame, box, cuts, count, rtol):
    """Whether the pixel's slabs between ``count`` isochrones were served; then cuts[j, PART] is slab j's ∫ a_k.

    Slab 0 is the part below cuts[0, TAU], slab j the part between cuts[j - 1, TAU] and
    cuts[j, TAU], slab ``count`` the part above the last; each within ``rtol`` of itself.

    Parameters
    ----------
    frame, box : analytic.kernels.isochrone.Frame, PixelBox
        The pair and the pixel (metres) as :func:`analytic.kernels.strips.single_cut` takes them.
    cuts : float64[:, CUT_COLUMNS]
        At least ``count + 1`` rows; cuts[:count, TAU] the breakpoints' path lengths inside the pixel's
        range of d, increasing and distinct, metres. The other columns are this function's.
    count : int
        How many, at least one.
    rtol : float
        Relative accuracy of each slab's integral.
    """
    swap, u0, u1, w0, w1 = across(frame, box)
    sides = Across(swap, w0, w1)
    for i in range(count):
        row = cuts[i]
        conic = isochrone_conic(frame, row[TAU], swap)
        if conic[2] == 0.0 or turns_inside(conic, u0, u1, w0, w1):
            return False
        for j in range(8):
            row[_CONIC + j] = conic[j]
        ends = cut_pieces(frame, conic, row[TAU], sides, u0, u1)
        for j in range(4):
            row[_ENDS + j] = ends[j]
        row[_RUNG] = FIRST_RUNG - 2
        row[_BELOW], row[_ABOVE] = 0.0, 0.0
        _climb(frame, cuts, i, count, sides, u0, u1)
        row[_CLIMB] = 1.0
    while True:
        for i in range(count):
            if cuts[i, _CLIMB] > 0.0:
                if cuts[i, _RUNG] >= LAST_RUNG:
                    return False
                _climb(frame, cuts, i, count, sides, u0, u1)
        served = True
        for j in range(count + 1):
            if j == count:          # above the last
                last = cuts[count - 1]
                value, error, size, worst = last[_ABOVE], last[_ABOVE_ERROR], last[_ABOVE_SIZE], count - 1
            elif j == 0:
                value, error, size, worst = cuts[0, _BELOW], cuts[0, _BELOW_ERROR], cuts[0, _BELOW_SIZE], 0
            else:
                lower, upper = cuts[j - 1], cuts[j]
                value = upper[_BELOW] - lower[_BELOW]
                error = upper[_BELOW_ERROR] + lower[_BELOW_ERROR]
                size = upper[_BELOW_SIZE] + lower[_BELOW_SIZE]
                worst = j if upper[_BELOW_ERROR] >= lower[_BELOW_ERROR] else j - 1
            cuts[j, PART] = value
            if not error <= rtol * abs(value) + 8.0 * ROUNDING * size:
                cuts[worst, _CLIMB] = 1.0
                served = False
        if served:
            return True


@njit(cache=True, error_model="numpy", forceinline=True)
def cut_entries(frame, box, column, table, axis, rtol, out, upper, cuts):
    """Whether a step-function S's (pixel, pair) that kernel breakpoints cut was served by :func:`multi_cut`.

    ``column`` holds the pixel's exact range of d; ``upper`` a second array as long as ``out``;
    ``cuts`` a :func:`cut_table`. When served, out[:run.bins] holds the entries: each slab's
    constant kernels (their values at the middle of its range of d, as
    :func:`analytic.kernels.strips.strip_entries` takes them) times its ∫ a_k. False (out left as it
    is) when no breakpoint lies inside (low, high), the pixel is near a foot or x*, or
    :func:`multi_cut` does not serve.
    """
    run, low, high = column.run, column.low, column.high
    kinked = table.kinked
    count = 0
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(kinked.size):
            tau = edge - kinked[i]
            if not low < tau < high:
                continue
            place = count               # kept increasing and distinct (insertion)
            while place > 0 and cuts[place - 1, TAU] > tau:
                place -= 1
            if place > 0 and cuts[place - 1, TAU] == tau:
                continue
            for j in range(count, place, -1):
                cuts[j, TAU] = cuts[j - 1, TAU]
            cuts[place, TAU] = tau
            count += 1
    if count == 0 or not clear_of_birth(frame, box, clear_of_feet(frame, box)):
        return False
    if not multi_cut(frame, box, cuts, count, rtol):
        return False
    for j in range(count + 1):
        below = low if j == 0 else cuts[j - 1, TAU]
        above = high if j == count else cuts[j, TAU]
        step_kernels(table.starts, table.constants, table.forms, axis, run, 0.5 * (below + above), cuts[j, PART],
                     out if j == 0 else upper)
        if j > 0:
            for i in range(run.bins):
                out[i] += upper[i]
    return True


@njit(cache=True, error_model="numpy", forceinline=True)
def cut_table(table, width):
    """The table :func:`cut_entries` gives :func:`multi_cut` for runs of up to ``width`` bins."""
    return np.empty(((max(width, 1) + 1) * max(table.kinked.size, 1) + 1, CUT_COLUMNS))
