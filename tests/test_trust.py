"""Outputs a user can trust: stragglers are stopped and flagged, inputs that cannot run are refused."""

import re
import warnings

import numpy as np
import pytest
import warp as wp

import warpfric as wf
from conftest import DEVICE, run


def test_a_straggler_is_stopped_within_a_bounded_factor_of_its_peers():
    """One member with eta = 0 under the stress gate among healthy ones, on a coarse grid with its own
    velocity error filter (error_filter_nodes=0: the member then resolves the pad's ringing after
    each gate opening, tens of thousands of steps): it is stopped with status 'stalled' and NaN
    mu_s once it needs more than stall_factor times the ensemble's median (itself counted at its
    attempts so far, more than any peer's); the others are untouched."""
    eta = np.full(12, 2.7e13)
    eta[5] = 0.0
    with pytest.warns(UserWarning) as caught:
        ds = run({"viscous_coefficient": eta, "eccentricity": np.linspace(-0.15, 0.15, 12)}, nodes=20, rtol=1e-5,
                 stall_factor=5.0, stall_min_steps=500, steps_per_launch=100, error_filter_nodes=0)
    # one warning says how many members failed, why, and what runs them to their end
    said = [str(w.message) for w in caught if "did not end ok" in str(w.message)]
    assert said == ["members that did not end ok have NaN mu_s and fronts: 1 of 12 members: 1 stalled (stopped by "
                    "the straggler rule after stall_factor = 5 times the attempts of the typical member, or "
                    "stall_min_steps = 500 where that is more: "
                    "Solver(stall_factor=float('inf')), in a sweep file [solver] stall_factor = inf, runs them to "
                    "their end); their numbers: ds.member[ds.status != 0] (docs/model.md, \"Statuses\")"]
    meanings = ds.status.attrs["flag_meanings"].split()
    attempts = ds.steps_accepted.values + ds.steps_rejected.values
    healthy = np.delete(np.arange(12), 5)
    assert meanings[ds.status.values[5]] == "stalled" and np.isnan(ds.mu_s.values[5])
    assert (ds.status.values[healthy] == 0).all() and np.isfinite(ds.mu_s.values[healthy]).all()
    limit = max(500, 5.0 * np.sort(attempts[healthy])[5])  # the lower median of the 12: the straggler the largest
    # the kernel stops it at its first attempt past the limit that the host derived from the peers;
    # the host's read-back runs one launch (100 attempts) behind, so the limit may arrive that late
    assert limit < attempts[5] <= limit + 100
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # every member ends ok: no warning
        alone = run({"viscous_coefficient": eta[healthy], "eccentricity": np.linspace(-0.15, 0.15, 12)[healthy]},
                    nodes=20, rtol=1e-5, stall_factor=5.0, stall_min_steps=500, steps_per_launch=100,
                    error_filter_nodes=0)
    np.testing.assert_array_equal(alone.mu_s.values, ds.mu_s.values[healthy])  # peers unaffected


def test_launch_chunks_do_not_change_results():
    """steps_per_launch only sets how often the host looks (progress, straggler limit): chunks of 7
    attempts (dozens of launches queued one ahead of the read-back) and of 100,000 (one launch) give
    the same outputs bit for bit, two passes with fronts and the stress gate included."""
    import warpfric as wf

    members = {"eccentricity": [0.0, 0.3], "normal_force": [1000.0, 300.0]}
    every_event = wf.Fronts(event=("contact", "strength", "velocity"))
    one = run(members, nodes=20, rtol=1e-5, fronts=every_event, steps_per_launch=100_000)
    many = run(members, nodes=20, rtol=1e-5, fronts=every_event, steps_per_launch=7)
    assert (one.steps_accepted.values > 7 * 10).all()
    for name in ("mu_s", "mu_s_time", "steps_accepted", "steps_rejected", "displacement", "arrival_time", "v_middle"):
        np.testing.assert_array_equal(many[name].values, one[name].values, err_msg=name)


