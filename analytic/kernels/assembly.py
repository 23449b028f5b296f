"""A's entries counted and filled, straight into CSR, block of pixels by block (compiled).

Rows of A are (pair k, bin n), k N + n; columns are pixels p = r M + c.
The pixels are cut into blocks, and each block is one job for a thread
(:mod:`analytic.operator.system` runs them on a pool of threads: these kernels
release Python's lock). :func:`count_block` tells, for one block and every
row, how many entries the block's pixels put in that row; their prefix sums
over the blocks give each block its own slice of each row of the CSR
arrays, so :func:`fill_block` writes every entry in its final place, in
increasing column order, with no conversion from CSC and no second copy of A.

Which bins a (pixel, pair) reaches and how its entries are computed is
decided here, alike for both passes. :func:`settled_run` takes the interval
of path length that :func:`analytic.kernels.isochrone.range_bound` gives from d and
∇d at a box's centre: where its ends fall in one bin (shifted by the
waveform's support), that bin is the run of every pixel inside the box, the
exact range's. Boxes are first segments of up to :data:`SEGMENT` pixels of
one image row, then single pixels; only where neither settles does a pixel
take the exact range of :func:`analytic.kernels.isochrone.rectangle_range`. A pixel
whose bound crosses no kernel breakpoint and lies clear of the feet is a
smooth pixel: for a step-function S (the impulse) its entries are the
kernels' constant values (one set per settled segment) times ∫_pixel a
(:func:`analytic.kernels.moments.pixel_integral`, a few nodes for a small pixel),
otherwise its moments over the bound
(:func:`analytic.kernels.moments.smooth_by_moments`). For a step-function S, a pixel
clear of the feet and of x* that kernel breakpoints' isochrones cut takes
:func:`analytic.kernels.cuts.cut_entries` (each slab's ∫ a from the parts below
each isochrone), its kernels once per slab; a pixel clear of the feet whose exact range no breakpoint
cuts takes its moments over that range.

Every other (pixel, pair) is *left* by the first pass: its slots hold NaN
(and its column), and :func:`run_jobs` computes it afterwards by the general
routes of :mod:`analytic.kernels.routes`, one route at a time (the direct
smooth route, strips, the cut quadrature, each trying what the one before
did not serve), compiled only when a scene leaves some pair: the paper's
scene leaves none, and its first run compiles only this module's first
pass. The entries are the same numbers either way: every route is a
function of its (pixel, pair) alone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba.extending import overload

from .bins import BinRun, StepTable, TimeAxis, bin_edge, bin_of, kernel_cut, pixel_bins, step_cut, step_kernels, \
    step_table
from .cache import njit
from .isochrone import PixelBox, pair_frame, range_bound, rectangle_range
from .moments import pixel_integral, smooth_by_moments
from .pieces import WaveformTerms
from .routes import SERVED, Column, clear_of_feet, clear_of_birth, make_scratch, route_entries, scratch_failures
from .cuts import cut_entries, cut_table

__all__ = ["ImageGrid", "Assembly", "StepAssembly", "Slots", "Jobs", "pixel_box", "settled_run", "pixel_run", "SEGMENT",
           "auto_entries", "count_block", "fill_block", "run_jobs", "job_routes", "pair_frame_of", "DIRECT_APPLIES",
           "STRIPS_APPLY"]


class ImageGrid(NamedTuple):
    """The rectangle's pixels as compiled code sees them: sides (metres) and M."""

    width: float
    height: float
    pixels: int


class Assembly(NamedTuple):
    """What every block of one assembly shares, for any waveform (its smooth pixels take their moments)."""

    pairs: np.ndarray       # analytic.geometry.PAIR_DTYPE records
    mode: int               # attenuation code
    grid: ImageGrid
    axis: TimeAxis
    terms: WaveformTerms
    rtol: float             # relative accuracy each quadrature asks of itself
    scales: np.ndarray      # (P,) factor of each pair's row block


