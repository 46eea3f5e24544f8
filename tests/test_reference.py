"""An independent float64 reference: the same semi-discrete equations written as a plain NumPy
right-hand side (studies/baseline_scipy.py, from docs/model.md, not from the kernels) and
integrated by scipy's BDF. warpfric must converge to the same solution."""

import sys
from dataclasses import replace as dataclasses_replace
from pathlib import Path

import numpy as np
import pytest
from conftest import DEVICE

import warpfric as wf

pytest.importorskip("scipy")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
from baseline_scipy import run_scipy as _run_scipy  # noqa: E402

_REFERENCES: dict = {}


def run_scipy(scene, n, rtol, model, **options):
    """baseline_scipy.run_scipy, each reference integrated once in a session: the heavy undamped pad
    serves both cases of the inertia test (~14 s of scipy BDF on a 2-core CPU)."""
    key = (scene, n, rtol, model, tuple(sorted(options.items())))
    if key not in _REFERENCES:
        _REFERENCES[key] = _run_scipy(scene, n, rtol, model, **options)
    return _REFERENCES[key]


@pytest.mark.parametrize("gate", ["none", "stress", "velocity"])
def test_warpfric_agrees_with_scipy_bdf_on_the_same_equations(gate):
    """For the stress gate the reference smooths the Heaviside (relative width 1e-4 of tau_c*A): the
    kernels' located sharp switches must agree with it as closely as with the smooth laws."""
    scene = wf.Parameters(end_time=20.4, eccentricity=0.2, normal_force=2000.0)
    n = 9
    model = wf.Model(relaxation_gate=gate)
    ref = run_scipy(scene, n, 1e-8, model, gate_width=1e-4)
    ds = wf.simulate(scene=scene, model=model, solver=wf.Solver(nodes=n, rtol=1e-10, max_steps=10**6), fronts=None,
                     device=DEVICE, progress=False)
    assert abs(float(ds.mu_s[0]) / ref["mu_s"] - 1) < 1e-6
    assert abs(float(ds.mu_s_time[0]) - ref["mu_s_time"]) < 1e-4
    y = ref["final_state"]
    u, v, tau, phi = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
    np.testing.assert_allclose(ds.displacement.values[0], u, rtol=1e-5, atol=1e-5 * np.abs(u).max())
    np.testing.assert_allclose(ds.elastic_stress.values[0], tau, rtol=1e-5, atol=1e-5 * np.abs(tau).max())
    np.testing.assert_allclose(ds.contact_age.values[0], phi, rtol=1e-5)
    np.testing.assert_allclose(ds.velocity.values[0], v, rtol=1e-3, atol=1e-3 * np.abs(v).max())


def test_smoothed_gate_converges_to_the_located_sharp_gate():
    """The scipy reference with a smooth gate of relative width w tends to warpfric's sharp gate as
    w -> 0 (measured: 8.5e-4, 2.3e-5, 1.2e-7 for w = 1e-2, 1e-3, 1e-4), and the gate matters: the
    gate-less law differs by percents."""
    scene = wf.Parameters(end_time=20.4, eccentricity=0.2, normal_force=2000.0)
    n = 9
    ds = wf.simulate(scene=scene, solver=wf.Solver(nodes=n, rtol=1e-10, max_steps=10**6), fronts=None,
                     device=DEVICE, progress=False)
    gaps = [abs(float(ds.mu_s[0]) / run_scipy(scene, n, 1e-8, wf.Model(), gate_width=w)["mu_s"] - 1) for w in (1e-2, 1e-3)]
    assert gaps[1] < gaps[0] / 10
    none = run_scipy(scene, n, 1e-8, wf.Model(relaxation_gate="none"))
    assert abs(float(ds.mu_s[0]) / none["mu_s"] - 1) > 0.01


@pytest.mark.parametrize("damping", [0.0, 3e8])
def test_warpfric_agrees_with_scipy_bdf_where_the_pad_s_inertia_matters(damping):
    """In the scene above the pad is quasi-static (its free mode rings at ~41 us), so the inertia term
    rho*H*dV/dt could be 100x too large or too small and the comparison above still passed (a
    mutation audit). With the density raised 1e6-fold (mode period ~41 ms, on the scale of the
    detachment) the gate-less law's mu_s moves 1.7e-5 from the quasi-static one, 17x this test's
    tolerance, and warpfric must follow the reference there (measured: 8.6e-9). The damping term,
    checked before only through a member's status, is too: damping = 3e8 Pa s/m moves mu_s 1.8e-5
    from the undamped pad's (measured agreement 3.8e-9). The protocol is ten times shorter than the
    paper's (the force ramped over 1 s, the disc started at 2 s): the undamped heavy pad rings all
    through it, and scipy's BDF at rtol 1e-8 takes 14 s for the short protocol against 78 s for the
    paper's 20 s (2-core CPU), where the inertia moved mu_s 3.6e-5 and a damping of 1e8 Pa s/m 1.9e-5
    (9.2e-6 in the short protocol)."""
    n = 9
    model = wf.Model(relaxation_gate="none")
    heavy = wf.Parameters(force_ramp_time=1.0, rest_until=2.0, end_time=2.4, eccentricity=0.2, normal_force=2000.0,
                          density=1.2e9, damping=damping)
    ref = run_scipy(heavy, n, 1e-8, model)
    # the term matters here: without it (quasi-static pad; undamped) mu_s is elsewhere
    without = dataclasses_replace(heavy, density=1200.0) if damping == 0 else dataclasses_replace(heavy, damping=0.0)
    assert abs(ref["mu_s"] / run_scipy(without, n, 1e-8, model)["mu_s"] - 1) > 1e-5
    ds = wf.simulate(scene=heavy, model=model, solver=wf.Solver(nodes=n, rtol=1e-10, max_steps=10**6), fronts=None,
                     device=DEVICE, progress=False)
    assert abs(float(ds.mu_s[0]) / ref["mu_s"] - 1) < 1e-6
    assert abs(float(ds.mu_s_time[0]) - ref["mu_s_time"]) < 1e-4
    u = ref["final_state"][:n]
    np.testing.assert_allclose(ds.displacement.values[0], u, rtol=1e-5, atol=1e-5 * np.abs(u).max())
