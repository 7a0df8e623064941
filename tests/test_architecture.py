"""The package layout holds: leaf packages never import ``cold_maps``, and no module import
cycle exists anywhere (lazy imports inside functions and ``TYPE_CHECKING`` blocks count)."""

from __future__ import annotations

import ast
from pathlib import Path


PROJECT_ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("cold_maps", "fusion", "converters", "gt_matching")
LEAF_PACKAGES = ("fusion", "converters", "gt_matching")


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def project_modules(root: Path = PROJECT_ROOT, packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    return {module_name(p, root): p for package in packages for p in sorted((root / package).rglob("*.py"))}


def imported_modules(path: Path, name: str, known: set[str]) -> set[str]:
    """Project modules that ``path`` (module ``name``) imports anywhere in its body.
    ``from package import module`` counts as importing the module; a module's own
    ancestor packages (initialised by Python first anyway) are not counted."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base for alias in node.names]
        for target in targets:
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name and not name.startswith(target + "."):
                found.add(target)
    return found


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    known = set(modules)
    return {name: imported_modules(path, name, known) for name, path in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a closed list of modules, or None (iterative depth-first search)."""
    state: dict[str, int] = {}
    for root in sorted(graph):
        if root in state:
            continue
        stack = [(root, iter(sorted(graph[root])))]
        path = [root]
        state[root] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(child) == 1:
                return path[path.index(child):] + [child]
            elif child not in state:
                state[child] = 1
                stack.append((child, iter(sorted(graph[child]))))
                path.append(child)
    return None


def leaf_imports_of_cold_maps(graph: dict[str, set[str]]) -> list[str]:
    return sorted(f"{name} -> {target}" for name, targets in graph.items() for target in targets
                  if name.split(".")[0] in LEAF_PACKAGES and target.split(".")[0] == "cold_maps")


def test_leaf_packages_never_import_cold_maps() -> None:
    assert leaf_imports_of_cold_maps(import_graph(project_modules())) == []


def test_no_import_cycle_anywhere() -> None:
    cycle = find_cycle(import_graph(project_modules()))
    assert cycle is None, " -> ".join(cycle or ())


def write_tree(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def test_graph_sees_lazy_relative_and_type_checking_imports(tmp_path: Path) -> None:
    write_tree(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "def f():\n    from pkg import b\n",
        "pkg/b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .c import thing\n",
        "pkg/c.py": "from . import a\n",
        "pkg/d.py": "import pkg.a\n",
    })
    graph = import_graph(project_modules(tmp_path, ("pkg",)))
    assert graph["pkg.d"] == {"pkg.a"}
    cycle = find_cycle(graph)
    assert cycle is not None and set(cycle) == {"pkg.a", "pkg.b", "pkg.c"}


def test_cycle_finder_on_an_acyclic_diamond() -> None:
    assert find_cycle({"a": {"b", "c"}, "b": {"d"}, "c": {"d"}, "d": set()}) is None


def test_leaf_check_catches_a_lazy_import_of_cold_maps(tmp_path: Path) -> None:
    write_tree(tmp_path, {
        "cold_maps/__init__.py": "",
        "cold_maps/network/__init__.py": "",
        "cold_maps/network/lane_graph.py": "",
        "fusion/__init__.py": "",
        "fusion/api.py": "def f():\n    from cold_maps.network import lane_graph\n",
    })
    graph = import_graph(project_modules(tmp_path, ("cold_maps", "fusion")))
    assert leaf_imports_of_cold_maps(graph) == ["fusion.api -> cold_maps.network.lane_graph"]
