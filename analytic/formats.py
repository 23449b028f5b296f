"""Other tools' file formats, by role and file suffix: a registry that :mod:`interop` fills.

The model reads and writes its own files (TOML scenes, ``.npy`` / ``.csv``
responses, ``.npy`` / ``.exr`` transients) and imports nothing of
:mod:`interop`. Where a user hands it another tool's file (a tal YAML
configuration as a scene, a tal HDF5 histogram as an instrument response or
a transient) it asks this registry for the reader of the file's suffix; and
:func:`analytic.files.write_transient` writes, beside its own files, each
file a registered writer names (tal's ``transient.h5``).

The registry is filled by the functions that the installed package declares
as entry points of the group :data:`ENTRY_POINT_GROUP` (``pyproject.toml``,
``[project.entry-points."diffuse_imaging.formats"]``): each one calls
:func:`register_reader` / :func:`register_writer`. They are looked up once,
on the first question this registry cannot answer from what is registered
(a suffix the model does not know), so that ``import analytic`` and the
model's own formats never load them. A plain ``import analytic`` thus reads
``load_scene("x.yaml")`` without the user importing :mod:`interop`.

Roles (what a reader returns):

- ``"scene"``: ``reader(path)`` -> a scene of a registered kind;
- ``"transient"``: ``reader(path)`` -> the ``(rows, bins)`` float64 array;
- ``"response"``: ``reader(path)`` -> a histogram record with ``transient``
  (``(1, n)`` counts), ``bin_width_opl`` and ``start_opl`` (metres of path).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from importlib.metadata import entry_points
from typing import Callable

__all__ = ["ENTRY_POINT_GROUP", "ROLES", "Reader", "register_reader", "register_writer", "reader_for",
           "readers", "writers"]

#: The entry-point group whose functions register the formats (each called once, without arguments).
ENTRY_POINT_GROUP = "diffuse_imaging.formats"
#: What a reader reads a file as.
ROLES = ("scene", "transient", "response")


@dataclass(frozen=True)
class Reader:
    """A registered reader: the format's name (for messages and ``transient_format``) and the function."""

    name: str
    read: Callable


_READERS: dict[str, dict[str, Reader]] = {role: {} for role in ROLES}
# file name -> writer(path, transient, meta, scene) -> Path, for write_transient
_WRITERS: dict[str, Callable] = {}
_LOCK = threading.RLock()
_loaded = False


def register_reader(role: str, name: str, suffixes, read: Callable) -> None:
    """Register ``read`` as the ``role`` reader of files ending in each of ``suffixes`` (lower case, with the dot).

    Registering the same function again is harmless; another function for a suffix taken raises ValueError.
    """
    if role not in ROLES:
        raise ValueError(f"role: one of {', '.join(ROLES)}, got {role!r}")
    with _LOCK:
        for suffix in suffixes:
            if not (suffix.startswith(".") and suffix == suffix.lower()):
                raise ValueError(f"suffix: lower case with its dot (\".h5\"), got {suffix!r}")
            taken = _READERS[role].get(suffix)
            if taken is not None and taken.read is not read:
                raise ValueError(f"{role} files {suffix}: read by {taken.name} already")
            _READERS[role][suffix] = Reader(name, read)


def register_writer(file_name: str, write: Callable) -> None:
    """Register ``write(path, transient, meta, scene) -> Path``: :func:`analytic.files.write_transient` writes
    ``file_name`` with it, among its own files (the same function again is harmless)."""
    with _LOCK:
        taken = _WRITERS.get(file_name)
        if taken is not None and taken is not write:
            raise ValueError(f"{file_name}: written by {taken.__module__}.{taken.__qualname__} already")
        _WRITERS[file_name] = write


def _load() -> None:
    """Call every function of :data:`ENTRY_POINT_GROUP`, once per process."""
    global _loaded
    with _LOCK:
        if _loaded:
            return
        points = entry_points(group=ENTRY_POINT_GROUP)
        if not points:
            raise RuntimeError(f"no entry points of the group {ENTRY_POINT_GROUP!r}: the package's metadata is "
                               f"missing or stale; install it (pip install -e .) from its folder")
        for point in points:
            point.load()()
        _loaded = True


def reader_for(role: str, suffix: str) -> Reader | None:
    """The ``role`` reader of files ending in ``suffix`` (any case), or None; loads the entry points on a miss."""
    suffix = suffix.lower()
    if suffix not in _READERS[role]:
        _load()
    return _READERS[role].get(suffix)


def readers(role: str) -> dict[str, Reader]:
    """Every ``role`` reader by suffix (entry points loaded)."""
    _load()
    return dict(_READERS[role])


def writers() -> dict[str, Callable]:
    """Every registered writer by the file name it writes (entry points loaded)."""
    _load()
    return dict(_WRITERS)
