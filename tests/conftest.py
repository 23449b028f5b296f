import os
import sys
from pathlib import Path


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


@pytest.fixture(scope="module")
def figures_drawn_once():
    """A module's commands, run in this process, draw each distinct figure once, here.

    A figure's PNG is a function of its request (the plotting function and its arguments): a request
    whose pickle equals an earlier one's gets the earlier bytes, without drawing again (about 0.6 s
    each); a new one is drawn as the command draws it, and a drawing that raises is raised, never
    remembered. No figure worker is started (a command's default; an explicit ``start`` is kept): the
    tests using this are about a command's inputs and files, not the worker
    (tests/validation/test_figure_worker.py is, and does not use this).
    """
    import pickle

    from validation.plots import worker

    drawn = {}
    start_worker, png = worker.FigureWorker.__init__, worker.FigureWorker.png

    def without_a_worker(self, start=None):
        start_worker(self, start=False if start is None else start)

    def once(self):
        request, sent = self._pending[0]
        if sent and self._process is not None:      # an explicit worker: its answers stay in order
            return png(self)
        try:
            key = pickle.dumps(request, protocol=pickle.HIGHEST_PROTOCOL)
        except (pickle.PickleError, AttributeError, TypeError):
            return png(self)                           # drawn, as the worker would have left it
        if key not in drawn:
            drawn[key] = png(self)
        else:
            self._pending.pop(0)
        return drawn[key]

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(worker.FigureWorker, "__init__", without_a_worker)
        patch.setattr(worker.FigureWorker, "png", once)
        yield


SLOW_CASES = Path(__file__).with_name("slow_cases.txt")


@pytest.hookimpl(tryfirst=True)   # before -m deselects by mark
def pytest_collection_modifyitems(config, items):
    """Mark slow the cases listed in tests/slow_cases.txt (see its header)."""
    listed = {line.strip() for line in SLOW_CASES.read_text(encoding="utf-8").splitlines()
              if line.strip() and not line.startswith("#")}
    found = set()
    for item in items:
        if item.nodeid in listed:
            item.add_marker(pytest.mark.slow)
            found.add(item.nodeid)
    collected = {item.nodeid.split("::")[0] for item in items}
    missing = sorted(case for case in listed - found if case.split("::")[0] in collected)
    if missing:     # a module collected without a listed case of it: renamed or removed
        raise pytest.UsageError(f"{SLOW_CASES.name} lists cases that do not exist: {missing[:3]}")
