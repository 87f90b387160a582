"""The package's layout: what imports what, how long a module is, and where state lives.

Read from the sources themselves (every ``import`` of every module, at module level or inside a
function, those under ``if TYPE_CHECKING:`` aside), so that a new cycle or a stray global fails here
whoever adds it.
"""

from __future__ import annotations

import ast
import graphlib
from importlib import resources
from pathlib import Path

import pytest

ROOT = Path(str(resources.files("tactrec")))
#: no module is longer than this (lines)
LONGEST = 400


def _modules() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its ``__init__``)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _typing_only(tree: ast.AST) -> set[int]:
    skip = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            skip.update(id(n) for n in ast.walk(node))
    return skip


def _imports(name: str) -> list[tuple[str, int]]:
    """The package's modules that module ``name`` imports, with the line of each import: a ``from X
    import y`` names ``X.y`` where that is a module, else ``X``."""
    path = MODULES[name]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    skip = _typing_only(tree)
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.Import):
            out += [(alias.name, node.lineno) for alias in node.names if alias.name.split(".")[0] == "tactrec"]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                depth = len(package.split(".")) - node.level + 1
                if depth < 1:                           # beyond the package: an error when it runs
                    out.append((f"{'.' * node.level}{node.module or ''} (beyond the package)", node.lineno))
                    continue
                module = ".".join(package.split(".")[:depth] + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            if module.split(".")[0] != "tactrec":
                continue
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                out.append((sub if sub in MODULES else module, node.lineno))
    return out


def _names(name: str) -> list[tuple[str, str, int]]:
    """Each ``from X import y`` of module ``name`` whose ``X`` is one of the package's modules and
    ``X.y`` is not: ``(X, y, line)``."""
    path = MODULES[name]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            depth = len(package.split(".")) - node.level + 1
            if depth < 1:
                continue
            module = ".".join(package.split(".")[:depth] + ([node.module] if node.module else []))
            out += [(module, alias.name, node.lineno) for alias in node.names
                    if f"{module}.{alias.name}" not in MODULES]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "tactrec":
            out += [(node.module, alias.name, node.lineno) for alias in node.names
                    if f"{node.module}.{alias.name}" not in MODULES]
    return out


def _graph() -> dict[str, set[str]]:
    return {name: {target for target, _ in _imports(name) if target != name} for name in MODULES}


def _part(name: str) -> str:
    """The top-level part of the package a module belongs to (``tactrec.engine``, ``tactrec.probability``)."""
    return ".".join(name.split(".")[:2])


def test_every_import_of_the_package_names_one_of_its_modules():
    """An import of ``tactrec.x`` that names no module (a relative import one level off, say) is caught
    here, not when the function holding it first runs."""
    wrong = [f"{MODULES[name].relative_to(ROOT.parent)}:{line}: {target}" for name in MODULES
             for target, line in _imports(name) if target not in MODULES]
    assert not wrong, "imports of no module:\n" + "\n".join(wrong)


def test_every_name_imported_from_the_package_is_there():
    """``from tactrec.x import y``: ``y`` is defined in ``tactrec.x`` (a name moved or removed fails
    here, not when the function that imports it first runs)."""
    import importlib

    wrong = []
    for name in MODULES:
        for module, attribute, line in _names(name):
            if module in MODULES and not hasattr(importlib.import_module(module), attribute):
                wrong.append(f"{MODULES[name].relative_to(ROOT.parent)}:{line}: {attribute} from {module}")
    assert not wrong, "names not there:\n" + "\n".join(wrong)


def test_no_module_imports_itself_back():
    """No cycle among the modules, nor among the package's parts (its subpackages and top-level
    modules): each stage imports only the stages below it."""
    graph = _graph()
    for level, edges in (("module", graph),
                         ("part", {p: {_part(t) for n in graph if _part(n) == p for t in graph[n]} - {p}
                                   for p in {_part(n) for n in graph}})):
        try:
            tuple(graphlib.TopologicalSorter(edges).static_order())
        except graphlib.CycleError as exc:
            pytest.fail(f"a {level} cycle: {' -> '.join(exc.args[1])}")


def test_the_engine_and_the_library_core_import_no_benchmark_cli_or_viewer():
    """The benchmarks, the command line and the viewer sit on top: nothing below them imports them."""
    above = ("tactrec.bench", "tactrec.cli", "tactrec.viewer", "tactrec.demo", "tactrec.plots", "tactrec.__main__")
    graph = _graph()
    wrong = [f"{name} -> {target}" for name in graph if not name.startswith(above)
             for target in graph[name] if target.startswith(above) and not target.startswith(name)]
    assert not wrong, "\n".join(wrong)


def test_no_module_is_longer_than_the_limit():
    long = {str(path.relative_to(ROOT.parent)): n for path in MODULES.values()
            if (n := len(path.read_text(encoding="utf-8").splitlines())) > LONGEST}
    assert not long, f"modules over {LONGEST} lines: {long}"


def _mutable(value: ast.AST) -> bool:
    if isinstance(value, (ast.List, ast.Dict, ast.Set)):
        return not (isinstance(value, ast.Dict) and value.keys) and not getattr(value, "elts", None)
    return (isinstance(value, ast.Call) and isinstance(value.func, ast.Name)
            and value.func.id in ("dict", "list", "set") and not value.args and not value.keywords)


def test_no_module_keeps_state_between_calls():
    """No ``global`` statement, and no module-level name bound to an empty container that calls fill
    in: state lives in objects a caller holds.  A cache is named as one (``..._CACHE``) and says
    what it keeps in its comment."""
    found = []
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        found += [f"{name}:{n.lineno}: global {', '.join(n.names)}" for n in ast.walk(tree)
                  if isinstance(n, ast.Global)]
        for node in tree.body:
            targets = (node.targets if isinstance(node, ast.Assign)
                       else [node.target] if isinstance(node, ast.AnnAssign) else [])
            value = getattr(node, "value", None)
            for target in targets:
                if isinstance(target, ast.Name) and value is not None and _mutable(value) \
                        and not target.id.endswith("CACHE"):
                    found.append(f"{name}:{node.lineno}: {target.id}")
    assert not found, "module-level state:\n" + "\n".join(found)