def test_every_accepted_eccentricity_runs_up_to_heavy_lift_off():
    """|2e/L| up to 0.6 is accepted (beyond, refused: tests/test_inputs.py): at 0.6 about half of the
    pad has lifted off, the run ends ok with its contact zone inside the pad, and the fronts stay in
    the contact zone (lifted-off nodes never arrive)."""
    import warpfric as wf

    ds = run({"eccentricity": [-0.6, 0.6], "normal_force": [300.0, 3000.0]}, nodes=40, rtol=1e-5,
             fronts=wf.Fronts(event=("velocity", "contact")))
    assert (ds.status.values == 0).all() and (ds.lift_off.values == 1).all()
    in_contact = ds.normal_stress.values > 0
    assert 0.3 < in_contact.mean() < 0.8
    # the velocity front's arrived nodes lie inside the final contact zone (a node without contact at
    # the end of a step never arrives)
    arrived = np.isfinite(ds.arrival_time.values)
    assert arrived.any(axis=1).all()
    for m in range(2):
        x_contact = ds.x.values[in_contact[m]]
        x_arrived = ds.x.values[arrived[m]]
        assert x_contact.min() - 1e-12 <= x_arrived.min() and x_arrived.max() <= x_contact.max() + 1e-12
    # the contact front's nodes opened their gates (which needs contact: A > 0) after the disc started;
    # the contact zone shrinks while the tilted pad slides, so some of them lifted off later
    opened = np.isfinite(ds.contact_arrival_time.values)
    assert opened.any(axis=1).all() and (np.isfinite(ds.yield_time.values) >= opened).all()
    assert (ds.contact_arrival_time.values[opened] > 20.0).all()


def test_a_sudden_stop_of_a_lifted_off_pad_is_advised_damping():
    """Stopped at 21 s with part of the pad lifted off, 2e/L = -0.35 vibrates undamped where nothing
    touches and reaches max_steps at ~21.002 s (2e/L = -0.25 ends ok); "a larger max_steps" alone
    was the advice, and reaching 22 s would need ~1e7 steps. The warning names the lift-off and
    damping, and a damping of 1e6 Pa s/m makes both members end ok with mu at 22 s within 1e-6."""
    import warpfric as wf

    members = {"eccentricity": [-0.35, -0.25]}
    with pytest.warns(UserWarning, match="1 max_steps_reached .*; 1 of them: part of the pad lifted off.*1e6 Pa s/m"):
        ds = run(members, scene=wf.Parameters(stop_time=21.0, end_time=22.0), rtol=1e-5, max_steps=4000,
                 stall_factor=float("inf"))
    assert list(ds.status.values) == [1, 0] and (ds.lift_off.values == 1).all()
    damped = run(members, scene=wf.Parameters(stop_time=21.0, end_time=22.0, damping=1e6), rtol=1e-5, max_steps=4000)
    assert (damped.status.values == 0).all() and (damped.final_time.values == 22.0).all()
    np.testing.assert_allclose(damped.mu_final.values[1], ds.mu_final.values[1], rtol=1e-6)


def test_a_disc_that_never_moves_has_no_peak_and_no_front():
    """disc_velocity = 0: the pad only feels the load ramp; its largest mu(t) is round-off before the
    disc would start, and its 'event' of ~1e-22 m/s is no event: status no_peak, NaN mu_s, no front."""
    import warpfric as wf

    with pytest.warns(UserWarning, match="1 of 2 members: 1 no_peak \\(disc_velocity = 0: the disc never moves"):
        ds = run({"disc_velocity": [0.0, 1e-4]}, nodes=20, rtol=1e-5,
                 fronts=wf.Fronts(event=("velocity", "contact", "strength")))
    meanings = ds.status.attrs["flag_meanings"].split()
    assert meanings[ds.status.values[0]] == "no_peak" and np.isnan(ds.mu_s.values[0])
    assert np.isnan(ds.event_max_velocity.values[0]) and np.isnan(ds.v_middle.values[0])
    # its front is not given (status no_peak): unknown, -3, not "none" (-2), which claims no front ran
    assert np.isnan(ds.nucleation_position.values[0]) and ds.nucleation_edge.values[0] == -3
    assert ds.status.values[1] == 0 and np.isfinite(ds.v_middle.values[1])
    # the moving member's event is orders above the floor of min_event_fraction * |v_max|
    assert ds.event_max_velocity.values[1] > 100 * wf.Fronts().min_event_fraction * 1e-4


