import os
import sys

import numpy as np
import pytest


def pytest_configure(config):
    """Each pytest-xdist worker (pyproject's ``-n auto``) runs Numba on its share of the cores.

    Numba's parallel kernels otherwise start a thread per core in every worker (and in every command a
    test starts, which inherits the variable): two workers ran four threads on 2 cores. Measured on 2
    cores (--dist loadfile), the default suite took 726 s with that and 654 s with one thread per worker.
    A value the user set is kept; a serial run (``-n 0``) is left alone. Set before any test imports Numba:
    Numba reads it once (tests/analytic/test_assembly.py still compares 1 thread against 2, in a child).
    """
    workers = getattr(config, "workerinput", {}).get("workercount")
    if workers and "numba" not in sys.modules:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        os.environ.setdefault("NUMBA_NUM_THREADS", str(max(1, cores // int(workers))))


@pytest.fixture
def rng():
    """A seeded generator: every random test is reproducible."""
    return np.random.default_rng(20261121)
