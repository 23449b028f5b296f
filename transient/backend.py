"""Mitsuba variant choice, and the libLLVM that Dr.Jit's CPU backend loads.

Dr.Jit's LLVM backend JIT-compiles every kernel with whatever ``libLLVM`` it
finds at run time. With LLVM 15 it aborts the whole process at the first
``dr.maximum`` ("LLVM ERROR: Cannot select: fmaximum"); LLVM >= 16 works.
Dr.Jit looks for the library in this order (drjit-core ``llvm_api.cpp``):
a libLLVM already loaded in the process, then ``DRJIT_LIBLLVM_PATH``, then
``libLLVM.so`` on the loader path, then a glob of
``/usr/lib/<triplet>/libLLVM*.so.*``. On a machine with both LLVM 15 and 19
installed the glob may pick either, so :func:`select_variant` decides before
Dr.Jit is imported: it points ``DRJIT_LIBLLVM_PATH`` at the newest
libLLVM >= 16 and refuses, with a one-line fix, when only older ones exist.

Dr.Jit also reads its kernel cache's folder when it is imported, from
``DRJIT_CACHE_DIR`` or else ``$HOME/.drjit``; with HOME unset it warns on
stderr and compiles every kernel afresh. :func:`select_variant` then names
the folder HOME would have given (the user's home from the password
database, else a private folder in the temporary directory) in
``DRJIT_CACHE_DIR`` for the import only, and removes the variable again:
Dr.Jit offers no other way to be told, and nothing else in the process
(or its children) sees it.

Nothing in this project imports ``mitsuba`` or ``drjit`` before
:func:`select_variant` has run.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import re
import stat
import sys
import tempfile
from pathlib import Path

from analytic.errors import ResourceError

__all__ = ["BackendError", "MIN_LLVM", "llvm_version_of", "find_llvm_libraries", "choose_libllvm",
           "select_variant", "usable_variants", "kernel_cache_folder", "SEARCH_PATTERNS"]

#: Oldest LLVM major version whose code generation Dr.Jit 1.5 survives.
MIN_LLVM = 16

#: Where shared libLLVM builds live on Debian/Ubuntu-like systems.
SEARCH_PATTERNS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
)

_FIX = "fix: apt-get install -y libllvm19 (or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16)"

# The whole-library names: libLLVM-19.so, libLLVM.so.19.1, libLLVM-15.so.1,
# libLLVM-14.0.6.so.1, libLLVM.so. Component archives such as
# libLLVMCore.a or libLLVMX86CodeGen.so are not the JIT library.
_LIBRARY_NAME = re.compile(r"^libLLVM(?:-(?P<dash>\d+)[\w.]*)?\.so(?:\.(?P<dot>\d+)[\d.]*)?$")


class BackendError(ResourceError):
    """The Mitsuba / Dr.Jit backend cannot be used as configured (one-line message with the fix)."""


def llvm_version_of(path: str | os.PathLike) -> int | None:
    """LLVM major version of a shared libLLVM, read from its file name.

    Parameters
    ----------
    path : str or path-like
        A libLLVM file or symbolic link. When its own name carries no
        version (``libLLVM.so``), the name of the file it resolves to is read.

    Returns
    -------
    int or None
        The major version, or None if neither name is a versioned libLLVM.

    Examples
    --------
    ``libLLVM-19.so`` -> 19, ``libLLVM.so.19.1`` -> 19,
    ``libLLVM-15.so.1`` -> 15, ``libLLVM-14.0.6.so.1`` -> 14.
    """
    path = Path(path)
    for name in (path.name, Path(os.path.realpath(path)).name):
        match = _LIBRARY_NAME.match(name)
        if match is None:
            continue
        version = match.group("dash") or match.group("dot")
        if version is not None:
            return int(version)
    # A versionless name inside /usr/lib/llvm-N/lib still says which LLVM it is.
    match = re.search(r"/llvm-(\d+)/", str(path))
    return int(match.group(1)) if match else None


def find_llvm_libraries(patterns=SEARCH_PATTERNS) -> list[tuple[int, str]]:
    """Shared libLLVM builds present on this system.

    Parameters
    ----------
    patterns : iterable of str
        Glob patterns to search.

    Returns
    -------
    list of (int, str)
        ``(major version, path)``, one entry per distinct real file, newest
        version last; libraries whose version cannot be read are left out.
    """
    found: dict[str, tuple[int, str]] = {}
    for pattern in patterns:
        for path in sorted(glob.glob(pattern)):
            if _LIBRARY_NAME.match(Path(path).name) is None or not os.path.exists(path):
                continue
            version = llvm_version_of(path)
            if version is None:
                continue
            real = os.path.realpath(path)
            # Keep the first name seen per real file: the glob order puts the
            # triplet directory (the loader's own) before /usr/lib/llvm-*.
            found.setdefault(real, (version, path))
    return sorted(found.values(), key=lambda entry: (entry[0], entry[1]))


def choose_libllvm(configured: str | None, candidates: list[tuple[int, str]]) -> str:
    """The libLLVM Dr.Jit must load, or a :class:`BackendError` saying why none will do.

    Parameters
    ----------
    configured : str or None
        The current ``DRJIT_LIBLLVM_PATH`` (None or empty: unset).
    candidates : list of (int, str)
        ``(major version, path)`` found on the system, as returned by
        :func:`find_llvm_libraries`.

    Returns
    -------
    str
        The path to put in ``DRJIT_LIBLLVM_PATH``: the configured one when it
        is acceptable (or its version cannot be read: the user's choice is
        kept, and checked again after the first kernel), else the newest
        candidate of version >= :data:`MIN_LLVM`.

    Raises
    ------
    BackendError
        If the configured library, or every candidate, is older than
        :data:`MIN_LLVM`, or no libLLVM exists at all.
    """
    if configured:
        version = llvm_version_of(configured)
        if version is not None and version < MIN_LLVM:
            raise BackendError(f"DRJIT_LIBLLVM_PATH={configured} is LLVM {version}, which crashes "
                               f"Dr.Jit's LLVM backend; {_FIX}")
        return configured
    usable = [entry for entry in candidates if entry[0] >= MIN_LLVM]
    if usable:
        return max(usable, key=lambda entry: entry[0])[1]
    if candidates:
        version, path = max(candidates, key=lambda entry: entry[0])
        raise BackendError(f"LLVM {version} at {path} crashes Dr.Jit's LLVM backend "
                           f"(needs LLVM >= {MIN_LLVM}); {_FIX}")
    raise BackendError(f"no libLLVM found for Dr.Jit's LLVM backend; {_FIX}")


def _configure_llvm() -> None:
    """Set DRJIT_LIBLLVM_PATH before Dr.Jit is imported; check it when it already was."""
    if "drjit" in sys.modules:
        # Too late to steer the loader; the version is checked after the first kernel.
        return
    chosen = choose_libllvm(os.environ.get("DRJIT_LIBLLVM_PATH"), find_llvm_libraries())
    os.environ["DRJIT_LIBLLVM_PATH"] = chosen


def _check_loaded_llvm() -> None:
    """After the first LLVM kernel: refuse a libLLVM that will abort the process later."""
    import drjit as dr
    import mitsuba as mi

    # A trivial kernel (no fmaximum) makes Dr.Jit load and report its libLLVM.
    dr.eval(mi.UInt32(1) + mi.UInt32(1))
    version = dr.detail.llvm_version()
    if version is not None and 0 < version[0] < MIN_LLVM:
        raise BackendError(f"Dr.Jit loaded LLVM {'.'.join(map(str, version))} "
                           f"(DRJIT_LIBLLVM_PATH={os.environ.get('DRJIT_LIBLLVM_PATH', '')!s}), which "
                           f"crashes its LLVM backend; {_FIX}")


def kernel_cache_folder() -> str | None:
    """The folder Dr.Jit's kernel cache should use when Dr.Jit cannot find one itself, or None.

    Returns
    -------
    str or None
        None when ``HOME`` or ``DRJIT_CACHE_DIR`` is set (Dr.Jit finds its
        folder). Else ``<home>/.drjit`` for the user's home in the password
        database (what HOME would hold), or, without a writable one, a
        folder ``drjit-<uid>`` of the temporary directory that this user
        owns and no one else may write (created so); None if neither exists.
    """
    if os.environ.get("HOME") or os.environ.get("DRJIT_CACHE_DIR"):
        return None
    try:
        home = pwd.getpwuid(os.getuid()).pw_dir
    except KeyError:
        home = ""
    if home and os.path.isdir(home) and os.access(home, os.W_OK | os.X_OK):
        return os.path.join(home, ".drjit")
    private = os.path.join(tempfile.gettempdir(), f"drjit-{os.getuid()}")
    with contextlib.suppress(FileExistsError, OSError):
        os.mkdir(private, 0o700)
    try:
        status = os.lstat(private)
    except OSError:
        return None
    # Compiled kernels are run from this folder: it must be ours alone.
    if not stat.S_ISDIR(status.st_mode) or status.st_uid != os.getuid() or status.st_mode & 0o022:
        return None
    return private


@contextlib.contextmanager
def _kernel_cache_while_importing():
    """Give Dr.Jit its cache folder (:func:`kernel_cache_folder`) for the import that initialises it only."""
    folder = None if "drjit" in sys.modules else kernel_cache_folder()
    if folder is None:
        yield
        return
    os.environ["DRJIT_CACHE_DIR"] = folder
    try:
        yield
    finally:
        os.environ.pop("DRJIT_CACHE_DIR", None)


def usable_variants(available: list[str]) -> list[str]:
    """The variants of ``available`` (``mitsuba.variants()``) the renderer runs on: mono llvm_* and cuda_*."""
    return [name for name in available if name.startswith(("llvm_", "cuda_")) and name.endswith("_mono")]


def default_variant(available: list[str]) -> str:
    """The CPU variant to use when none is asked for.

    Parameters
    ----------
    available : list of str
        ``mitsuba.variants()``.

    Returns
    -------
    str
        ``llvm_mono`` when the build has it (no AD bookkeeping: faster),
        else ``llvm_ad_mono``.
    """
    for name in ("llvm_mono", "llvm_ad_mono"):
        if name in available:
            return name
    raise BackendError(f"Mitsuba has neither llvm_mono nor llvm_ad_mono "
                       f"(available: {', '.join(available)})")


_llvm_checked = False
# The variant the plugin modules were last imported for: their classes (and
# the constructors registered with Mitsuba) belong to that variant.
_plugins_variant: str | None = None

#: The plugin modules, registered (imported, or re-imported for a new variant)
#: by :func:`select_variant`: each defines its class against the active
#: variant's Mitsuba base classes and registers it at import, as Mitsuba's own
#: Python integrators do.
PLUGIN_MODULES = ("transient.sensor", "transient.plane", "transient.path", "transient.nlos")


def _register_plugins() -> None:
    """Import the plugin modules for the active variant (re-import them after a variant change)."""
    import importlib

    for name in PLUGIN_MODULES:
        if name in sys.modules:
            importlib.reload(sys.modules[name])
        else:
            importlib.import_module(name)


def _check_cuda(variant: str) -> None:
    """Refuse a CUDA variant on a machine where Dr.Jit finds no CUDA device."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.CUDA):
        raise BackendError(f"variant {variant}: no CUDA device or driver found on this machine; "
                           f"use a CPU variant (llvm_ad_mono)")


