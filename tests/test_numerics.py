"""Convergence, precision, hard cases and the health of the implicit solver."""

import numpy as np
import pytest
from conftest import run

import warpfric as wf


@pytest.fixture(scope="module")
def reference():
    """float64, N = 40, rtol = 1e-9: the time-converged reference of mu_s on the default scene."""
    return run(nodes=40, rtol=1e-9, max_steps=10**6)


def test_mu_s_converges_with_tolerance(reference):
    """Global error of an order-2 method under local error control scales as rtol^(2/3)."""
    mu_ref = reference.mu_s.values[0]
    rtols = np.array([1e-5, 1e-6, 1e-7])
    errors = np.array([abs(run(nodes=40, rtol=r).mu_s.values[0] / mu_ref - 1) for r in rtols])
    order = np.polyfit(np.log10(rtols), np.log10(errors), 1)[0]
    print(f"mu_s relative errors {errors}, observed order in rtol {order:.2f}")
    assert np.all(np.diff(errors) < 0)
    assert 0.45 < order < 1.0
    assert errors[0] < 1e-5  # the default rtol (1e-5) is well inside the 1e-4 target


@pytest.mark.parametrize("gate, min_order", [("none", 1.5), ("stress", 1.1)])
def test_mu_s_converges_with_grid(gate, min_order):
    """Second-order finite volumes: successive differences of mu_s shrink ~4x per halving of dx with
    the smooth (gate-less) law. With the stress gate each node yields at its own time and the grid
    samples the yielding zone node by node; the observed order is lower (1.27, 1.38 measured at
    N = 10..80), still above first order."""
    model = wf.Model(relaxation_gate=gate)
    mus = np.array([run(nodes=n, rtol=1e-8, model=model).mu_s.values[0] for n in (10, 20, 40, 80)])
    diffs = np.abs(np.diff(mus))
    orders = np.log2(diffs[:-1] / diffs[1:])
    print(f"{gate}: mu_s {mus}, observed spatial orders {orders}")
    assert np.all(orders > min_order)


def test_float32_agrees_with_float64():
    """At rtol = 1e-5 both precisions resolve mu_s far below the 1e-4 target; float32 round-off
    (eps = 6e-8, amplified by the cancellations of the second difference) adds < 1e-5."""
    members = {"eccentricity": [-0.2, 0.0, 0.2], "normal_force": [500.0, 1000.0, 5000.0]}
    gateless = wf.Model(relaxation_gate="none")  # the stress gate in float32: tests/test_gate.py
    f64 = run(members, rtol=1e-5, dtype="float64", model=gateless)
    f32 = run(members, rtol=1e-5, dtype="float32", model=gateless)
    assert (f32.status.values == 0).all()
    np.testing.assert_allclose(f32.mu_s.values, f64.mu_s.values, rtol=1e-5)
    np.testing.assert_allclose(f32.mu_s_time.values, f64.mu_s_time.values, atol=1e-3)


def test_hard_cases_end_ok_and_finite():
    hard = {
        "viscous_coefficient": [0.0, 2.7e13, 2.7e13, 2.7e13, 2.7e13],
        "normal_force": [1000.0, 5000.0, 1000.0, 1000.0, 1000.0],
        "eccentricity": [0.0, 0.0, 0.3, -0.3, 0.0],
        "stop_time": [np.inf, np.inf, np.inf, np.inf, 20.15],
    }
    # eta = 0 is a dynamic rupture under the stress gate (more steps): not a straggler here
    ds = run(hard, rtol=1e-5, scene=wf.Parameters(end_time=22.0), stall_factor=float("inf"))
    meanings = ds.status.attrs["flag_meanings"].split()
    # the stop (20.15 s) comes before the peak of the uninterrupted run (20.23 s): mu was still
    # rising, so its largest value, at the stop, is no mu_s (it was reported as one, status ok)
    assert [meanings[k] for k in ds.status.values] == ["ok"] * 4 + ["no_peak"]
    assert np.isfinite(ds.mu_s.values[:4]).all() and np.isfinite(ds.mu_s_time.values[:4]).all()
    assert np.isnan(ds.mu_s.values[4]) and np.isnan(ds.mu_s_time.values[4])
    for name in ("displacement", "velocity", "friction_stress", "normal_stress", "mu_final"):
        assert np.isfinite(ds[name].values).all(), name
    # 1.85 s after the sudden stop the pad is at rest (it moves at ~1e-7 m/s while driven)
    assert abs(ds.velocity.values[4]).max() < 1e-9


