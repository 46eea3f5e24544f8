"""An independent float64 reference: the same semi-discrete equations written as a plain NumPy
right-hand side (studies/baseline_scipy.py, from docs/model.md, not from the kernels) and
integrated by scipy's BDF. warpfric must converge to the same solution."""

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DEVICE

import warpfric as wf

pytest.importorskip("scipy")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
from baseline_scipy import run_scipy  # noqa: E402


def test_warpfric_agrees_with_scipy_bdf_on_the_same_equations():
    scene = wf.Parameters(end_time=20.4, eccentricity=0.2, normal_force=2000.0)
    n = 9
    ref = run_scipy(scene, n, 1e-8)
    ds = wf.simulate(scene=scene, solver=wf.Solver(nodes=n, rtol=1e-10, max_steps=10**6), fronts=None,
                     device=DEVICE, progress=False)
    assert abs(float(ds.mu_s[0]) / ref["mu_s"] - 1) < 1e-6
    assert abs(float(ds.mu_s_time[0]) - ref["mu_s_time"]) < 1e-4
    y = ref["final_state"]
    u, v, tau, phi = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
    np.testing.assert_allclose(ds.displacement.values[0], u, rtol=1e-5, atol=1e-5 * np.abs(u).max())
    np.testing.assert_allclose(ds.elastic_stress.values[0], tau, rtol=1e-5, atol=1e-5 * np.abs(tau).max())
    np.testing.assert_allclose(ds.contact_age.values[0], phi, rtol=1e-5)
    np.testing.assert_allclose(ds.velocity.values[0], v, rtol=1e-3, atol=1e-3 * np.abs(v).max())