def test_the_advice_for_a_non_finite_state_names_float64_only_to_members_that_ran_in_float32():
    """A force of 1e300 N makes the state non-finite; the warning's advice was 'a tighter rtol, or
    float64' to a member that ran in float64. float64 is named where members ran in float32, and a
    warning before the run says why such a force fails."""
    import xarray as xr

    from warpfric.simulate import members_not_ok_text

    with pytest.warns(UserWarning) as caught:
        ds = run({"normal_force": [1e300, 1000.0]}, nodes=20, rtol=1e-5)
    said = [str(w.message) for w in caught]
    assert any(re.search(r"1 of 2 members: 1 non_finite_state \(the state became NaN or inf: a tighter rtol\); their "
                         "numbers", text) for text in said), said
    # and why, before the run: the mean normal stress F/(L p) far above the hardness (it passed the range (0, inf))
    assert any(text.startswith("normal_force / (length * depth) reaches the hardness in 1 of 2 members (member index "
                               "0: 4.17e+301 Pa against 5.4e+08 Pa)") for text in said), said
    assert list(ds.status.values) == [2, 0] and (ds.working_precision.values == 64).all()
    single = xr.Dataset({"status": ds.status, "disc_velocity": ds.disc_velocity,
                         "working_precision": ("member", np.array([32, 64], np.int8))})
    assert members_not_ok_text(single, wf.Solver()).endswith(
        "1 of 2 members: 1 non_finite_state (the state became NaN or inf: a tighter rtol, or float64 (1 of them ran "
        "in float32))")
    # without working_precision (an interrupted run's kept chunks of an earlier version): the solver's precision
    unknown = single.drop_vars("working_precision")
    assert members_not_ok_text(unknown, wf.Solver()).endswith("(the state became NaN or inf: a tighter rtol)")
    assert members_not_ok_text(unknown, wf.Solver(dtype="float32")).endswith("or float64 (1 of them ran in float32))")


