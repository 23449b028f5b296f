import os
import sys


def _one_share_of_the_cores_per_worker():
    """Each pytest-xdist worker (pyproject's ``-n auto``) runs Numba and OpenBLAS on its share of the cores.

    Both otherwise start a thread per core in every worker (and in every command a test starts, which
    inherits the variables): two workers ran four threads on 2 cores. Measured on 2 cores (--dist
    loadfile), the default suite took 726 s with Numba's and 654 s with one thread per worker. OpenBLAS's
    waiting threads spin: with one other process busy, tests/analytic/inversion/test_tikhonov.py (serial)
    took 9.3 and 8.6 s on its default 2 threads, 5.3 and 4.9 s on 1 (the same either way on an idle
    machine). A value the user set is kept; a serial run (``-n 0``) is left alone. Run when this file is
    imported, before any test imports NumPy or Numba: each reads its variable once, when loaded
    (pytest-xdist names the worker count before then; tests/analytic/test_assembly.py still compares 1
    Numba thread against 2, in a child).
    """
    workers = os.environ.get("PYTEST_XDIST_WORKER_COUNT")
    if not workers:
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    share = str(max(1, cores // int(workers)))
    for variable, module in (("NUMBA_NUM_THREADS", "numba"), ("OPENBLAS_NUM_THREADS", "numpy")):
        if module not in sys.modules:
            os.environ.setdefault(variable, share)


_one_share_of_the_cores_per_worker()

import numpy as np  # noqa: E402 (after the thread counts above)
import pytest  # noqa: E402


@pytest.fixture
def rng():
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)
