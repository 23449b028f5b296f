"""Compiled kernels run block by block on a pool of threads, with a progress bar, interruptible.

The model's kernels (:mod:`analytic.kernels`) release Python's lock, so a
pool of threads runs them in parallel with no compiled parallel loop (whose
compile took more than the rest of a first run). Blocks are pulled by the
threads as they finish the last, so the threads stay balanced; between
blocks the calling thread updates the bar, and Ctrl-C stops the work as
soon as the running blocks end (a block is a fraction of a second).
"""

from __future__ import annotations

import concurrent.futures
from typing import Callable, Sequence

from ..kernels.cache import compiled

__all__ = ["run_blocks", "thread_count"]


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
    with concurrent.futures.ThreadPoolExecutor(max_workers=threads) as pool:
        pending = {pool.submit(kernel, *arguments(block)): block for block in range(blocks)}
        try:
            while pending:
                done, _ = concurrent.futures.wait(pending, timeout=0.2,
                                                  return_when=concurrent.futures.FIRST_COMPLETED)
                for future in done:
                    block = pending.pop(future)
                    results[block] = future.result()
                    if bar is not None:
                        bar.update(1 if weights is None else int(weights[block]))
        except BaseException:
            for future in pending:
                future.cancel()
            raise
    return results
