"""Draw a command's figure in a forked process, so that matplotlib loads while the command computes.

A short command such as ``forward`` spends about as long importing
matplotlib and drawing as computing A. On two or more cores the import can
run beside the computation: :func:`start` forks a process that imports
matplotlib and waits; :meth:`FigureProcess.submit` sends it a figure
function and its arguments, and :meth:`FigureProcess.result` gets the
PNG's bytes back, which the command writes itself (atomically, with its
other files). Whatever goes wrong in the
process (it cannot fork, dies, or raises), the figure is drawn in the
command's own process instead: a figure is never lost, only not overlapped.

The process is forked only where it can gain and cannot harm: fork exists,
matplotlib is not loaded yet (nothing to overlap otherwise) and Numba is not
either (its worker threads must not be forked). It ignores Ctrl-C (the
command handles it), exits when the command closes its pipe or dies, and
is killed if the command fails first or it does not answer within
:data:`PATIENCE` seconds.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import sys
import time
from typing import Callable

__all__ = ["FigureProcess", "start"]

_HEADER = 8     # bytes of the length that precedes each message
#: Seconds the command waits on the process (to take a request, or to answer it) before it kills it and
#: draws the figure itself: a drawing takes well under a second, so only a stuck process hits this.
PATIENCE = 60.0


def _wait(descriptor: int, writing: bool, deadline: float) -> None:
    """Until the pipe can be written (or read), or TimeoutError (an OSError) at the deadline."""
    left = deadline - time.monotonic()
    ready = select.select([], [descriptor], [], max(left, 0.0)) if writing else \
        select.select([descriptor], [], [], max(left, 0.0))
    if not any(ready):
        raise TimeoutError("the figure process did not answer")


def _send(descriptor: int, payload: bytes, deadline: float = float("inf")) -> None:
    data = len(payload).to_bytes(_HEADER, "little") + payload
    view = memoryview(data)
    while view:
        if deadline < float("inf"):
            _wait(descriptor, True, deadline)
        # at most PIPE_BUF bytes once select says writable: such a write never blocks
        view = view[os.write(descriptor, view[:select.PIPE_BUF] if deadline < float("inf") else view):]


def _read(descriptor: int, size: int, deadline: float) -> bytes | None:
    """Exactly ``size`` bytes, or None at end of file (the other side closed or died)."""
    chunks = []
    while size:
        if deadline < float("inf"):
            _wait(descriptor, False, deadline)
        chunk = os.read(descriptor, min(size, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        size -= len(chunk)
    return b"".join(chunks)


def _receive(descriptor: int, deadline: float = float("inf")) -> bytes | None:
    """One message, or None at end of file."""
    header = _read(descriptor, _HEADER, deadline)
    return None if header is None else _read(descriptor, int.from_bytes(header, "little"), deadline)


def _serve(requests: int, replies: int) -> None:
    """The forked process: load matplotlib, then draw the one figure asked for."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from matplotlib.backends import backend_agg  # noqa: F401  (the point: load it now)
    from matplotlib import figure  # noqa: F401

    message = _receive(requests)
    if message is None:
        return
    try:
        function, args, kwargs = pickle.loads(message)
        from .plots import png_bytes

        reply = ("png", png_bytes(function(*args, **kwargs)))
    except Exception as error:      # reported to the command, which then draws the figure itself
        reply = ("error", f"{type(error).__name__}: {error}")
    _send(replies, pickle.dumps(reply))


class FigureProcess:
    """One figure, drawn in a forked process when there is one (see :func:`start`), else here."""

    def __init__(self, pid: int = -1, requests: int = -1, replies: int = -1):
        self._pid, self._requests, self._replies = pid, requests, replies
        self._job = None
        self._answered = False

    @property
    def forked(self) -> bool:
        """Whether a process was forked to draw the figure."""
        return self._pid > 0

    def submit(self, function: Callable, *args, **kwargs) -> None:
        """Ask for ``function(*args, **kwargs)``, a module-level function returning a Figure."""
        self._job = (function, args, kwargs)
        if self._requests >= 0:
            try:
                _send(self._requests, pickle.dumps(self._job), time.monotonic() + PATIENCE)
            except OSError:     # the process died (a broken pipe) or is stuck: result() draws it here
                self.close()
                return
            os.close(self._requests)
            self._requests = -1

    def result(self) -> bytes:
        """The submitted figure as PNG bytes: from the process, or drawn here if it could not."""
        message = None
        if self._replies >= 0:
            try:
                message = _receive(self._replies, time.monotonic() + PATIENCE)
            except OSError:
                message = None
            self._answered = message is not None
        self.close()
        if message is not None:
            kind, value = pickle.loads(message)
            if kind == "png":
                return value
        from .plots import png_bytes

        function, args, kwargs = self._job
        return png_bytes(function(*args, **kwargs))

    def close(self) -> None:
        """End the process (idempotent) and reap it: once it has answered it exits by itself; before
        that (the command failed, or the process is stuck) it is killed, for it holds nothing of value."""
        for name in ("_requests", "_replies"):
            descriptor = getattr(self, name)
            if descriptor >= 0:
                os.close(descriptor)
                setattr(self, name, -1)
        if self._pid > 0:
            try:
                if not self._answered:
                    os.kill(self._pid, signal.SIGKILL)
                os.waitpid(self._pid, 0)
            except (ChildProcessError, ProcessLookupError):
                pass
            self._pid = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def start() -> FigureProcess:
    """Fork the figure process where that can gain and is safe (module docstring); else draw here."""
    if not hasattr(os, "fork") or "matplotlib" in sys.modules or "numba" in sys.modules:
        return FigureProcess()
    requests_read, requests_write = os.pipe()
    replies_read, replies_write = os.pipe()
    try:
        pid = os.fork()
    except OSError:
        for descriptor in (requests_read, requests_write, replies_read, replies_write):
            os.close(descriptor)
        return FigureProcess()
    if pid == 0:    # the child never returns into the command
        status = 0
        try:
            os.close(requests_write)
            os.close(replies_read)
            _serve(requests_read, replies_write)
        except BaseException:
            status = 1
        finally:
            os._exit(status)
    os.close(requests_read)
    os.close(replies_write)
    return FigureProcess(pid, requests_write, replies_read)