INVISCID = {"eccentricity": [0.0], "normal_force": [1000.0], "viscous_coefficient": [0.0]}


@pytest.mark.parametrize("lanes", [1, 4])
def test_coarse_grids_filter_the_velocity_error_as_the_finer_grid_does(lanes):
    """Solver.error_filter_nodes: the velocity error estimate's filter takes the elastic diagonal of
    a grid of Solver().error_filter_nodes (800) nodes where the grid is coarser. Without it (0: the
    grid's own, which grows as N^2) a member without velocity strengthening resolves the pad's
    low-mode ringing that every gate opening kicks: 85,116 attempts at N = 20; with it N = 20 takes
    317 and N = 200 364 (470 and 523 with the filter of 200), and its mu_s moves by the tolerance's
    order only (1.6e-6 here). Both kernels: the thread kernel and a team of 4 lanes
    (docs/performance.md, "Known limits")."""
    def attempts_and_mu(nodes, **kw):
        ds = run(INVISCID, nodes=nodes, rtol=1e-5, max_steps=300_000, stall_factor=float("inf"), lanes=lanes, **kw)
        assert ds.status.values[0] == 0
        return int(ds.steps_accepted[0] + ds.steps_rejected[0]), float(ds.mu_s[0])

    own, mu_own = attempts_and_mu(20, error_filter_nodes=0)
    coarse, mu_coarse = attempts_and_mu(20)
    fine, mu_fine = attempts_and_mu(200) if lanes == 1 else (None, None)
    assert own > 50 * coarse
    if fine is not None:
        assert coarse <= 1.2 * fine
        assert abs(mu_fine / mu_coarse - 1) < 1e-5  # the grid's own error at N = 20 is that small here
    assert abs(mu_coarse / mu_own - 1) < 1e-5


@pytest.mark.parametrize("dtype, method, lanes, gate", [
    ("float64", "tr_bdf2", 1, "stress"), ("float64", "esdirk4", 1, "stress"), ("float64", "tr_bdf2", 4, "stress"),
    ("float64", "esdirk4", 4, "stress"), ("float32", "tr_bdf2", 1, "none")])
def test_the_velocity_error_filter_changes_nothing_on_grids_at_least_as_fine(dtype, method, lanes, gate):
    """error_filter_nodes at or below the grid's nodes leaves every output bit for bit (the filter's
    extra stiffness is exactly 0 there), in each build that has the filter (TR-BDF2 and ESDIRK4, the
    thread kernel and a team, float32 under the gate-less law that allows it); one node more changes
    the step sizes (ESDIRK4 keeps its step counts here, and its mu_s moves by 4e-12)."""
    model = wf.Model(relaxation_gate=gate)
    fronts = wf.Fronts(event="contact" if gate == "stress" else "strength")

    def outputs(**kw):
        return run(INVISCID, nodes=40, rtol=1e-5, max_steps=300_000, stall_factor=float("inf"), model=model,
                   fronts=fronts, dtype=dtype, method=method, lanes=lanes, **kw)

    own = outputs(error_filter_nodes=0)
    for same in (outputs(error_filter_nodes=40), outputs(error_filter_nodes=3)):
        for name in ("mu_s", "mu_s_time", "steps_accepted", "steps_rejected", "arrival_time", "velocity"):
            np.testing.assert_array_equal(same[name].values, own[name].values, err_msg=name)
    finer = outputs(error_filter_nodes=41)  # the filter is in the build: one node more moves the steps
    assert finer.mu_s.values[0] != own.mu_s.values[0]


LOADED_FAST = {"eccentricity": [-0.5532169907603456], "normal_force": [91108.68726784074],
               "disc_velocity": [0.10693808344323688]}  # a member of a wide random sample: F*|v| ~ 2e4 x the default scene's