def test_float32_members_that_stall_are_rerun_in_float64():
    """Without damping, float32 round-off of the displacement excites the grid's highest elastic mode
    at the end of the force ramp, and the error control then needs ~1e-8 s steps (docs/model.md,
    "Precision"): members 0 and 2 below end max_steps_reached in float32 at t ~ 10.0001 s. With the
    default float32_fallback they are run again in float64: status ok, working_precision 64, and
    exactly the outputs of a float64 run of the same members; a healthy float32 member keeps its
    float32 result (within 1e-6 of float64). Member 1 is healthy on the CPU; on an H100 float32
    round-off (another compiler's) decides which of members 1 and 2 stall (at 9acd1f2 member 1 did
    and member 2 did not), and those that do are rerun like member 0."""
    import warpfric as wf

    members = {"viscous_coefficient": [0.0, 0.0, 0.0], "normal_force": [1000.0, 100.0, 316.0],
               "eccentricity": [-0.35, -0.2, -0.2], "disc_velocity": [1e-5] * 3, "damping": [0.0, 1e5, 1e5]}
    model = wf.Model(relaxation_gate="none")
    record = wf.Record(members=(1, 2), times=(5.0, 15.0, 20.0))
    kw = dict(model=model, nodes=100, rtol=1e-5, max_steps=3000, record=record)
    plain = run(members, dtype="float32", float32_fallback=False, **kw)
    meanings = plain.status.attrs["flag_meanings"].split()
    statuses = [meanings[s] for s in plain.status.values]
    assert set(statuses) <= {"max_steps_reached", "ok"} and statuses[0] == "max_steps_reached"
    if not DEVICE.startswith("cuda"):
        assert statuses == ["max_steps_reached", "ok", "max_steps_reached"]
    stalled = np.array([s == "max_steps_reached" for s in statuses])
    assert np.isnan(plain.mu_s.values[stalled]).all() and (plain.final_time.values[stalled] < 10.001).all()
    ds = run(members, dtype="float32", **kw)
    f64 = run(members, dtype="float64", **kw)
    assert (ds.status.values == 0).all()
    assert ds.working_precision.values.tolist() == [64 if s else 32 for s in stalled]
    assert f64.working_precision.values.tolist() == [64, 64, 64]
    for name in ("mu_s", "mu_s_time", "steps_accepted", "final_time"):
        np.testing.assert_array_equal(ds[name].values[stalled], f64[name].values[stalled])
    np.testing.assert_array_equal(ds.friction_stress.values[stalled], f64.friction_stress.values[stalled].astype(np.float32))
    for slot, member in enumerate(record.members):  # the recorded members 1 and 2
        source = f64.velocity_history.values[slot].astype(np.float32) if stalled[member] else plain.velocity_history.values[slot]
        np.testing.assert_array_equal(ds.velocity_history.values[slot], source)
    kept = ~stalled
    assert (np.abs(ds.mu_s.values[kept] - f64.mu_s.values[kept]) < 1e-6).all()


def test_grid_check_needs_a_grid_to_halve():
    """grid_check compares with (N + 1)//2 nodes: below 5 nodes that is no coarser grid (3 -> 3, a
    change of exactly 0 would pass for a converged speed): refused before running."""
    import pytest

    import warpfric as wf

    with pytest.raises(ValueError, match=r"grid_check.*nodes.*>= 5 \(got 4\)"):
        run(nodes=4, fronts=wf.Fronts(grid_check=True))


def test_device_none_keeps_a_lone_member_on_the_cpu():
    """device=None: one member on the CPU whatever the GPUs (there a CPU core ties the GPU's team of
    lanes and starts sooner), two or more on cuda:0 when there is one; where the GPU would run the
    thread-per-member kernel (float32, lanes=1, fewer than 16 nodes) up to 32 members on the CPU
    (docs/performance.md, "Where device=None runs")."""
    import warp as wp

    import warpfric as wf
    from warpfric.device import SMALL_ENSEMBLE, SMALL_ENSEMBLE_THREAD_KERNEL, cpu_ensemble_limit

    gpu = "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"
    assert (SMALL_ENSEMBLE, SMALL_ENSEMBLE_THREAD_KERNEL) == (1, 32)
    assert wf.default_device(1) == wf.default_device(1, wf.Solver()) == "cpu"
    assert wf.default_device(2) == wf.default_device(2, wf.Solver(nodes=200)) == wf.default_device(17) == gpu
    for thread_kernel in (wf.Solver(lanes=1), wf.Solver(dtype="float32"), wf.Solver(nodes=11)):
        assert cpu_ensemble_limit(thread_kernel) == 32
        assert wf.default_device(32, thread_kernel) == "cpu"
        assert wf.default_device(33, thread_kernel) == gpu
    assert cpu_ensemble_limit(wf.Solver(lanes=32)) == cpu_ensemble_limit(wf.Solver(nodes=16)) == 1
    ds = wf.simulate({"eccentricity": [0.0]}, solver=wf.Solver(nodes=11), fronts=None, device=None, progress=False)
    assert ds.attrs["device"] == "cpu"


