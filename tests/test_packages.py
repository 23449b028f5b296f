"""Package APIs: one convention (``lazy_loader.attach`` with ``__all__``) in every package, every public name
resolving to what it names whatever was imported before, and imports that stay cheap.

The references are the interpreter's own: a fresh process per check, its ``sys.modules`` after the import.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Packages not (yet) converted: none.
NOT_YET_LAZY: set[str] = set()
# Packages whose public names are their modules (the compiled kernels: the Python side imports the modules it drives).
MODULE_PACKAGES = {"analytic.kernels"}


def _packages() -> list[str]:
    found = []
    for top in ("analytic", "transient", "validation", "interop"):
        found.append(top)
        module = importlib.import_module(top)
        found += [info.name for info in pkgutil.walk_packages(module.__path__, f"{top}.") if info.ispkg]
    return sorted(found)


def _python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("name", [p for p in _packages() if p not in NOT_YET_LAZY])
def test_every_package_loads_its_names_lazily_and_lists_them(name):
    package = importlib.import_module(name)
    assert getattr(package.__getattr__, "__module__", None) == "lazy_loader", f"{name}: not lazy_loader.attach"
    assert package.__all__ and sorted(package.__all__) == sorted(set(package.__all__))
    for public in package.__all__:
        assert getattr(package, public) is not None, f"{name}.{public}"


@pytest.mark.parametrize("name", [p for p in _packages() if p not in MODULE_PACKAGES])
def test_a_public_name_is_what_it_names_after_its_same_named_module_is_imported(name):
    # ``analytic.attenuation`` (a function in attenuation.py) and ``transient.render`` (in render.py): the
    # import system binds the submodule to the package's attribute when it first loads it; the public name
    # must stay the function, whichever comes first.
    code = f"""
import importlib, importlib.util, inspect
package = importlib.import_module({name!r})
clashes = [n for n in package.__all__ if importlib.util.find_spec({name!r} + "." + n) is not None]
for n in clashes:
    importlib.import_module({name!r} + "." + n)
bad = [n for n in clashes if inspect.ismodule(getattr(package, n))]
print(len(clashes), bad)
"""
    done = _python(code)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split(maxsplit=1)[1].strip() == "[]", done.stdout


def test_importing_the_packages_imports_no_heavy_library():
    done = _python("import sys, analytic, transient, validation, interop, analytic.files, analytic.inversion, "
                   "analytic.scenes, analytic.operator, analytic.measurement, interop.tal, interop.mitransient, "
                   "validation.judging, validation.runs, validation.check, validation.plots, validation.sweep, "
                   "validation.cli\n"
                   "print(sorted({m.split('.')[0] for m in sys.modules} & {'numba', 'mitsuba', 'drjit', "
                   "'matplotlib', 'dask', 'distributed', 'scipy', 'h5py', 'OpenEXR'}))")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def test_help_imports_no_numba_mitsuba_matplotlib_or_dask():
    done = _python("import sys\nfrom validation.cli import main\n"
                   "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
                   "print(sorted({m.split('.')[0] for m in sys.modules} & {'numba', 'mitsuba', 'drjit', "
                   "'matplotlib', 'dask', 'distributed'}), file=sys.stderr)")
    assert done.stderr.strip().splitlines()[-1] == "[]", done.stderr


def test_the_model_never_imports_the_files_package():
    done = _python("import sys, analytic.operator.system, analytic.operator.response, analytic.operator.window, "
                   "analytic.operator.conditioning, analytic.scenes.scene_file\nprint(sorted(m for m in sys.modules if m.startswith('analytic.files')))")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


def _installed_entry_points(folder: Path) -> Path:
    """A dist-info in ``folder`` with pyproject.toml's entry points, as ``pip install`` writes them."""
    import tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    info = folder / "diffuse_imaging-0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {project['name']}\nVersion: 0\n")
    (info / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{name} = {value}\n" for name, value in points.items()) + "\n"
        for group, points in project["entry-points"].items()))
    return folder


def test_a_plain_import_of_the_model_reads_other_tools_files_through_the_declared_entry_points(tmp_path):
    """``analytic.load_scene("x.yaml")`` works without the user importing interop: the model asks its format
    registry, which loads pyproject.toml's entry points on the first suffix it does not know, and only then."""
    code = ("import sys, analytic\n"
            "own = analytic.load_scene('examples/square.toml')\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'interop'))\n"
            "tal = analytic.load_scene('examples/tal/plane-single.yaml')\n"
            "print(own.kind, tal.kind, 'interop.tal.formats' in sys.modules)\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(_installed_entry_points(tmp_path))])}
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env=env)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[:2] == ["[]", "plane relay_wall True"], done.stdout