@pytest.mark.parametrize("method", ["tr_bdf2", "esdirk4"])
def test_a_loaded_pad_with_a_fast_disc_converges_from_the_disc_start(method):
    """F = 91 kN, 2e/L = -0.55, v = 0.107 m/s (N = 30): the member's velocity scale u_scale*v/D
    (2 m/s) let a velocity error of 1.2e-6 m/s through the disc's first step, which moved an edge
    node's viscous stress, logarithmic in the slip rate near v*, by 220 kPa: the node opened 11 us
    after the disc started, against 1.85 ms at rtol 1e-7, and the front nucleated at the other edge
    (v_first 1.7 against 4.6 m/s). Capped at 10 hardness/eta in contact (Solver.viscous_velocity_cap),
    rtol 1e-5 finds rtol 1e-7's nucleation, first opening, v_first and mu_s."""
    fronts = wf.Fronts()
    loose = run(LOADED_FAST, nodes=30, rtol=1e-5, method=method, fronts=fronts)
    tight = run(LOADED_FAST, nodes=30, rtol=1e-7, fronts=fronts)
    for ds in (loose, tight):
        assert ds.status.values[0] == 0
    assert loose.nucleation_position.values[0] == tight.nucleation_position.values[0]
    first = [np.nanmin(ds.yield_time.values[0]) - 20.0 for ds in (loose, tight)]
    print(method, "first opening after the disc start (ms) at rtol 1e-5, 1e-7:", np.array(first) * 1e3)
    assert abs(first[0] - first[1]) < 1e-5
    np.testing.assert_allclose(loose.v_first.values, tight.v_first.values, rtol=0.05)
    np.testing.assert_allclose(loose.mu_s.values, tight.mu_s.values, rtol=1e-4)


def test_the_viscous_velocity_cap_leaves_members_below_it_bit_for_bit():
    """Members whose velocity scale is below the cap (the default scene, and the benchmark's
    heaviest load, 5 kN, with v = 1e-4 m/s) run bit for bit as with the cap off (inf), under both
    methods; the loaded pad with a fast disc does not."""
    below = {"eccentricity": [0.0, 0.2], "normal_force": [1000.0, 5000.0]}
    for method in ("tr_bdf2", "esdirk4"):
        on, off = (run(below, nodes=30, rtol=1e-5, method=method, fronts=wf.Fronts(), viscous_velocity_cap=cap)
                   for cap in (10.0, float("inf")))
        for name in ("mu_s", "mu_s_time", "steps_accepted", "steps_rejected", "arrival_time", "newton_iterations"):
            if name in on:
                np.testing.assert_array_equal(on[name].values, off[name].values, err_msg=f"{method} {name}")
    on, off = (run(LOADED_FAST, nodes=30, rtol=1e-5, viscous_velocity_cap=cap) for cap in (10.0, float("inf")))
    assert on.steps_accepted.values[0] != off.steps_accepted.values[0]


def test_newton_converges_quadratically():
    """An exact Jacobian needs about two Newton iterations per implicit stage (full protocol to 22 s)."""
    ds = run(rtol=1e-6, scene=wf.Parameters(end_time=22.0))
    stages = 2 * ds.steps_accepted.values[0]
    assert ds.newton_iterations.values[0] / stages < 3.0


def test_float32_members_reach_the_ramp_end():
    """Regression: these float32 members (from the 10,000-member benchmark, N = 200) stalled just
    before the velocity ramp's end when a step clipped to the breakpoint left a sliver; the last
    two steps before a breakpoint are now split evenly."""
    members = {
        "eccentricity": [0.06802473972597439, -0.01916448466915663, 0.075313056446496, -0.16269441192618112],
        "normal_force": [2449.158389218588, 1436.6277291857823, 637.7688105267864, 1401.0899504810648],
    }
    gateless = wf.Model(relaxation_gate="none")  # a regression of the ramp-end sliver, law-independent
    f32 = run(members, nodes=200, rtol=1e-5, dtype="float32", max_steps=3000, model=gateless)
    f64 = run(members, nodes=200, rtol=1e-5, dtype="float64", model=gateless)
    assert list(f32.status.values) == [0, 0, 0, 0]
    assert (f32.steps_accepted.values + f32.steps_rejected.values).max() < 600
    np.testing.assert_allclose(f32.mu_s.values, f64.mu_s.values, rtol=1e-5)
