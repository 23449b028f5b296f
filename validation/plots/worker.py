"""A figure drawn in a second Python process while this one computes its data.

On this project's 2-core machine matplotlib's import takes about 0.9 s and a
two-panel figure's drawing about 0.5 s, each on one core; before its
data exist a command is mostly on one core too (its own imports and
Numba's set-up). :class:`FigureWorker` starts ``python -m
validation.plots.worker`` when a command starts: that process imports
matplotlib on the idle core, then turns a plotting function's arguments
into PNG bytes while the command writes its other files
(``benchmarks/bench_model.py`` measures what ``forward`` gains). It is
started only where a core is idle (a busy machine would only pay its
imports twice) and imports the command's own copy of the code (its
``sys.path``, not the working directory's).

The worker writes no file: the command writes the bytes it gets back with
:func:`analytic.files.atomic_write`, inside its staged writes. Anything
but a clean drawing (an exception, a warning, a worker that died, never
started or wrote anything else on its output) is drawn again in this
process, so errors, warnings and bytes are exactly those of
:func:`~validation.plots.common.save_figure`.
"""

from __future__ import annotations

import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import warnings
from pathlib import Path

from .common import figure_png, save_png

__all__ = ["FigureWorker"]


#: Each message starts with these bytes, then its length (8 bytes), then its pickle.
_MAGIC = b"diffuse-imaging figure\n"
#: The longest message read: a PNG or a request beyond it is not this protocol's.
_LONGEST = 2**31


def _message(value) -> bytes:
    """One message: magic, length, pickle (a reader never stops inside one, nor takes stray output for one)."""
    data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return _MAGIC + struct.pack("<Q", len(data)) + data


def _receive(stream) -> bytes:
    """One message's pickle; EOFError when the stream ends first, ValueError when it is not a message."""
    head = stream.read(len(_MAGIC) + 8)
    if len(head) < len(_MAGIC) + 8:
        raise EOFError
    size, = struct.unpack("<Q", head[len(_MAGIC):])
    if head[:len(_MAGIC)] != _MAGIC or size > _LONGEST:
        raise ValueError("not a figure worker's message")
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return data


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:     # not Linux
        return os.cpu_count() or 1


def _others_running() -> float:
    """How many other tasks are running: Linux's count of runnable tasks less this one, the least of five
    looks 2 ms apart (a kernel thread or a shell's pipe is runnable for a moment, a busy process always);
    elsewhere the last minute's load average (which a loop of commands fills with its own earlier runs)."""
    import time

    try:
        counts = []
        for _ in range(5):
            with open("/proc/loadavg") as file:
                counts.append(int(file.read().split()[3].split("/")[0]) - 1)
            time.sleep(0.002)
        return min(counts)
    except (OSError, ValueError, IndexError):
        try:
            return os.getloadavg()[0]
        except OSError:     # not available: assume the machine is ours
            return 0.0


def _idle_core() -> bool:
    """Whether a core is free for the worker: two or more cores, and fewer others running than cores - 1."""
    cores = _cores()
    return cores >= 2 and _others_running() < cores - 1


