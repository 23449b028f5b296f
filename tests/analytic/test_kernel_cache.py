"""The kernels' cache is keyed by every module they use, not only their own file."""

import os
import shutil
from pathlib import Path

from numba.core.caching import CacheImpl

from analytic import kernel_cache, system
from analytic.kernel_cache import PackageCacheLocator, module_closure

PACKAGE = Path(kernel_cache.__file__).resolve().parent


def test_closure_follows_imports_through_other_modules():
    names = {str(path.relative_to(PACKAGE)) for path in module_closure(PACKAGE / "system.py")}
    # system imports kernels, which imports quadrature, which imports isochrone, which imports attenuation;
    # kernels imports the waveforms' pieces (a subpackage)
    assert {"system.py", "kernels.py", "quadrature.py", "isochrone.py", "attenuation.py",
            "waveforms/pieces.py"} <= names
    assert "io.py" not in names and "capture.py" not in names


def test_stamp_changes_when_an_imported_module_changes(tmp_path, monkeypatch):
    """On a copy of the package: editing the real ``pieces.py``, even for a moment, would make every cached
    kernel stale for another process loading one meanwhile (a second pytest-xdist worker, a user's command),
    which would recompile it. The stamp follows the sources' content, not their times."""
    copy = tmp_path / PACKAGE.name
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    monkeypatch.setattr(kernel_cache, "_PACKAGE", copy)
    locator = PackageCacheLocator.from_function(system.forward, str(copy / "system.py"))
    before = locator.get_source_stamp()
    dependency = copy / "waveforms" / "pieces.py"
    original = dependency.read_bytes()
    status = dependency.stat()
    os.utime(dependency, ns=(status.st_atime_ns, status.st_mtime_ns + 10**9))
    assert locator.get_source_stamp() == before          # touched, not changed
    dependency.write_bytes(original + b"# edited\n")
    assert locator.get_source_stamp() != before
    dependency.write_bytes(original)
    assert locator.get_source_stamp() == before


def test_only_this_package_is_served():
    assert CacheImpl._locator_classes[0] is PackageCacheLocator
    assert PackageCacheLocator.from_function(os.path.join, os.path.__file__) is None
