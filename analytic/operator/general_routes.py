"""The general routes on the (pixel, pair)s that assembly's first pass leaves, a bounded batch at a time.

The first pass (:func:`analytic.kernels.assembly.fill_block`) writes NaN in the slots of the (pixel,
pair)s it leaves: a cut pixel near x* or a foot, or one its rules did not settle. They are gathered
from the blocks' slots in windows of at most :data:`~analytic.operator.blocks.ROUTE_SLOTS` slots and
run in batches through the direct smooth route, strips, then the cut route (:data:`GENERAL_ROUTES`),
each trying those the one before did not serve, on the threads; so the jobs' arrays are a bounded
working set beside A (once ~60 bytes per left slot of the whole of A at once).
"""

from __future__ import annotations

import numpy as np

from ..kernels import assembly, routes
from ..kernels.assembly import Assembly, Jobs
from ..kernels.cache import compiled
from ..kernels.arcs import nested_integral_arguments, pixel_isochrone_integral
from ..kernels.routes import Route
from .blocks import ROUTE_SLOTS, Layout, run_blocks

__all__ = ["left_pairs", "run_left", "run_route", "progress_bar", "GENERAL_ROUTES"]


def progress_bar(progress: bool, total: int, description: str, unit: str):
    """A tqdm bar on stderr when ``progress``, else None (tqdm imported only then)."""
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=int(total), desc=description, unit=unit, leave=False)


#: Jobs per block of the general routes (each a cut pixel's quadrature: about a millisecond or more).
_JOBS_PER_BLOCK = 64


def _window_jobs(starts: np.ndarray, ends: np.ndarray, first_row: int, indices: np.ndarray, data: np.ndarray,
                 bins: int) -> Jobs:
    """The (pair, pixel)s the first pass left (NaN in their slots) among slots[starts[r]:ends[r]] of rows
    first_row + r, each with its slots in bin order (the rows hold whole pairs)."""
    lengths = ends - starts
    until = np.cumsum(lengths)                      # the gathered slots up to each row's end
    positions = np.repeat(starts - (until - lengths), lengths)
    positions += np.arange(positions.size, dtype=np.int64)
    left = np.flatnonzero(np.isnan(data[positions]))
    slots = positions[left]
    del positions                                   # each array freed as soon as the next is made: the
    rows = first_row + np.searchsorted(until, left, side="right")     # window's peak stays a few per slot
    del left
    pairs, bin_index = np.divmod(rows, bins)
    del rows
    pixels = indices[slots].astype(np.int64)
    order = np.lexsort((bin_index, pixels, pairs))
    slots = slots[order]
    pairs = pairs[order]
    bin_index = bin_index[order]
    pixels = pixels[order]
    del order
    # a window may hold no left slot (its block's left pairs lie in its other windows)
    begins = np.flatnonzero(np.concatenate([[slots.size > 0], (pairs[1:] != pairs[:-1]) | (pixels[1:] != pixels[:-1])]))
    offsets = np.append(begins, slots.size).astype(np.int64)
    return Jobs(pairs[begins], pixels[begins], bin_index[begins], offsets, slots, np.empty(begins.size),
                np.empty(begins.size))


def _joined(parts: list[Jobs]) -> Jobs:
    """Several windows' jobs as one."""
    if len(parts) == 1:
        return parts[0]
    shifts = np.cumsum([0] + [part.slots.size for part in parts[:-1]])
    offsets = np.concatenate([[0]] + [part.offsets[1:] + shift for part, shift in zip(parts, shifts)])
    joined = {name: np.concatenate([getattr(part, name) for part in parts]) for name in Jobs._fields
              if name != "offsets"}
    return Jobs(**joined, offsets=offsets.astype(np.int64))