def select_variant(variant: str | None = None) -> str:
    """Choose the libLLVM, set the Mitsuba variant and register this package's plugins.

    Parameters
    ----------
    variant : str, optional
        A mono Mitsuba variant (``"llvm_mono"``, ``"llvm_ad_mono"``,
        ``"cuda_mono"``, ``"cuda_ad_mono"``). Default: ``llvm_mono`` if this
        Mitsuba build has it, else ``llvm_ad_mono``.

    Returns
    -------
    str
        The variant now active.

    Raises
    ------
    BackendError
        When only a libLLVM < 16 exists (or ``DRJIT_LIBLLVM_PATH`` names
        one), the variant is not in this Mitsuba build or not mono, or a
        CUDA variant is asked for where no CUDA device exists. The message
        is one line and says how to fix it.

    Notes
    -----
    Must run before anything imports ``drjit``: Dr.Jit picks its libLLVM
    when it is first imported and never again.
    """
    if variant is not None and not (variant.startswith(("llvm_", "cuda_")) and variant.endswith("_mono")):
        raise BackendError(f"variant {variant!r}: the renderer needs a mono llvm_* or cuda_* variant")
    if variant is None or variant.startswith("llvm_"):
        _configure_llvm()
    with _kernel_cache_while_importing():
        import mitsuba as mi

    available = list(mi.variants())
    if variant is None:
        variant = default_variant(available)
    elif variant not in available:
        raise BackendError(f"variant {variant!r} is not in this Mitsuba build; use one of "
                           f"{', '.join(usable_variants(available))}")
    if variant.startswith("cuda_"):
        _check_cuda(variant)
    if mi.variant() != variant:
        mi.set_variant(variant)
    global _llvm_checked, _plugins_variant
    if variant.startswith("llvm_") and not _llvm_checked:
        _check_loaded_llvm()
        _llvm_checked = True
    if _plugins_variant != variant:
        _register_plugins()
        _plugins_variant = variant
    return variant
