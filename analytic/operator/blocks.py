"""Compiled kernels run block by block on a pool of threads, with a progress bar, interruptible; how A is cut
into blocks and what its assembly holds in memory.

The model's kernels (:mod:`analytic.kernels`) release Python's lock, so a
pool of threads runs them in parallel with no compiled parallel loop (whose
compile took more than the rest of a first run). Blocks are pulled by the
threads as they finish the last, so the threads stay balanced; between
blocks the calling thread updates the bar, and Ctrl-C stops the work as
soon as the running blocks end (a block is a fraction of a second).

A is cut into blocks of pixels (column ranges) times chunks of pairs (row
ranges): each block writes its own slots of the rows its pairs fill, after
the slots of the blocks of pixels before it (:func:`assembly_layout`). The
pixels are cut first (their counts per row cost memory, :data:`COUNTS_BYTES`),
the pairs then, so that every block holds at most :data:`COMBINATIONS_PER_BLOCK`
(pixel, pair)s: a relay wall's 2^20 pairs run on every thread, and Ctrl-C stops
them within about a second. :func:`assembly_bytes` is the peak memory of that
assembly, held to the allocations by tests/analytic/test_system_memory.py.
"""

from __future__ import annotations

import concurrent.futures
from typing import Callable, NamedTuple, Sequence

import numpy as np

from ..geometry import PAIR_DTYPE
from ..kernels.cache import compiled

__all__ = ["run_blocks", "thread_count", "Layout", "assembly_layout", "assembly_bytes", "index_bytes",
           "COMBINATIONS_PER_BLOCK", "COUNTS_BYTES", "ROUTE_SLOTS"]

BLOCKS_PER_THREAD = 16  # blocks per thread at least (pulled by the threads as they finish the last)
#: At most this much (and an eighth of the memory limit) for the blocks of pixels' counts per row.
COUNTS_BYTES = 2**28
#: (pixel, pair)s per block at most: about a second of one thread at the slowest (~30 µs each).
COMBINATIONS_PER_BLOCK = 2**15
#: Slots of A the general routes gather at once, a window inside one block (analytic.operator.general_routes).
ROUTE_SLOTS = 2**17
#: Bytes per slot of a window of the general routes while its jobs are made (its slots' positions, values,
#: NaN tests; for a left slot its row, pair, bin, pixel and sort order), and per left slot of a batch
#: (the windows' jobs, their joined copy and a route's subset): measured on relay walls, where every slot
#: is left, with a margin. A window lies inside one block and holds at most ROUTE_SLOTS slots; a batch
#: runs once it holds ROUTE_SLOTS / 2 left slots.
_WINDOW_BYTES_PER_SLOT, _BATCH_BYTES_PER_SLOT = 64, 56
#: Bytes per pair of the pairs' table and the scene's points and normals that build it (analytic.geometry).
_PAIR_BYTES = PAIR_DTYPE.itemsize + 8 * 16
#: Bytes per pair of a block's frames (compiled: the kernels' Frame record, ~20 floats, and its time shift).
_FRAME_BYTES = 8 * 24


def thread_count() -> int:
    """Threads the model's kernels run on: Numba's (``numba.set_num_threads``, else ``NUMBA_NUM_THREADS``,
    default the cores), read without starting Numba's own thread pool."""
    from numba.core import config
    from numba.np.ufunc import parallel

    if parallel._is_initialized:       # the pool exists, so numba.set_num_threads may have been called
        return max(1, int(parallel.get_num_threads()))
    return max(1, int(config.NUMBA_NUM_THREADS))


def run_blocks(kernel, arguments: Callable[[int], Sequence], blocks: int, *, threads: int | None = None,
               bar=None, weights: Sequence[int] | None = None) -> list:
    """``kernel(*arguments(b))`` for b = 0 ... blocks - 1, on ``threads`` threads; the results in block order.

    Parameters
    ----------
    kernel : numba dispatcher
        Compiled with ``nogil=True``; compiled (or loaded) once, before the threads start
        (:func:`analytic.kernels.cache.compiled`).
    arguments : callable
        Block index -> the kernel's arguments. Blocks must write disjoint outputs.
    blocks : int
        How many.
    threads : int, optional
        Default :func:`thread_count`.
    bar : tqdm, optional
        Advanced by ``weights[b]`` (default 1) as block b ends.
    weights : sequence of int, optional
        Each block's share of the bar.

    Raises
    ------
    KeyboardInterrupt
        Re-raised once the blocks already running have ended; no block starts after it.
    """
    if blocks == 0:
        return []
    compiled(kernel, *arguments(0))
    threads = min(thread_count() if threads is None else threads, blocks)
    results: list = [None] * blocks
    upcoming = iter(range(blocks))
    with concurrent.futures.ThreadPoolExecutor(max_workers=threads) as pool:
        pending: dict = {}

        def submit():
            # a few blocks per thread in flight, not all: each wait() visits every pending future
            for block in upcoming:
                pending[pool.submit(kernel, *arguments(block))] = block
                if len(pending) >= 2 * threads:
                    break

        try:
            submit()
            while pending:
                done, _ = concurrent.futures.wait(pending, timeout=0.2,
                                                  return_when=concurrent.futures.FIRST_COMPLETED)
                for future in done:
                    block = pending.pop(future)
                    results[block] = future.result()
                    if bar is not None:
                        bar.update(1 if weights is None else int(weights[block]))
                submit()
        except BaseException:
            for future in pending:
                future.cancel()
            raise
    return results