def _windows(layout: Layout, left: np.ndarray, cursors: np.ndarray, indptr: np.ndarray, bins: int):
    """(starts, ends, first row) of the slots of each window of the blocks that left pairs: whole pairs of one
    block, as many as hold at most :data:`~analytic.operator.blocks.ROUTE_SLOTS` slots (one pair at least)."""
    most_rows = max(bins, ROUTE_SLOTS // 8 // bins * bins)     # the rows looked at once (their sizes' sums)
    for b in np.flatnonzero(left):
        i, _, _, first, last = layout.block(int(b))
        row, end = first * bins, last * bins
        while row < end:
            stop = min(end, row + most_rows)
            starts = (cursors[i - 1] if i else indptr[:-1])[row:stop]
            sizes = np.cumsum(cursors[i, row:stop] - starts)[bins - 1::bins]   # slots up to each pair's end
            pairs = max(1, int(np.searchsorted(sizes, ROUTE_SLOTS, side="right")))
            stop = row + pairs * bins
            yield starts[:pairs * bins], cursors[i, row:stop], row
            row = stop


def left_pairs(record: Assembly, layout: Layout, left: np.ndarray, cursors: np.ndarray, indptr: np.ndarray,
                indices: np.ndarray, data: np.ndarray, bins: int, *, progress: bool = False) -> tuple[int, int]:
    """The general routes on the pairs the first pass left, a batch of windows at a time; (pieces failed,
    served smooth).

    ``left[b]``: the pairs block b left. The jobs are gathered from the blocks' slots (``cursors``: each
    block of pixels' end in each row) in windows of about :data:`~analytic.operator.blocks.ROUTE_SLOTS`
    slots, so that their arrays stay a bounded working set beside A.
    """
    failures = smooth = 0
    parts, gathered = [], 0
    bar = progress_bar(progress, int(left.sum()), "cut pixels", "pixel-pair")
    try:
        for starts, ends, row in _windows(layout, left, cursors, indptr, bins):
            parts.append(_window_jobs(starts, ends, row, indices, data, bins))
            gathered += parts[-1].slots.size
            if gathered >= ROUTE_SLOTS // 2:
                batch, parts, gathered = _joined(parts), [], 0        # the parts freed before the routes run
                failures, smooth = _add(run_left(record, batch, data, layout.threads), failures, smooth, bar)
                del batch
        if parts:
            batch, parts = _joined(parts), []
            failures, smooth = _add(run_left(record, batch, data, layout.threads), failures, smooth, bar)
    finally:
        if bar is not None:
            bar.close()
    return failures, smooth


def _add(outcome: tuple[int, int, int], failures: int, smooth: int, bar) -> tuple[int, int]:
    more_failures, more_smooth, jobs = outcome
    if bar is not None:
        bar.update(jobs)
    return failures + more_failures, smooth + more_smooth


def _subset(jobs: Jobs, chosen: np.ndarray) -> Jobs:
    """The jobs where ``chosen`` is True, with their slots (``jobs`` itself when all are)."""
    if np.all(chosen):
        return jobs
    index = np.flatnonzero(chosen)
    lengths = np.diff(jobs.offsets)[index]
    offsets = np.zeros(index.size + 1, dtype=np.int64)
    np.cumsum(lengths, out=offsets[1:])
    positions = np.repeat(jobs.offsets[index] - offsets[:-1], lengths)
    positions += np.arange(positions.size, dtype=np.int64)
    return Jobs(jobs.pairs[index], jobs.pixels[index], jobs.firsts[index], offsets, jobs.slots[positions],
                jobs.lows[index], jobs.highs[index])


def _compile_nested() -> None:
    """The φ-integrals that the cut routes nest in their τ-integrals, compiled first (see
    :func:`analytic.kernels.arcs.nested_integral_arguments`)."""
    compiled(pixel_isochrone_integral, *nested_integral_arguments())


#: The general routes assembly runs, in order, on the pairs its first pass leaves.
GENERAL_ROUTES = (Route(routes.DIRECT), Route(routes.STRIP), Route(routes.CUT))


def run_left(record: Assembly, jobs: Jobs, data: np.ndarray, threads: int) -> tuple[int, int, int]:
    """:data:`GENERAL_ROUTES` on ``jobs``, each trying those the one before did not serve; (failures, smooth,
    jobs).

    Their kernels are compiled (or loaded) only when some pair is left (:mod:`analytic.kernels.assembly`); a
    route that does not serve a pair leaves it to the next.
    """
    flags = np.zeros(jobs.pairs.size, dtype=np.int64)
    compiled(assembly.job_routes, record, jobs, flags)(record, jobs, flags)
    waiting = np.ones(jobs.pairs.size, dtype=bool)
    failures, smooth = 0, 0
    for route, applies in zip(GENERAL_ROUTES, (flags & assembly.DIRECT_APPLIES > 0,
                                                flags & assembly.STRIPS_APPLY > 0, None)):
        chosen = waiting if applies is None else waiting & applies
        if not np.any(chosen):
            continue
        batch = _subset(jobs, chosen)
        outcomes, more = run_route(route, record, batch, data, threads)
        failures += more
        served = outcomes == routes.SERVED
        if route.code == routes.DIRECT:
            smooth += int(served.sum())
        waiting[np.flatnonzero(chosen)[served]] = False
    return failures, smooth, int(jobs.pairs.size)


def run_route(route: Route, record: Assembly, jobs: Jobs, data: np.ndarray, threads: int):
    """(outcomes, pieces failed) of one route on every job, in blocks on ``threads`` threads."""
    _compile_nested()
    outcomes = np.zeros(jobs.pairs.size, dtype=np.int64)
    count = jobs.pairs.size
    blocks = max(1, -(-count // _JOBS_PER_BLOCK))
    failures = run_blocks(assembly.run_jobs, lambda b: (route, record, jobs, b * count // blocks,
                                                        (b + 1) * count // blocks, data, outcomes),
                          blocks, threads=threads)
    return outcomes, int(sum(failures))
