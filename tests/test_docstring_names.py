"""Every dotted name the documentation cites resolves: ``analytic.operator.matrix_free.forward`` in a docstring or in
docs/*.md must import, so that a rename or a move cannot leave a citation pointing at nothing.

The reference is the interpreter: each name is imported (its longest importable prefix) and the rest looked
up as attributes, dataclass fields or annotations. Sphinx roles with a leading dot (``:mod:`.config```) are
resolved against the package of the module that holds them.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import re
import types
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("analytic", "transient", "validation", "interop")

# A dotted name rooted at one of our packages, in any text (roles, double backticks or plain prose).
_DOTTED = re.compile(r"(?<![\w./-])((?:analytic|transient|validation|interop)(?:\.[A-Za-z_][A-Za-z0-9_]*)+)")
# A Sphinx role whose target is relative to the current package: :mod:`.config`, :func:`..errors.X`.
_RELATIVE_ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|exc):`~?(\.+[A-Za-z_][\w.]*)`")
# File names that read like dotted names: transient.npy is a file, not an attribute of the package.
_FILE_SUFFIXES = {"npy", "npz", "exr", "h5", "hdf5", "png", "json", "md", "csv", "toml", "py", "xml", "txt",
                  "lock", "pyi"}


def cited_names(text: str, package: str | None = None) -> set[str]:
    """The dotted names ``text`` cites, relative roles resolved against ``package`` (a dotted package name)."""
    names = {match.group(1).rstrip(".") for match in _DOTTED.finditer(text)}
    names = {name for name in names if name.rsplit(".", 1)[-1] not in _FILE_SUFFIXES}
    if package is not None:
        for match in _RELATIVE_ROLE.finditer(text):
            target = match.group(1)
            dots = len(target) - len(target.lstrip("."))
            base = package.split(".")
            if dots - 1 >= len(base):
                names.add(target)            # climbs above the top package: unresolvable, reported
                continue
            base = base[:len(base) - (dots - 1)]
            names.add(".".join(base + [target.lstrip(".")]))
    return names


def resolves(name: str) -> bool:
    """Whether ``name`` (a.b.c) imports: its longest importable prefix, then attributes, fields or annotations."""
    parts = name.split(".")
    if not parts[0]:
        return False
    for split in range(len(parts), 0, -1):
        try:
            value = importlib.import_module(".".join(parts[:split]))
        except ModuleNotFoundError:
            continue
        except ImportError:
            return False
        break
    else:
        return False
    for attribute in parts[split:]:
        if hasattr(value, attribute):
            owner, value = value, getattr(value, attribute)
            if _imported_not_defined(owner, value):
                return False
        elif isinstance(value, type) and (attribute in getattr(value, "__annotations__", {})
                                          or (dataclasses.is_dataclass(value)
                                              and attribute in {f.name for f in dataclasses.fields(value)})):
            return True                      # a field: its value lives on instances
        else:
            return False
    return True


def _imported_not_defined(owner, value) -> bool:
    """A function or class cited in a module (not a package's API) that merely imports it from elsewhere."""
    is_plain_module = isinstance(owner, types.ModuleType) and not hasattr(owner, "__path__")
    defined_in = getattr(value, "__module__", None) if callable(value) else None
    return is_plain_module and defined_in is not None and defined_in != owner.__name__


def _module_name(path: Path) -> tuple[str, str]:
    """(module, package) of a source file: the package a relative role is resolved against."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
        return ".".join(parts), ".".join(parts)
    return ".".join(parts), ".".join(parts[:-1])


def _docstrings(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = [tree] + [node for node in ast.walk(tree)
                      if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))]
    texts = [ast.get_docstring(node, clean=False) for node in nodes]
    # attribute docstrings and ``#:`` comments are prose too, but only docstrings are required to resolve
    return [text for text in texts if text]


def _citations() -> dict[str, list[str]]:
    """Cited name -> where (file:kind) it is cited."""
    where: dict[str, list[str]] = {}
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            module, package = _module_name(path)
            for text in _docstrings(path):
                for name in cited_names(text, package):
                    where.setdefault(name, []).append(str(path.relative_to(ROOT)))
    for path in sorted((ROOT / "docs").glob("*.md")):
        for name in cited_names(path.read_text(encoding="utf-8")):
            where.setdefault(name, []).append(str(path.relative_to(ROOT)))
    return where


def test_the_checker_finds_and_refuses_wrong_names():
    text = (":func:`analytic.operator.matrix_free.forward`, ``analytic.files.build_meta``, :mod:`.verdict`, "
            "transient.npy and ``analytic.no_such_module.forward``; :func:`analytic.operator.system.no_such_name`")
    names = cited_names(text, "validation.check")
    assert names == {"analytic.operator.matrix_free.forward", "analytic.files.build_meta", "validation.check.verdict",
                     "analytic.no_such_module.forward", "analytic.operator.system.no_such_name"}
    assert resolves("analytic.operator.matrix_free.forward") and resolves("analytic.files.build_meta")
    assert resolves("validation.check.verdict") and resolves("analytic.Sampling.start_opl")   # a field
    assert not resolves("analytic.operator.system.no_such_name")
    assert not resolves("analytic.no_such_module.forward")
    assert not resolves("analytic.io.build_meta")            # moved to analytic.files
    assert not resolves("analytic.operator.conditioning.covering_sampling")   # imported there, defined in window


def test_every_cited_name_resolves():
    from transient import backend

    backend.select_variant()      # the renderer's plugins are Mitsuba classes: importing them needs a variant
    citations = _citations()
    assert len(citations) > 50                                  # the scan found the documentation
    broken = {name: sorted(set(places)) for name, places in citations.items() if not resolves(name)}
    assert not broken, "names cited that do not import:\n" + "\n".join(
        f"  {name}  ({', '.join(places)})" for name, places in sorted(broken.items()))


def test_design_citations_name_sections_the_design_document_has():
    """``docs/design.md section N`` (or ``sections N``) names a section of docs/design.md."""
    design = ROOT / "docs" / "design.md"
    sections = {int(number) for number in re.findall(r"^## (\d+)\.", design.read_text(encoding="utf-8"), re.M)}
    assert sections >= set(range(1, 9))
    sources = [p for top in PACKAGES for p in (ROOT / top).rglob("*.py")] + sorted((ROOT / "docs").glob("*.md"))
    cited = 0
    for source in sources:
        for number in re.findall(r"docs/design\.md\s+sections?\s+(\d+)", source.read_text(encoding="utf-8")):
            cited += 1
            assert int(number) in sections, f"{source}: docs/design.md section {number}"
    assert cited > 20


_PATH = re.compile(r"(?<![\w/.-])((?:analytic|transient|validation|interop|tests|docs|benchmarks|examples|scripts)"
                   r"/[\w/.-]+\.(?:py|md|toml|sh))\b")


def test_every_cited_file_of_the_repository_exists():
    """A path such as ``tests/interop/tal/test_capture.py`` in the code or docs/*.md names a file there."""
    sources = [p for top in PACKAGES for p in (ROOT / top).rglob("*.py")] + sorted((ROOT / "docs").glob("*.md"))
    missing = sorted({f"{cited} ({source.relative_to(ROOT)})" for source in sources
                      for cited in _PATH.findall(source.read_text(encoding="utf-8"))
                      if not (ROOT / cited).exists()})
    assert not missing, "files cited that do not exist:\n  " + "\n  ".join(missing)