def test_state_read_back_buffer_is_pinned_and_reused_on_a_gpu_only():
    """The member states are read back through a host buffer. On a CUDA device it is pinned
    (asynchronous copies) and, being costly to allocate (~1.3 ms, 9 % of a one-member run:
    docs/performance.md), kept in a pool: the next run of as many members takes that very buffer
    and its outputs are bit for bit the first's; a run of another size gets its own. On the CPU
    nothing is pinned and the pool stays empty."""
    from warpfric import engine

    engine._PINNED_POOL.clear()
    members = {"eccentricity": [0.0, 0.15]}
    first = run(members, rtol=1e-4)
    key = (str(wp.get_device(DEVICE)), 2)
    if not DEVICE.startswith("cuda"):
        assert engine._PINNED_POOL == {}
        return
    (buffer,) = engine._PINNED_POOL[key]
    assert buffer.pinned
    second = run(members, rtol=1e-4)
    assert len(engine._PINNED_POOL[key]) == 1 and engine._PINNED_POOL[key][0] is buffer
    for name, var in first.data_vars.items():
        np.testing.assert_array_equal(second[name].values, var.values, err_msg=name)
    run({"eccentricity": [0.0]}, rtol=1e-4)
    assert len(engine._PINNED_POOL[(str(wp.get_device(DEVICE)), 1)]) == 1


def test_pinned_pool_keeps_at_most_its_total_newest_first(monkeypatch):
    """The pool of pinned read-back buffers keeps at most PINNED_POOL_MAX_TOTAL bytes: a buffer
    handed back beyond it evicts the member counts used longest ago, whole; buffers above
    PINNED_POOL_MAX_BYTES are never kept. (Fake buffers: the pool's bookkeeping alone.)"""
    from warpfric import engine

    class Buffer:
        def __init__(self, capacity):
            self.capacity = capacity

    def hand_back(key, capacity):
        snapshot = engine.StateSnapshots.__new__(engine.StateSnapshots)
        snapshot.cuda, snapshot.key, snapshot.buffer = True, key, Buffer(capacity)
        snapshot.close()
        assert snapshot.buffer is None

    monkeypatch.setattr(engine, "_PINNED_POOL", {})
    monkeypatch.setattr(engine, "PINNED_POOL_MAX_BYTES", 400)
    monkeypatch.setattr(engine, "PINNED_POOL_MAX_TOTAL", 1000)
    hand_back(("cuda:0", 1), 300)
    hand_back(("cuda:0", 2), 300)
    hand_back(("cuda:0", 1), 300)  # member count 1 used again: now the newest
    assert list(engine._PINNED_POOL) == [("cuda:0", 2), ("cuda:0", 1)]
    hand_back(("cuda:0", 3), 300)  # 1,200 bytes: member count 2 (the oldest) goes
    assert list(engine._PINNED_POOL) == [("cuda:0", 1), ("cuda:0", 3)]
    assert sum(b.capacity for free in engine._PINNED_POOL.values() for b in free) == 900
    hand_back(("cuda:0", 4), 500)  # above PINNED_POOL_MAX_BYTES: not kept
    assert ("cuda:0", 4) not in engine._PINNED_POOL


