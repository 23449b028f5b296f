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

import ast
import functools
import hashlib
import os
from pathlib import Path

from numba import njit
from numba.core import config
from numba.core.caching import CacheImpl, InTreeCacheLocator

__all__ = ["PackageCacheLocator", "module_closure", "install", "njit"]

_PACKAGE = Path(__file__).resolve().parent


@functools.lru_cache(maxsize=None)
def _imports(path: Path, stamp: tuple[int, int]) -> tuple[Path, ...]:
    """Modules of the package that ``path`` imports (``from .<module> import``, ``from analytic.<module> import``)."""
    del stamp   # part of the memo's key: a file edited while the process runs is parsed again
    found = []
    for node in ast.walk(ast.parse(path.read_bytes(), str(path))):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = path.parent
            for _ in range(node.level - 1):
                base = base.parent
        elif node.module and node.module.split(".")[0] == _PACKAGE.name:
            base = _PACKAGE.parent
        else:
            continue
        parts = node.module.split(".") if node.module else []
        target = base.joinpath(*parts)
        names = [target / f"{alias.name}.py" for alias in node.names]   # ``from . import x``
        for candidate in [target.with_suffix(".py"), target / "__init__.py", *names]:
            if candidate.is_file() and _PACKAGE in candidate.resolve().parents:
                found.append(candidate.resolve())
    return tuple(found)


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
            self._cache_path = os.path.join(config.CACHE_DIR, self.get_suitable_cache_subpath(py_file))

    def get_source_stamp(self):
        digest = hashlib.sha256()
        for module in module_closure(self._py_file):
            digest.update(f"{module.relative_to(_PACKAGE.parent)}:{_stamp(module)}\n".encode())
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
