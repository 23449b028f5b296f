"""Atomic writes: every file through a checked temporary, renamed into place (docs/design.md section 5).

Every file is written to a temporary name in its destination folder,
flushed, fsynced and checked (non-empty, and read back by the writer's own
check) before it is renamed over the final name, so an interrupted command
never leaves a torn file. Inside :func:`staged_writes` the renames wait for
the end of the block: a command that fails half-way leaves its folder as it
was. Every file-system failure (disk full, read-only, ``--out`` naming a
file, no permission, a name too long) becomes one
:class:`~analytic.errors.ResourceError` line naming the path.

Temporaries are named ``.diffuse-imaging-tmp-<host>-<pid>-<random>-<name>``
(:data:`TEMPORARY_PREFIX`): a name no other program uses, carrying the
process that made it. In each folder it writes, a command removes the
temporaries of dead processes of this host (:func:`remove_temporaries`),
and nothing else: not a user's files, not another folder's, not those of a
live process.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import functools
import hashlib
import os
import re
import socket
import stat
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from analytic.errors import ResourceError

__all__ = ["atomic_write", "staged_writes", "discard", "remove_temporaries", "TEMPORARY_PREFIX"]

#: Start of every temporary file name this program makes, and of no other file's.
TEMPORARY_PREFIX = ".diffuse-imaging-tmp-"
_TEMPORARY_NAME = re.compile(re.escape(TEMPORARY_PREFIX) + r"(?P<host>[0-9a-f]{8})-(?P<pid>[0-9]+)-")

# Longest file name (bytes) of the common file systems.
_NAME_MAX = 255

_staged: contextvars.ContextVar[list | None] = contextvars.ContextVar("staged", default=None)

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


def resource_error(error: OSError, path: Path, action: str) -> ResourceError:
    """The one-line ResourceError for a file-system failure: the path, the action, the fix."""
    fix = _FIXES.get(error.errno, "check the path")
    return ResourceError(f"{path}: cannot {action} ({error.strerror or error}); {fix}")


def _resource_failure(error: Exception, path: Path) -> ResourceError | None:
    """The ResourceError behind a writer's exception, or None when it is no file-system failure.

    Writers report a full disk in their own ways: ``OSError`` with an errno
    (h5py, Pillow), ``OSError`` without one for a short write (NumPy's "N
    requested and M written"), ``RuntimeError`` quoting the C library's
    message (OpenEXR, h5py's flush), possibly as the context of a later one.
    """
    if isinstance(error, OSError) and error.errno is not None:
        return resource_error(error, path, "write")
    # h5py's close after a failed flush raises a second error that names no cause: the first one,
    # which names errno 28, is in the chain
    chain, link = [], error
    while link is not None and len(chain) < 8:
        chain.append(link)
        link = link.__cause__ or link.__context__
    for code in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EIO):
        if any(os.strerror(code) in str(raised) for raised in chain):
            return resource_error(OSError(code, os.strerror(code)), path, "write")
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

def make_folder(folder: Path) -> None:
    """Create ``folder`` and its parents; a ResourceError when a file is in the way or the system refuses."""
    try:
        if folder.exists() and not folder.is_dir():
            raise ResourceError(f"{folder}: is a file, not a folder; choose another --out")
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise resource_error(error, folder, "create the folder") from None


def _rename(temporary: Path, path: Path) -> None:
    try:
        os.replace(temporary, path)
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise resource_error(error, path, "write") from None


def _remove_final(path: Path) -> None:
    try:
        path.unlink(missing_ok=True)
    except OSError as error:
        raise resource_error(error, path, "remove") from None


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
    make_folder(path.parent)
    _sweep_once(path.parent)
    try:
        temporary = _temporary_path(path)
    except OSError as error:
        raise resource_error(error, path, "write") from None
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
        raise resource_error(error, path, "write") from None
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
    except BaseException:
        _discard_temporaries(_staged.get())
        _staged.reset(token)
        raise
    staged = _staged.get()
    _staged.reset(token)
    done = 0
    try:
        # every target is checked before the first rename: one in the way would otherwise be
        # found only by its own rename, after the files before it had been replaced
        for _, path in staged:
            _check_target(path)
        for temporary, path in staged:
            done += 1            # _rename removes its own temporary when it fails
            if temporary is None:
                _remove_final(path)
            else:
                _rename(temporary, path)
    except BaseException:
        _discard_temporaries(staged[done:])
        raise


def _discard_temporaries(staged) -> None:
    """Remove the temporaries of staged writes that will not be renamed."""
    for temporary, _ in staged:
        if temporary is not None:
            temporary.unlink(missing_ok=True)


def _check_target(path: Path) -> None:
    """Refuse a final name that a rename cannot replace: a folder, a device, a FIFO, a socket."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as error:
        raise resource_error(error, path, "write") from None
    if stat.S_ISDIR(mode):
        raise ResourceError(f"{path}: a folder is in the way of this output file; move it away or "
                            f"choose another --out")
    if not (stat.S_ISREG(mode) or stat.S_ISLNK(mode)):
        raise ResourceError(f"{path}: something that is not a file is in the way of this output file; "
                            f"move it away or choose another --out")

