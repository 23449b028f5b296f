"""The project's module import graph, read from the source by AST (no module is imported).

Rules (what counts as "module A imports module B"):

- every ``import`` statement of A, at module level or inside a function, a
  class or an ``if`` (a function-level import "because the other imports
  this one" is the cycle, not its cure: docs/STYLE);
- ``import p.q.r`` is an edge to ``p.q.r``; ``from p.q import r`` to ``p.q``
  and, when ``r`` is a submodule of ``p.q``, to ``p.q.r``; relative imports
  resolve against A's package (``from . import x`` is an edge to the sibling
  module ``x``);
- a parent package whose ``__init__`` Python runs on the way to ``p.q.r`` is
  not counted (every package's ``__init__`` loads its names lazily, so it
  imports nothing of its own by running);
- lazy_loader: a package's ``submod_attrs`` are not edges of the package
  (nothing is imported until a name is used); a name taken from the package
  is an edge to the submodule that provides it, since that is what runs
  then: ``from p import name`` and ``p.name`` (with ``import p`` in A) reach
  that submodule. So a cycle through a package's lazy names is counted
  exactly when using the name would run the other module.

Only the project's packages are nodes; the standard library and third-party
modules are left out.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The project's packages: the graph's nodes are their modules.
PACKAGES = ("analytic", "transient", "validation", "interop")


@cache
def modules() -> dict[str, tuple[Path, bool]]:
    """Dotted module name -> (its file, whether it is a package's ``__init__``)."""
    found = {}
    for top in PACKAGES:
        for path in sorted((ROOT / top).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            is_package = parts[-1] == "__init__"
            found[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return found


@cache
def _tree(name: str) -> ast.Module:
    return ast.parse(modules()[name][0].read_text(encoding="utf-8"))


@cache
def lazy_names(package: str) -> dict[str, str]:
    """Name -> the submodule providing it, from the package's ``lazy_loader.attach`` call."""
    path, is_package = modules()[package]
    names = {}
    if not is_package:
        return names
    for node in ast.walk(_tree(package)):
        if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "attach":
            for keyword in node.keywords:
                if keyword.arg == "submod_attrs":
                    for submodule, provided in ast.literal_eval(keyword.value).items():
                        names.update({public: f"{package}.{submodule}" for public in provided})
                elif keyword.arg == "submodules":
                    names.update({sub: f"{package}.{sub}" for sub in ast.literal_eval(keyword.value)})
    return names


def _taken(module: str, attribute: str) -> list[str]:
    """The module that runs when ``attribute`` is taken from ``module``: a submodule, or a lazy name's provider."""
    if f"{module}.{attribute}" in modules():
        return [f"{module}.{attribute}"]
    provider = lazy_names(module).get(attribute)
    return [provider] if provider else []


def _absolute(name: str, node: ast.ImportFrom) -> str:
    """The module an ``ImportFrom`` in module ``name`` names, relative ones resolved."""
    if not node.level:
        return node.module
    package = name if modules()[name][1] else name.rpartition(".")[0]
    parts = package.split(".")
    parts = parts[:len(parts) - node.level + 1]
    return ".".join(parts + ([node.module] if node.module else []))


@cache
def imports(name: str) -> frozenset[str]:
    """The project's modules that module ``name`` imports (module and function level, module docstring rules)."""
    found, aliases = set(), {}
    tree = _tree(name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name in modules():
                    found.add(alias.name)
                    aliases[alias.asname or alias.name] = alias.name
        elif isinstance(node, ast.ImportFrom):
            module = _absolute(name, node)
            if module.split(".")[0] not in PACKAGES:
                continue
            if module in modules():
                found.add(module)
            for alias in node.names:
                found.update(_taken(module, alias.name))
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            found.update(_taken(aliases[node.value.id], node.attr))
    found.discard(name)
    return frozenset(found)


def graph() -> dict[str, frozenset[str]]:
    """Every module of the project -> the project's modules it imports."""
    return {name: imports(name) for name in modules()}


def cycles(edges: dict[str, frozenset[str]]) -> list[list[str]]:
    """The import cycles: each strongly connected component of more than one module, as one cycle through it."""
    index, low, stack, on_stack, components = {}, {}, [], set(), []

    def visit(start):
        # Tarjan's algorithm, iterative (no recursion limit to meet)
        work = [(start, iter(sorted(edges[start])))]
        index[start] = low[start] = len(index)
        stack.append(start)
        on_stack.add(start)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(edges[successor]))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        components.append(_cycle_through(sorted(component), edges))

    for name in sorted(edges):
        if name not in index:
            visit(name)
    return components


def _cycle_through(component: list[str], edges) -> list[str]:
    """One cycle inside a strongly connected component, from its first module back to it (breadth first)."""
    members, start = set(component), component[0]
    parents, frontier = {start: None}, [start]
    while frontier:
        following = []
        for node in frontier:
            for successor in sorted(edges[node] & members):
                if successor == start:
                    path = [node]
                    while parents[path[-1]] is not None:
                        path.append(parents[path[-1]])
                    return [*reversed(path), start]
                if successor not in parents:
                    parents[successor] = node
                    following.append(successor)
        frontier = following
    return component