class StepAssembly(NamedTuple):
    """:class:`Assembly` for a waveform whose S is a step function (the impulse: ``WaveformTerms.degree`` 0).

    Its own type, so that :func:`fill_block` is compiled for it without the moments route, which such a
    waveform never needs: its kernels are constant between breakpoints, a smooth pixel's entries are
    those constants times ∫_pixel a.
    """

    pairs: np.ndarray
    mode: int
    grid: ImageGrid
    axis: TimeAxis
    terms: WaveformTerms
    rtol: float
    scales: np.ndarray


class Slots(NamedTuple):
    """Where one block writes A's entries: its next slot in each row (advanced as it writes), the CSR arrays."""

    cursor: np.ndarray      # (rows,) int64
    indices: np.ndarray
    data: np.ndarray


class Jobs(NamedTuple):
    """The (pair, pixel)s the first pass left, and the CSR slots of their bins."""

    pairs: np.ndarray       # (J,) int64 pair k
    pixels: np.ndarray      # (J,) int64 pixel p
    firsts: np.ndarray      # (J,) int64 first bin of the run
    offsets: np.ndarray     # (J + 1,) int64: job j's slots are slots[offsets[j]:offsets[j + 1]], one per bin
    slots: np.ndarray       # int64
    lows: np.ndarray        # (J,) float64: the pixel's exact range of d, metres (:func:`job_routes` fills it)
    highs: np.ndarray


@njit(cache=True, error_model="numpy", forceinline=True)
def pixel_box(grid, p):
    """The :class:`~analytic.kernels.isochrone.PixelBox` of pixel p = r M + c (row r from the top), metres."""
    du = grid.width / grid.pixels
    dv = grid.height / grid.pixels
    r = p // grid.pixels
    c = p % grid.pixels
    return PixelBox(c * du, (c + 1) * du, (grid.pixels - r - 1) * dv, (grid.pixels - r) * dv)


@njit(cache=True, error_model="numpy", forceinline=True)
def settled_run(frame, box, axis, lead, duration):
    """(run, low, high, settled): the bins of every range of d inside the box's bound, when they are one run.

    [low, high] is :func:`analytic.kernels.isochrone.range_bound`'s interval. Where its ends fall in the same
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


@njit(cache=True, error_model="numpy", forceinline=True)
def pixel_run(frame, box, axis, lead, duration):
    """(run, low, high, exact): the bins a (pixel, pair) reaches and a range of d holding the pixel's.

    The run is the one :func:`analytic.kernels.bins.pixel_bins` gives on the exact range, settled by the
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


@njit(cache=True, error_model="numpy", forceinline=True)
def _segment_length(grid, axis):
    side = max(grid.width, grid.height) / grid.pixels
    return max(1, min(SEGMENT, int(axis.bin_width_opl / (8.0 * side))))


