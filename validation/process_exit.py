"""Ending a process after its exit handlers, without the interpreter's teardown.

Tearing down NumPy, SciPy, matplotlib and the compiled kernels (Numba's LLVM
modules) took 0.7 to 0.9 s after ``forward`` had written its files, and
0.2 to 0.3 s in the figure worker (:mod:`validation.plots.worker`) that its
command waits for. The exit handlers (``atexit``, hence weakref finalizers:
temporary folders, matplotlib's temporary configuration folder, logging,
multiprocessing) still run and the standard streams are flushed.
"""

from __future__ import annotations

import os
import sys

__all__ = ["exit_without_teardown"]


def exit_without_teardown(status: int) -> None:
    """End the process with ``status`` after its exit handlers; return (for the usual exit) where that
    cannot be done as Python's own exit would: no handler runner, or a non-daemon thread still running.

    Call it only once every file is closed and renamed.
    """
    import atexit
    import threading

    run_handlers = getattr(atexit, "_run_exitfuncs", None)
    running = [thread for thread in threading.enumerate()
               if thread is not threading.main_thread() and not thread.daemon and thread.is_alive()]
    if run_handlers is None or running:
        return
    run_handlers()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)
