"""No import cycle between the modules of ``gevi_cli`` (issue 12).

Every module is parsed with ``ast`` (nothing is imported). The graph holds the imports that run when
a module is loaded: ``import gevi_cli.x``, ``from gevi_cli.x import y`` and relative imports at
module level, including those inside module-level ``if``/``try``/``with`` blocks and class bodies.
Imports inside functions are deliberate lazy imports and are left out, and so are
``if TYPE_CHECKING:`` blocks, which never run. ``from pkg import name`` points at ``pkg.name`` when
that is a module and at ``pkg`` otherwise; parent packages that an import loads implicitly are not
edges (a package ``__init__`` that re-exports its submodules is not a cycle).
"""
from __future__ import annotations

import ast
from pathlib import Path

import gevi_cli

PKG = "gevi_cli"
ROOT = Path(gevi_cli.__file__).resolve().parent


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imports(tree: ast.Module, include_lazy: bool = False):
    """Import nodes that execute when the module is loaded (not in functions or TYPE_CHECKING);
    with ``include_lazy`` also those inside functions."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) and not include_lazy:
            continue
        elif isinstance(node, ast.If) and _is_type_checking(node.test):
            stack.extend(node.orelse)
        else:
            stack.extend(ast.iter_child_nodes(node))


def _resolve(mod: str, is_pkg: bool, node: ast.ImportFrom) -> str | None:
    if not node.level:
        return node.module
    base = mod.split(".") if is_pkg else mod.split(".")[:-1]
    if node.level > 1:
        base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def import_graph(include_lazy: bool = False) -> dict[str, dict[str, int]]:
    """module -> {imported gevi_cli module: line of the first such import}."""
    mods = _modules()
    graph: dict[str, dict[str, int]] = {m: {} for m in mods}
    for mod, path in mods.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        is_pkg = path.name == "__init__.py"
        for node in _imports(tree, include_lazy):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = _resolve(mod, is_pkg, node)
                if base is None:
                    continue
                for a in node.names:
                    sub = f"{base}.{a.name}"
                    targets.append(sub if sub in mods else base)
            for t in targets:
                if t != mod and (t == PKG or t.startswith(PKG + ".")):
                    # ``import gevi_cli.x.y`` of a name that is not a module file: its nearest module
                    while t not in mods and "." in t:
                        t = t.rsplit(".", 1)[0]
                    if t in mods and t != mod:
                        graph[mod].setdefault(t, node.lineno)
    return graph


def find_cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """One cycle (as a closed path) per strongly connected component with more than one module."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    sccs: list[list[str]] = []
    counter = [0]

    def strongconnect(v: str) -> None:  # Tarjan; the package has ~100 modules, recursion is fine
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                sccs.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strongconnect(v)

    cycles = []
    for comp in sccs:
        members = set(comp)
        start = comp[0]
        # shortest path start -> ... -> start inside the component (BFS)
        prev = {start: None}
        queue = [start]
        end = None
        while queue and end is None:
            nxt = []
            for v in queue:
                for w in sorted(graph[v]):
                    if w not in members:
                        continue
                    if w == start:
                        end = v
                        break
                    if w not in prev:
                        prev[w] = v
                        nxt.append(w)
                if end is not None:
                    break
            queue = nxt
        path = [start]
        v = end
        while v is not None and v != start:
            path.append(v)
            v = prev[v]
        path = [start] + path[1:][::-1] + [start]
        cycles.append(path)
    return cycles


def _describe(graph, cycle: list[str]) -> str:
    return " -> ".join(f"{a} (line {graph[a][b]})" for a, b in zip(cycle, cycle[1:])) + f" -> {cycle[-1]}"


def test_graph_sees_known_imports():
    graph = import_graph()
    assert len(graph) > 20
    assert "gevi_cli.geometry" in graph["gevi_cli.estimators"]  # relative `from gevi_cli.geometry import ...`
    assert "gevi_cli.simulate.constants" in graph["gevi_cli.simulate.generate"]
    # a lazy import (inside a function) is not an edge, unless asked for
    assert "gevi_cli.simulate.writers" not in graph["gevi_cli.simulate.generate"]
    assert "gevi_cli.simulate.writers" in import_graph(include_lazy=True)["gevi_cli.simulate.generate"]


def test_find_cycles_reports_a_cycle():
    g = {"a": {"b": 1}, "b": {"c": 2}, "c": {"a": 3, "d": 4}, "d": {}}
    assert find_cycles(g) == [["a", "b", "c", "a"]]
    assert find_cycles({"a": {"b": 1}, "b": {}}) == []


def test_estimators_do_not_import_studies():
    """The estimator library is pure: not even a lazy import of the study package."""
    graph = import_graph(include_lazy=True)
    bad = {m: sorted(t for t in deps if t.startswith("gevi_cli.studies"))
           for m, deps in graph.items() if m.startswith("gevi_cli.estimators")}
    assert not {m: d for m, d in bad.items() if d}


def test_no_import_cycle():
    graph = import_graph()
    cycles = find_cycles(graph)
    assert not cycles, "import cycles in gevi_cli (module-level imports):\n" + "\n".join(
        _describe(graph, c) for c in cycles)
