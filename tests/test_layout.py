"""The package's layout: layers that read bottom-up, no import cycle, small modules.

Imports are read from the source as written, including those inside functions and under TYPE_CHECKING, since each
is a dependency all the same. Layers, lowest first: the core types, geometry, errors and text reading; the
configuration; the cells, loop detection and maps; the SLAM system and navigation on its map; perception, the
simulator, datasets, the map store, file formats, evaluation, plots and reports; the commands; sweeps; the CLI. A
module never imports a higher layer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "neoslam"
MAX_MODULE_LINES = 500

LAYERS: list[set[str]] = [
    {"types", "record_checks", "geometry", "errors", "text", "inputs", "stopping", "boxes", "memory"},
    {"config"},
    {"cells", "loop", "mapping"},
    {"relocalisation", "step_inputs", "pipeline", "navigation"},
    {"perception", "sim", "datasets", "store", "io", "evaluation", "viz", "report", "live"},
    {"commands"},
    {"sweep"},
    {"cli", "__main__"},
]


def _modules() -> dict[str, Path]:
    """Dotted module name -> file (a package by its name, through its __init__)."""
    modules = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        modules[".".join(parts)] = path
    return modules


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the modules of this package it imports (the package's root, imported by every module, left out)."""
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        base = name if is_package else name.rpartition(".")[0]
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                module = node.module or ""
                if node.level:
                    package = base
                    for _ in range(node.level - 1):
                        package = package.rpartition(".")[0]
                    module = f"{package}.{module}" if module else package
                names = [module] + [f"{module}.{alias.name}" for alias in node.names]
            else:
                continue
            for imported in names:
                while imported and imported not in modules:
                    imported = imported.rpartition(".")[0]
                if imported and imported not in (name, "neoslam") and not name.startswith(imported + "."):
                    targets.add(imported)
        graph[name] = targets
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph.get(node, ())):
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def _area(module: str) -> str:
    """The first part below the root: a subpackage or a top-level module."""
    return module.split(".")[1]


def _layer(module: str) -> int:
    area = _area(module)
    for level, areas in enumerate(LAYERS):
        if area in areas:
            return level
    raise AssertionError(f"{module}: in no layer; add {area!r} to LAYERS in {Path(__file__).name}")


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    return _imports(_modules())


def test_no_module_imports_another_that_imports_it_back(graph):
    assert _cycles(graph) == []


def test_no_package_imports_another_that_imports_it_back(graph):
    areas: dict[str, set[str]] = {}
    for module, targets in graph.items():
        if module == "neoslam":
            continue
        areas.setdefault(_area(module), set()).update(_area(t) for t in targets if _area(t) != _area(module))
    assert _cycles(areas) == []


def test_no_module_imports_a_higher_layer(graph):
    upward = [
        f"{module} (layer {_layer(module)}) imports {target} (layer {_layer(target)})"
        for module, targets in graph.items()
        if module != "neoslam"
        for target in targets
        if _layer(target) > _layer(module)
    ]
    assert upward == []


def test_every_module_is_in_a_layer(graph):
    for module in graph:
        if module != "neoslam":
            _layer(module)


def test_no_module_is_longer_than_the_limit():
    long = {
        str(path.relative_to(PACKAGE)): n
        for path in PACKAGE.rglob("*.py")
        if (n := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert long == {}


def test_the_graph_sees_imports_inside_functions_and_under_type_checking(tmp_path):
    """The reader itself: an import in a function body or a TYPE_CHECKING block is an edge."""
    package = tmp_path / "neoslam"
    (package / "inner").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "inner" / "__init__.py").write_text("")
    (package / "a.py").write_text("def f():\n    from neoslam.inner import b\n")
    (package / "inner" / "b.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from neoslam import a\nfrom . import c\n"
    )
    (package / "inner" / "c.py").write_text("")
    modules = {}
    for path in sorted(package.rglob("*.py")):
        parts = list(path.relative_to(tmp_path).with_suffix("").parts)
        modules[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    graph = _imports(modules)
    assert graph["neoslam.a"] == {"neoslam.inner", "neoslam.inner.b"}
    assert graph["neoslam.inner.b"] == {"neoslam.a", "neoslam.inner.c"}
    assert _cycles(graph) == [["neoslam.a", "neoslam.inner.b"]]
