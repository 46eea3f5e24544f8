"""No module of warpfric imports a module that imports it back (function-level imports count): a
circle makes the import order matter and hides which module owns what."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "warpfric"
CHECKED = ("cli", "io", "members", "parameters", "runner", "sweep", "sweep_file", "sensitivity")


def _imports() -> dict:
    modules = {p.stem for p in PACKAGE.glob("*.py")}
    graph = {}
    for path in PACKAGE.glob("*.py"):
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 1:
                deps |= {node.module.split(".")[0]} if node.module else {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("warpfric."):
                deps.add(node.module.split(".")[1])
        graph[path.stem] = deps & modules
    return graph


def _reaches(graph, start, goal) -> bool:
    seen, todo = set(), [start]
    while todo:
        node = todo.pop()
        if node == goal:
            return True
        if node not in seen:
            seen.add(node)
            todo.extend(graph.get(node, ()))
    return False


def test_no_import_circles_through_the_sweep_and_file_modules():
    graph = _imports()
    assert {"runner", "sweep_file"} <= graph["sweep"] and "sweep_file" in graph["runner"]
    circles = [(a, b) for a in CHECKED for b in graph[a] if _reaches(graph, b, a)]
    assert circles == [], circles


def test_no_import_circles_anywhere_in_the_package():
    """Every module, the engine's path included: simulate, fronts, pool and device."""
    graph = _imports()
    assert "device" in graph["simulate"] and "device" in graph["fronts"] and "simulate" not in graph["pool"]
    modules = [m for m in graph if m != "__init__"]
    circles = [(a, b) for a in modules for b in graph[a] if _reaches(graph, b, a)]
    assert circles == [], circles
