import os

import numpy as np
import pytest

import warpfric as wf

# CPU by default (CI); WARPFRIC_TEST_DEVICE=cuda:0 runs the same assertions on a GPU
DEVICE = os.environ.get("WARPFRIC_TEST_DEVICE", "cpu")

# the members of studies/outputs_equal.py: e = 0, -0.2 (1000 N), 0.3 (300 N), 0.6 (3000 N: lift-off)
REFACTOR_MEMBERS = {"eccentricity": [0.0, -0.2, 0.3, 0.6], "normal_force": [1000.0, 1000.0, 300.0, 3000.0]}

# a sweep file of three tiny members without fronts, for the command-line tests
TINY_SWEEP = """
fronts = false
[solver]
nodes = 11
[grid]
eccentricity = [-0.2, 0.0, 0.2]
"""


def run_cli(capsys, *args):
    """warpfric's main() in this process (no interpreter start-up): (exit code, stdout lines, stderr
    lines)."""
    from warpfric.cli import main

    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out.strip().splitlines(), err.strip().splitlines()


def one_line_error(err, *words):
    """stderr is one line, warpfric's error line, and it names each of ``words``."""
    assert len(err) == 1 and err[0].startswith("warpfric: error:"), err
    for word in words:
        assert word in err[0], (word, err[0])


def run(members=None, *, scene=None, model=None, nodes=40, rtol=1e-6, dtype="float64", fronts=None,
        record=None, **solver_kw):
    """simulate on the CPU with small, fast defaults for tests (front metrics off unless asked for:
    they cost a second pass)."""
    return wf.simulate(
        members,
        scene=scene or wf.Parameters(),
        model=model or wf.Model(),
        solver=wf.Solver(nodes=nodes, rtol=rtol, dtype=dtype, **solver_kw),
        fronts=fronts,
        record=record,
        device=DEVICE,
        progress=False,
    )


def moment_weights(x):
    """Exact weights for int x f dx of a piecewise-linear f on the uniform grid x (independent of the
    kernels' implementation: integrates the hat functions analytically)."""
    dx = x[1] - x[0]
    w = x * dx
    w[0] = dx * (x[0] / 2 + dx / 6)
    w[-1] = dx * (x[-1] / 2 - dx / 6)
    return w


def trapezoid_weights(x):
    dx = x[1] - x[0]
    w = np.full_like(x, dx)
    w[0] = w[-1] = dx / 2
    return w


@pytest.fixture
def paper_scene():
    return wf.Parameters()
