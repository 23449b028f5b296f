"""Draw a command's figure in a forked process, so that matplotlib loads while the command computes.

A short command such as ``forward`` spends about as long importing
matplotlib and drawing as computing A. On two or more cores the import can
run beside the computation: :func:`start` forks a process that imports
matplotlib and waits; :meth:`FigureProcess.submit` sends it a figure
function and its arguments (pickled), and :meth:`FigureProcess.result` gets
the PNG's bytes back, which the command writes itself (atomically, with its
other files). A fork, not a new interpreter: the child shares the modules
already loaded (NumPy), so it is ready before the command needs it, where a
fresh ``python -m`` took 0.1–0.2 s longer and competed with A's threads.

Whatever goes wrong (the fork fails, the process dies, raises, or does not
answer within :data:`PATIENCE_SECONDS`), the command draws the figure
itself: a figure is never lost, only not overlapped.

The process is forked only where that is safe and can gain: when asked
(``enabled``: the console script, whose process is the command's alone, not
a caller such as pytest), where fork exists, and before matplotlib (nothing
to overlap otherwise) and Numba (its worker threads) are loaded. Ctrl-C is
blocked around the fork and ignored in the child (the command handles it);
the child exits when its pipe closes, so a command that fails or is killed
leaves nothing running; one that fails before asking for its figure gives
the child :data:`GRACE_SECONDS` to exit by itself (it may be writing
matplotlib's font cache on a first run) before killing it.
"""

from __future__ import annotations

import os
import pickle
import select
import signal
import sys
import time
from typing import Callable

__all__ = ["FigureProcess", "start", "PATIENCE_SECONDS", "GRACE_SECONDS"]

#: Seconds the command waits on the process (to take the request, then to answer it) before it kills
#: the process and draws the figure itself: a drawing takes well under a second.
PATIENCE_SECONDS = 60.0
#: Seconds a process whose figure is not wanted gets to exit by itself before it is killed.
GRACE_SECONDS = 5.0

_HEADER = 8     # bytes of the length that precedes each message


def _ready(descriptor: int, event: int, deadline: float) -> None:
    """Wait until the pipe is ready (``select.POLLIN`` or ``POLLOUT``); TimeoutError (an OSError) at the
    deadline. poll, not select: select fails on descriptors from 1024 up."""
    poller = select.poll()
    poller.register(descriptor, event)
    left = deadline - time.monotonic()
    if not poller.poll(max(left, 0.0) * 1000.0 if left < float("inf") else None):
        raise TimeoutError("the figure process did not answer")


def _send(descriptor: int, payload: bytes, deadline: float = float("inf")) -> None:
    """Write a length-prefixed message; at most PIPE_BUF bytes per write once the pipe is writable, so
    that no write blocks past the deadline."""
    for part in (len(payload).to_bytes(_HEADER, "little"), payload):
        view = memoryview(part)
        while view:
            _ready(descriptor, select.POLLOUT, deadline)
            view = view[os.write(descriptor, view[:select.PIPE_BUF]):]


def _read(descriptor: int, size: int, deadline: float) -> bytes | None:
    """Exactly ``size`` bytes, or None at end of file (the other side closed or died)."""
    chunks = []
    while size:
        _ready(descriptor, select.POLLIN, deadline)
        chunk = os.read(descriptor, min(size, 1 << 20))
        if not chunk:
            return None
        chunks.append(chunk)
        size -= len(chunk)
    return b"".join(chunks)


def _receive(descriptor: int, deadline: float = float("inf")) -> bytes | None:
    """One length-prefixed message, or None at end of file."""
    header = _read(descriptor, _HEADER, deadline)
    return None if header is None else _read(descriptor, int.from_bytes(header, "little"), deadline)


def _serve(requests: int, replies: int) -> None:
    """The forked process: load matplotlib, then draw the one figure asked for (none: return)."""
    from matplotlib.backends import backend_agg  # noqa: F401  (the point: load it now)
    from matplotlib import figure  # noqa: F401

    from .plots import png_bytes

    message = _receive(requests)
    if message is None:
        return
    function, args, kwargs = pickle.loads(message)
    _send(replies, png_bytes(function(*args, **kwargs)))


