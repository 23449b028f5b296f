"""A's entries counted and filled, straight into CSR, in parallel over blocks of pixels (compiled).

Rows of A are (pair k, bin n), k N + n; columns are pixels p = r M + c.
The pixels are cut into B contiguous blocks, and each block is one job for
a thread. :func:`count` tells, for every block and row, how many entries
the block's pixels put in that row; their prefix sums over the blocks give
each block its own slice of each row of the CSR arrays, so :func:`fill`
writes every entry in its final place, in increasing column order, with
no conversion from CSC and no second copy of A.

Which bins a (pixel, pair) reaches and how its entries are computed is
decided here, alike for both passes. :func:`settled_run` takes the interval
of path length that :func:`analytic.isochrone.range_bound` gives from d and
∇d at a box's centre: where its ends fall in one bin (shifted by the
waveform's support), that bin is the run of every pixel inside the box, the
exact range's. Boxes are first segments of up to :data:`SEGMENT` pixels of
one image row, then single pixels; only where neither settles does a pixel
take the exact range of :func:`analytic.isochrone.rectangle_range`. A pixel
whose bound crosses no kernel breakpoint and lies clear of the feet is a
smooth pixel: for a step-function S (the impulse) its entries are the
kernels' constant values (one set per settled segment) times ∫_pixel a
(:func:`analytic.moments.pixel_integral`, a few nodes for a small pixel),
otherwise its moments over the bound
(:func:`analytic.moments.smooth_by_moments`). For a step-function S, a pixel
clear of the feet and of x* that one kernel breakpoint's isochrone cuts takes
:func:`analytic.strips.single_cut` (a real call on scalars: the two parts' ∫ a),
its kernels once per part; every other pair goes to
:func:`analytic.kernels.pair_entries` (a real call) with its exact range.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import prange

from .bins import BinRun, TimeAxis, bin_edge, bin_of, pixel_bins, step_cut, step_kernels, step_table
from .isochrone import PixelBox, pair_frame, range_bound, rectangle_range
from .kernel_cache import njit
from .kernels import clear_of_feet, clear_of_birth, make_scratch, pair_entries, scratch_failures
from .moments import pixel_integral, smooth_by_moments
from .strips import single_cut

__all__ = ["ImageGrid", "pixel_box", "settled_run", "pixel_run", "SEGMENT", "auto_entries", "block_bounds", "dealt", "count", "fill"]


class ImageGrid(NamedTuple):
    """The rectangle's pixels as compiled code sees them: sides (metres) and M."""

    width: float
    height: float
    pixels: int


@njit(cache=True, error_model="numpy")
def pixel_box(grid, p):
    """The :class:`~analytic.isochrone.PixelBox` of pixel p = r M + c (row r from the top), metres."""
    du = grid.width / grid.pixels
    dv = grid.height / grid.pixels
    r = p // grid.pixels
    c = p % grid.pixels
    return PixelBox(c * du, (c + 1) * du, (grid.pixels - r - 1) * dv, (grid.pixels - r) * dv)


@njit(cache=True, error_model="numpy", inline="always")
def settled_run(frame, box, axis, lead, duration):
    """(run, low, high, settled): the bins of every range of d inside the box's bound, when they are one run.

    [low, high] is :func:`analytic.isochrone.range_bound`'s interval. Where its ends fall in the same
    bin (shifted by the waveform's lead, and by its duration), every range inside it gives that
    bin, the exact range of the box and of any pixel inside it included: the run is settled
    (``settled``). Otherwise ``run`` is meaningless.
    """
    low, high = range_bound(frame, 0.5 * (box.x0 + box.x1), 0.5 * (box.y0 + box.y1), 0.5 * (box.x1 - box.x0),
                            0.5 * (box.y1 - box.y0))
    first = bin_of(low + lead, axis)
    if first == bin_of(high + lead, axis):
        last = bin_of(low + duration, axis)
        if last == bin_of(high + duration, axis):
            first = max(0, first)
            last = min(axis.count - 1, last)
            return (BinRun(first, last - first + 1) if last >= first else BinRun(0, 0)), low, high, True
    return BinRun(0, 0), low, high, False


