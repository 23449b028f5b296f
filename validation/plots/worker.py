"""A figure drawn in a second Python process while this one computes its data.

On this project's 2-core machine matplotlib's import takes about 0.9 s and a
two-panel figure's drawing about 0.5 s, each on one core; before its
data exist a command is mostly on one core too (its own imports and
Numba's set-up). :class:`FigureWorker` starts ``python -m
validation.plots.worker`` when a command starts: that process imports
matplotlib on the idle core, then turns a plotting function's arguments
into PNG bytes while the command writes its other files. ``forward`` at
M = 1024 ends about 1 s sooner (docs/benchmarks.md).

The worker writes no file: the command writes the bytes it gets back with
:func:`analytic.files.atomic_write`, inside its staged writes. Anything
but a clean drawing (an exception, a warning, a worker that died or never
started, a machine with one core) is drawn again in this process, so
errors, warnings and bytes are exactly those of :func:`save_figure`.
"""

from __future__ import annotations

import io
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import warnings
from pathlib import Path

from analytic.files import atomic_write

__all__ = ["FigureWorker", "figure_png"]


def figure_png(figure) -> bytes:
    """The PNG :func:`~validation.plots.common.save_figure` writes of a figure, as bytes."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=figure.dpi)
    return buffer.getvalue()


def _message(value) -> bytes:
    """One message: its length (8 bytes), then its pickle, so that a reader never stops inside one."""
    data = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    return struct.pack("<Q", len(data)) + data


def _receive(stream) -> bytes:
    """One message's pickle; EOFError when the stream ends first."""
    head = stream.read(8)
    if len(head) < 8:
        raise EOFError
    size, = struct.unpack("<Q", head)
    data = stream.read(size)
    if len(data) < size:
        raise EOFError
    return data


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:     # not Linux
        return os.cpu_count() or 1


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
            Start the second process: by default only where it saves time, on two or more cores when
            this process has not imported matplotlib yet (a notebook's or a test's call draws here).
        """
        self._process = None
        self._pending = []            # (request, sent to the worker), in the order asked
        #: Figures the worker drew (the others were drawn in this process).
        self.drawn_there = 0
        if start is None:
            start = _cores() >= 2 and "matplotlib.figure" not in sys.modules
        if not start:
            return
        environment = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        try:
            self._process = subprocess.Popen([sys.executable, "-m", "validation.plots.worker"],
                                             stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                             stderr=subprocess.DEVNULL, env=environment)
        except OSError:
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
            except (OSError, EOFError, pickle.PickleError):
                drawn = None
                self.close()     # the worker is gone: this figure and the rest are drawn here
            if drawn is not None:
                self.drawn_there += 1
                return drawn
        return figure_png(build(*args, **kwargs))

    def save(self, path: str | Path) -> Path:
        """Write the earliest figure :meth:`draw` asked for and not yet taken at ``path`` as PNG, atomically."""
        png = self.png()
        return atomic_write(path, lambda temporary: Path(temporary).write_bytes(png))

    def close(self) -> None:
        """Stop the worker at once (it writes no file: nothing of it is lost)."""
        process, self._process = self._process, None
        if process is None:
            return
        process.kill()
        self._outbox.put(None)
        self._sender.join()
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

    signal.signal(signal.SIGINT, signal.SIG_IGN)     # the command handles Ctrl-C and closes the input
    requests, answers = sys.stdin.buffer, sys.stdout.buffer
    sys.stdout = sys.stderr                            # only answers on the pipe
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


if __name__ == "__main__":
    serve()