class FigureProcess:
    """One figure, drawn in a forked process when there is one (see :func:`start`), else here.

    Parameters
    ----------
    pid : int
        The forked process, or -1 to draw here.
    requests, replies : int
        The pipes' descriptors to it and from it (-1 without a process).
    """

    def __init__(self, pid: int = -1, requests: int = -1, replies: int = -1):
        self._pid, self._requests, self._replies = pid, requests, replies
        self._job = None
        self._settled = False     # the exchange is over (answered, or the process killed)

    @property
    def forked(self) -> bool:
        """Whether a process was forked to draw the figure."""
        return self._pid > 0

    def submit(self, function: Callable, *args, **kwargs) -> None:
        """Ask for the figure ``function(*args, **kwargs)``.

        Parameters
        ----------
        function : callable
            A module-level function (pickled by name) returning a
            :class:`matplotlib.figure.Figure`.
        *args, **kwargs
            Its arguments (picklable).
        """
        self._job = (function, args, kwargs)
        if self._requests < 0:
            return
        try:
            _send(self._requests, pickle.dumps(self._job, protocol=pickle.HIGHEST_PROTOCOL),
                  time.monotonic() + PATIENCE_SECONDS)
        except OSError:     # the process died (a broken pipe) or is stuck: result() draws the figure here
            self._kill()
            return
        os.close(self._requests)
        self._requests = -1

    def result(self) -> bytes:
        """The submitted figure as PNG bytes: from the process, or drawn here if it could not.

        Returns
        -------
        bytes
            A PNG file's contents.
        """
        png = None
        if self._replies >= 0:
            try:
                png = _receive(self._replies, time.monotonic() + PATIENCE_SECONDS)
            except OSError:
                png = None
            if png is None:
                self._kill()
            self._settled = True
        self.close()
        if png is not None:
            return png
        from .plots import png_bytes

        function, args, kwargs = self._job
        return png_bytes(function(*args, **kwargs))

    def _kill(self) -> None:
        if self._pid > 0:
            try:
                os.kill(self._pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self._settled = True

    def close(self) -> None:
        """End the process (idempotent) and reap it.

        Its pipes close; it then exits by itself (it has answered, or reads
        the end of its input once matplotlib is loaded), or is killed after
        :data:`GRACE_SECONDS`; a process asked for a figure that is no longer
        wanted (the command failed meanwhile) is killed at once.
        """
        if self._job is not None and not self._settled:
            self._kill()
        for name in ("_requests", "_replies"):
            descriptor = getattr(self, name)
            if descriptor >= 0:
                os.close(descriptor)
                setattr(self, name, -1)
        if self._pid <= 0:
            return
        deadline = time.monotonic() + GRACE_SECONDS
        while True:
            try:
                pid, _ = os.waitpid(self._pid, os.WNOHANG)
            except ChildProcessError:
                break
            if pid:
                break
            if time.monotonic() > deadline:
                self._kill()
                deadline = float("inf")
            time.sleep(0.005)
        self._pid = -1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def start(enabled: bool = True) -> FigureProcess:
    """Fork the figure process where that is safe and can gain (module docstring), else draw here.

    Parameters
    ----------
    enabled : bool
        False draws here: only a process that is the command's alone (the
        console script) may fork.

    Returns
    -------
    FigureProcess
    """
    if (not enabled or not hasattr(os, "fork") or "matplotlib" in sys.modules
            or "numba" in sys.modules):
        return FigureProcess()
    try:
        requests_read, requests_write = os.pipe()
    except OSError:
        return FigureProcess()
    try:
        replies_read, replies_write = os.pipe()
    except OSError:
        os.close(requests_read)
        os.close(requests_write)
        return FigureProcess()
    descriptors = (requests_read, requests_write, replies_read, replies_write)
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pid = os.fork()
    except Exception:   # OSError, or a warning made an error (Python >= 3.12 warns when threads exist)
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        for descriptor in descriptors:
            os.close(descriptor)
        return FigureProcess()
    if pid == 0:    # the child never returns into the command
        status = 0
        try:
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
            os.close(requests_write)
            os.close(replies_read)
            _serve(requests_read, replies_write)
        except BaseException:
            status = 1
        finally:
            os._exit(status)
    signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
    os.close(requests_read)
    os.close(replies_write)
    return FigureProcess(pid, requests_write, replies_read)