@njit(cache=True, error_model="numpy", inline="always")
def pixel_run(frame, box, axis, lead, duration):
    """(run, low, high, exact): the bins a (pixel, pair) reaches and a range of d holding the pixel's.

    The run is the one :func:`analytic.bins.pixel_bins` gives on the exact range, settled by the
    bound where it can be (:func:`settled_run`; ``exact`` False, [low, high] the bound); otherwise
    [low, high] is the exact range (``exact`` True).
    """
    run, low, high, settled = settled_run(frame, box, axis, lead, duration)
    if settled:
        return run, low, high, False
    low, high = rectangle_range(frame, box)
    return pixel_bins(low, high, axis, lead, duration), low, high, True


#: Most pixels of one image row whose runs are settled together (:func:`settled_run` of their union);
#: fewer where a bin is under eight segments long (d changes by up to twice their length over them),
#: as then many would not settle.
SEGMENT = 8


@njit(cache=True, error_model="numpy", inline="always")
def _segment_length(grid, axis):
    side = max(grid.width, grid.height) / grid.pixels
    return max(1, min(SEGMENT, int(axis.bin_width_opl / (8.0 * side))))


@njit(cache=True, error_model="numpy", inline="always")
def _segment(grid, p, end, length):
    """(stop, box): pixels p ... stop - 1, at most ``length`` of one image row before ``end``, and their union."""
    stop = min(p + length, end, (p // grid.pixels + 1) * grid.pixels)
    first = pixel_box(grid, p)
    return stop, PixelBox(first.x0, pixel_box(grid, stop - 1).x1, first.y0, first.y1)


# What the smooth path of a (pixel, pair) did: wrote its entries, or left them to its moments or the other routes.
_SERVED, _MOMENTS, _OTHER = 0, 1, 2


@njit(cache=True, error_model="numpy", inline="always")
def _step_column(frame, box, lead, duration, kinked, steps, starts, constants, forms, axis, rtol, out):
    """(run, outcome, low, high, exact): one (pixel, pair)'s run of bins, and its entries when smooth and steps.

    ``kinked`` ... ``forms``: the waveform's :class:`~analytic.bins.StepTable`, field by field: in
    the fill's loop a record of arrays (the table, the waveform's terms, the scratch) passed or read
    costs a reference count per array and per pair, more than a small pixel's quadrature. For a
    step-function S (``steps``) a smooth pixel's entries are its kernels' constant values times
    ∫_pixel a (outcome ``_SERVED``); other smooth pixels take their moments (``_MOMENTS``), the
    rest the other routes (``_OTHER``), both in :func:`_finish`. [low, high] holds the pixel's
    range of d; ``exact``: it is that range.
    """
    run, low, high, exact = pixel_run(frame, box, axis, lead, duration)
    if run.bins == 0 or exact or not clear_of_feet(frame, box) or step_cut(kinked, low, high, axis, run):
        return run, _OTHER, low, high, exact
    if not steps:
        return run, _MOMENTS, low, high, exact
    value, converged = pixel_integral(frame, box, rtol)
    if not converged:
        return run, _OTHER, low, high, exact
    step_kernels(starts, constants, forms, axis, run, 0.5 * (low + high), value, out)
    return run, _SERVED, low, high, exact


@njit(cache=True, error_model="numpy", inline="always")
def _single_cut_column(frame, box, low, high, kinked, starts, constants, forms, axis, run, rtol, out, upper):
    """Whether a step-function S's (pixel, pair) that one kernel breakpoint cuts was served by :func:`single_cut`.

    [low, high] is the pixel's exact range of d; ``kinked`` ... ``forms`` the waveform's
    :class:`~analytic.bins.StepTable` (``steps`` True); ``upper`` a second array as long as ``out``.
    When served, out[:run.bins] holds the entries: each part's constant kernels (their values at
    the middle of its range of d, as :func:`analytic.strips.strip_entries` takes them) times its
    ∫ a_k. False (out left as it is) when no breakpoint or more than one lies inside (low, high),
    the pixel is near a foot or x*, or :func:`single_cut` does not serve.
    """
    tau = 0.0
    cuts = 0
    for n in range(run.first, run.first + run.bins + 1):
        edge = bin_edge(axis, n)
        for i in range(kinked.size):
            if low < edge - kinked[i] < high:
                tau = edge - kinked[i]
                cuts += 1
    if cuts != 1 or not clear_of_birth(frame, box, clear_of_feet(frame, box)):
        return False
    below, above, served = single_cut(frame, box, tau, rtol)
    if not served:
        return False
    step_kernels(starts, constants, forms, axis, run, 0.5 * (low + tau), below, out)
    step_kernels(starts, constants, forms, axis, run, 0.5 * (tau + high), above, upper)
    for i in range(run.bins):
        out[i] += upper[i]
    return True


@njit(cache=True, error_model="numpy", inline="always")
def _finish(outcome, frame, box, low, high, exact, terms, axis, run, rtol, out, scratch):
    """The entries :func:`_step_column` left (outcome ``_MOMENTS`` or ``_OTHER``); True if the smooth route served.

    Called only for those pairs: the scratch (a record of arrays) is touched only here.
    """
    if outcome == _MOMENTS:
        for i in range(run.bins):
            out[i] = 0.0
        if smooth_by_moments(frame, box, low, high, terms, axis, run, rtol, out, scratch):
            return True
    if not exact:
        low, high = rectangle_range(frame, box)
    return pair_entries(frame, box, low, high, terms, axis, run, rtol, out, scratch)


@njit(cache=True, error_model="numpy")
def auto_entries(frame, box, terms, axis, rtol, out, scratch):
    """(run, smooth) of one (pixel, pair) exactly as :func:`fill` computes it (for tests and diagnosis)."""
    table = step_table(terms)
    run, outcome, low, high, exact = _step_column(frame, box, terms.lead, terms.duration, table.kinked, table.steps,
                                                  table.starts, table.constants, table.forms, axis, rtol, out)
    if run.bins == 0 or outcome == _SERVED:
        return run, run.bins > 0
    if (table.steps and exact
            and _single_cut_column(frame, box, low, high, table.kinked, table.starts, table.constants, table.forms,
                                   axis, run, rtol, out, np.empty(run.bins))):
        return run, False
    return run, _finish(outcome, frame, box, low, high, exact, terms, axis, run, rtol, out, scratch)


def block_bounds(columns: int, blocks: int) -> np.ndarray:
    """(B + 1,) int64 column bounds of B contiguous blocks of pixels, as even as integers allow."""
    return (np.arange(blocks + 1, dtype=np.int64) * columns) // blocks


def dealt(job, jobs, threads):
    """The block of job ``job``: a static schedule gives thread t jobs t J/T ... and so blocks t, t + T, ...

    Spread over the image, so that a thread's share of cut pixels is the others' (when the threading
    layer schedules otherwise, only the balance changes).
    """
    job, jobs, threads = np.int64(job), np.int64(jobs), np.int64(threads)   # a prange index may be unsigned
    per_thread = jobs // threads
    if per_thread * threads != jobs:
        return job
    return (job % per_thread) * threads + job // per_thread


_dealt = njit(cache=True, error_model="numpy", inline="always")(dealt)


@njit(cache=True, error_model="numpy")
def _frames(pairs, mode):
    """Every pair's :class:`~analytic.isochrone.Frame` and the start of its time axis (its added length moves it)."""
    frames = [pair_frame(pairs[k], mode) for k in range(pairs.shape[0])]
    starts = np.empty(pairs.shape[0])
    for k in range(pairs.shape[0]):
        starts[k] = pairs[k].offset
    return frames, starts


@njit(parallel=True, cache=True, error_model="numpy")
def count(pairs, mode, grid, axis, lead, duration, bounds, threads, per_pixel, counts, widest):
    """Count the entries: per_pixel[p] of column p, counts[b, row] of block b's pixels in a row, widest[b].

    ``widest[b]``: the most bins one (pixel, pair) of block b reaches (its scratch's width).
    """
    jobs = bounds.size - 1
    for job in prange(jobs):
        block = _dealt(job, jobs, threads)
        widest[block] = _count_block(pairs, mode, grid, axis, lead, duration, bounds[block], bounds[block + 1],
                                     per_pixel, counts[block])


@njit(cache=True, error_model="numpy")
def _count_block(pairs, mode, grid, axis, lead, duration, begin, end, per_pixel, row_counts):
    frames, offsets = _frames(pairs, mode)
    length = _segment_length(grid, axis)
    most = 0
    for p in range(begin, end):
        per_pixel[p] = 0
    p = begin
    while p < end:
        stop, whole = _segment(grid, p, end, length)
        for k in range(len(frames)):
            pair_axis = TimeAxis(axis.start_opl - offsets[k], axis.bin_width_opl, axis.count)
            shared, settled = BinRun(0, 0), False
            if stop - p > 1:
                shared, _, _, settled = settled_run(frames[k], whole, pair_axis, lead, duration)
            for q in range(p, stop):
                run = shared if settled else pixel_run(frames[k], pixel_box(grid, q), pair_axis, lead, duration)[0]
                row = k * axis.count + run.first
                for i in range(run.bins):
                    row_counts[row + i] += 1
                per_pixel[q] += run.bins
                most = max(most, run.bins)
        p = stop
    return most


@njit(parallel=True, cache=True, error_model="numpy")
def fill(pairs, mode, grid, axis, terms, rtol, bounds, first, last, threads, widest, scales, cursors, indices, data,
         statistics):
    """Entries of blocks first ... last - 1 into their CSR slots.

    ``cursors[b, row]``: where block b writes its next entry of that row (advanced as it writes);
    ``statistics[b]``: (quadrature pieces failed, pairs the smooth route served, pairs whose light
    reaches a bin), added to.
    """
    jobs = bounds.size - 1
    for job in prange(first, last):
        block = _dealt(job, jobs, threads)
        failed, served, reached = _fill_block(pairs, mode, grid, axis, terms, rtol, bounds[block],
                                              bounds[block + 1], widest[block], scales, cursors[block], indices,
                                              data)
        statistics[block, 0] += failed
        statistics[block, 1] += served
        statistics[block, 2] += reached


@njit(cache=True, error_model="numpy")
def _fill_block(pairs, mode, grid, axis, terms, rtol, begin, end, width, scales, cursor, indices, data):
    """Columns begin ... end - 1, in order; returns (pieces failed, pairs served smooth, pairs reached).

    One sequential function per block, so that the smooth path inlines into it (a real call per
    pair would pay a reference count on each of the scratch's arrays); the pairs it leaves take
    :func:`_finish` (the same steps as :func:`auto_entries`).
    """
    scratch = make_scratch(width)
    values = np.empty(max(width, 1))
    kernels = np.empty(max(width, 1))
    upper = np.empty(max(width, 1))
    frames, offsets = _frames(pairs, mode)
    table = step_table(terms)
    kinked, steps, starts, constants, forms = table.kinked, table.steps, table.starts, table.constants, table.forms
    lead, duration = terms.lead, terms.duration
    length = _segment_length(grid, axis) if steps else 1
    served = 0
    reached = 0
    p = begin
    while p < end:
        stop, whole = _segment(grid, p, end, length)
        for k in range(len(frames)):
            frame = frames[k]
            pair_axis = TimeAxis(axis.start_opl - offsets[k], axis.bin_width_opl, axis.count)
            # a segment whose run is settled and crossed by no breakpoint: one set of constant kernels
            shared, low, high, settled = BinRun(0, 0), 0.0, 0.0, False
            if stop - p > 1:
                shared, low, high, settled = settled_run(frame, whole, pair_axis, lead, duration)
                if settled and shared.bins == 0:
                    continue
                settled = settled and not step_cut(kinked, low, high, pair_axis, shared)
                if settled:
                    step_kernels(starts, constants, forms, pair_axis, shared, 0.5 * (low + high), 1.0, kernels)
            for q in range(p, stop):
                box = pixel_box(grid, q)
                smooth = False
                if settled and clear_of_feet(frame, box):
                    value, smooth = pixel_integral(frame, box, rtol)
                    run = shared
                    for i in range(run.bins):
                        values[i] = kernels[i] * value
                if not smooth:
                    run, outcome, low, high, exact = _step_column(frame, box, lead, duration, kinked, steps, starts,
                                                                  constants, forms, pair_axis, rtol, values)
                    if run.bins == 0:
                        continue
                    smooth = outcome == _SERVED
                    if not smooth and not (steps and exact and _single_cut_column(
                            frame, box, low, high, kinked, starts, constants, forms, pair_axis, run, rtol, values,
                            upper)):
                        smooth = _finish(outcome, frame, box, low, high, exact, terms, pair_axis, run, rtol, values,
                                         scratch)
                reached += 1
                if smooth:
                    served += 1
                row = k * axis.count + run.first
                scale = scales[k]
                for i in range(run.bins):
                    slot = cursor[row + i]
                    indices[slot] = q
                    data[slot] = values[i] * scale
                    cursor[row + i] = slot + 1
        p = stop
    return scratch_failures(scratch), served, reached
