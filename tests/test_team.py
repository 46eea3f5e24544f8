"""The cooperative kernel (Solver.lanes > 1: a team of threads per member, kernels/team.py) against
the thread-per-member kernel: the same members, the same law, the same outputs within the error
control (sums are taken in another order, so not bit for bit). On the CPU the team runs on Warp's
cooperative fibers (warp.config.enable_cpu_blocks); WARPFRIC_TEST_DEVICE=cuda:0 runs the same
assertions on a GPU. The partitioned bordered solve alone is tested against numpy in test_kernels.py."""

import numpy as np
import pytest
from conftest import DEVICE, run

import warpfric as wf
from warpfric.engine import AUTO_LANES, AUTO_MIN_NODES, choose_lanes

# the members of studies/outputs_equal.py: e = 0, -0.2 (1000 N), 0.3 (300 N), 0.6 (3000 N: lift-off)
MEMBERS = {"eccentricity": [0.0, -0.2, 0.3, 0.6], "normal_force": [1000.0, 1000.0, 300.0, 3000.0]}


@pytest.mark.parametrize("gate, lanes, fronts", [("none", 4, False), ("stress", 4, True)])
def test_a_team_gives_the_thread_per_member_outputs(gate, lanes, fronts):
    """mu_s, its time and the front speeds of a team of `lanes` threads equal the thread-per-member
    kernel's within 1e-5 relative (the runs' own error control is rtol 1e-5); same statuses; the
    steps taken differ by at most 2 % but for the lift-off member (under the stress gate its located
    switches after the peak take 608 against 842 steps, with mu_s equal to 4e-8) (the final fields are not compared: the automatic end falls at
    slightly different times)."""
    model = wf.Model(relaxation_gate=gate)
    front = wf.Fronts() if fronts else None
    ref = run(MEMBERS, model=model, nodes=30, rtol=1e-5, fronts=front, lanes=1)
    if DEVICE.startswith("cuda"):
        team = run(MEMBERS, model=model, nodes=30, rtol=1e-5, fronts=front, lanes=lanes)
    else:
        with pytest.warns(UserWarning, match="CPU fibers"):  # a team on the CPU is for tests only
            team = run(MEMBERS, model=model, nodes=30, rtol=1e-5, fronts=front, lanes=lanes)
    assert ref.attrs["lanes"] == 1 and team.attrs["lanes"] == lanes
    np.testing.assert_array_equal(team.status.values, ref.status.values)
    assert (ref.status.values == 0).all() and ref.lift_off.values[3] == 1
    np.testing.assert_allclose(team.mu_s.values, ref.mu_s.values, rtol=1e-5)
    np.testing.assert_allclose(team.mu_s_time.values, ref.mu_s_time.values, rtol=1e-5)
    steps, steps_ref = team.steps_accepted.values[:3], ref.steps_accepted.values[:3]  # lift-off: see below
    assert np.all(np.abs(steps - steps_ref) <= 0.02 * steps_ref + 2)
    if fronts:
        for name in ("v_left", "v_middle", "v_right"):
            np.testing.assert_allclose(team[name].values, ref[name].values, rtol=1e-4, equal_nan=True)


def test_lanes_is_validated_and_chosen():
    """Solver.lanes: None, 1 or 2..nodes//2, float64 only; None picks the cooperative kernel on a
    CUDA device in float64 (the largest power of two <= min(32, nodes // 2) lanes, from 16 nodes),
    the thread-per-member kernel otherwise."""
    for bad in (0, 51, 2.0, True):
        with pytest.raises(ValueError, match="lanes"):
            wf.Solver(nodes=100, lanes=bad)
    with pytest.raises(ValueError, match="float64"):
        wf.Solver(nodes=100, lanes=8, dtype="float32")
    assert choose_lanes(wf.Solver(nodes=100, lanes=8), "cpu") == 8
    assert choose_lanes(wf.Solver(nodes=100), "cpu") == 1
    assert choose_lanes(wf.Solver(nodes=200), "cuda:0") == AUTO_LANES == 32
    assert choose_lanes(wf.Solver(nodes=40), "cuda:0") == 16  # a power of two, >= 2 nodes per lane
    assert choose_lanes(wf.Solver(nodes=AUTO_MIN_NODES), "cuda:0") == 8
    assert choose_lanes(wf.Solver(nodes=AUTO_MIN_NODES - 1), "cuda:0") == 1
    assert choose_lanes(wf.Solver(nodes=100, dtype="float32"), "cuda:0") == 1
