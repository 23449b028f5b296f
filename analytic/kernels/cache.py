"""Where the compiled kernels are cached, what invalidates them, and the line a long compile prints.

Numba compiles a kernel on its first use and can keep it on disk. Three
rules make that cache serve users (docs/benchmarks.md, "Cold start"):

- **Keyed by what the compiled code depends on.** This sub-package is
  closed: its modules import each other, NumPy, Numba and ``math``, and
  nothing else of the project. :class:`KernelCacheLocator` stamps every
  kernel with the SHA-256 of all of this sub-package's sources, so that an
  edit anywhere else (a scene reader, a docstring of the Python side) never
  recompiles a kernel, and an edit here recompiles the kernels that are
  used next (their calls resolve across modules at compile time, so one
  stamp for the sub-package is the honest dependency).
- **Found where it can be written.** Under ``NUMBA_CACHE_DIR`` when the
  user set it; else beside the sources (``__pycache__``) when that folder
  can be written; else in the user's cache folder
  (``$XDG_CACHE_HOME/diffuse-imaging`` or ``~/.cache/diffuse-imaging``), so
  that a read-only install (a system or shared install, a container) builds
  its kernels once per user and finds them there afterwards. The process
  environment is never changed.
- **Said when slow.** :func:`install` registers a listener of Numba's compile
  events: a compile of this sub-package's kernels still running after
  :data:`NOTICE_SECONDS` prints one line on stderr (what is compiled, that
  it happens once, where it is kept). :func:`compiled` compiles an entry
  point for given arguments under its lock file in the cache folder, so that
  processes starting together (Dask workers, pytest-xdist workers) compile
  it once and the others load it.
- **Interrupted only between compiles.** While Numba holds its compiler lock
  (a compile, or a load from the cache), LLVM calls back into Python
  (llvmlite's object-cache hooks, through ctypes): a KeyboardInterrupt
  raised there is dropped by ctypes and LLVM goes on with what the callback
  never produced, a crash (exit -11) instead of Ctrl-C's exit. :func:`install`
  therefore holds SIGINT in the main thread while the lock is held and
  delivers it as soon as the lock is released (a load takes milliseconds, a
  compile seconds, which the compile notice announces).

Each stamp gets its own folder under that root (:func:`cache_folder`): the
caches of other sources (an older release, another checkout) are never
read, and are left for the user to delete.

Modules that compile kernels take ``njit`` from here, which installs the
locator and the listener first.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import signal
import sys
import tempfile
import threading
from pathlib import Path

from numba import njit
from numba.core import config, event
from numba.core.caching import CacheImpl, IndexDataCacheFile, _CacheLocator

__all__ = ["KernelCacheLocator", "sources_stamp", "cache_folder", "compiled", "install", "njit", "NOTICE_SECONDS"]

_KERNELS = Path(__file__).resolve().parent

#: A compile of the kernels still running after this many seconds says so on stderr (once per process).
NOTICE_SECONDS = 2.0


@functools.lru_cache(maxsize=None)
def _stamp_of(files: tuple[tuple[str, int, int], ...]) -> str:
    digest = hashlib.sha256()
    for name, _, _ in files:
        digest.update(name.encode() + b"\0" + (_KERNELS / name).read_bytes() + b"\0")
    return digest.hexdigest()


def sources_stamp() -> str:
    """SHA-256 of every source of this sub-package (names and contents), as hex.

    Memoised on the files' times and sizes, so that a source edited while the process runs is read again.
    """
    files = []
    for path in sorted(_KERNELS.glob("*.py")):
        status = path.stat()
        files.append((path.name, status.st_mtime_ns, status.st_size))
    return _stamp_of(tuple(files))


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def _user_cache_root() -> Path:
    """``$XDG_CACHE_HOME/diffuse-imaging``, ``~/.cache/diffuse-imaging``, or a private temporary folder."""
    base = os.environ.get("XDG_CACHE_HOME")
    if not base:
        home = os.path.expanduser("~")
        base = os.path.join(home, ".cache") if home and home != "~" else ""
    if base and _writable(Path(base) / "diffuse-imaging"):
        return Path(base) / "diffuse-imaging"
    return Path(tempfile.gettempdir()) / f"diffuse-imaging-{os.getuid() if hasattr(os, 'getuid') else 'user'}"


@functools.lru_cache(maxsize=None)
def _folder(cache_dir: str) -> Path:
    if cache_dir:
        return Path(cache_dir) / "diffuse-imaging" / "kernels"
    beside = _KERNELS / "__pycache__"
    if _writable(beside):
        return beside
    return _user_cache_root() / "kernels"


def cache_folder() -> Path:
    """The folder the kernels are cached in: one per :func:`sources_stamp`, under the root the module
    docstring names.

    One folder per stamp, not Numba's stamp check alone: Numba unpickles a kernel's whole index before it
    compares the stamp, and an index written by other sources (an older release, another checkout sharing
    ``NUMBA_CACHE_DIR``) can name modules or record types these sources no longer have
    (``ModuleNotFoundError`` instead of a recompile).
    """
    folder = _folder(config.CACHE_DIR or "") / sources_stamp()[:16]
    with contextlib.suppress(OSError):
        folder.mkdir(parents=True, exist_ok=True)
    return folder


class KernelCacheLocator(_CacheLocator):
    """Numba's cache locator for this sub-package's kernels: :func:`cache_folder`, stamped by :func:`sources_stamp`."""

    def __init__(self, py_func, py_file):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno

    def get_cache_path(self):
        return str(cache_folder())

    def get_source_stamp(self):
        return sources_stamp()

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            inside = Path(py_file).resolve().parent == _KERNELS
        except OSError:
            return None
        if not inside:
            return None
        locator = cls(py_func, py_file)
        try:
            locator.ensure_cache_path()
        except OSError:
            return None
        return locator


class _CompileNotice:
    """Prints one line on stderr when a compile of the kernels outlasts :data:`NOTICE_SECONDS` (once per process)."""

    def __init__(self):
        self.depth = 0
        self.said = False
        self.timer: threading.Timer | None = None
        self.started = 0.0
        self.lock = threading.Lock()

    def _say(self, name: str) -> None:
        with self.lock:
            if self.said or self.depth == 0:
                return
            self.said = True
        try:
            print(f"diffuse-imaging: compiling the model's kernels ({name}); once: they are kept in "
                  f"{cache_folder()} for every later run", file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass    # stderr is gone: the notice is not worth failing for

    def __call__(self, record: event.Event) -> None:
        dispatcher = record.data.get("dispatcher")
        module = getattr(getattr(dispatcher, "py_func", None), "__module__", "") or ""
        if record.is_start:
            self.depth += 1
            if self.depth == 1 and not self.said and module.startswith(__package__ or "analytic.kernels"):
                name = f"{module.rsplit('.', 1)[-1]}.{dispatcher.py_func.__name__}"
                self.timer = threading.Timer(NOTICE_SECONDS, self._say, args=(name,))
                self.timer.daemon = True
                self.timer.start()
        else:
            self.depth = max(self.depth - 1, 0)
            if self.depth == 0 and self.timer is not None:
                self.timer.cancel()
                self.timer = None


class _Listener(event.Listener):
    def __init__(self, notice: _CompileNotice):
        self.notice = notice

    def on_start(self, record):
        if threading.current_thread() is threading.main_thread():
            self.notice(record)

    def on_end(self, record):
        if threading.current_thread() is threading.main_thread():
            self.notice(record)


_NOTICE = _CompileNotice()


class _HeldInterrupts(event.Listener):
    """Holds SIGINT in the main thread while Numba's compiler lock is held, and delivers it on release.

    The lock is re-entrant (a compile loads or compiles the kernels it calls): only the outermost
    acquisition swaps the handler. A handler that is not Python's (ignored, or the default action) is
    left alone: it never raises inside a callback.
    """

    def __init__(self):
        self.depth = 0
        self.saved = None
        self.caught = False

    def _hold(self, number, frame):
        self.caught = True

    def on_start(self, record):
        if threading.current_thread() is not threading.main_thread():
            return
        self.depth += 1
        if self.depth == 1:
            handler = signal.getsignal(signal.SIGINT)
            if callable(handler):
                self.saved, self.caught = handler, False
                signal.signal(signal.SIGINT, self._hold)

    def on_end(self, record):
        if threading.current_thread() is not threading.main_thread() or self.depth == 0:
            return
        self.depth -= 1
        if self.depth == 0 and self.saved is not None:
            saved, self.saved = self.saved, None
            signal.signal(signal.SIGINT, saved)
            if self.caught:
                # delivered as the terminal would have: the handler runs at Python's next instruction
                signal.raise_signal(signal.SIGINT)


_HELD = _HeldInterrupts()


@contextlib.contextmanager
def _compile_lock(name: str):
    """An exclusive lock file in the cache folder while kernel ``name`` is compiled or loaded (POSIX; else none).

    One lock per entry point and argument types: processes compiling different ones (the set-up's warm-ups)
    run side by side.
    """
    try:
        import fcntl
    except ImportError:       # not POSIX: each process compiles for itself
        yield
        return
    try:
        handle = open(cache_folder() / f".{name}.lock", "a")
    except OSError:
        yield
        return
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def compiled(kernel, *args):
    """``kernel`` (a Numba dispatcher) compiled or loaded for ``args``' types, once per process.

    The first time, under a lock file in :func:`cache_folder` (one per kernel and types): a second process starting at the same
    time waits for the first one's compile and then loads it from the cache instead of compiling it again.
    Returns ``kernel``.
    """
    signature = tuple(kernel.typeof_pyval(argument) for argument in args)
    if signature in kernel.overloads:
        return kernel
    typed = hashlib.sha256(str(signature).encode()).hexdigest()[:12]
    with _compile_lock(f"{kernel.py_func.__qualname__}-{typed}"):
        kernel.compile(signature)
    return kernel


_numba_save = IndexDataCacheFile.save


def _locked_save(self, key, data):
    """Numba's save of a cache entry, under a lock file beside the index when the index is ours.

    Numba reads the index, picks the first free data file, writes the index, then the data, with no lock:
    two processes saving two signatures of one kernel at once (the warm-up's two waveform kinds, xdist or
    Dask workers) could pick the same data file, and the index could then map one signature to the other's
    machine code. One lock per index makes each save whole.
    """
    if Path(self._cache_path) != cache_folder():      # another package's cache: Numba's own save
        return _numba_save(self, key, data)
    try:
        import fcntl
        handle = open(self._index_path + ".lock", "a")
    except (ImportError, OSError):      # not POSIX, or a folder we cannot write: Numba's own save
        return _numba_save(self, key, data)
    with handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            return _numba_save(self, key, data)
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def install() -> None:
    """Put :class:`KernelCacheLocator` first among Numba's locators, lock its saves, listen for long
    compiles, and hold SIGINT while Numba's compiler lock is held (once)."""
    if KernelCacheLocator not in CacheImpl._locator_classes:
        CacheImpl._locator_classes.insert(0, KernelCacheLocator)
        IndexDataCacheFile.save = _locked_save
        event.register("numba:compile", _Listener(_NOTICE))
        event.register("numba:compiler_lock", _HELD)


install()
