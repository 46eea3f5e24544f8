"""Solver(method='esdirk4'): ESDIRK4(3)6L[2]SA in both kernels (docs/model.md, "Time
integration"). mu_s converges to the same float64 reference as TR-BDF2 (a tight TR-BDF2 run) and
needs fewer Newton iterations at equal error; the new parameter is validated."""

import numpy as np
import pytest

import warpfric as wf
from conftest import DEVICE, REFACTOR_MEMBERS

N = 30


def run(method, rtol, gate):
    ds = wf.simulate(model=wf.Model(relaxation_gate=gate), solver=wf.Solver(nodes=N, rtol=rtol, method=method, max_steps=10**6),
                     fronts=None, device=DEVICE, progress=False)
    assert str(ds.status.values[0]) in ("ok", "0")
    return float(ds.mu_s[0]), int(ds.newton_iterations[0])


def rel(a, b):
    return abs(a - b) / abs(b)


def test_method_validation():
    with pytest.raises(ValueError, match="'method' = 'rk4'.*'tr_bdf2' or 'esdirk4'"):
        wf.Solver(method="rk4")
    assert wf.Solver(method="esdirk4", lanes=1).method == "esdirk4"
    assert wf.Solver().method == "tr_bdf2"
    with pytest.raises(ValueError, match="'event' = 'velocity' is invalid with solver setting 'method' = 'esdirk4'"):
        wf.simulate(solver=wf.Solver(nodes=N, method="esdirk4"), fronts=wf.Fronts(event="velocity"), device=DEVICE,
                    progress=False)


@pytest.mark.parametrize("gate", ["none", "stress"])
def test_cooperative_kernel_agrees_with_the_thread_kernel(gate):
    """ESDIRK4 on a team of 4 and of 7 lanes (CPU fibers) against one thread per member: the same
    steps and mu_s to 1e-12 (only the order of the team's sums differs), the members of
    studies/outputs_equal.py, lift-off at e = 0.6 included."""
    import warnings

    members = REFACTOR_MEMBERS
    runs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the CPU-fibers warning of lanes > 1
        for lanes in (1, 4, 7):
            runs[lanes] = wf.simulate(members, model=wf.Model(relaxation_gate=gate),
                                      solver=wf.Solver(nodes=30, rtol=1e-6, method="esdirk4", lanes=lanes),
                                      fronts=None, device=DEVICE, progress=False)
    for lanes in (4, 7):
        assert runs[lanes].attrs["lanes"] == lanes
        assert (runs[lanes].status.values == 0).all()
        np.testing.assert_array_equal(runs[lanes].steps_accepted.values, runs[1].steps_accepted.values)
        np.testing.assert_allclose(runs[lanes].mu_s.values, runs[1].mu_s.values, rtol=0, atol=1e-12)


def test_tableau_order_conditions():
    """The tableau as typed: row sums = c, b = last row (stiffly accurate), order-4 conditions of b,
    order-3 conditions of b_hat."""
    from warpfric.kernels import esdirk as e

    A, b, bh, c = np.array(e.E4_A), np.array(e.E4_B), np.array(e.E4_B_HAT), np.array(e.E4_C)
    np.testing.assert_allclose(A.sum(1), c, atol=1e-15)
    np.testing.assert_array_equal(A[-1], b)
    for w, order in ((b, 4), (bh, 3)):
        conds = [w.sum() - 1, w @ c - 1 / 2, w @ c**2 - 1 / 3, w @ A @ c - 1 / 6]
        if order == 4:
            conds += [w @ c**3 - 1 / 4, (w * c) @ A @ c - 1 / 8, w @ A @ c**2 - 1 / 12, w @ A @ A @ c - 1 / 24]
        np.testing.assert_allclose(conds, 0, atol=1e-12)


def test_gateless_converges_with_fewer_newton_iterations():
    """Gate-less law, N = 30: both methods against TR-BDF2 at rtol 1e-9; ESDIRK4 at rtol 1e-6 is at
    least as accurate as TR-BDF2 at 1e-7 (9.1e-8 against 1.3e-7) with fewer Newton iterations, and
    its error falls with rtol. The share moves with TR-BDF2's velocity error filter, which ESDIRK4's
    steps here hardly feel: 870 against 1,613 iterations (0.54) on this CPU with the default
    Solver.error_filter_nodes 800, against 2,255 (0.386) with 200 and 0.174 with every grid's own
    filter (where the bounds were 0.5 and 0.4)."""
    ref, _ = run("tr_bdf2", 1e-9, "none")
    tr, tr_newton = run("tr_bdf2", 1e-7, "none")
    e5, _ = run("esdirk4", 1e-5, "none")
    e6, e6_newton = run("esdirk4", 1e-6, "none")
    e7, _ = run("esdirk4", 1e-7, "none")
    print(f"ref {ref:.12f}; tr 1e-7 {rel(tr, ref):.2e} ({tr_newton}); esdirk4 1e-5/6/7 {rel(e5, ref):.2e} "
          f"{rel(e6, ref):.2e} ({e6_newton}) {rel(e7, ref):.2e}")
    assert rel(e6, ref) <= rel(tr, ref)
    assert e6_newton < 0.6 * tr_newton
    assert rel(e7, ref) < rel(e5, ref)
    assert rel(e7, ref) < 5e-8


def test_stress_gate_converges():
    """Stress gate, N = 30: ESDIRK4 converges to the TR-BDF2 reference (rtol 1e-9). Its error is not
    monotone in rtol between 1e-6 and 1e-7 (docs/model.md, "Time integration"): only the ends are asserted."""
    ref, _ = run("tr_bdf2", 1e-9, "stress")
    e5, _ = run("esdirk4", 1e-5, "stress")
    e8, _ = run("esdirk4", 1e-8, "stress")
    print(f"ref {ref:.12f}; esdirk4 1e-5 {rel(e5, ref):.2e}, 1e-8 {rel(e8, ref):.2e}")
    assert rel(e5, ref) < 1e-5
    assert rel(e8, ref) < 1e-7


@pytest.mark.parametrize("dtype,gate", [("float32", "none"), ("float64", "velocity")])
def test_other_dtype_and_gate(dtype, gate):
    """float32 and the velocity gate run with ESDIRK4 and agree with TR-BDF2 within the tolerance."""
    kw = dict(model=wf.Model(relaxation_gate=gate), fronts=None, device=DEVICE, progress=False)
    ref = float(wf.simulate(solver=wf.Solver(nodes=N, rtol=1e-7), **kw).mu_s[0])
    ds = wf.simulate(solver=wf.Solver(nodes=N, rtol=1e-4, method="esdirk4", dtype=dtype), **kw)
    assert int(ds.status.values[0]) == 0
    assert rel(float(ds.mu_s[0]), ref) < 2e-4
