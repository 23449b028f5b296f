"""Folders and their locks: one writing command at a time, readers kept out of a half-written folder.

:func:`output_folder` gives a folder to one writing command at a time. It
holds an exclusive ``flock`` on the folder's ``.diffuse-imaging.lock``
(which holds its process id, for the message a second command gets) and on
the folder itself. :func:`reading_folder` holds a shared ``flock`` on the
data's folder and on every folder above it while the data are read, so a
reader never pairs files of two commits; it creates no file. The lock file
is removed while it is still held (removed after the release, a second
command could lock the doomed file while a third locks its replacement),
and a taker that finds, once it holds the lock, that the path no longer
names the file it locked tries again. Every way out of a command removes
the lock file; one left by a killed command is harmless (the kernel
released its lock) and is taken over.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import stat
import time
from pathlib import Path
from typing import Iterator

from analytic.errors import ResourceError

from .atomic import make_folder, remove_temporaries, resource_error

__all__ = ["output_folder", "reading_folder", "LOCK_FILE", "LOCK_WAIT_SECONDS"]

#: Held (flock) by the command writing a folder; holds its process id.
LOCK_FILE = ".diffuse-imaging.lock"

#: Seconds a reader waits for a writer to finish, and a writer for readers, before refusing.
LOCK_WAIT_SECONDS = 2.0

# Folders (device, inode) this process holds for writing: its own readers must not wait on them.
_writing: set[tuple[int, int]] = set()

# Folders (device, inode) this process holds for reading, and how many times.
_reading: dict[tuple[int, int], int] = {}


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


def _prepare_output_folder(folder: str | Path, option: str) -> tuple[Path, Path | None]:
    """The output folder, created when absent; the topmost folder this call created (None when none)."""
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
        top = folder
        while not os.path.lexists(top.parent) and top.parent != top:
            top = top.parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise resource_error(error, folder, "create the folder") from None
        return folder, top
    except OSError as error:
        raise resource_error(error, folder, "use the folder") from None
    if not stat.S_ISDIR(mode):
        raise ResourceError(f"{option} {folder}: is {_file_kind(mode)}, not a folder; "
                            f"choose another {option}")
    return folder, None


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
            make_folder(folder)
            continue
        except OSError as error:
            raise resource_error(error, folder, "lock the folder") from None
        try:
            fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            other = os.pread(descriptor, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(descriptor)
            raise ResourceError(f"{option} {folder}: another diffuse-imaging command (process {other}) "
                                f"is writing this folder; wait for it or choose another {option}") from None
        except OSError as error:
            os.close(descriptor)
            raise resource_error(error, folder, "lock the folder") from None
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
            if created is not None:
                _remove_if_only_lock(folder)
                with contextlib.suppress(OSError):   # and the empty parents it made (a refused export left them)
                    for parent in folder.parents:
                        if len(parent.parts) < len(created.parts):
                            break
                        parent.rmdir()
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
