"""The layout's rules, read from the source: no import circles (deferred imports included), the algorithm
never imports the env, and the product never imports an experiment."""

from __future__ import annotations

import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = ("sb3_pixeldqn", "shelf_env", "research")


def module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_modules() -> dict[str, pathlib.Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def imports_of(path: pathlib.Path, modules: dict[str, pathlib.Path]) -> set[str]:
    """The project modules ``path`` imports anywhere in its code (top level, functions, TYPE_CHECKING)."""
    here = module_name(path)
    package = here if path.name == "__init__.py" else here.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative import
                anchor = package.split(".")
                anchor = anchor[:len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            # `from pkg import sub` imports the module pkg.sub where there is one, else pkg itself
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names]
        else:
            continue
        for name in names:
            while name and name not in modules:  # `import a.b.c` of a project module, or a name in it
                name = name.rpartition(".")[0]
            if name and name != here:
                found.add(name)
    return found


def import_graph() -> dict[str, set[str]]:
    modules = project_modules()
    return {name: imports_of(path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_circle() -> None:
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_walk_sees_deferred_and_relative_imports(tmp_path: pathlib.Path) -> None:
    graph = import_graph()
    assert "sb3_pixeldqn.exploration" in graph["sb3_pixeldqn.actor"]
    assert "shelf_env.world.cabinet" in graph["shelf_env.world"]  # the package's re-export
    assert "sb3_pixeldqn" in graph["shelf_env.policies"]  # a deferred import inside make_policy


def test_no_import_circles() -> None:
    assert cycles(import_graph()) == []


def test_the_algorithm_never_imports_the_env() -> None:
    graph = import_graph()
    offenders = {m: sorted(i for i in imps if not i.startswith("sb3_pixeldqn"))
                 for m, imps in graph.items() if m.startswith("sb3_pixeldqn")}
    assert {m: i for m, i in offenders.items() if i} == {}


def test_the_product_never_imports_an_experiment() -> None:
    graph = import_graph()
    offenders = {m: sorted(i for i in imps if i.startswith("research"))
                 for m, imps in graph.items() if not m.startswith("research")}
    assert {m: i for m, i in offenders.items() if i} == {}
