"""The offset route: a capture whose pairs are translates of a few by whole pixels, each distinct offset computed once.

An entry of A depends on its (pair, pixel) only through the pair's two ends relative to the pixel (in
the rectangle's frame: their coordinates, heights, the cosine forms of their surfaces and the pair's
added path). Moving both ends of a pair by whole pixels along the rectangle's edges, and the pixel
with them, leaves the entry as it was. So when the pairs fall into a few *groups*, the members of
each a translate of its first one by whole pixels (:func:`offset_plan`; heights, cosines and added
paths equal to 1e-12 and positions to 1e-10 of a pixel), A's entries are those of the groups' first
pairs over a *virtual* rectangle of Mv x Mv pixels that holds every shifted pixel: G Mv² (pixel, pair)s
instead of P M².

That is the case of a hidden rectangle parallel to the relay wall with its edges along the scan grid's,
and a scan grid whose pitch is a whole number of pixels, or a fraction 1/q of one (q² groups): a 64 x 64
confocal scan of a 2 m wall over a 1 m square of 64 x 64 pixels is one group over 190 x 190 virtual
pixels, 36,100 (pixel, pair)s instead of 16.8 million (465 times fewer); an exhaustive scan, one group
per laser-to-read offset. A tilted rectangle (its heights differ from point to point), a single scan
(one laser point: no two pairs are translates), or pairs whose added paths differ
(``account_first_and_last_bounces``) keep the general route; so does any capture for which the
virtual work is not at most a quarter of the general one (:data:`MIN_SAVING`).

The virtual entries are assembled by the general machinery (every route, the same tolerance), kept as
one run of bins per (group, virtual pixel), and read by the compiled kernels of
:mod:`analytic.kernels.offsets`: A in CSR (:func:`offset_matrix`), or y = A f without A
(:func:`offset_forward`), each entry the pair's scale times the run's value, as the general route makes it.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np
import scipy.sparse

from ..errors import ResourceError
from ..kernels import offsets as kernels
from ..kernels.assembly import ImageGrid
from .blocks import index_bytes, run_blocks, thread_count

__all__ = ["OffsetPlan", "offset_plan", "offset_work", "offset_matrix", "offset_forward", "virtual_entries",
           "MIN_SAVING", "ENTRY_SECONDS"]

#: The offset route runs when its (pixel, pair)s are at most this share of the general route's.
MIN_SAVING = 0.25
#: Largest disagreement of a member with its group's first pair, in pixels (positions) and relative to
#: the scene's lengths (heights, cosine forms, added paths): far below the smallest tolerance's effect.
_POSITION_SLACK, _LENGTH_SLACK = 1e-10, 1e-12
#: Thread seconds per entry of A that the offset route sums into y or writes into A, measured
#: (benchmarks/bench_nlos.py: 25.6 million entries of a 32 x 32 confocal scan in about 0.3 s on 2 threads).
ENTRY_SECONDS = 2.5e-8
#: (pixel, pair)s per block of the compiled kernels at most (a block: a fraction of a second, ~10 ns each, so
#: that Ctrl-C stops them within about a second).
_COMBINATIONS_PER_BLOCK = 2**22


class OffsetPlan(NamedTuple):
    """Where each pair's entries come from: its group's virtual pairs and its shift (see the module docstring)."""

    virtual: object             # the virtual problem: analytic.operator.system's _Problem, G pairs, Mv² pixels
    groups: np.ndarray          # (P,) int64 group of each pair
    shift_c: np.ndarray         # (P,) int64 virtual column of the pair's pixel column 0
    shift_r: np.ndarray         # (P,) int64 virtual frame row of its frame row 0 (frame rows from the bottom)
    scales: np.ndarray          # (P,) each pair's factor
    pixels: int                 # M
    bins: int                   # N

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.pixels, self.virtual.grid.pixels, self.bins

    @property
    def mapping(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.groups, self.shift_c, self.shift_r


def _grouping(table: np.ndarray, grid) -> tuple | None:
    """(first pair of each group, each pair's group, its whole pixels from its group's first, the largest of
    those, Mv) of the pairs ``table`` over ``grid``, or None where the offset route does not apply or saves
    less than :data:`MIN_SAVING` asks."""
    count, pixels = len(table), grid.pixels
    if count < 2:
        return None
    du, dv = grid.width / pixels, grid.height / pixels
    steps = np.array([du, dv, du, dv])
    where = np.column_stack([table["source_x"], table["source_y"], table["sensor_x"], table["sensor_y"]])
    whole = np.round(where / steps)
    fraction = where / steps - whole
    length = max(grid.width, grid.height, float(np.max(np.abs(where))),
                 float(np.max(table["source_height"])), float(np.max(table["sensor_height"])))
    forms = _forms(table, whole * steps)
    # the key: fractions, the read end's whole offset from the lit end's, and every translation-invariant field
    key = np.column_stack([np.round(fraction * 2**20), whole[:, 2:] - whole[:, :2],
                           np.round(forms / length * 2**30)]).astype(np.int64)
    _, first, groups = np.unique(key, axis=0, return_index=True, return_inverse=True)
    groups = groups.ravel().astype(np.int64)
    shift = whole[:, :2] - whole[first[groups], :2]          # each member's whole pixels from its first pair
    low, high = shift.min(axis=0), shift.max(axis=0)
    virtual = int(pixels + np.max(high - low))
    if first.size * virtual**2 > MIN_SAVING * count * pixels**2:
        return None
    if (np.max(np.abs(fraction - fraction[first[groups]])) > _POSITION_SLACK
            or np.max(np.abs(forms - forms[first[groups]])) > _LENGTH_SLACK * length):
        return None
    return first, groups, shift, high, virtual


def offset_work(table: np.ndarray, grid) -> tuple[int, int] | None:
    """(G, Mv): the offset route's groups and virtual pixels per side for the pairs ``table`` over ``grid``
    (an :class:`~analytic.kernels.assembly.ImageGrid`), or None where it does not run."""
    grouping = _grouping(table, grid)
    return None if grouping is None else (len(grouping[0]), grouping[4])


def offset_plan(problem) -> OffsetPlan | None:
    """The offset route's plan for ``problem`` (analytic.operator.system's _Problem), or None where it does not
    apply or saves less than :data:`MIN_SAVING` asks."""
    grouping = _grouping(problem.pairs, problem.grid)
    if grouping is None:
        return None
    first, groups, shift, high, virtual = grouping
    grid = problem.grid
    du, dv = grid.width / grid.pixels, grid.height / grid.pixels
    # the virtual rectangle starts -high whole pixels from the real one: its first pairs move by +high
    moved = problem.pairs[first].copy()
    for end in ("source", "sensor"):
        moved[f"{end}_x"] += high[0] * du
        moved[f"{end}_y"] += high[1] * dv
        moved[f"{end}_cosine_0"] -= moved[f"{end}_cosine_u"] * high[0] * du + moved[f"{end}_cosine_v"] * high[1] * dv
    virtual_problem = problem._replace(pairs=moved, grid=ImageGrid(virtual * du, virtual * dv, virtual),
                                       scales=np.ones(first.size))
    shift = (high - shift).astype(np.int64)
    return OffsetPlan(virtual_problem, groups, np.ascontiguousarray(shift[:, 0]), np.ascontiguousarray(shift[:, 1]),
                      np.asarray(problem.scales, dtype=np.float64), grid.pixels, problem.axis.count)


def _forms(table: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """(P, 11) what must agree within a group: heights, added path, cosine flags and forms at the whole-pixel
    origin (each end's n·(x - p) = c0 + cu x + cv y, its c0 taken back by the end's whole pixels)."""
    columns = [table["source_height"], table["sensor_height"], table["offset"]]
    for index, end in enumerate(("source", "sensor")):
        cu, cv = table[f"{end}_cosine_u"], table[f"{end}_cosine_v"]
        c0 = table[f"{end}_cosine_0"] + cu * moved[:, 2 * index] + cv * moved[:, 2 * index + 1]
        columns += [table[f"{end}_cosine"].astype(np.float64), c0, cu, cv]
    return np.column_stack(columns)


def virtual_entries(plan: OffsetPlan, assemble: Callable) -> tuple:
    """(starts, firsts, values): one run of bins per (group, virtual pixel), from ``assemble(plan.virtual)``
    (A of the virtual problem, CSR)."""
    matrix = assemble(plan.virtual).tocoo()
    bins, side = plan.bins, plan.virtual.grid.pixels
    run = (matrix.row // bins) * side**2 + matrix.col
    n = (matrix.row % bins).astype(np.int64)
    order = np.lexsort((n, run))
    run, n, value = run[order], n[order], matrix.data[order]
    runs = len(plan.virtual.pairs) * side**2
    firsts = np.full(runs, 0, dtype=np.int64)
    lasts = np.full(runs, -1, dtype=np.int64)
    begins = np.flatnonzero(np.r_[True, run[1:] != run[:-1]]) if run.size else np.zeros(0, np.int64)
    ends = np.r_[begins[1:], run.size] - 1
    firsts[run[begins]] = n[begins]
    lasts[run[begins]] = n[ends]
    starts = np.zeros(runs + 1, dtype=np.int64)
    np.cumsum(lasts - firsts + 1, out=starts[1:])
    values = np.zeros(int(starts[-1]))
    values[starts[run] + n - firsts[run]] = value
    return starts, firsts, values


def _blocks(count: int, pixels: int) -> int:
    return min(count, max(4 * thread_count(), -(-count * pixels**2 // _COMBINATIONS_PER_BLOCK)))


def offset_matrix(plan: OffsetPlan, runs: tuple, limit: int) -> scipy.sparse.csr_array:
    """A (P N x M², CSR, columns ascending in each row) from the virtual runs, its size checked against ``limit``."""
    count, bins, pixels = len(plan.groups), plan.bins, plan.pixels
    rows, blocks = count * bins, _blocks(count, pixels)
    indptr = np.zeros(rows + 1, dtype=np.int64)
    bounds = (np.arange(blocks + 1) * count) // blocks

    def span(b):
        return int(bounds[b]), int(bounds[b + 1])

    run_blocks(kernels.offset_entries, lambda b: (runs, plan.shape, plan.mapping, plan.scales, *span(b),
                                                  indptr[1 + bounds[b] * bins:1 + bounds[b + 1] * bins],
                                                  np.empty(0, np.int32), np.empty(0), False), blocks)
    np.cumsum(indptr, out=indptr)
    nnz = int(indptr[-1])
    kind = np.int32 if index_bytes(nnz, rows, pixels**2) == 4 else np.int64
    needed = nnz * (8 + np.dtype(kind).itemsize) + 2 * 8 * (rows + 1)
    if needed > limit:
        raise ResourceError(f"sampling: the system matrix would hold {nnz:,} entries ({needed / 2**30:.3g} GiB), "
                            f"over the {limit / 2**30:.3g} GiB limit; use fewer bins (sampling.count / period) or "
                            f"fewer pixels")
    indices = np.empty(nnz, dtype=kind)
    data = np.empty(nnz)
    cursors = indptr[:-1].copy()
    run_blocks(kernels.offset_entries, lambda b: (runs, plan.shape, plan.mapping, plan.scales, *span(b),
                                                  cursors[bounds[b] * bins:bounds[b + 1] * bins], indices, data,
                                                  True), blocks)
    del cursors
    return scipy.sparse.csr_array((data, indices, indptr.astype(kind, copy=False)), shape=(rows, pixels**2))


def offset_forward(plan: OffsetPlan, runs: tuple, image: np.ndarray, *, bar=None) -> tuple[np.ndarray, int]:
    """(y = A f as (P, N), A's non-zeros) from the virtual runs, without A."""
    count = len(plan.groups)
    y = np.zeros((count, plan.bins))
    image = np.ascontiguousarray(image, dtype=np.float64).ravel()
    blocks = _blocks(count, plan.pixels)
    bounds = (np.arange(blocks + 1) * count) // blocks
    nonzeros = run_blocks(kernels.offset_product,
                         lambda b: (runs, plan.shape, plan.mapping, plan.scales, image, int(bounds[b]),
                                    int(bounds[b + 1]), y[bounds[b]:bounds[b + 1]]), blocks, bar=bar)
    return y, int(sum(nonzeros))