def test_the_straggler_limit_is_the_ensembles_median_at_any_launch_once_half_have_ended():
    """Members advance in step, so at any snapshot after half have ended the running ones have made
    at least as many attempts as any ended one, and the limit is stall_factor x the median of the
    final counts, whichever launch it is read after. A member needing 9.5x that median (as the
    slowest disc of the figures' velocity map does) is not stopped at stall_factor 10; one needing
    10.5x is."""
    import warpfric as wf
    from warpfric.engine import NO_STALL_LIMIT, straggler_limit
    from warpfric.kernels.types import IntegratorState

    final = np.array([200, 240, 260, 280, 285, 289, 310, 330, 400, 2745, 3040])  # median 289
    solver = wf.Solver(stall_factor=10.0, stall_min_steps=2000)
    limits = []
    for launch_end in (280, 300, 500, 2800):  # attempts given to every member so far
        st = np.zeros(final.size, dtype=IntegratorState.numpy_dtype())
        ended = final <= launch_end
        st["done"], st["steps_accepted"] = ended, np.minimum(final, launch_end)
        limits.append(straggler_limit(st, solver))
    assert limits[0] == NO_STALL_LIMIT  # 4 of 11 ended: no limit yet
    assert limits[1:] == [2890] * 3
    assert final[-2] < limits[1] < final[-1]
    # two members, one ended ok: the limit is 10x its count however far the other has run (a plain
    # median would follow the running count and never stop it); a failed member does not count
    for running_for in (300, 5000, 90000):
        st = np.zeros(2, dtype=IntegratorState.numpy_dtype())
        st["done"], st["steps_accepted"] = [1, 0], [250, running_for]
        assert straggler_limit(st, solver) == 2500
    st = np.zeros(6, dtype=IntegratorState.numpy_dtype())
    st["done"], st["status"], st["steps_accepted"] = [1, 1, 1, 1, 1, 0], [5, 5, 0, 0, 0, 0], [3, 4, 300, 320, 340, 700]
    assert straggler_limit(st, solver) == 3200  # ok or running: 300, 320, 340, 700 (not the failed 3, 4)


def _front_outputs(ds):
    """The names of ds's front outputs (those whose long name speaks of a front event, and the
    nucleation edge), every one of which a cut-off run must leave NaN."""
    names = [name for name, var in ds.data_vars.items()
             if "front" in var.attrs.get("long_name", "") and name not in ("detachment_end_time",)]
    assert {"v_main", "v_first", "detached_fraction", "arrival_time", "front_end_time"} <= set(names)
    return names


