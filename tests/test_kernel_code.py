"""The shape of the integrate kernel's code, where it decides the GPU's speed (docs/performance.md,
"GPU: where the time goes"): the stage code (Newton solve, stage derivatives) has one call site,
so that CUDA compiles it once instead of inlining a copy per stage, the benchmark switches of
its compilation are validated, and a run compiles only the observers it may use. The call-site
tests compile nothing (they read the Python source the kernel is built from); the observers' test
runs the engine on the CPU."""

import ast
import inspect
import textwrap

import pytest

import warpfric as wf
from warpfric.kernels.integrator import TeamCompileOptions, device_functions, get_integrator, team_compile_options


def esdirk4_only(node):
    """An ``if wp.static(esdirk4):`` block: compiled only for Solver(method='esdirk4')."""
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Call) and isinstance(test.func, ast.Attribute) and test.func.attr == "static"
            and len(test.args) == 1 and isinstance(test.args[0], ast.Name) and test.args[0].id == "esdirk4")


def calls(node, name):
    """Calls of ``name`` under an AST node, but in the branches compiled for ESDIRK4 only."""
    if esdirk4_only(node):
        return sum(calls(child, name) for child in node.orelse)
    here = isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == name
    return int(here) + sum(calls(child, name) for child in ast.iter_child_nodes(node))


def call_sites(kernel, name):
    """Calls of the device function ``name`` in the TR-BDF2 kernel's source and in every device
    function it reaches."""
    sources = [kernel.func] + [fn.func for fn in device_functions(kernel)]
    return sum(calls(ast.parse(textwrap.dedent(inspect.getsource(py))), name) for py in sources)


@pytest.mark.parametrize("lanes", [1, 4])
def test_the_stage_code_has_one_call_site(lanes):
    """TR-BDF2's two stages and the backward-Euler restart share one Newton solve and one
    stage-derivative evaluation (esdirk.implicit_step); the kernel calls the stepper once."""
    integrate = get_integrator("float64", wf.Model(), lanes=lanes)["integrate"]
    assert call_sites(integrate, "implicit_step") == 1
    assert call_sites(integrate, "newton_solve") == 1
    assert call_sites(integrate, "stage_derivatives") == 1
    assert call_sites(integrate, "node_row") == 1  # the Newton iteration's node loop


def test_compile_switches_are_validated_and_applied(monkeypatch):
    monkeypatch.setenv("WARPFRIC_INLINE", "sometimes")
    with pytest.raises(ValueError, match="WARPFRIC_INLINE='sometimes' is invalid; valid: 'force', 'never'"):
        team_compile_options()
    monkeypatch.delenv("WARPFRIC_INLINE")
    monkeypatch.setenv("WARPFRIC_NOINLINE", "newton_solve")
    assert team_compile_options() == TeamCompileOptions(out_of_line=("newton_solve",))
    monkeypatch.setenv("WARPFRIC_TEAM_MAX_REGISTERS", "168")
    assert team_compile_options() == TeamCompileOptions(max_registers=168, out_of_line=("newton_solve",))
    monkeypatch.delenv("WARPFRIC_TEAM_MAX_REGISTERS")
    integrate = get_integrator("float64", wf.Model(relaxation_gate="velocity"), lanes=4)["integrate"]
    hints = {fn.func.__name__: fn.inline_hint for fn in device_functions(integrate)}
    assert hints["newton_solve"] == "noinline"
    assert hints["stage_derivatives"] is None and hints["node_row"] is None


def test_compile_switches_do_not_leak_into_later_builds(monkeypatch):
    """A switch marks shared functions too (team.settle, the load protocol): the next request
    undoes it, cached kernels included, so a kernel asked for without the switch compiles with the
    compiler's own choices."""
    get_integrator("float64", wf.Model(relaxation_gate="none"), lanes=1)  # cached before the switch
    monkeypatch.setenv("WARPFRIC_INLINE", "never")
    team = get_integrator("float64", wf.Model(relaxation_gate="none"), lanes=8)["integrate"]
    assert all(fn.inline_hint == "noinline" for fn in device_functions(team))
    monkeypatch.delenv("WARPFRIC_INLINE")
    thread = get_integrator("float64", wf.Model(relaxation_gate="none"), lanes=1)["integrate"]
    assert [fn.func.__name__ for fn in device_functions(thread) if fn.inline_hint is not None] == []
    monkeypatch.setenv("WARPFRIC_INLINE", "never")
    get_integrator("float64", wf.Model(relaxation_gate="none"), lanes=8)  # cached now: the hints come back
    monkeypatch.delenv("WARPFRIC_INLINE")
    get_integrator("float64", wf.Model(relaxation_gate="none"), lanes=1)  # cached too: undone again
    assert [fn.func.__name__ for fn in device_functions(thread) if fn.inline_hint is not None] == []


def test_a_run_compiles_only_the_observers_it_may_use(monkeypatch):
    """engine.observer_set: the velocity and strength fronts are compiled into a run's kernel only
    where its front events include them (the recording always: a sweep's chunks with and without
    recorded members share one kernel), and leaving them out changes no output (the same members
    with every observer compiled in: bit for bit equal, a recorded member and the contact front
    included)."""
    import numpy as np

    from warpfric import engine
    from warpfric.kernels.observers import ObserverSet

    record = wf.Record.window(20.1, 20.3, 5, members=(1,))
    assert engine.observer_set(None) == ObserverSet(False, False)
    assert engine.observer_set(wf.Fronts()) == ObserverSet(False, False)  # contact: kernels/gates.py
    assert engine.observer_set(wf.Fronts(event="velocity")) == ObserverSet(True, False)
    assert engine.observer_set(wf.Fronts(event="strength")) == ObserverSet(False, True)
    members = {"eccentricity": [0.0, -0.2]}

    def run_with(observed_all):
        if observed_all:
            monkeypatch.setattr(engine, "observer_set", lambda fronts: ObserverSet())
        ds = wf.simulate(members, solver=wf.Solver(nodes=12), fronts=wf.Fronts(), record=record, device="cpu",
                         progress=False)
        monkeypatch.undo()
        return ds

    pruned, full = run_with(False), run_with(True)
    for name in ("mu_s", "mu_s_time", "v_main", "front_start_time", "steps_accepted", "newton_iterations"):
        np.testing.assert_array_equal(pruned[name].values, full[name].values)
    recorded = [name for name in full.data_vars if "time" in full[name].dims and "x" in full[name].dims]
    assert recorded, "the recorded member's fields are in the Dataset"
    for name in recorded:
        np.testing.assert_array_equal(pruned[name].values, full[name].values)