class Layout(NamedTuple):
    """Blocks of pixels x chunks of pairs, and the threads that run them.

    Block b is pixel block ``b % B`` of pair chunk ``b // B``: a chunk's blocks follow each other, and
    within a row (one pair) the blocks of pixels write their slots in column order.
    """

    pixel_bounds: np.ndarray    # (B + 1,) int64 column bounds
    pair_bounds: np.ndarray     # (C + 1,) int64 pair bounds
    threads: int

    @property
    def pixel_blocks(self) -> int:
        return len(self.pixel_bounds) - 1

    @property
    def blocks(self) -> int:
        return self.pixel_blocks * (len(self.pair_bounds) - 1)

    def block(self, b: int) -> tuple[int, int, int, int, int]:
        """(pixel block i, first column, end column, first pair, end pair) of block b."""
        i, chunk = b % self.pixel_blocks, b // self.pixel_blocks
        return (i, int(self.pixel_bounds[i]), int(self.pixel_bounds[i + 1]), int(self.pair_bounds[chunk]),
                int(self.pair_bounds[chunk + 1]))

    def combinations(self) -> np.ndarray:
        """(blocks,) (pixel, pair)s of each block: its share of a progress bar."""
        return np.multiply.outer(np.diff(self.pair_bounds), np.diff(self.pixel_bounds)).ravel()


def _bounds(size: int, parts: int) -> np.ndarray:
    """(parts + 1,) int64 bounds of ``parts`` contiguous ranges of ``size``, as even as integers allow."""
    return (np.arange(parts + 1, dtype=np.int64) * size) // parts


def assembly_layout(pairs: int, bins: int, pixels: int, limit: int, *, threads: int | None = None) -> Layout:
    """How A of ``pairs`` x ``bins`` rows and ``pixels``² columns is cut into blocks (see the module docstring).

    Parameters
    ----------
    pairs, bins, pixels : int
        P, N and M.
    limit : int
        Bytes A may use: the blocks of pixels' counts per row take at most an eighth of it.
    threads : int, optional
        Default :func:`thread_count`.
    """
    threads = thread_count() if threads is None else threads
    rows = max(pairs * bins, 1)
    columns = pixels ** 2
    wanted = BLOCKS_PER_THREAD * threads
    affordable = max(1, min(limit // 8, COUNTS_BYTES) // (8 * rows))
    if pairs < wanted:
        # few pairs (a plane's sensors): blocks of pixels, each its own count per row (rows are few)
        pixel_blocks = max(1, min(wanted, affordable, columns))
        per_block = -(-columns // pixel_blocks)
        chunks = max(1, min(pairs, -(-(per_block * pairs) // COMBINATIONS_PER_BLOCK)))
    else:
        # many pairs (a relay wall's scan): chunks of pairs, whose rows need no count of their own
        chunks = min(pairs, max(wanted, -(-(columns * pairs) // COMBINATIONS_PER_BLOCK)))
        per_chunk = -(-pairs // chunks)
        pixel_blocks = max(1, min(-(-(columns * per_chunk) // COMBINATIONS_PER_BLOCK), affordable, columns))
    return Layout(_bounds(columns, pixel_blocks), _bounds(pairs, chunks), threads)


def index_bytes(nnz: int, rows: int, columns: int) -> int:
    """Bytes of one of A's column indices (and of its final row pointers): 4 where int32 holds them all."""
    return 4 if max(nnz, rows, columns) < 2**31 else 8


def assembly_bytes(nnz: float, pairs: int, bins: int, pixels: int, layout: Layout, *, widest: int = 0,
                   list_bytes: float = 0.0) -> float:
    """Peak bytes of assembling A (:mod:`analytic.operator.system`) with ``nnz`` entries, as it allocates them.

    Parameters
    ----------
    nnz : float
        A's entries (counted, or estimated by :func:`analytic.operator.cost.model_cost`).
    pairs, bins, pixels : int
        P, N and M.
    layout : Layout
    widest : int
        Most bins one (pixel, pair) reaches (each thread's scratch holds a few of them).
    list_bytes : float
        Every thread's kink lists (:attr:`analytic.operator.cost.ModelCost.list_memory`).

    Notes
    -----
    While the blocks are filled and the general routes run: A's values and column indices (8 and 4 or 8
    bytes per entry), its row pointers (int64), each block of pixels' next slot in each row (int64), the
    counts per column (one copy per pair chunk), the pairs' table, the routes' working set
    (a window of at most :data:`ROUTE_SLOTS` slots inside one block, and a batch of jobs) and each
    thread's frames and scratch.
    The row pointers' final int32 copy, A's exact zeros dropped in place and y = A f come after the
    counts per row are freed, which are larger.
    """
    rows = pairs * bins
    columns = pixels ** 2
    matrix = nnz * (8 + index_bytes(int(nnz), rows, columns)) + (rows + 1) * 8
    counts = layout.pixel_blocks * rows * 8 + (len(layout.pair_bounds) - 1) * columns * 8 + layout.blocks * 8
    # a block's window: at most ROUTE_SLOTS, and about its share of A (twice the mean, for uneven blocks)
    window = min(ROUTE_SLOTS, 2 * nnz / layout.blocks, nnz)
    routes = _WINDOW_BYTES_PER_SLOT * window + _BATCH_BYTES_PER_SLOT * min(nnz, ROUTE_SLOTS // 2 + window)
    chunk = int(np.max(np.diff(layout.pair_bounds), initial=0))
    threads = layout.threads * (_FRAME_BYTES * chunk + 16 * 8 * widest) + list_bytes
    return matrix + counts + routes + pairs * _PAIR_BYTES + threads
