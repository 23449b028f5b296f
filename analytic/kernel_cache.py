"""Numba's on-disk cache for this package's kernels, invalidated when any module they use changes.

Numba keys a cached kernel by the file that defines it (its modification
time and size). Our kernels inline code from other modules of the package
(the waveform's S(u), the attenuation, the quadrature rules), so an edit of
``waveforms.py`` alone would leave ``system.py``'s cached kernels stale.
:class:`PackageCacheLocator` keys each kernel by its own file *and* every
module of the package that file imports, directly or through others; it
serves only this package's files (every other library keeps Numba's own
locators) and stores the cache where Numba would: ``__pycache__`` beside the
sources, or under ``NUMBA_CACHE_DIR`` when the user set it. Nothing in the
process environment is changed. Modules that compile kernels take ``njit``
from here, which installs the locator first.
"""

from __future__ import annotations

import functools
import hashlib
import os
import re
from pathlib import Path

from numba import njit
from numba.core import config
from numba.core.caching import CacheImpl, InTreeCacheLocator

__all__ = ["PackageCacheLocator", "module_closure", "install", "njit"]

_PACKAGE = Path(__file__).resolve().parent


# ``from <module> import <names>`` anywhere in a file (a function's body too), the names parenthesised over
# lines or on one line; a match inside a string only adds a module to the closure (a needless recompile)
_FROM_IMPORT = re.compile(r"^[ \t]*from[ \t]+([\w.]+)[ \t]+import[ \t]+(\([^)]*\)|[^\n#]*)", re.MULTILINE)


@functools.lru_cache(maxsize=None)
def _imports(path: Path, stamp: tuple[int, int]) -> tuple[Path, ...]:
    """Modules of the package that ``path`` imports (``from .<module> import``, ``from analytic.<module> import``).

    Read by a regular expression, not by parsing the file: every process that loads a cached kernel
    reads its module closure, and parsing the package's modules took a good part of a second.
    """
    del stamp   # part of the memo's key: a file edited while the process runs is read again
    found = []
    for module, names in _FROM_IMPORT.findall(path.read_text(encoding="utf-8")):
        level = len(module) - len(module.lstrip("."))
        if level:
            base = path.parent
            for _ in range(level - 1):
                base = base.parent
        elif module.split(".")[0] == _PACKAGE.name:
            base = _PACKAGE.parent
        else:
            continue
        parts = [part for part in module[level:].split(".") if part]
        target = base.joinpath(*parts)
        aliases = [name.split()[0] for name in names.strip("() \t").replace("\\", " ").split(",") if name.split()]
        candidates = [target.with_suffix(".py"), target / "__init__.py",
                      *(target / f"{alias}.py" for alias in aliases)]   # ``from . import x``
        for candidate in candidates:
            if candidate.is_file() and _PACKAGE in candidate.resolve().parents:
                found.append(candidate.resolve())
    return tuple(found)


@functools.lru_cache(maxsize=None)
def _content(path: Path, stamp: tuple[int, int]) -> str:
    """The file's SHA-256: a kernel stays cached across copies and checkouts of the same source."""
    del stamp   # part of the memo's key, as for _imports
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _stamp(path: Path) -> tuple[int, int]:
    status = path.stat()
    return status.st_mtime_ns, status.st_size


def module_closure(path: str | Path) -> list[Path]:
    """``path`` and every module of the package it imports, directly or through others, sorted."""
    seen: set[Path] = set()
    waiting = [Path(path).resolve()]
    while waiting:
        current = waiting.pop()
        if current in seen:
            continue
        seen.add(current)
        waiting.extend(_imports(current, _stamp(current)))
    return sorted(seen)


class PackageCacheLocator(InTreeCacheLocator):
    """Numba's in-tree locator (or ``NUMBA_CACHE_DIR`` when the user set it), stamped by the module closure."""

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        if config.CACHE_DIR:
            # by the path inside the package: copies of the package with the same sources share kernels
            relative = Path(py_file).resolve().parent.relative_to(_PACKAGE.parent)
            self._cache_path = os.path.join(config.CACHE_DIR, *relative.parts)

    def get_source_stamp(self):
        digest = hashlib.sha256()
        for module in module_closure(self._py_file):
            digest.update(f"{module.relative_to(_PACKAGE.parent)}:{_content(module, _stamp(module))}\n".encode())
        return digest.hexdigest()

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            inside = _PACKAGE in Path(py_file).resolve().parents
        except OSError:
            return None
        if not inside:
            return None
        return super().from_function(py_func, py_file)


def install() -> None:
    """Put :class:`PackageCacheLocator` first among Numba's locators (once; before any kernel is defined)."""
    if PackageCacheLocator not in CacheImpl._locator_classes:
        CacheImpl._locator_classes.insert(0, PackageCacheLocator)


# Every module of the package that compiles kernels imports ``njit`` from here, so the locator is
# in place before the first kernel is defined.
install()
