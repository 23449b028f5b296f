"""Output files of DESIGN.md section 5: written atomically, checked, in a locked folder.

Every file is written to a temporary name in its destination folder,
flushed, fsynced and checked (non-empty, and read back: the array's shape,
the JSON, the EXR's values, the HDF5's datasets) before it is renamed over
the final name, so an interrupted command never leaves a torn file. Inside
:func:`staged_writes` the renames wait for the end of the block: a command
that fails half-way leaves its folder as it was. Every file-system failure
(disk full, read-only, ``--out`` naming a file, no permission, a name too
long) becomes one :class:`~analytic.errors.ResourceError` line naming the
path.

Folders and their locks: :func:`output_folder` gives a folder to one
writing command at a time. It holds an exclusive ``flock`` on the folder's
``.diffuse-imaging.lock`` (which holds its process id, for the message a
second command gets) and on the folder itself. :func:`reading_folder` holds
a shared ``flock`` on the data's folder and on every folder above it while
the data are read, so a reader never pairs files of two commits; it creates
no file. The lock file is removed while it is still held (removed after the
release, a second command could lock the doomed file while a third locks
its replacement), and a taker that finds, once it holds the lock, that the
path no longer names the file it locked tries again. Every way out of a
command removes the lock file; one left by a killed command is harmless
(the kernel released its lock) and is taken over.

Temporaries are named ``.diffuse-imaging-tmp-<host>-<pid>-<random>-<name>``
(:data:`TEMPORARY_PREFIX`): a name no other program uses, carrying the
process that made it. In each folder it writes, a command removes the
temporaries of dead processes of this host (:func:`remove_temporaries`),
and nothing else: not a user's files, not another folder's, not those of a
live process.

Metadata has one schema for every command, built by :func:`build_meta`
(DESIGN.md section 5 names its keys), written to ``meta.json`` and, as
numbers, into the EXR header. The EXR is float32: where float32 cannot hold
the values (:func:`float32_problem`), ``transient.exr`` is not written, a
:class:`PrecisionWarning` says why and ``meta.json``'s ``exr`` records it;
``transient.npy`` (float64) is the exact record.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import fcntl
import functools
import hashlib
import json
import os
import re
import socket
import stat
import tempfile
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np

from .errors import DataError, ResourceError

__all__ = ["atomic_write", "staged_writes", "discard", "output_folder", "reading_folder", "save_npy",
           "save_json", "save_text", "save_exr", "save_png_image", "write_transient", "read_transient",
           "read_exr", "build_meta", "remove_temporaries", "json_ready", "float32_problem", "PrecisionWarning",
           "LOCK_FILE", "TEMPORARY_PREFIX", "LOCK_WAIT_SECONDS", "UNITS"]

#: Held (flock) by the command writing a folder; holds its process id.
LOCK_FILE = ".diffuse-imaging.lock"

#: Start of every temporary file name this program makes, and of no other file's.
TEMPORARY_PREFIX = ".diffuse-imaging-tmp-"
_TEMPORARY_NAME = re.compile(re.escape(TEMPORARY_PREFIX) + r"(?P<host>[0-9a-f]{8})-(?P<pid>[0-9]+)-")

#: Seconds a reader waits for a writer to finish, and a writer for readers, before refusing.
LOCK_WAIT_SECONDS = 2.0

# Longest file name (bytes) of the common file systems.
_NAME_MAX = 255

#: How y's units follow from the source's intensity (DESIGN.md section 1).
UNITS = ("lengths in metres; time as optical path length in metres (c = 1); y in W/sr x m^-2 x m "
         "of path length: the source's peak radiant intensity I (W/sr) times the pulse's "
         "integral over the bin (m of path length) times the attenuation (m^-4) times area (m^2); "
         "noise sigma in the units of y")

_staged: contextvars.ContextVar[list | None] = contextvars.ContextVar("staged", default=None)

# Folders (device, inode) this process holds for writing: its own readers must not wait on them.
_writing: set[tuple[int, int]] = set()

# Folders (device, inode) this process holds for reading, and how many times.
_reading: dict[tuple[int, int], int] = {}

# Folders (device, inode) whose abandoned temporaries this process has removed.
_swept: set[tuple[int, int]] = set()

_FIXES = {errno.ENOSPC: "free some space or choose another --out",
          errno.EDQUOT: "free some space or choose another --out",
          errno.EFBIG: "the file is too large for this file system; choose another --out",
          errno.EROFS: "the file system is read-only; choose another --out",
          errno.EACCES: "no permission; choose another --out",
          errno.EPERM: "no permission; choose another --out",
          errno.ENOTDIR: "a parent of it is a file, not a folder; choose another --out",
          errno.EEXIST: "a file or link of that name is in the way; choose another --out",
          errno.EISDIR: "a folder of that name is in the way; choose another --out",
          errno.ENAMETOOLONG: f"a name in the path is longer than the file system allows "
                              f"({_NAME_MAX} bytes); choose a shorter --out",
          errno.ELOOP: "its symbolic links loop; choose another --out",
          errno.ENOENT: "a folder of the path does not exist or went away; choose another --out",
          errno.EIO: "the device reports an input/output error; choose another --out",
          errno.ENOLCK: "this file system cannot lock files; choose another --out"}


def _resource_error(error: OSError, path: Path, action: str) -> ResourceError:
    fix = _FIXES.get(error.errno, "check the path")
    return ResourceError(f"{path}: cannot {action} ({error.strerror or error}); {fix}")


def _resource_failure(error: Exception, path: Path) -> ResourceError | None:
    """The ResourceError behind a writer's exception, or None when it is no file-system failure.

    Writers report a full disk in their own ways: ``OSError`` with an errno
    (h5py, Pillow), ``OSError`` without one for a short write (NumPy's "N
    requested and M written"), ``RuntimeError`` quoting the C library's
    message (OpenEXR).
    """
    if isinstance(error, OSError) and error.errno is not None:
        return _resource_error(error, path, "write")
    text = str(error)
    for code in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EIO):
        if os.strerror(code) in text:
            return _resource_error(OSError(code, os.strerror(code)), path, "write")
    if isinstance(error, OSError):
        return ResourceError(f"{path}: cannot write ({error}): a short write, is the disk full?; "
                             f"free some space or choose another --out")
    return None


# --------------------------------------------------------------------------- temporaries

@functools.cache
def _host_tag() -> str:
    """8 hex digits naming this host and process-id namespace: another's process ids mean nothing here."""
    try:
        namespace = os.readlink("/proc/self/ns/pid")
    except OSError:
        namespace = ""
    name = f"{socket.gethostname()}\0{namespace}".encode("utf-8", "surrogateescape")
    return hashlib.blake2s(name, digest_size=4).hexdigest()


def _temporary_path(path: Path) -> Path:
    prefix = f"{TEMPORARY_PREFIX}{_host_tag()}-{os.getpid()}-"
    suffix = f"-{path.name}"
    if len(os.fsencode(prefix + "x" * 8 + suffix)) > _NAME_MAX:   # mkstemp adds 8 characters
        suffix = path.suffix if len(os.fsencode(path.suffix)) <= 16 else ""
    handle, temporary = tempfile.mkstemp(prefix=prefix, suffix=suffix, dir=path.parent)
    os.close(handle)
    return Path(temporary)


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:      # alive, another user's
        return True
    except (OverflowError, ValueError):
        return False             # no process has such an id
    return True


def _abandoned(name: str) -> bool:
    """Whether ``name`` is a temporary of ours whose process, on this host, is dead."""
    match = _TEMPORARY_NAME.match(name)
    if match is None or match["host"] != _host_tag():
        return False
    pid = int(match["pid"])
    return pid != os.getpid() and not _process_alive(pid)


def remove_temporaries(folder: str | Path) -> int:
    """Remove the temporaries that dead processes of this host left in ``folder`` (not below it).

    Only names that begin with :data:`TEMPORARY_PREFIX` and carry the id of a
    process that no longer runs are touched: a user's files, other folders and
    a running command's temporaries stay.

    Returns
    -------
    int
        The number removed.
    """
    removed = 0
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return 0
    for entry in entries:
        if _abandoned(entry.name) and entry.is_file(follow_symlinks=False):
            with contextlib.suppress(OSError):   # gone already, or not ours to remove (a sticky folder)
                os.unlink(entry.path)
                removed += 1
    return removed


def _sweep_once(folder: Path) -> None:
    """Remove abandoned temporaries the first time this process writes into ``folder``."""
    try:
        info = os.stat(folder)
    except OSError:
        return
    key = (info.st_dev, info.st_ino)
    if key not in _swept:
        remove_temporaries(folder)
        _swept.add(key)


# --------------------------------------------------------------------------- writing files

def _make_folder(folder: Path) -> None:
    try:
        if folder.exists() and not folder.is_dir():
            raise ResourceError(f"{folder}: is a file, not a folder; choose another --out")
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise _resource_error(error, folder, "create the folder") from None


def _rename(temporary: Path, path: Path) -> None:
    try:
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise _resource_error(error, path, "write") from None


def _remove_final(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError as error:
        raise _resource_error(error, path, "remove") from None


def discard(path: str | Path) -> None:
    """Remove a file an earlier command wrote that this one does not, with the staged renames.

    Inside :func:`staged_writes` the removal waits for the end of the block
    (and does not happen if it fails); outside, it happens now.
    """
    staged = _staged.get()
    if staged is not None:
        staged.append((None, Path(path)))
    else:
        _remove_final(Path(path))


def atomic_write(path: str | Path, write: Callable[[str], None],
                 verify: Callable[[str], None] | None = None) -> Path:
    """Write a file through a temporary name, check it, then rename it onto ``path``.

    Parameters
    ----------
    path : str or Path
        Final file; its folder is created. The first write into a folder
        removes the temporaries dead commands left there.
    write : callable
        ``write(temporary_path)`` writes the whole file.
    verify : callable, optional
        ``verify(temporary_path)`` reads it back and raises if it is not what
        was meant (any exception: the write failed, e.g. a full disk).

    Returns
    -------
    Path
        ``path``. Inside :func:`staged_writes` the rename waits for the end
        of the block.

    Raises
    ------
    ResourceError
        When the file system refuses (full, read-only, a file in the way).
    """
    path = Path(path)
    _make_folder(path.parent)
    _sweep_once(path.parent)
    try:
        temporary = _temporary_path(path)
    except OSError as error:
        raise _resource_error(error, path, "write") from None
    try:
        try:
            write(str(temporary))
        except Exception as error:   # a writer's own way of saying the disk is full
            failure = _resource_failure(error, path)
            if failure is None:
                raise
            raise failure from None
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(temporary, 0o666 & ~umask)   # mkstemp makes 0600; give the usual mode
        with open(temporary, "rb+") as stream:
            os.fsync(stream.fileno())
        if temporary.stat().st_size == 0:
            raise ResourceError(f"{path}: the written file is empty (disk full?); free some space "
                                f"or choose another --out")
        if verify is not None:
            try:
                verify(str(temporary))
            except Exception as error:  # any failure to read it back means the write failed
                raise ResourceError(f"{path}: the written file does not read back ({error}); "
                                    f"is the disk full?") from None
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise _resource_error(error, path, "write") from None
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    staged = _staged.get()
    if staged is not None:
        staged.append((temporary, path))
    else:
        _rename(temporary, path)
    return path


@contextlib.contextmanager
def staged_writes() -> Iterator[None]:
    """Rename every file :func:`atomic_write` writes in this block together, at its end.

    If the block raises, its temporaries are removed and no final file has
    changed: a command that fails half-way leaves its folder as it was.
    """
    if _staged.get() is not None:   # nested: the outer block commits
        yield
        return
    token = _staged.set([])
    try:
        yield
        staged = _staged.get()
        _staged.reset(token)
        token = None
        for temporary, path in staged:
            if temporary is None:
                _remove_final(path)
            else:
                _rename(temporary, path)
    except BaseException:
        if token is not None:
            for temporary, _ in _staged.get():
                if temporary is not None:
                    temporary.unlink(missing_ok=True)
            _staged.reset(token)
        raise


# --------------------------------------------------------------------------- folders and locks

def _file_kind(mode: int) -> str:
    if stat.S_ISREG(mode):
        return "a file"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "something other than a folder"


def _prepare_output_folder(folder: str | Path, option: str) -> tuple[Path, bool]:
    """The output folder, created when absent; True when this call created it."""
    text = os.fsdecode(os.fspath(folder))
    if not text.strip():      # Path("") is the current folder: never write there unasked
        raise ResourceError(f"{option}: an empty path; name the output folder")
    if "\0" in text:
        raise ResourceError(f"{option} {text!r}: the path holds a NUL byte, which no file name can; "
                            f"name the output folder without it")
    folder = Path(text)
    try:
        mode = os.stat(folder).st_mode
    except FileNotFoundError:
        if os.path.islink(folder):
            target = "a missing target"
            with contextlib.suppress(OSError):
                target = os.readlink(folder)
            raise ResourceError(f"{option} {folder}: a symbolic link to {target}, which does not exist; "
                                f"create the folder it names or choose another {option}") from None
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise _resource_error(error, folder, "create the folder") from None
        return folder, True
    except OSError as error:
        raise _resource_error(error, folder, "use the folder") from None
    if not stat.S_ISDIR(mode):
        raise ResourceError(f"{option} {folder}: is {_file_kind(mode)}, not a folder; "
                            f"choose another {option}")
    return folder, False


def _names(path: Path, descriptor: int) -> bool:
    """Whether ``path`` (not followed if a link) still names the file open as ``descriptor``."""
    try:
        on_path = os.stat(path, follow_symlinks=False)
    except OSError:
        return False
    held = os.fstat(descriptor)
    return (on_path.st_dev, on_path.st_ino) == (held.st_dev, held.st_ino)


def _writer_of(folder: Path) -> str:
    """The process id in ``folder``'s lock file, read without creating it; "unknown" when absent."""
    try:
        with open(folder / LOCK_FILE, "rb") as stream:
            text = stream.read(32).decode(errors="replace").strip()
    except OSError:
        return "unknown"
    return text or "unknown"


def _lock_the_lock_file(folder: Path, option: str) -> int:
    """Open and exclusively lock ``folder``'s lock file; the descriptor holding it."""
    path = folder / LOCK_FILE
    for _ in range(1000):   # a retry follows another command's removing the file we opened: rare
        try:
            descriptor = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        except FileNotFoundError:   # a failed command removed the folder it had created: make it again
            _make_folder(folder)
            continue
        except OSError as error:
            raise _resource_error(error, folder, "lock the folder") from None
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.pread(descriptor, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(descriptor)
            raise ResourceError(f"{option} {folder}: another diffuse-imaging command (process {other}) "
                                f"is writing this folder; wait for it or choose another {option}") from None
        except OSError as error:
            os.close(descriptor)
            raise _resource_error(error, folder, "lock the folder") from None
        if _names(path, descriptor):
            return descriptor
        os.close(descriptor)   # locked a file its last holder removed: lock the one the path names
    raise ResourceError(f"{option} {folder}: its lock file keeps being replaced; wait for the other "
                        f"commands or choose another {option}")


def _release_the_lock_file(folder: Path, descriptor: int) -> None:
    """Remove the lock file while still holding it, then release it."""
    try:
        path = folder / LOCK_FILE
        if _names(path, descriptor):
            with contextlib.suppress(OSError):
                os.unlink(path)
    finally:
        os.close(descriptor)


def _lock_against_readers(folder: Path, option: str) -> int | None:
    """Exclusively lock the folder itself (readers hold it shared); None where folders cannot be locked."""
    try:
        descriptor = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:       # unreadable: no reader can lock it either
        return None
    info = os.fstat(descriptor)
    if _reading.get((info.st_dev, info.st_ino)):
        os.close(descriptor)
        raise RuntimeError(f"{folder}: output_folder inside a reading_folder block that holds it; end the "
                           f"reading block before writing")
    deadline = time.monotonic() + LOCK_WAIT_SECONDS
    while True:
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if time.monotonic() < deadline:
                time.sleep(0.02)
                continue
            os.close(descriptor)
            raise ResourceError(f"{option} {folder}: another diffuse-imaging command is reading this "
                                f"folder or a file below it; wait for it or choose another "
                                f"{option}") from None
        except OSError:   # a file system without folder locks (NFS): readers cannot lock it either
            os.close(descriptor)
            return None
        _writing.add((info.st_dev, info.st_ino))
        return descriptor


def _release_against_readers(descriptor: int | None) -> None:
    if descriptor is None:
        return
    with contextlib.suppress(OSError):
        info = os.fstat(descriptor)
        _writing.discard((info.st_dev, info.st_ino))
    os.close(descriptor)


@contextlib.contextmanager
def output_folder(folder: str | Path, *, option: str = "--out") -> Iterator[Path]:
    """Create and lock an output folder for one command; undo its creation if the command fails.

    Parameters
    ----------
    folder : str or Path
        The folder (an existing one, or a link to one, or a new one).
    option : str
        The command-line option that named it, for messages.

    Raises
    ------
    ResourceError
        When the path is empty, holds a NUL byte, names a file, a FIFO, a
        device or a dangling link, cannot be created or written, or another
        command holds its lock (its process id is named), or readers hold it
        for longer than :data:`LOCK_WAIT_SECONDS`.

    Notes
    -----
    On every way out (success, an exception, an interrupt) the lock file is
    removed and the locks released; a folder this call created is removed
    again if the command failed and left it empty. Do not write a folder
    inside a :func:`reading_folder` block on it: end the reading first.
    """
    folder, created = _prepare_output_folder(folder, option)
    lock = _lock_the_lock_file(folder, option)
    against_readers = None
    try:
        against_readers = _lock_against_readers(folder, option)
        with contextlib.suppress(OSError):   # the process id only names us in another command's message
            os.ftruncate(lock, 0)
            os.pwrite(lock, str(os.getpid()).encode(), 0)
        remove_temporaries(folder)
        try:
            yield folder
        except BaseException:
            if created:
                _remove_if_only_lock(folder)
            raise
    finally:
        _release_against_readers(against_readers)
        _release_the_lock_file(folder, lock)


def _remove_if_only_lock(folder: Path) -> None:
    """Remove a folder this command created, if it holds nothing but empty folders and the lock."""
    with contextlib.suppress(OSError):
        for inner in sorted((p for p in folder.rglob("*") if p.is_dir()), reverse=True):
            inner.rmdir()   # fails, and stops everything, at the first one that holds a file
        if {p.name for p in folder.iterdir()} <= {LOCK_FILE}:
            (folder / LOCK_FILE).unlink(missing_ok=True)
            folder.rmdir()


def _folders_holding(path: Path) -> list[Path]:
    """The data's own folder (the path itself when it is one) and every folder above it, links resolved."""
    try:
        real = Path(os.path.realpath(path))
        first = real if real.is_dir() else real.parent
    except (OSError, ValueError):   # a path no file can have: its reader says so
        return []
    return [first, *first.parents]


def _lock_for_reading(folder: Path, path: Path, option: str, wait_seconds: float) -> int | None:
    """A descriptor holding ``folder`` shared, or None where it cannot or need not be locked."""
    deadline = time.monotonic() + wait_seconds
    while True:
        try:
            descriptor = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
        except OSError:     # unreadable: no writer can lock it either
            return None
        info = os.fstat(descriptor)
        if (info.st_dev, info.st_ino) in _writing:   # this process writes it: no other can
            os.close(descriptor)
            return None
        try:
            fcntl.flock(descriptor, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(descriptor)
            if time.monotonic() >= deadline:
                raise ResourceError(f"{option} {path}: another diffuse-imaging command (process "
                                    f"{_writer_of(folder)}) is writing {folder}; wait for it to finish, "
                                    f"then run again") from None
            time.sleep(0.02)
            continue
        except OSError:     # a file system without folder locks (NFS)
            os.close(descriptor)
            return None
        if _names(folder, descriptor):
            key = (info.st_dev, info.st_ino)
            _reading[key] = _reading.get(key, 0) + 1
            return descriptor
        os.close(descriptor)   # the folder was replaced while we waited: lock the one the path names


@contextlib.contextmanager
def reading_folder(path: str | Path, *, option: str = "--data",
                   wait_seconds: float | None = None) -> Iterator[Path]:
    """Keep diffuse-imaging commands from writing where ``path`` lies while the block reads it.

    Parameters
    ----------
    path : str or Path
        A data file or folder (it need not exist: its reader reports that).
    option : str
        The command-line option that named it, for messages.
    wait_seconds : float, optional
        How long to wait for a writer to finish before refusing (default
        :data:`LOCK_WAIT_SECONDS`).

    Yields
    ------
    Path
        ``path``.

    Raises
    ------
    ResourceError
        When a command still writes the data's folder, or a folder above it
        (whose command may write below it), after ``wait_seconds``: the line
        names its process id.

    Notes
    -----
    Holds a shared ``flock`` on the data's folder and each folder above it
    (links resolved), as :func:`output_folder` holds its folder
    exclusively: while the block runs no command can start writing there,
    and the block does not start while one writes. Nothing is created, so
    read-only folders are read as any other; folders that cannot be opened
    or locked (no permission, NFS) are read unlocked. A folder this process
    itself writes (inside :func:`output_folder`) is not waited for; the
    reverse, :func:`output_folder` on a folder this block holds, is a bug
    (RuntimeError): end the reading block before writing.
    """
    path = Path(path)
    wait = LOCK_WAIT_SECONDS if wait_seconds is None else float(wait_seconds)
    held = []
    try:
        for folder in _folders_holding(path):
            descriptor = _lock_for_reading(folder, path, option, wait)
            if descriptor is not None:
                held.append(descriptor)
        yield path
    finally:
        for descriptor in held:
            _release_for_reading(descriptor)


def _release_for_reading(descriptor: int) -> None:
    with contextlib.suppress(OSError):
        info = os.fstat(descriptor)
        key = (info.st_dev, info.st_ino)
        _reading[key] -= 1
        if not _reading[key]:
            del _reading[key]
    os.close(descriptor)


def _verify_npy(expected: np.ndarray) -> Callable[[str], None]:
    def verify(temporary):
        back = np.load(temporary, mmap_mode="r", allow_pickle=False)
        if back.shape != expected.shape or back.dtype != expected.dtype:
            raise ValueError(f"read back {back.shape} {back.dtype}")
    return verify


def save_npy(path: str | Path, array: np.ndarray) -> Path:
    """Save an array as ``.npy``, atomically, checking its shape and dtype on disk."""
    array = np.asarray(array)

    def write(temporary):
        with open(temporary, "wb") as stream:
            np.save(stream, array)
    return atomic_write(path, write, _verify_npy(array))


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def json_ready(value):
    """The value as save_json writes it: NaN and infinity as None (JSON has neither), arrays as lists."""
    return json.loads(json.dumps(_finite_or_null(value), default=_json_default, allow_nan=False))


def _finite_or_null(value):
    """JSON has no NaN or infinity: write them as null."""
    if isinstance(value, dict):
        return {key: _finite_or_null(v) for key, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_null(v) for v in value]
    if isinstance(value, np.ndarray):
        return _finite_or_null(value.tolist())
    if isinstance(value, (float, np.floating)) and not np.isfinite(value):
        return None
    return value


def save_json(path: str | Path, data: Any) -> Path:
    """Save JSON (sorted keys, indented, NaN and infinity as null), atomically."""
    text = json.dumps(_finite_or_null(data), indent=2, sort_keys=True, default=_json_default,
                      allow_nan=False) + "\n"
    return save_text(path, text, verify=lambda temporary: json.loads(Path(temporary).read_text()))


def save_text(path: str | Path, text: str, verify: Callable[[str], None] | None = None) -> Path:
    """Save UTF-8 text (a report, a CSV), atomically, checking its length on disk.

    File names that are not UTF-8 (held as surrogate escapes) are written back as their bytes.
    """
    data = text.encode("utf-8", "surrogateescape")

    def write(temporary):
        with open(temporary, "wb") as stream:
            stream.write(data)

    def check(temporary):
        if os.path.getsize(temporary) != len(data):
            raise ValueError(f"{os.path.getsize(temporary)} bytes on disk, {len(data)} written")
        if verify is not None:
            verify(temporary)
    return atomic_write(path, write, check)


def _exr_value(value):
    """A header attribute: numbers as numbers (doubles: float32 would misplace t0 = 800 m by a
    fine bin), strings as strings, vectors of 3 as V3d; None for what EXR cannot hold."""
    if isinstance(value, (bool, np.bool_)):
        return int(value)
    if isinstance(value, (int, np.integer)):
        return int(value) if -2**31 <= int(value) < 2**31 else np.array(float(value))
    if isinstance(value, (float, np.floating)):
        return np.array(float(value), dtype=np.float64)
    if isinstance(value, str):
        return value
    array = np.asarray(value) if isinstance(value, (list, tuple, np.ndarray)) else None
    if array is not None and array.shape == (3,) and np.issubdtype(array.dtype, np.number):
        return array.astype(np.float64)
    return None


class PrecisionWarning(UserWarning):
    """A float32 copy (``transient.exr``) left unwritten: float32 cannot hold the values.

    The float64 file (``transient.npy``) is the exact record.
    """


#: float32's unit roundoff: rounding to nearest moves a normal value by at most this share of it.
_FLOAT32_ROUNDOFF = 2.0**-24


def float32_problem(values) -> str | None:
    """Why float32 cannot hold ``values`` to its own precision; None when it can.

    Parameters
    ----------
    values : array_like
        The numbers (any units).

    Returns
    -------
    str or None
        None when rounding to float32 moves no value by more than
        2^-24 of the largest |value|; else the reason, in a few words.

    Notes
    -----
    Float32 holds a value to 2^-24 of itself between its smallest normal
    (1.18e-38) and its largest (3.40e38). Above, values become infinite;
    below, subnormals keep 2^-150 absolutely and then zero. The error is
    measured, not inferred, so an array whose largest value is normal
    passes (its subnormals err by at most 2^-150 <= 2^-24 of the largest)
    and one whose largest lies below 1.18e-38 fails (1e-300 becomes 0).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.size == 0:
        return None
    if not np.all(np.isfinite(values)):
        return "it holds NaN or infinite values"
    largest = float(np.max(np.abs(values)))
    with np.errstate(over="ignore", under="ignore"):
        rounded = values.astype(np.float32)
    limits = np.finfo(np.float32)
    if not np.all(np.isfinite(rounded)):
        return f"its largest |value| {largest:.3g} exceeds float32's largest, {float(limits.max):.3g}"
    error = float(np.max(np.abs(rounded.astype(np.float64) - values)))
    if error > _FLOAT32_ROUNDOFF * largest:
        return (f"its largest |value| {largest:.3g} lies below float32's smallest normal, "
                f"{float(limits.tiny):.3g}: float32 would keep zeros and subnormals")
    return None


def save_exr(path: str | Path, image: np.ndarray, attributes: dict[str, Any] | None = None) -> Path:
    """Save a one-channel float32 EXR (channel ``Y``) with header attributes.

    Parameters
    ----------
    path : str or Path
        Destination.
    image : numpy.ndarray
        ``(height, width)`` values; float32 must hold them
        (:func:`float32_problem` returns None): check first.
    attributes : dict, optional
        Header attributes: numbers are stored as EXR doubles (ints as ints),
        strings as strings, 3-vectors as V3d; nested tables are flattened to
        ``table_key``; lists of other lengths are left to meta.json.

    Raises
    ------
    ValueError
        When float32 cannot hold the image (the caller's to avoid).
    ResourceError
        When the file cannot be written, or does not read back as the
        image rounded to float32.
    """
    import OpenEXR

    problem = float32_problem(image)
    if problem is not None:
        raise ValueError(f"{path}: a float32 EXR cannot hold this image: {problem}")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    for key, value in _flatten(attributes or {}).items():
        converted = _exr_value(value)
        if converted is not None:
            header[key] = converted
    pixels = np.ascontiguousarray(image, dtype=np.float32)

    def write(temporary):
        with OpenEXR.File(header, {"Y": pixels}) as handle:
            handle.write(temporary)

    def verify(temporary):
        with OpenEXR.File(temporary) as handle:
            back = np.array(handle.channels()["Y"].pixels)
        if back.shape != pixels.shape or back.dtype != np.float32:
            raise ValueError(f"read back {back.shape} {back.dtype}")
        if not (np.all(np.isfinite(back)) and np.array_equal(back, pixels)):
            raise ValueError("the values read back differ from those written")
    return atomic_write(path, write, verify)


def _flatten(table: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in table.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}_"))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def save_png_image(path: str | Path, image: np.ndarray) -> Path:
    """Save a [0, 1] grey image as 16-bit PNG (value * 65535, no sRGB), atomically."""
    from PIL import Image

    data = np.round(np.clip(image, 0.0, 1.0) * 65535.0).astype(np.uint16)

    def write(temporary):
        Image.fromarray(data).save(temporary, format="PNG")

    def verify(temporary):
        with Image.open(temporary) as handle:
            if handle.size != (data.shape[1], data.shape[0]):
                raise ValueError(f"read back {handle.size}")
    return atomic_write(path, write, verify)


def build_meta(scene, *, kind: str, samples: int = 0, seed: int | None = None,
               window_share: float | None = None, **extra) -> dict:
    """The one metadata record of every command (DESIGN.md section 5).

    Parameters
    ----------
    scene : analytic.Scene
        The scene the transient belongs to.
    kind : {"model", "render"}
        Who computed it.
    samples : int
        Monte Carlo samples (0 for the model).
    seed : int, optional
        The render's seed, or the noise seed of a model with noise.
    window_share : float, optional
        Share of the light the window holds (:func:`analytic.window_share`).
    **extra
        Further keys (a command's own: variant, timings, ...); they may not
        redefine the schema's keys.

    Returns
    -------
    dict
        ``kind``, ``samples``, ``seed``, ``scene``, ``plane_size``, ``pixels``,
        ``source``, ``intensity``, ``sensor_positions``, ``attenuation``,
        ``illumination`` (the waveform's name) and ``illumination_parameters``,
        ``tolerance`` (the model's; None for a render), ``window_share``,
        ``noise`` (the scene's, None when noiseless), ``start_opl``,
        ``bin_width_opl``, ``bins``, ``sensors``, ``units``.
    """
    from .waveforms import make_waveform

    if kind not in ("model", "render"):
        raise ValueError(f"kind: 'model' or 'render', got {kind!r}")
    waveform = make_waveform(scene.illumination, scene.sampling.bin_width_opl)
    noise = scene.noise
    meta = {
        "kind": kind,
        "samples": int(samples),
        "seed": None if seed is None else int(seed),
        "scene": scene.name,
        "plane_size": float(scene.size),
        "pixels": int(scene.pixels),
        "source": [float(v) for v in scene.source],
        "intensity": float(scene.intensity),
        "sensor_positions": np.asarray(scene.sensors, dtype=np.float64).tolist(),
        "attenuation": scene.attenuation,
        "illumination": waveform.name,
        "illumination_parameters": dict(waveform.parameters),
        "tolerance": float(scene.tolerance) if kind == "model" else None,
        "window_share": None if window_share is None else float(window_share),
        "noise": None if noise is None else {"kind": noise.kind, "sigma": noise.sigma,
                                             "photons": noise.photons, "seed": noise.seed},
        "start_opl": float(scene.sampling.start_opl),
        "bin_width_opl": float(scene.sampling.bin_width_opl),
        "bins": int(scene.sampling.count),
        "sensors": int(scene.sensor_count),
        "units": UNITS,
    }
    clash = sorted(set(extra) & set(meta))
    if clash:
        raise ValueError(f"extra: {', '.join(clash)} are schema keys")
    meta.update(extra)
    return meta


#: meta.json's ``exr`` when transient.exr is written.
_EXR_WRITTEN = ("written: float32, every value within float32's rounding (2^-24 of the largest) "
                "of transient.npy")


def write_transient(out_dir: str | Path, transient: np.ndarray, meta: dict[str, Any], *,
                    stderr: np.ndarray | None = None, noisy: np.ndarray | None = None) -> dict[str, Path]:
    """Write ``transient.{npy,exr,h5}``, ``meta.json`` (+ ``stderr.npy``, ``transient_noisy.npy``), together.

    ``transient.h5`` is tal's HDF5 capture (:mod:`analytic.capture`), readable
    by ``tal.io.read_capture``, with the metadata as its ``scene_info``.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created).
    transient : numpy.ndarray
        ``(K, N)`` samples y_k[n]; saved as float64 ``.npy``, float32 EXR
        (width N = time, height K = sensors; only where float32 holds them,
        :func:`float32_problem`) and tal's HDF5 capture (float64).
    meta : dict
        From :func:`build_meta`; all of it goes to meta.json, its numbers and
        strings to the EXR header, with ``exr`` added: whether
        ``transient.exr`` was written, and why not (float32 cannot hold the
        values: then a :class:`PrecisionWarning` says so, and an earlier
        ``transient.exr`` in the folder is removed).
    stderr : numpy.ndarray, optional
        ``(K, N)`` per-bin standard error (renders).
    noisy : numpy.ndarray, optional
        ``(K, N)`` noisy samples (model with noise).

    Returns
    -------
    dict
        Name -> path of every file written. The files are renamed into place
        together (see :func:`staged_writes`).
    """
    from .capture import write_capture   # capture imports this module

    out_dir = Path(out_dir)
    transient = np.asarray(transient, dtype=np.float64)
    if transient.shape != (meta["sensors"], meta["bins"]):
        raise ValueError(f"transient: shape {transient.shape}, meta says "
                         f"({meta['sensors']}, {meta['bins']})")
    problem = float32_problem(transient)
    meta = dict(meta)
    meta["exr"] = (_EXR_WRITTEN if problem is None
                   else f"not written: {problem}; transient.npy is the exact record")
    written = {}
    with staged_writes():
        written["transient.npy"] = save_npy(out_dir / "transient.npy", transient)
        if stderr is not None:
            written["stderr.npy"] = save_npy(out_dir / "stderr.npy", np.asarray(stderr, dtype=np.float64))
        if noisy is not None:
            written["transient_noisy.npy"] = save_npy(out_dir / "transient_noisy.npy",
                                                      np.asarray(noisy, dtype=np.float64))
        if problem is None:
            written["transient.exr"] = save_exr(out_dir / "transient.exr", transient, meta)
        else:
            discard(out_dir / "transient.exr")   # an earlier command's: it is not this transient
        written["transient.h5"] = write_capture(out_dir / "transient.h5", transient,
                                                start_opl=meta["start_opl"],
                                                bin_width_opl=meta["bin_width_opl"], source=meta["source"],
                                                sensors=meta["sensor_positions"],
                                                scene_info=_finite_or_null(meta))
        written["meta.json"] = save_json(out_dir / "meta.json", meta)
    if problem is not None:
        warnings.warn(f"{out_dir / 'transient.exr'}: not written, {problem}; transient.npy (float64) is "
                      f"the exact record", PrecisionWarning, stacklevel=2)
    return written


def read_exr(path: str | Path) -> tuple[np.ndarray, dict]:
    """The ``Y`` channel of an EXR as float64 and its header, numbers as Python floats and ints.

    Raises
    ------
    DataError
        Unreadable, or without a ``Y`` channel.
    """
    import OpenEXR

    path = Path(path)
    try:
        with OpenEXR.File(str(path)) as handle:   # copies: header and pixels die with the handle
            channels = handle.channels()
            if "Y" not in channels:
                raise DataError(f"{path}: EXR has no channel Y (found {', '.join(sorted(channels))}); "
                                f"expected one of ours (width = bins, height = sensors)")
            pixels = np.array(channels["Y"].pixels, dtype=np.float64)
            header = {key: _header_value(value) for key, value in handle.header().items()}
    except DataError:
        raise
    except Exception as error:  # the binding raises RuntimeError and others for a bad file
        raise DataError(f"{path}: cannot read it as an EXR ({type(error).__name__}: {error})") from None
    return pixels, header


def _header_value(value):
    """EXR doubles come back as 1-element arrays: give the number itself."""
    if isinstance(value, np.ndarray):
        return float(value.ravel()[0]) if value.size == 1 else value.copy()
    return value


def read_transient(path: str | Path) -> np.ndarray:
    """Read a transient from ``.npy``, ``.exr`` (channel ``Y``) or tal's ``.h5``, or from a folder holding them.

    Returns
    -------
    numpy.ndarray
        ``(K, N)`` float64.

    Raises
    ------
    DataError
        Missing, unreadable or not a (K, N) array.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "transient.npy" if (path / "transient.npy").exists() else path / "transient.exr"
    if not path.is_file():
        raise DataError(f"{path}: no such file")
    try:
        if path.suffix == ".npy":
            data = np.load(path, allow_pickle=False)
        elif path.suffix == ".exr":
            data, _ = read_exr(path)
        elif path.suffix in (".h5", ".hdf5"):
            from .capture import read_capture   # capture imports this module

            data = read_capture(path).transient
        else:
            raise DataError(f"{path}: expected a .npy, .exr or .h5 (tal capture) transient")
    except DataError:
        raise
    except Exception as error:  # NumPy raises many types for a bad file
        raise DataError(f"{path}: cannot read it ({type(error).__name__}: {error})") from None
    if not np.issubdtype(np.asarray(data).dtype, np.number):
        raise DataError(f"{path}: holds {np.asarray(data).dtype} values, not numbers")
    data = np.asarray(data, dtype=np.float64)
    if data.ndim != 2:
        raise DataError(f"{path}: expected a (sensors, bins) array, got shape {data.shape}")
    return data