@njit(cache=True, error_model="numpy", forceinline=True)
def _segment(grid, p, end, length):
    """(stop, box): pixels p ... stop - 1, at most ``length`` of one image row before ``end``, and their union."""
    stop = min(p + length, end, (p // grid.pixels + 1) * grid.pixels)
    first = pixel_box(grid, p)
    return stop, PixelBox(first.x0, pixel_box(grid, stop - 1).x1, first.y0, first.y1)


# What the first pass did with a (pixel, pair): wrote its entries (by a smooth route or not), left its moments
# to its exact range, or left it to the general routes.
_SERVED, _MOMENTS, _OTHER = 0, 1, 2


@njit(cache=True, error_model="numpy", forceinline=True)
def _step_column(frame, box, table, terms, axis, rtol, out):
    """(column, outcome): one (pixel, pair)'s run of bins and range of d, and its entries when smooth and steps.

    For a step-function S (``table.steps``) a smooth pixel's entries are its kernels' constant values
    times ∫_pixel a (outcome ``_SERVED``); other smooth pixels take their moments (``_MOMENTS``), the
    rest the other routes (``_OTHER``), both in :func:`_finish`.
    """
    run, low, high, exact = pixel_run(frame, box, axis, terms.lead, terms.duration)
    column = Column(run, low, high, exact)
    if run.bins == 0 or exact or not clear_of_feet(frame, box) or step_cut(table.kinked, low, high, axis, run):
        return column, _OTHER
    if not table.steps:
        return column, _MOMENTS
    value, converged = pixel_integral(frame, box, rtol)
    if not converged:
        return column, _OTHER
    step_kernels(table.starts, table.constants, table.forms, axis, run, 0.5 * (low + high), value, out)
    return column, _SERVED


@njit(cache=True, error_model="numpy", forceinline=True)
def _finish(outcome, frame, box, column, terms, axis, rtol, out, scratch):
    """(served, exact column): the moments of what :func:`_step_column` left; ``served`` False leaves it.

    A ``_MOMENTS`` pixel first takes its moments over the bound; then, as
    the general routes begin (:func:`analytic.kernels.routes.route_entries`), a pixel clear of the
    feet whose exact range no breakpoint cuts takes its moments over that range.
    """
    run = column.run
    if outcome == _MOMENTS:
        for i in range(run.bins):
            out[i] = 0.0
        if smooth_by_moments(frame, box, column.low, column.high, terms, axis, run, rtol, out, scratch):
            return True, column
    if not column.exact:
        low, high = rectangle_range(frame, box)
        column = Column(run, low, high, True)
    for i in range(run.bins):
        out[i] = 0.0
    if clear_of_feet(frame, box) and not kernel_cut(column.low, column.high, terms, axis, run):
        if smooth_by_moments(frame, box, column.low, column.high, terms, axis, run, rtol, out, scratch):
            return True, column
    return False, column


@njit(cache=True, error_model="numpy", forceinline=True)
def _finish_steps(frame, box, column, table, axis, rtol, out):
    """(served, exact column) of a step-function S's (pixel, pair) that :func:`_step_column` left.

    On its exact range: where it is clear of the feet and no breakpoint cuts it, its kernels are
    constant and its entries those constants times ∫_pixel a, the numbers the moments route gives
    for one Taylor term (:func:`analytic.kernels.moments.pixel_integral` takes the moments' nodes
    and judgement); else (or where that integral does not converge) it is left.
    """
    run = column.run
    if not column.exact:
        low, high = rectangle_range(frame, box)
        column = Column(run, low, high, True)
    if not clear_of_feet(frame, box) or step_cut(table.kinked, column.low, column.high, axis, run):
        return False, column
    value, converged = pixel_integral(frame, box, rtol)
    if not converged:
        return False, column
    step_kernels(table.starts, table.constants, table.forms, axis, run, 0.5 * (column.low + column.high), value, out)
    return True, column


def _left_smooth(problem, outcome, frame, box, column, table, axis, out, scratch):
    """(served, exact column): what the first pass does with a (pixel, pair) its fast paths left (compiled only).

    :func:`_finish_steps` for a :class:`StepAssembly`, :func:`_finish` (the moments) for an :class:`Assembly`.
    """
    raise TypeError("_left_smooth is called from compiled code")


@overload(_left_smooth, jit_options={"error_model": "numpy"}, inline="always")
def _left_smooth_of(problem, outcome, frame, box, column, table, axis, out, scratch):
    kind = getattr(problem, "instance_class", None)
    if kind is StepAssembly:
        return lambda problem, outcome, frame, box, column, table, axis, out, scratch: _finish_steps(
            frame, box, column, table, axis, problem.rtol, out)
    if kind is Assembly:
        return lambda problem, outcome, frame, box, column, table, axis, out, scratch: _finish(
            outcome, frame, box, column, problem.terms, axis, problem.rtol, out, scratch)
    return None


def _block_scratch(problem, width):
    """The scratch one block's first pass needs (compiled only): none for a :class:`StepAssembly`."""
    raise TypeError("_block_scratch is called from compiled code")


@overload(_block_scratch, jit_options={"error_model": "numpy"}, inline="always")
def _block_scratch_of(problem, width):
    kind = getattr(problem, "instance_class", None)
    if kind is StepAssembly:
        return lambda problem, width: np.zeros(1, dtype=np.int64)
    if kind is Assembly:
        return lambda problem, width: make_scratch(width)
    return None


def _failures(scratch):
    """Quadrature pieces a block's scratch counted as failed (compiled only)."""
    raise TypeError("_failures is called from compiled code")


@overload(_failures, jit_options={"error_model": "numpy"}, inline="always")
def _failures_of(scratch):
    if getattr(scratch, "instance_class", None) is not None:
        return lambda scratch: scratch_failures(scratch)
    return lambda scratch: scratch[0]


@njit(cache=True, error_model="numpy")
def auto_entries(frame, box, terms, axis, rtol, out, scratch):
    """(column, served, smooth): one (pixel, pair) as the first pass computes it (for tests and diagnosis).

    ``served`` False: the first pass leaves it (to :func:`run_jobs`), with ``column`` its exact range.
    ``smooth``: a smooth route served it.
    """
    table = step_table(terms)
    column, outcome = _step_column(frame, box, table, terms, axis, rtol, out)
    run = column.run
    if run.bins == 0 or outcome == _SERVED:
        return column, True, run.bins > 0
    if (table.steps and column.exact
            and cut_entries(frame, box, column, table, axis, rtol, out, np.empty(run.bins),
                            cut_table(table, run.bins))):
        return column, True, False
    if table.steps:
        served, column = _finish_steps(frame, box, column, table, axis, rtol, out)
    else:
        served, column = _finish(outcome, frame, box, column, terms, axis, rtol, out, scratch)
    return column, served, served


@njit(cache=True, error_model="numpy")
def pair_frame_of(pairs, k, mode):
    """The :class:`~analytic.kernels.isochrone.Frame` of pair k."""
    return pair_frame(pairs[k], mode)


@njit(cache=True, error_model="numpy")
def _frames(pairs, mode):
    """Every pair's :class:`~analytic.kernels.isochrone.Frame` and the start of its time axis (its added length moves it)."""
    frames = [pair_frame(pairs[k], mode) for k in range(pairs.shape[0])]
    starts = np.empty(pairs.shape[0])
    for k in range(pairs.shape[0]):
        starts[k] = pairs[k].offset
    return frames, starts


@njit(cache=True, error_model="numpy", nogil=True)
def count_block(problem, begin, end, per_pixel, row_counts):
    """Count pixels begin ... end - 1's entries: per_pixel[p] of column p, row_counts[row] in each row.

    Returns the most bins one (pixel, pair) of the block reaches (its scratch's width).
    """
    frames, offsets = _frames(problem.pairs, problem.mode)
    grid, axis, lead, duration = problem.grid, problem.axis, problem.terms.lead, problem.terms.duration
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


@njit(cache=True, error_model="numpy", nogil=True)
def fill_block(problem, begin, end, width, slots):
    """Columns begin ... end - 1 into their CSR slots; returns (pieces failed, pairs served smooth, reached, left).

    A (pixel, pair) the first pass leaves (see the module docstring) gets its column index and NaN in
    its slots, for :func:`run_jobs`. ``width``: the most bins one (pixel, pair) of the block reaches.
    """
    scratch = _block_scratch(problem, width)
    values = np.empty(max(width, 1))
    kernels = np.empty(max(width, 1))
    upper = np.empty(max(width, 1))
    frames, offsets = _frames(problem.pairs, problem.mode)
    terms, grid, axis, rtol = problem.terms, problem.grid, problem.axis, problem.rtol
    table = step_table(terms)
    cuts = cut_table(table, width)
    cursor, indices, data = slots.cursor, slots.indices, slots.data
    lead, duration = terms.lead, terms.duration
    length = _segment_length(grid, axis) if table.steps else 1
    served = 0
    reached = 0
    left = 0
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
                settled = settled and not step_cut(table.kinked, low, high, pair_axis, shared)
                if settled:
                    step_kernels(table.starts, table.constants, table.forms, pair_axis, shared, 0.5 * (low + high),
                                 1.0, kernels)
            for q in range(p, stop):
                box = pixel_box(grid, q)
                smooth = False
                done = False
                run = shared
                if settled and clear_of_feet(frame, box):
                    value, smooth = pixel_integral(frame, box, rtol)
                    done = smooth
                    for i in range(run.bins):
                        values[i] = kernels[i] * value
                if not done:
                    column, outcome = _step_column(frame, box, table, terms, pair_axis, rtol, values)
                    run = column.run
                    if run.bins == 0:
                        continue
                    smooth = outcome == _SERVED
                    done = smooth or (table.steps and column.exact and cut_entries(
                        frame, box, column, table, pair_axis, rtol, values, upper, cuts))
                    if not done:
                        smooth, column = _left_smooth(problem, outcome, frame, box, column, table, pair_axis, values,
                                                      scratch)
                        done = smooth
                reached += 1
                row = k * axis.count + run.first
                if not done:
                    left += 1
                    for i in range(run.bins):
                        slot = cursor[row + i]
                        indices[slot] = q
                        data[slot] = np.nan
                        cursor[row + i] = slot + 1
                    continue
                if smooth:
                    served += 1
                scale = problem.scales[k]
                for i in range(run.bins):
                    slot = cursor[row + i]
                    indices[slot] = q
                    data[slot] = values[i] * scale
                    cursor[row + i] = slot + 1
        p = stop
    return _failures(scratch), served, reached, left


#: :func:`job_routes`' flags: the direct smooth route applies; strips apply.
DIRECT_APPLIES, STRIPS_APPLY = 1, 2


@njit(cache=True, error_model="numpy", nogil=True)
def job_routes(problem, jobs, routes):
    """routes[j]: which general routes apply to left (pixel, pair) j (:data:`DIRECT_APPLIES` | :data:`STRIPS_APPLY`).

    Cheap geometric tests (no quadrature), which say what each route is tried on; the cut route
    applies to every job. :mod:`analytic.operator.system` tries the direct route, then strips, then the cut route.
    """
    axis = problem.axis
    for j in range(jobs.pairs.size):
        k = jobs.pairs[j]
        frame = pair_frame(problem.pairs[k], problem.mode)
        pair_axis = TimeAxis(axis.start_opl - problem.pairs[k].offset, axis.bin_width_opl, axis.count)
        box = pixel_box(problem.grid, jobs.pixels[j])
        low, high = rectangle_range(frame, box)
        jobs.lows[j] = low
        jobs.highs[j] = high
        run = BinRun(jobs.firsts[j], jobs.offsets[j + 1] - jobs.offsets[j])
        clear = clear_of_feet(frame, box)
        flags = 0
        if clear and not kernel_cut(low, high, problem.terms, pair_axis, run):
            flags |= DIRECT_APPLIES
        if clear_of_birth(frame, box, clear):
            flags |= STRIPS_APPLY
        routes[j] = flags


@njit(cache=True, error_model="numpy", nogil=True)
def run_jobs(route, problem, jobs, begin, end, data, outcomes):
    """Jobs begin ... end - 1 by one :class:`~analytic.kernels.routes.Route`; returns the quadrature pieces failed.

    outcomes[j]: what :func:`~analytic.kernels.routes.route_entries` did; where it served, the job's
    entries went to its slots of ``data``, elsewhere both are left for the next route.
    """
    width = 1
    for j in range(begin, end):
        width = max(width, jobs.offsets[j + 1] - jobs.offsets[j])
    scratch = make_scratch(width)
    out = np.empty(width)
    axis = problem.axis
    k = jobs.pairs[begin] if end > begin else 0
    frame = pair_frame(problem.pairs[k], problem.mode)
    for j in range(begin, end):
        if jobs.pairs[j] != k:          # the jobs come pair by pair
            k = jobs.pairs[j]
            frame = pair_frame(problem.pairs[k], problem.mode)
        pair_axis = TimeAxis(axis.start_opl - problem.pairs[k].offset, axis.bin_width_opl, axis.count)
        box = pixel_box(problem.grid, jobs.pixels[j])
        first, last = jobs.offsets[j], jobs.offsets[j + 1]
        column = Column(BinRun(jobs.firsts[j], last - first), jobs.lows[j], jobs.highs[j], True)
        outcomes[j] = route_entries(route, frame, box, column, problem.terms, pair_axis, problem.rtol, out, scratch)
        if outcomes[j] == SERVED:
            scale = problem.scales[k]
            for i in range(last - first):
                data[jobs.slots[first + i]] = out[i] * scale
    return scratch_failures(scratch)