@pytest.mark.parametrize("event", ["contact", "strength", "velocity"])
def test_a_front_cut_off_by_end_time_is_nan_not_a_part_of_it(event):
    """The default scene's front starts at ~20.22 s and the detachment is over at ~20.27 s (the
    automatic end). A run ended at 20.245 s by an explicit end_time sees part of the front (a strength
    front's speeds measured on 7 % of the nodes came out 7x too slow): its status stays ok, its mu_s
    is the automatic run's, detachment_end_time is NaN, every front output is NaN, and one warning
    names the member. A run past the end (end_time 40 s) sees the detachment through: the same
    detachment_end_time as the automatic end, which is that run's final time, and the same fronts."""
    auto = run({"eccentricity": [0.0]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(event=event))
    assert auto.detachment_end_time.values[0] == auto.final_time.values[0]
    with pytest.warns(UserWarning, match="runs ended before the detachment was over") as caught:
        cut = run({"eccentricity": [0.0]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(event=event),
                  scene=wf.Parameters(end_time=20.245))
    said = [str(w.message) for w in caught if "detachment was over" in str(w.message)]
    assert len(said) == 1 and "1 at end_time" in said[0] and "member 0" in said[0], said
    assert cut.status.values[0] == 0 and cut.final_time.values[0] == 20.245
    assert abs(cut.mu_s.values[0] - auto.mu_s.values[0]) < 1e-8 * auto.mu_s.values[0]
    assert np.isnan(cut.detachment_end_time.values[0])
    for name in _front_outputs(cut):
        values = cut[name].values
        if name.endswith("nucleation_edge"):
            assert (values == -3).all(), name  # unknown (not "none": a front was under way)
        else:
            assert np.isnan(values).all(), (name, values)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        late = run({"eccentricity": [0.0]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(event=event),
                   scene=wf.Parameters(end_time=40.0))
    assert late.final_time.values[0] == 40.0
    np.testing.assert_allclose(late.detachment_end_time.values, auto.detachment_end_time.values, rtol=1e-9)
    np.testing.assert_allclose(late.v_first.values, auto.v_first.values, rtol=1e-6)


def test_a_run_capped_at_max_end_time_says_its_detachment_was_not_over():
    """aging_coefficient 5e-3: mu barely exceeds its sliding level, never falls 1 % below its maximum,
    and the automatic end never comes: the run stops at max_end_time. Its mu_s stands (it fell by
    more than rtol: docs/model.md, "Statuses"), but detachment_end_time is NaN, its fronts are NaN,
    and the warning says that the cap ended it and mu_s may be a plateau's; the member beside it with
    the default aging ends at its detachment, with fronts."""
    with pytest.warns(UserWarning, match="runs ended before the detachment was over") as caught:
        ds = run({"aging_coefficient": [5e-3, 0.075]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(),
                 scene=wf.Parameters(max_end_time=24.0))
    said = [str(w.message) for w in caught if "detachment was over" in str(w.message)]
    assert len(said) == 1 and "1 at max_end_time" in said[0] and "plateau" in said[0] and "member 0" in said[0]
    assert (ds.status.values == 0).all()
    assert ds.final_time.values[0] == 24.0 and np.isnan(ds.detachment_end_time.values[0])
    assert np.isnan(ds.v_first.values[0]) and np.isfinite(ds.v_first.values[1])
    assert ds.detachment_end_time.values[1] == ds.final_time.values[1] < 24.0


def test_an_explicit_end_past_max_end_time_is_a_cut_not_the_cap():
    """max_end_time caps the automatic end only (docs/model.md): a member whose explicit end_time lies
    past it, inside its front, was said to be stopped 'at max_end_time' with the advice of a later
    max_end_time, which changes nothing. It is a cut at end_time; without fronts nothing is said."""
    with pytest.warns(UserWarning, match="detachment was over") as caught:
        run({"end_time": [20.245]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(), scene=wf.Parameters(max_end_time=20.1))
    said = [str(w.message) for w in caught if "detachment was over" in str(w.message)]
    assert len(said) == 1 and "1 at end_time" in said[0] and "max_end_time" not in said[0], said
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run({"end_time": [20.245]}, nodes=30, rtol=1e-5, scene=wf.Parameters(max_end_time=20.1))


def test_a_velocity_front_that_never_ends_is_told_apart_from_a_plateau():
    """A sudden stop inside the velocity front leaves the pad ringing above half the arrival level,
    so the automatic end never comes and max_end_time stops the run, with mu 9 % below its maximum:
    the warning said 'mu never fell 1 % below its maximum' (a plateau), which was false. It says the
    front event was not over; the member stopped later ends by itself."""
    with pytest.warns(UserWarning, match="detachment was over") as caught:
        ds = run({"stop_time": [20.2722, 20.5]}, nodes=30, rtol=1e-5, fronts=wf.Fronts(event="velocity"),
                 scene=wf.Parameters(max_end_time=22.0))
    said = [str(w.message) for w in caught if "detachment was over" in str(w.message)]
    assert len(said) == 1 and "with mu 1% below its maximum but the front event not over" in said[0], said
    assert "plateau" not in said[0] and ds.mu_final.values[0] < 0.99 * ds.mu_s.values[0]
    assert ds.final_time.values[0] == 22.0 and int(ds.nucleation_edge.values[0]) == -3
    assert ds.final_time.values[1] < 22.0 and np.isfinite(ds.detachment_end_time.values[1])


def test_mu_s_at_a_fast_discs_kinked_start_is_the_peak_not_a_parabolas_overshoot():
    """A fast disc (0.03 m/s) under a high load (5e4 N): mu(t) falls from ~0.02 to ~0 within
    microseconds where the disc starts, and the parabola through a long step and that drop rose to
    mu_s = 79.6 at 20.00002 s, status ok; the automatic end then never came (the false maximum lies
    before 0.5 D of travel) and the run went on to max_end_time. The peak must agree with an
    independent run (ESDIRK4, whose cubic refinement had the same fault: 5.86 at 3e4 N, v = 0.1 m/s)
    and with a run at rtol 1e-8, to the error control, and lie where the disc slides."""
    members = {"normal_force": [5e4, 3e4], "disc_velocity": [0.03, 0.1]}
    ds = run(members, rtol=1e-5)
    tight = run(members, rtol=1e-8)
    esdirk = run(members, rtol=1e-5, method="esdirk4")  # at 1e-6 its cubic does not overshoot here
    assert (ds.status.values == 0).all() and (esdirk.status.values == 0).all()
    np.testing.assert_allclose(ds.mu_s.values, tight.mu_s.values, rtol=1e-4)
    np.testing.assert_allclose(esdirk.mu_s.values, tight.mu_s.values, rtol=1e-4)
    assert (tight.mu_s.values > 0.5).all() and (tight.mu_s.values < 0.6).all()
    assert (ds.mu_s_time.values > 20.01).all() and (ds.final_time.values < 21.0).all()  # the automatic end came


def test_an_arrested_partial_slip_does_not_end_the_run_before_the_detachment():
    """At 1e6 N (N = 40) mu dips 2.7 % in a partial slip that arrests with about half of the nodes
    opened, then rises to the detachment's peak: the automatic end took the dip (mu_s 0.3997 at
    21.346 s, detached_fraction 0.525, status ok) while a run to 22 s read 0.4613 at 21.475 s. With
    the stress gate the automatic end waits until every node in contact has opened: then it gives
    the peak that the fixed end gives, and every node's stick-to-slip time."""
    auto = run({"normal_force": [1e6]}, rtol=1e-5, fronts=wf.Fronts())
    fixed = run({"normal_force": [1e6]}, rtol=1e-5, scene=wf.Parameters(end_time=22.0))
    assert int(auto.status[0]) == 0 and int(fixed.status[0]) == 0
    assert float(auto.mu_s[0]) == pytest.approx(float(fixed.mu_s[0]), rel=1e-9)
    assert float(auto.mu_s_time[0]) == pytest.approx(float(fixed.mu_s_time[0]), rel=1e-9)
    assert float(auto.final_time[0]) > float(auto.mu_s_time[0])
    assert np.isfinite(auto.yield_time.values).all()
    assert float(auto.detachment_end_time[0]) == pytest.approx(float(fixed.detachment_end_time[0]), abs=2e-3)


def test_an_undamped_lift_off_that_rings_is_told_and_damping_settles_it():
    """2e/L = 0.6 with the disc dragging towards the loaded edge and a high aging coefficient: the
    lifted part rings undamped during the detachment, and mu_s at the default rtol (0.909) was the
    integrator's damped answer, 7 % above rtol 1e-7's, status ok without a word. The members that
    lifted off with no damping are told; with a damping mu_s is one value at every rtol."""
    import warpfric as wf

    member = {"eccentricity": [0.6, 0.0], "disc_velocity": [-5e-3, -5e-3], "aging_coefficient": [0.2, 0.2]}
    with pytest.warns(UserWarning, match=r"pad lifted off with no damping \(lift_off 1, damping 0\) in 1 of 2 members: "
                                         r"member 0: .*depends on rtol"):
        loose = run(member, nodes=50, rtol=1e-5)
    tight = run(member, nodes=50, rtol=1e-7, stall_factor=float("inf"))
    assert list(loose.lift_off.values) == [1, 0] and (loose.status.values == 0).all() and (tight.status.values == 0).all()
    assert loose.mu_s.values[0] - tight.mu_s.values[0] > 0.03  # the warning's point: far beyond rtol
    assert abs(loose.mu_s.values[1] - tight.mu_s.values[1]) < 1e-4  # the member that did not lift off
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning of the damped members
        damped = [run(member, scene=wf.Parameters(damping=1e6), nodes=50, rtol=rtol) for rtol in (1e-5, 1e-7)]
    np.testing.assert_allclose(damped[0].mu_s.values[0], damped[1].mu_s.values[0], rtol=1e-6)
    np.testing.assert_allclose(damped[0].mu_s.values[0], loose.mu_s.values[0], rtol=1e-5)
