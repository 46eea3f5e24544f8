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


def test_the_documented_submodules_are_reachable_from_the_package_alone():
    """docs/guide.md writes `warpfric.io.write_ensemble(...)` after `import warpfric as wf`: each
    documented submodule is an attribute of the package without its own import statement (a fresh
    interpreter, so that no other test has imported it first)."""
    import subprocess
    import sys

    code = ("import sys, warpfric as wf; "
            "assert 'warpfric.io' not in sys.modules; "
            "print(wf.io.write_ensemble.__module__, wf.sweep.__name__, wf.sensitivity.__name__, wf.plots.__name__, "
            "wf.fronts.__name__); "
            "getattr(wf, 'no_such_module')")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.stdout.split() == ["warpfric.io", "warpfric.sweep", "warpfric.sensitivity", "warpfric.plots",
                                  "warpfric.fronts"], run.stderr
    assert "AttributeError: module 'warpfric' has no attribute 'no_such_module'" in run.stderr