class FigureWorker:
    """A second process that draws figures; a context manager that stops it.

    Start it before the work whose results the figures show; :meth:`draw`
    each figure once its data exist (the requests queue up, and the worker
    draws them in turn while this process goes on), then :meth:`save` (or
    :meth:`png`) them in the same order, in the command's
    :func:`analytic.files.staged_writes` block.
    """

    def __init__(self, start: bool | None = None):
        """
        Parameters
        ----------
        start : bool, optional
            Start the second process: by default only where it saves time, when a core is idle and
            this process has not imported matplotlib yet (a notebook's or a test's call draws here,
            with its own matplotlib settings).
        """
        self._process = None
        self._pending = []            # (request, sent to the worker), in the order asked
        #: Figures the worker drew (the others were drawn in this process).
        self.drawn_there = 0
        if start is None:
            start = "matplotlib" not in sys.modules and _idle_core()
        if not start or not sys.executable:      # an embedded Python may not know its executable
            return
        # this process's path, in its order ("" is the working directory); -P: not the child's own folder
        path = os.pathsep.join(os.path.abspath(entry) for entry in sys.path)
        environment = dict(os.environ, PYTHONPATH=path)
        try:
            self._process = subprocess.Popen([sys.executable, "-P", "-m", "validation.plots.worker"],
                                             stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                             stderr=subprocess.DEVNULL, env=environment)
        except (OSError, ValueError):            # no process to be had: drawn here
            return
        # requests are written by a thread: a large one must not wait here while the worker is busy
        self._outbox = queue.SimpleQueue()
        self._sender = threading.Thread(target=_send_all, args=(self._process.stdin, self._outbox), daemon=True)
        self._sender.start()

    def __enter__(self) -> "FigureWorker":
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    def draw(self, build, *args, **kwargs) -> None:
        """Ask for the figure ``build(*args, **kwargs)`` (a function of :mod:`validation.plots` that returns a
        Figure); :meth:`save` or :meth:`png` takes the figures in the order asked."""
        request, message = (build, args, kwargs), None
        if self._process is not None:
            try:
                message = _message(request)
            except (pickle.PickleError, AttributeError, TypeError):
                pass             # unpicklable arguments: drawn here
        if message is not None:
            self._outbox.put(message)
        self._pending.append((request, message is not None))

    def png(self) -> bytes:
        """The PNG bytes of the earliest figure :meth:`draw` asked for and not yet taken."""
        (build, args, kwargs), sent = self._pending.pop(0)
        if sent and self._process is not None:
            try:
                drawn = pickle.loads(_receive(self._process.stdout))
            except Exception:    # noqa: BLE001 (gone, or not our protocol: this figure and the rest drawn here)
                drawn = None
                self.close()
            if drawn is not None:
                self.drawn_there += 1
                return drawn
        return figure_png(build(*args, **kwargs))

    def save(self, path: str | Path) -> Path:
        """Write the earliest figure :meth:`draw` asked for and not yet taken at ``path`` as PNG, atomically."""
        return save_png(self.png(), path)

    def close(self) -> None:
        """Stop the worker now: SIGTERM, which it turns into a normal exit (matplotlib's temporary
        configuration folder, if it made one, is removed); it writes no file, so nothing is lost."""
        process, self._process = self._process, None
        if process is None:
            return
        process.terminate()
        self._outbox.put(None)
        self._sender.join()
        try:
            process.wait(timeout=5)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        for stream in (process.stdin, process.stdout):
            try:
                stream.close()
            except OSError:
                pass         # a request the killed worker never read


def _send_all(stream, outbox) -> None:
    """The sender thread: write each queued message until None (or until the worker is gone)."""
    while (message := outbox.get()) is not None:
        try:
            stream.write(message)
            stream.flush()
        except (OSError, ValueError):
            return       # the worker is gone: png() finds its output ended and draws here


def serve() -> None:
    """The worker: import matplotlib, then answer each request with PNG bytes, or None to be drawn again
    by the caller (an exception or a warning); end when the input closes."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the command handles Ctrl-C and stops the worker
    signal.signal(signal.SIGTERM, _exit)             # close(): exit handlers run (matplotlib's clean-up)
    # answers on a descriptor of their own; anything else written to standard output goes to standard error
    answers = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    requests = sys.stdin.buffer
    from . import relay_wall, transients  # noqa: F401 (what forward and render draw)
    from .common import new_figure, plain_text

    figure = new_figure(1, 1)
    figure.text(0.5, 0.5, plain_text("warm"))     # the font's file and characters, read once
    figure_png(figure)
    while True:
        try:
            request = _receive(requests)
        except EOFError:
            return
        try:
            build, args, kwargs = pickle.loads(request)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                png = figure_png(build(*args, **kwargs))
            answer = None if caught else png
        except Exception:        # noqa: BLE001 (the caller draws it again and raises it there)
            answer = None
        answers.write(_message(answer))
        answers.flush()


def _exit(signal_number, frame):
    """SIGTERM: end after the exit handlers (matplotlib's removal of a temporary configuration folder),
    without the teardown the command would wait for."""
    from validation.process_exit import exit_without_teardown

    exit_without_teardown(0)
    raise SystemExit(0)


if __name__ == "__main__":
    serve()
