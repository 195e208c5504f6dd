"""The package's imports go one way: no module imports itself back through others.

Every module of ``ddcm_casadi`` (and of ``formulations/``, installed as ``ddcm_casadi.formulations``) is
parsed with :mod:`ast`; every ``import`` and ``from ... import`` at any depth counts (an import inside a
function is still a dependency, only a later one), those under ``if TYPE_CHECKING:`` included: a type
that needs a module above is a dependency on it too (a seam, such as a protocol, breaks it). A cycle
among the resulting module graph fails the test and is named.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "ddcm_casadi"
# Installed name -> source folder (pyproject.toml's package-dir); the example cases hold no modules.
FOLDERS = {PACKAGE: ROOT / PACKAGE, f"{PACKAGE}.formulations": ROOT / "formulations"}


def package_modules() -> dict[str, Path]:
    """Map each module's dotted name to its source file (a package's name to its ``__init__.py``)."""
    modules: dict[str, Path] = {}
    for prefix, folder in FOLDERS.items():
        for path in sorted(folder.rglob("*.py")):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            modules[".".join([prefix, *parts])] = path
    return modules


def _imported_names(tree: ast.AST, module: str, is_package: bool, modules: dict[str, Path]) -> list[str]:
    """The absolute dotted names imported anywhere in ``tree`` (``if TYPE_CHECKING:`` bodies included)."""
    names: list[str] = []
    package = module if is_package else module.rpartition(".")[0]

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.Import):
            names.extend(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - (node.level - 1)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            # ``from pkg import sub`` depends on the submodule ``pkg.sub`` when there is one, else on ``pkg``
            for alias in node.names:
                submodule = f"{stem}.{alias.name}"
                names.append(submodule if submodule in modules else stem)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return names


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The package module that importing ``name`` loads last (the longest known prefix), if any."""
    parts = name.split(".")
    for end in range(len(parts), 0, -1):
        candidate = ".".join(parts[:end])
        if candidate in modules:
            return candidate
    return None


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports (an import of a package is one of its ``__init__``)."""
    modules = package_modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        targets = {_resolve(name, modules) for name in _imported_names(tree, module, path.name == "__init__.py", modules)}
        graph[module] = {target for target in targets if target is not None and target != module}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a closed list of nodes (first == last), or None if it has none."""
    WHITE, GREY, BLACK = 0, 1, 2
    colour = dict.fromkeys(graph, WHITE)
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        colour[node] = GREY
        stack.append(node)
        for target in sorted(graph.get(node, ())):
            if colour.get(target, BLACK) == GREY:
                return stack[stack.index(target):] + [target]
            if colour.get(target) == WHITE:
                found = visit(target)
                if found:
                    return found
        stack.pop()
        colour[node] = BLACK
        return None

    for node in sorted(graph):
        if colour[node] == WHITE:
            found = visit(node)
            if found:
                return found
    return None


def test_graph_sees_the_package():
    graph = import_graph()
    assert "ddcm_casadi.formulations.penalty" in graph
    assert "ddcm_casadi.formulations.base" in graph["ddcm_casadi.formulations.penalty"]
    assert "ddcm_casadi.problems.contract" in graph["ddcm_casadi.formulations.penalty"]


def test_find_cycle_names_a_cycle():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_no_import_cycle():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


#: What each layer may import (besides the core modules ``ddcm_casadi.<name>`` and itself); the
#: table of docs/architecture.md, downwards only.
LAYERS = {
    "data": set(),
    "models": {"data"},
    "problems": {"models", "data"},
    "loops": {"problems"},
    "formulations": {"loops", "problems"},
    "drivers": {"formulations", "loops", "problems", "models", "data"},
    "casefiles": {"drivers", "formulations", "models", "data"},
    "outputs": {"drivers", "models", "data", "problems"},
    "validation": {"casefiles", "drivers", "formulations", "loops", "problems", "models", "data", "cases"},
}
CORE = {"errors", "registry", "inputs", "io", "linalg", "heap", "factor_updates", "evaluate", "parallel", "version"}


def _layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_layers_import_downwards_only():
    """Models never import case files, drivers, outputs or commands; loops never import drivers;
    and so on down the table: a layer imports only the layers below it and the core."""
    wrong = []
    for module, targets in import_graph().items():
        layer = _layer(module)
        if layer not in LAYERS:
            continue
        for target in targets:
            other = _layer(target)
            # the package root runs before any of its modules anyway (here: ``from ddcm_casadi import cases``)
            if other not in (layer, "__init__") and other not in CORE and other not in LAYERS[layer]:
                wrong.append(f"{module} -> {target}")
    assert not wrong, wrong
