"""The cooperative kernel (Solver.lanes > 1: a team of threads per member, kernels/team.py) against
the thread-per-member kernel: the same members, the same law, the same outputs within the error
control (sums are taken in another order, so not bit for bit). On the CPU the team runs on Warp's
cooperative fibers (warp.config.enable_cpu_blocks); WARPFRIC_TEST_DEVICE=cuda:0 runs the same
assertions on a GPU. The partitioned bordered solve alone is tested against numpy in test_kernels.py."""

import math

import numpy as np
import pytest
import warp as wp
from conftest import DEVICE, run
from conftest import REFACTOR_MEMBERS as MEMBERS  # the members of studies/outputs_equal.py

import warpfric as wf
from warpfric.engine import (AUTO_LANES, AUTO_MIN_NODES, alike_blocks, choose_lanes, cpu_blocks, member_order,
                             morton_key, slower_float32)


# the lane exchange (kernels/team.py): None is the device's automatic one (tiles on the CPU, warp
# shuffles on a GPU); "emulated" runs the shuffles' algorithms (tree reductions, parallel cyclic
# reduction of the separators) on the CPU
@pytest.mark.parametrize("gate, lanes, fronts, nodes, rtol, exchange, steps", [
    ("none", 2, False, 30, 1e-8, None, 1), ("none", 7, False, 30, 1e-8, None, 1), ("none", 8, False, 30, 1e-8, None, 1),
    ("stress", 4, True, 30, 1e-8, None, 1), ("none", 8, False, 16, 1e-7, None, 1),
    ("stress", 7, False, 30, 1e-8, "emulated", 1), ("none", 8, False, 16, 1e-7, "emulated", 1),
    ("stress", 64, False, 130, 1e-7, None if DEVICE.startswith("cuda") else "emulated", 8)])
def test_a_team_gives_the_thread_per_member_outputs(gate, lanes, fronts, nodes, rtol, exchange, steps, monkeypatch):
    """mu_s, its time and the front speeds of a team of `lanes` threads equal the thread-per-member
    kernel's to 1e-8 relative (the runs' own error control is rtol 1e-5: the kernels differ only by
    the order of their sums); same statuses; the steps taken differ by at most ``steps`` (one; at
    N = 130 the lift-off member's sliding after its peak takes 415-423 accepted steps with the
    order of the sums, its mu_s within 1.8e-8: on the H100 at a8cf0bf 423 one thread, 417 / 415 /
    417 teams of 16 / 32 / 64 lanes with the work in shared memory, 418 64 lanes with it in global
    memory; 417 one thread on the CPU (`studies/results/h100/team130_steps_a8cf0bf.txt`): that case
    allows 8, the spread on the H100; before the touchdown's location, 797d042, it took 434-438
    steps and allowed 4). 7 and 8 lanes
    of 30 nodes on the lift-off member are the case the review's shared-memory race broke
    (kernels/team.py, settle); 8 lanes of 16 nodes give every lane two nodes, both of them end
    nodes whose border-row entries come from the neighbouring lanes (kernels/newton.py,
    assemble_system); there the lift-off member's mu_s_time moves by 2e-8 (before that exchange)
    to 4e-8 with the order of the sums, the others by 1e-15, hence 1e-7. The final fields are not
    compared: the automatic end may fall a step apart. The emulated exchange (7 lanes: a team that
    is not a power of two, the lift-off member; 8 lanes of 2 nodes) checks on the CPU the
    algorithms of the GPU's warp shuffles; 64 lanes of 130 nodes (two warps) those of a team of
    several warps (kernels/team.py make_warps_team), which a GPU runs with its shuffles and
    buffer; without fronts, because there the lift-off member's middle front speed moves by
    1.3e-5 with the order of the sums in every team (3.58121-3.58126 m/s: tiles of 32 and 64
    lanes, emulated 32 and 64, one thread). The members without lift-off agree to 1e-10 in every
    case (1e-13 and below where measured); at N = 130 the lift-off member's mu_s moves by 6.1e-9
    (417 against 416 accepted steps, emulated 64 lanes on the CPU, at 6713b46; 2.1e-8 with 433
    against 437 before 797d042) and by up to 1.8e-8 over the H100's kernels, hence 1e-7 there."""
    if exchange:
        monkeypatch.setenv("WARPFRIC_TEAM_EXCHANGE", exchange)
    model = wf.Model(relaxation_gate=gate)
    front = wf.Fronts() if fronts else None
    ref = run(MEMBERS, model=model, nodes=nodes, rtol=1e-5, fronts=front, lanes=1)
    if DEVICE.startswith("cuda"):
        team = run(MEMBERS, model=model, nodes=nodes, rtol=1e-5, fronts=front, lanes=lanes)
    else:
        with pytest.warns(UserWarning, match="CPU fibers"):  # a team on the CPU is for tests only
            team = run(MEMBERS, model=model, nodes=nodes, rtol=1e-5, fronts=front, lanes=lanes)
    assert ref.attrs["lanes"] == 1 and team.attrs["lanes"] == lanes
    np.testing.assert_array_equal(team.status.values, ref.status.values)
    assert (ref.status.values == 0).all() and ref.lift_off.values[3] == 1
    for name in ("mu_s", "mu_s_time"):  # members without lift-off to 1e-10, the lift-off member to rtol
        np.testing.assert_allclose(team[name].values[:3], ref[name].values[:3], rtol=1e-10, err_msg=name)
        np.testing.assert_allclose(team[name].values[3], ref[name].values[3], rtol=rtol, err_msg=name)
    assert np.all(np.abs(team.steps_accepted.values - ref.steps_accepted.values) <= steps)
    if fronts:
        for name in ("v_left", "v_middle", "v_right"):
            np.testing.assert_allclose(team[name].values, ref[name].values, rtol=1e-6, equal_nan=True)


@pytest.mark.filterwarnings("ignore:Solver\\(lanes=:UserWarning")  # a team on the CPU's fibers
@pytest.mark.parametrize("lanes, nodes", [(8, 30), (7, 30)])
def test_a_team_gives_the_thread_per_member_fields(lanes, nodes):
    """The final fields of a team equal the thread-per-member kernel's node by node (each lane
    writes its own nodes of the member's arrays; the host reads them in node order). The run ends
    at a fixed time (20.05 s: the load ramped, the disc started, the interface still stuck; the
    eccentric load and the disc's drag make the fields vary along the pad), so both kernels take
    the same steps; they differ by the order of their sums only. 7 lanes of 30 nodes: lanes of 5
    and 4 nodes."""
    scene = wf.Parameters(end_time=20.05)
    ref = run(MEMBERS, scene=scene, nodes=nodes, rtol=1e-6, lanes=1)
    team = run(MEMBERS, scene=scene, nodes=nodes, rtol=1e-6, lanes=lanes)
    for name in ("displacement", "velocity", "elastic_stress", "contact_age", "normal_stress", "friction_stress"):
        r, t = ref[name].values, team[name].values
        scale = np.abs(r).max(axis=1, keepdims=True)
        np.testing.assert_allclose(t / scale, r / scale, rtol=0, atol=1e-7, err_msg=name)
    # the fields vary along the pad: a wrong node order could not pass
    u = ref["displacement"].values
    assert np.all(np.abs(np.diff(u, axis=1)).max(axis=1) > 1e-3 * np.abs(u).max(axis=1))


def _reductions_kernel(lanes, exchange):
    from warpfric.kernels.team import make_team, vec12d

    team = make_team(wp.float64, lanes, exchange)
    team_sum_vec12, team_max, team_sum = team["team_sum_vec12"], team["team_max"], team["team_sum"]

    @wp.kernel(module="unique")
    def reduce(out: wp.array3d(dtype=wp.float64)):
        """Three rounds of a vector sum followed at once by a maximum and a scalar sum, as in a
        Newton iteration; every lane stores what it got."""
        m, lane = wp.tid()
        for it in range(3):
            v = vec12d()
            for j in range(12):
                v[j] = wp.float64(1.0 + float(j) + float(lane)) / wp.float64(3.0)
            total = team_sum_vec12(v)
            biggest = team_max(wp.float64(lane + it))
            plain = team_sum(wp.float64(lane))
            for j in range(12):
                out[it, lane, j] = total[j]
            out[it, lane, 12] = biggest
            out[it, lane, 13] = plain

    return reduce


EXCHANGES = ["tile", "emulated"] + (["shuffle"] if DEVICE.startswith("cuda") else [])


@pytest.mark.parametrize("exchange", EXCHANGES)
@pytest.mark.parametrize("lanes", [2, 4, 7, 8, 16, 32, 64, 96])
def test_every_lane_reads_the_same_team_reductions(lanes, exchange):
    """Each lane of a team gets the sums (of k/3: exact to 1e-15 in any order) and the maximum in
    back-to-back reductions: the review's race (Warp's CPU reduction writing into the freed shared
    memory of the previous result before synchronising) gave lanes 0..6 of 8 a zero component.
    Every lane exchange (kernels/team.py), teams that are not a power of two included."""
    out = wp.zeros((3, lanes, 14), dtype=wp.float64, device=DEVICE)
    with cpu_blocks(True):
        wp.launch_tiled(_reductions_kernel(lanes, exchange), dim=[1], inputs=[out], block_dim=lanes, device=DEVICE)
    o = out.numpy()
    lane_sum = lanes * (lanes - 1) / 2.0
    expected = np.array([(lanes * (1.0 + j) + lane_sum) / 3.0 for j in range(12)])
    for it in range(3):
        np.testing.assert_allclose(o[it, :, :12], np.broadcast_to(expected, (lanes, 12)), rtol=1e-15)
        assert (o[it, :, 12] == lanes - 1 + it).all() and (o[it, :, 13] == lane_sum).all()
        assert (o[it] == o[it, :1]).all()  # every lane the same bits


def _sum_kernel(lanes, exchange):
    from warpfric.kernels.team import make_team

    team_sum = make_team(wp.float64, lanes, exchange)["team_sum"]

    @wp.kernel(module="unique")
    def total(x: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
        _m, lane = wp.tid()
        out[lane] = team_sum(x[lane])

    return total


def _sum_in_order(x, lanes):
    """The team's sum in the order kernels/team.py documents: a butterfly (partners lane ^ s, s = 16
    or lanes / 2 down to 1) inside each warp for a power-of-two warp, else a tree to the warp's
    first lane (lane + s, s = 2^(ceil(log2 lanes) - 1) down to 1, then lane 0's value); then, for
    several warps, the warps' results added in warp order."""
    in_warp = min(lanes, 32)
    v = np.array(x, dtype=np.float64)
    levels = max(1, (in_warp - 1).bit_length())
    s = 1 << (levels - 1)
    while s:
        lane = np.arange(lanes)
        if in_warp & (in_warp - 1) == 0:
            v = v + v[lane ^ s]
        else:
            v = np.where(lane + s < lanes, v + v[np.minimum(lane + s, lanes - 1)], v)
        s //= 2
    if in_warp & (in_warp - 1):
        v = np.full(lanes, v[0])
    total = v[0]
    for w in range(1, lanes // 32 if lanes > 32 else 1):
        total = total + v[32 * w]
    return total


@pytest.mark.parametrize("exchange", ["emulated"] + (["shuffle"] if DEVICE.startswith("cuda") else []))
@pytest.mark.parametrize("lanes", [7, 8, 32, 64, 96])
def test_a_team_sums_in_its_documented_order(lanes, exchange):
    """A team's sum of values of both signs over 6 orders of magnitude and two of 1e17 that cancel
    (the order of the sums shows: what is added to 1e17 first is lost, so the sum is not the exact
    one) equals bit for bit the sum in the order kernels/team.py documents, in every lane: the
    CPU's emulated exchange, and on a GPU its shuffles, so that the CPU tests the GPU's arithmetic
    (one warp, a tree of 7 lanes, and teams of two and three warps)."""
    rng = np.random.default_rng(lanes)
    x = rng.choice([-1.0, 1.0], lanes) * 10.0 ** rng.uniform(-3.0, 3.0, lanes)
    x[0], x[min(lanes - 1, 32)] = 1e17, -1e17  # they cancel (in the first two warps), and swallow what meets them first
    out = wp.zeros(lanes, dtype=wp.float64, device=DEVICE)
    with cpu_blocks(True):
        values = wp.array(x, dtype=wp.float64, device=DEVICE)
        wp.launch_tiled(_sum_kernel(lanes, exchange), dim=[1], inputs=[values, out], block_dim=lanes, device=DEVICE)
    expected = _sum_in_order(x, lanes)
    assert expected != math.fsum(x)  # the order shows in these bits
    np.testing.assert_array_equal(out.numpy(), np.full(lanes, expected))


def test_lanes_is_validated_and_chosen(monkeypatch):
    """Solver.lanes: None, 1 or 2..nodes//2, float64 only; None picks the cooperative kernel on a
    CUDA device in float64 (min(32, nodes // 2) lanes, from 16 nodes; for a run whose members fit
    the GPU at once in teams of the most whole warps of lanes of two nodes or more, those), the
    thread-per-member kernel otherwise."""
    for name in ("WARPFRIC_TEAM_BLOCK_MEMBERS", "WARPFRIC_TEAM_EXCHANGE"):
        monkeypatch.delenv(name, raising=False)
    for bad in (0, 51, 2.0, True):
        with pytest.raises(ValueError, match="lanes"):
            wf.Solver(nodes=100, lanes=bad)
    with pytest.raises(ValueError, match="float64"):
        wf.Solver(nodes=100, lanes=8, dtype="float32")
    assert choose_lanes(wf.Solver(nodes=100, lanes=8), "cpu") == 8
    assert choose_lanes(wf.Solver(nodes=100), "cpu") == 1
    assert choose_lanes(wf.Solver(nodes=200), "cuda:0") == AUTO_LANES == 32
    assert choose_lanes(wf.Solver(nodes=40), "cuda:0") == 20  # >= 2 nodes per lane
    assert choose_lanes(wf.Solver(nodes=25), "cuda:0") == 12  # lanes of 2 and one of 3 nodes
    assert choose_lanes(wf.Solver(nodes=64), "cuda:0") == choose_lanes(wf.Solver(nodes=65), "cuda:0") == 32
    assert choose_lanes(wf.Solver(nodes=AUTO_MIN_NODES), "cuda:0") == 8
    assert choose_lanes(wf.Solver(nodes=AUTO_MIN_NODES - 1), "cuda:0") == 1
    assert choose_lanes(wf.Solver(nodes=100, dtype="float32"), "cuda:0") == 1
    # a run whose members fit the GPU at once in teams of the most whole warps of >= 2 nodes a lane
    # (8 warps an SM): those teams
    sms = 132  # an H100's
    at_200 = [choose_lanes(wf.Solver(nodes=200), "cuda:0", m, sms) for m in (1, 2 * sms, 2 * sms + 1)]
    assert at_200 == [96, 96, 32]  # 3 warps: 2 members an SM
    at_400 = [choose_lanes(wf.Solver(nodes=400), "cuda:0", m, sms) for m in (1, sms, sms + 1)]
    assert at_400 == [192, 192, 32]  # 6 warps: one member an SM
    assert choose_lanes(wf.Solver(nodes=1000), "cuda:0", sms, sms) == 256  # MAX_TEAM_LANES, 8 warps
    assert choose_lanes(wf.Solver(nodes=128), "cuda:0", 4 * sms, sms) == 64  # 2 warps: 4 an SM
    assert choose_lanes(wf.Solver(nodes=128), "cuda:0", 4 * sms + 1, sms) == 32
    assert choose_lanes(wf.Solver(nodes=127), "cuda:0", 1, sms) == 32  # 63 lanes of two nodes: one warp
    assert choose_lanes(wf.Solver(nodes=40), "cuda:0", 1, sms) == 20
    assert choose_lanes(wf.Solver(nodes=200), "cpu", 1, 0) == 1
    assert choose_lanes(wf.Solver(nodes=200, lanes=8), "cuda:0", 1, sms) == 8
    # the benchmark switches that only one-warp teams take keep lanes=None at one warp
    for name, value in (("WARPFRIC_TEAM_BLOCK_MEMBERS", "8"), ("WARPFRIC_TEAM_EXCHANGE", "tile")):
        with monkeypatch.context() as switch:
            switch.setenv(name, value)
            assert choose_lanes(wf.Solver(nodes=200), "cuda:0", 1, sms) == 32
    with monkeypatch.context() as switch:
        switch.setenv("WARPFRIC_TEAM_BLOCK_MEMBERS", "1")
        assert choose_lanes(wf.Solver(nodes=200), "cuda:0", 1, sms) == 96


def test_the_lane_exchange_is_chosen_and_refused():
    """team_exchange: warp shuffles on a GPU for one warp or whole warps up to MAX_TEAM_LANES (a team
    of several warps), tiles otherwise and on the CPU; a requested exchange that cannot run is
    refused, naming the lanes."""
    from warpfric.kernels.integrator import team_exchange
    from warpfric.kernels.team import MAX_TEAM_LANES

    assert team_exchange(32, True) == team_exchange(20, True) == team_exchange(96, True) == "shuffle"
    assert team_exchange(MAX_TEAM_LANES, True) == "shuffle"
    assert team_exchange(48, True) == team_exchange(MAX_TEAM_LANES + 32, True) == team_exchange(64, False) == "tile"
    assert team_exchange(64, False, "emulated") == "emulated"
    with pytest.raises(ValueError, match="48 lanes"):
        team_exchange(48, True, "shuffle")
    with pytest.raises(ValueError, match="the CPU and 64 lanes"):
        team_exchange(64, False, "shuffle")
    with pytest.raises(ValueError, match="got 48"):
        team_exchange(48, False, "emulated")


def test_float32_on_a_gpu_says_it_is_the_slower_precision():
    """float32 runs the thread-per-member kernel; on a GPU, where float64 would run a team, a run
    warns that float32 is slower there (docs/performance.md: 0.98 s against 0.19 s on an H100).
    Nothing is said on the CPU (both precisions run the thread kernel), for float64, or where
    float64 would not run a team either (too few nodes, or lanes=1 asked for)."""
    note = slower_float32(wf.Solver(nodes=200, dtype="float32"), "cuda:0")
    assert note is not None and "float32" in note and "cuda:0" in note and "faster" in note
    assert slower_float32(wf.Solver(nodes=200, dtype="float32"), "cpu") is None
    assert slower_float32(wf.Solver(nodes=200), "cuda:0") is None
    assert slower_float32(wf.Solver(nodes=AUTO_MIN_NODES - 1, dtype="float32"), "cuda:0") is None
    assert slower_float32(wf.Solver(nodes=200, dtype="float32", lanes=1), "cuda:0") is None


def test_a_run_warns_with_the_float32_note(monkeypatch):
    """engine.run passes slower_float32's note on as a warning (the note itself needs a GPU to be
    given, so it is forced here)."""
    import warpfric.engine as engine

    monkeypatch.setattr(engine, "slower_float32", lambda solver, device: "float32 is the slower one here (test)")
    with pytest.warns(UserWarning, match="float32 is the slower one here"):
        run({"eccentricity": [0.0]}, nodes=12, rtol=1e-4, lanes=1)


def test_members_per_block_choice(monkeypatch):
    """Teams whose lanes exchange by warp shuffles (at most 32 lanes: one warp, on a GPU) run blocks
    of up to 8 members; tiles and the emulated exchange span their block (one member each). A run
    puts min(8, ceil(members / SMs)) members into a block: while there are fewer members than SMs,
    one per SM, as before. WARPFRIC_TEAM_BLOCK_MEMBERS forces the number (1: the layout of a block
    per member), 1 to 8, and is refused where members cannot share a block, naming the variable
    and the valid values."""
    from warpfric.kernels.integrator import MAX_BLOCK_MEMBERS, block_members_for, blocked_layout, team_compile_options

    assert blocked_layout(32, "shuffle") and blocked_layout(20, "shuffle") and blocked_layout(2, "shuffle")
    assert not blocked_layout(32, "tile") and not blocked_layout(64, "tile") and not blocked_layout(8, "emulated")
    assert not blocked_layout(32, "shuffle", 1) and blocked_layout(12, "shuffle", 4)
    with pytest.raises(ValueError, match="WARPFRIC_TEAM_BLOCK_MEMBERS=2 needs teams that exchange by warp shuffles"):
        blocked_layout(16, "tile", 2)
    # an H100 has 132 SMs
    assert block_members_for(1, 132) == block_members_for(100, 132) == block_members_for(132, 132) == 1
    assert block_members_for(133, 132) == 2 and block_members_for(500, 132) == 4
    assert block_members_for(1000, 132) == block_members_for(100_000, 132) == MAX_BLOCK_MEMBERS == 8
    assert block_members_for(100, 132, requested=8) == 8
    assert block_members_for(10_000, 132, most=7) == 7 and block_members_for(100, 132, requested=8, most=7) == 7
    monkeypatch.setenv("WARPFRIC_TEAM_BLOCK_MEMBERS", "3")
    assert team_compile_options().block_members == 3
    for bad in ("0", "9", "two", "-1"):
        monkeypatch.setenv("WARPFRIC_TEAM_BLOCK_MEMBERS", bad)
        with pytest.raises(ValueError, match=f"WARPFRIC_TEAM_BLOCK_MEMBERS='{bad}' is invalid; valid: an integer from 1 to 8"):
            team_compile_options()
    monkeypatch.delenv("WARPFRIC_TEAM_BLOCK_MEMBERS")
    assert team_compile_options().block_members is None  # the automatic choice


def test_work_array_memory_choice(monkeypatch):
    """The blocked kernel keeps its work array in the block's shared memory where a block of 7
    members' work fits, (N_WORK = 13, N, stride) float64 with the smallest odd stride >= the block's
    members: on an H100 (232,448 bytes a block, 4,096 kept back) 9 fits to N = 243 (8 members), 7 to
    N = 313 (7 members a block at most), else the work stays in global memory with 8 members a
    block. The choice does not depend on the member count (a member's outputs do not depend on its
    ensemble), only the stride does, and every stride gives the same outputs (the GPU test below).
    WARPFRIC_TEAM_SHARED_WORK=0 keeps the work in global memory (empty is unset); other values are
    refused, naming the variable, but only where a team runs: the thread-per-member kernel reads
    none of the team's switches. Warp's debug mode keeps the work in global memory (its bounds checks
    would reject the shared view's indexing by member). A team of several warps (one member a
    block) keeps its member's work there beside its team buffer where it fits."""
    from warpfric.kernels.integrator import shared_work_members, shared_work_stride, team_layout
    from warpfric.kernels.types import N_WORK

    for name in ("WARPFRIC_TEAM_SHARED_WORK", "WARPFRIC_TEAM_POISON_SHARED_WORK"):
        monkeypatch.delenv(name, raising=False)

    h100 = 232_448
    assert N_WORK == 13
    assert 13 * 243 * 9 * 8 <= h100 - 4096 < 13 * 244 * 9 * 8 and 13 * 313 * 7 * 8 <= h100 - 4096 < 13 * 314 * 7 * 8
    assert [shared_work_stride(200, k, h100) for k in range(1, 9)] == [1, 3, 3, 5, 5, 7, 7, 9]
    assert [shared_work_stride(250, k, h100) for k in range(1, 9)] == [1, 3, 3, 5, 5, 7, 7, 0]
    assert shared_work_members(243, h100) == 8 and shared_work_members(244, h100) == 7
    assert shared_work_members(313, h100) == 7 and shared_work_members(314, h100) == 0
    monkeypatch.delenv("WARPFRIC_TEAM_BLOCK_MEMBERS", raising=False)
    monkeypatch.delenv("WARPFRIC_TEAM_EXCHANGE", raising=False)
    members = (1, 300, 1000, 10_000)
    assert [team_layout(32, 200, m, True, 132, h100) for m in members] == [
        (True, 1, (200, 1)), (True, 3, (200, 3)), (True, 8, (200, 9)), (True, 8, (200, 9))]
    assert [team_layout(32, 250, m, True, 132, h100) for m in members] == [
        (True, 1, (250, 1)), (True, 3, (250, 3)), (True, 7, (250, 7)), (True, 7, (250, 7))]
    assert [team_layout(32, 320, m, True, 132, h100) for m in members] == [
        (True, 1, None), (True, 3, None), (True, 8, None), (True, 8, None)]
    assert team_layout(20, 40, 10_000, True, 132, h100) == (True, 8, (40, 9))
    assert team_layout(32, 200, 10_000, False) == (False, 1, None)  # the CPU: tiles, a block per member
    assert team_layout(1, 200, 10_000, True, 132, h100) == (False, 1, None)  # the thread-per-member kernel
    # a team of several warps: one member a block, its work beside the 24 KB team buffer while it fits
    # (13 * N * 8 <= h100 - 4096 - 24,576: N <= 1,959)
    wide_200 = (False, 1, (200, 1))
    assert team_layout(96, 200, 1, True, 132, h100) == team_layout(96, 200, 100, True, 132, h100) == wide_200
    assert team_layout(256, 1959, 1, True, 132, h100) == (False, 1, (1959, 1))
    assert team_layout(256, 1960, 1, True, 132, h100) == (False, 1, None)
    assert team_layout(96, 200, 1, False) == (False, 1, None)  # the CPU
    with monkeypatch.context() as tiles:
        tiles.setenv("WARPFRIC_TEAM_EXCHANGE", "tile")
        assert team_layout(96, 200, 1, True, 132, h100) == (False, 1, None)
    monkeypatch.setenv("WARPFRIC_TEAM_BLOCK_MEMBERS", "8")  # a request above what fits gets what fits
    assert team_layout(32, 250, 10_000, True, 132, h100) == (True, 7, (250, 7))
    monkeypatch.delenv("WARPFRIC_TEAM_BLOCK_MEMBERS")
    with monkeypatch.context() as debug:
        debug.setattr(wp.config, "mode", "debug")
        assert team_layout(32, 200, 10_000, True, 132, h100) == (True, 8, None)
        assert team_layout(96, 200, 1, True, 132, h100) == (False, 1, None)
    monkeypatch.setenv("WARPFRIC_TEAM_SHARED_WORK", "")
    assert team_layout(32, 200, 10_000, True, 132, h100) == (True, 8, (200, 9))
    monkeypatch.setenv("WARPFRIC_TEAM_SHARED_WORK", "0")
    assert team_layout(32, 200, 10_000, True, 132, h100) == (True, 8, None)
    assert team_layout(96, 200, 1, True, 132, h100) == (False, 1, None)
    for name in ("WARPFRIC_TEAM_SHARED_WORK", "WARPFRIC_TEAM_POISON_SHARED_WORK"):
        monkeypatch.setenv(name, "yes")
        with pytest.raises(ValueError, match=f"{name}='yes' is invalid; valid: 0, 1 or unset"):
            team_layout(32, 200, 10_000, True, 132, h100)
        assert team_layout(1, 200, 10_000, True, 132, h100) == (False, 1, None)  # no team, no switch read
        monkeypatch.delenv(name)
    # the probe WARPFRIC_TEAM_SHARED_PAD: bytes reserved beside the work (a multiple of 8), no layout change
    from warpfric.kernels.integrator import team_compile_options

    monkeypatch.setenv("WARPFRIC_TEAM_SHARED_PAD", "40000")
    assert team_compile_options().shared_pad == 40_000
    assert team_layout(32, 200, 10_000, True, 132, h100) == (True, 8, (200, 9))
    room = h100 - 4096 - 13 * 200 * 9 * 8  # 41,152 bytes beside 8 members' work
    monkeypatch.setenv("WARPFRIC_TEAM_SHARED_PAD", str(room + 8))
    with pytest.raises(ValueError, match=f"WARPFRIC_TEAM_SHARED_PAD={room + 8} does not fit .* at most {room} bytes"):
        team_layout(32, 200, 10_000, True, 132, h100)
    monkeypatch.setenv("WARPFRIC_TEAM_SHARED_PAD", str(room))
    assert team_layout(32, 200, 10_000, True, 132, h100) == (True, 8, (200, 9))
    for bad in ("7", "-8", "x"):
        monkeypatch.setenv("WARPFRIC_TEAM_SHARED_PAD", bad)
        with pytest.raises(ValueError, match=f"WARPFRIC_TEAM_SHARED_PAD='{bad}' is invalid; valid: a multiple of 8"):
            team_compile_options()
    monkeypatch.delenv("WARPFRIC_TEAM_SHARED_PAD")
    assert team_compile_options().shared_pad == 0


def test_similar_members_are_neighbours():
    """member_order (warpfric/engine.py): the blocked kernel gets its members along a Z-order curve
    through the varied parameters' ranks. The curve's bits, checked by hand: (x, y) cells of one
    bit each give keys 2x + y. 4,096 members drawn as in studies/bench_engine.py: a Z-order cell
    of 8 members spans 1/32 and 1/16 of the two ranks' range, so runs of 8 consecutive members (a
    block's) span 0.05 and 0.07 of the range on average, against 7/9 for 8 members at random (the
    given order); the constant parameter is ignored; members with equal varied parameters are
    consecutive; "given", or the thread kernel unasked, keep the caller's order; a bad request
    names the variable."""
    corners = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    np.testing.assert_array_equal(morton_key(corners, 1), [0, 1, 2, 3])
    np.testing.assert_array_equal(morton_key(np.array([[0.5, 0.25]]), 2), [0b1001])  # x = 10, y = 01
    rng = np.random.default_rng(3)
    m = 4096
    values = {"eccentricity": rng.uniform(-0.2, 0.2, m),
              "normal_force": np.exp(rng.uniform(np.log(500.0), np.log(5000.0), m)), "depth": np.full(m, 0.006)}
    order = member_order(values, blocked=True)
    np.testing.assert_array_equal(np.sort(order), np.arange(m))
    for name in ("eccentricity", "normal_force"):
        rank = np.argsort(np.argsort(values[name])) / (m - 1)
        assert np.ptp(rank[order].reshape(-1, 8), axis=1).mean() < 0.1, name
        assert np.ptp(rank.reshape(-1, 8), axis=1).mean() > 0.7, name
    without_constant = {name: values[name] for name in ("eccentricity", "normal_force")}
    np.testing.assert_array_equal(member_order(without_constant, blocked=True), order)
    twice = {name: np.concatenate([column[:50], column[:50]]) for name, column in values.items()}
    pairs = member_order(twice, blocked=True)
    position = np.argsort(pairs)
    np.testing.assert_array_equal(position[50:] - position[:50], 1)  # ties: the caller's order
    assert member_order(values, blocked=False) is None and member_order(values, True, "given") is None
    np.testing.assert_array_equal(member_order(values, False, "similar"), order)
    with pytest.raises(ValueError, match="WARPFRIC_MEMBER_ORDER='random'"):
        member_order(values, True, "random")
    # the default: blocks of several members, at least two blocks per SM (132 SMs: 264 blocks, 2,105 members or more)
    from warpfric.kernels.integrator import TeamLayout

    eight = TeamLayout(True, 8, (200, 9))
    assert not alike_blocks(eight, 1000, 132) and not alike_blocks(eight, 2104, 132)
    assert alike_blocks(eight, 2105, 132) and alike_blocks(eight, 10_000, 132)
    assert not alike_blocks(TeamLayout(True, 1, (200, 1)), 10_000, 132)
    assert not alike_blocks(TeamLayout(False, 1, None), 10_000, 1)  # the thread kernel, the CPU


def test_members_taken_as_raw_records_match_fancy_indexing():
    """engine.take_members gathers structured member states as rows of bytes: the same records as
    numpy's fancy indexing (field by field) for every field, NaN and -inf included; a plain
    array is indexed as usual. engine.alike: one value in every member (inf too), not with NaN."""
    from warpfric.engine import alike, initial_states, take_members
    from warpfric.parameters import Solver

    rng = np.random.default_rng(5)
    st = initial_states(37, Solver(), np.arange(37, dtype=np.int32))
    for name in st.dtype.names:
        st[name] = rng.integers(-3, 1000, 37).astype(st.dtype[name])
    st["mu_s"][3] = np.nan
    st["front_max"][4] = -np.inf
    index = rng.permutation(37)[:30]
    taken = take_members(st, index)
    assert taken.dtype == st.dtype and taken.shape == (30,)
    for name in st.dtype.names:
        np.testing.assert_array_equal(taken[name], st[index][name], err_msg=name)
    np.testing.assert_array_equal(take_members(st["t"], index), st["t"][index])
    assert alike(np.full(5, 2.0)) and alike(np.full(3, np.inf)) and alike(np.array([]))
    assert not alike(np.array([1.0, 2.0])) and not alike(np.array([np.nan, np.nan]))


@pytest.mark.parametrize("built_from", [0, 4096])
def test_member_params_and_states_built_on_the_device_match_the_host_ones(built_from, monkeypatch):
    """engine.device_member_params and device_member_states build on the device (from
    DEVICE_BUILT_MIN_MEMBERS members on; 0 here: always) what member_params and initial_states
    build on the host: the same bytes, for members that differ in some parameters (an infinite
    end_time among them: the automatic end), in none, and one alone; the states with record slots,
    and with the velocity front's front_level and front_until. Below the threshold they are the
    host's, uploaded."""
    import warp as wp

    import warpfric.engine as engine
    from warpfric.engine import device_member_params, device_member_states, initial_states, member_params

    monkeypatch.setattr(engine, "DEVICE_BUILT_MIN_MEMBERS", built_from)
    from warpfric.kernels.integrator import make_layout_kernels
    from warpfric.members import resolve_members
    from warpfric.parameters import Parameters, Solver

    layout = make_layout_kernels(wp.float64)
    solver = Solver(initial_step=3e-7)
    rng = np.random.default_rng(11)
    cases = [dict(eccentricity=rng.uniform(-0.2, 0.2, 9), normal_force=rng.uniform(500, 5000, 9),
                  end_time=np.where(rng.random(9) < 0.5, np.inf, 30.0)), dict(eccentricity=np.zeros(4)), {}]
    for members in cases:
        values, _ = resolve_members(members, Parameters())
        n = values["normal_force"].shape[0]
        with wp.ScopedDevice(DEVICE):
            params = device_member_params(values, layout).numpy()
            assert params.tobytes() == member_params(values).tobytes(), members.keys()
            slots = rng.integers(-1, 3, n).astype(np.int32)
            expected = initial_states(n, solver, slots)
            states = device_member_states(n, solver, slots, layout).numpy()
            for name in expected.dtype.names:  # field by field: a struct's padding bytes are not set
                np.testing.assert_array_equal(states[name], expected[name], err_msg=name)
            level, until = rng.uniform(0, 1, n), np.where(rng.random(n) < 0.5, -np.inf, 20.0)
            expected["front_level"], expected["front_until"] = level, until
            states = device_member_states(n, solver, slots, layout, front_level=level, front_until=until).numpy()
            for name in expected.dtype.names:
                np.testing.assert_array_equal(states[name], expected[name], err_msg=name)


def test_state_snapshots_reuse_one_host_array_and_hand_the_last_over():
    """engine.StateSnapshots: each wait fills the same host array with the states taken; final()
    hands it over, so that a later take and wait (the velocity front's second pass) fill another."""
    import warp as wp

    from warpfric.engine import StateSnapshots, initial_states
    from warpfric.kernels.types import IntegratorState
    from warpfric.parameters import Solver

    states = initial_states(5, Solver(), np.arange(5, dtype=np.int32))
    device_states = wp.array(states, dtype=IntegratorState, device=DEVICE)
    snapshot = StateSnapshots(5, DEVICE)
    first = snapshot.wait(snapshot.take(device_states))
    np.testing.assert_array_equal(first["record_slot"], np.arange(5))
    states["t"] = 7.0
    device_states.assign(wp.array(states, dtype=IntegratorState, device=DEVICE))
    again = snapshot.wait(snapshot.take(device_states))
    assert again is first and (first["t"] == 7.0).all()
    kept = snapshot.final(snapshot.take(device_states))
    states["t"] = 9.0
    device_states.assign(wp.array(states, dtype=IntegratorState, device=DEVICE))
    later = snapshot.wait(snapshot.take(device_states))
    assert later is not kept and (kept["t"] == 7.0).all() and (later["t"] == 9.0).all()
    snapshot.close()


def test_host_copy_lands_in_the_array_it_is_given():
    """engine.host_copy fills the host array it is given (the engine reads its final fields back
    into arrays allocated and touched while a GPU integrates: landing_arrays, used on every device)
    and refuses one of another shape, dtype or layout, or a read-only one, naming both."""
    import warp as wp

    from warpfric.engine import host_copy, touched_empty

    values = np.arange(12.0).reshape(3, 4)
    a = wp.array(values, dtype=wp.float64, device="cpu")
    out = touched_empty((3, 4), np.float64)
    assert host_copy(a, out) is out
    np.testing.assert_array_equal(out, values)
    np.testing.assert_array_equal(host_copy(a), values)
    read_only = np.empty((3, 4))
    read_only.flags.writeable = False
    for wrong in (np.empty((4, 3)), np.empty((3, 4), np.float32), np.empty((4, 3)).T, read_only):
        with pytest.raises(ValueError, match=r"must be the device array's float64\(3, 4\)"):
            host_copy(a, wrong)


@pytest.mark.filterwarnings("ignore:Solver\\(lanes=:UserWarning")  # a team on the CPU's fibers
def test_the_member_order_changes_no_output(monkeypatch):
    """The kernel's members in the similar order (WARPFRIC_MEMBER_ORDER=similar, which the CPU's
    thread kernel takes only on request) give every output of the caller's order bit for bit, put
    back in the caller's order: the stress gate with the contact and velocity fronts (two passes:
    the second pass's members are chosen by the first's events) and two recorded members, in the
    thread kernel and (with the strength front) a team of 4 lanes; the order of these 5 members is
    not its own inverse, so a read-back through the wrong one fails. A bad value is refused."""
    values = {"eccentricity": [0.3, -0.2, 0.0, 0.6, -0.1], "normal_force": [300.0, 1000.0, 1000.0, 3000.0, 600.0]}
    record = wf.Record.window(20.1, 20.4, 4, members=(0, 3))
    order = member_order({k: np.asarray(v) for k, v in values.items()}, False, "similar")
    assert list(order[order]) != list(range(5))  # not its own inverse: reading back through it would show
    for lanes, events in ((1, ("contact", "velocity")), (4, ("contact", "strength"))):
        runs = {}
        for order_name in ("given", "similar"):
            monkeypatch.setenv("WARPFRIC_MEMBER_ORDER", order_name)
            runs[order_name] = run(values, nodes=20, rtol=1e-5, fronts=wf.Fronts(event=events), record=record,
                                   lanes=lanes)
            assert runs[order_name].attrs["member_order"] == order_name
        assert runs["given"].attrs["integration_passes"] == (2 if "velocity" in events else 1)
        for name, var in runs["given"].data_vars.items():
            np.testing.assert_array_equal(runs["similar"][name].values, var.values, err_msg=f"{lanes} lanes: {name}")
    monkeypatch.setenv("WARPFRIC_MEMBER_ORDER", "random")
    with pytest.raises(ValueError, match="WARPFRIC_MEMBER_ORDER='random'"):
        run(values, nodes=20, rtol=1e-5)


@pytest.mark.skipif(not DEVICE.startswith("cuda"), reason="warp shuffles, and so several members per block, need a GPU")
def test_members_in_one_block_give_the_outputs_of_one_member_per_block(monkeypatch):
    """Members that share a thread block wait for each other at every attempt; nothing else changes,
    so every output equals, bit for bit, that of one member per block: 11 members in blocks of 8
    (WARPFRIC_TEAM_BLOCK_MEMBERS: one block of 8 and one of 3 with 5 idle warps), the default law with the contact front, at
    N = 200 (32 lanes) and N = 40 (20 lanes: each warp's last 12 threads idle, and the team's
    reductions are trees, not butterflies). With the work in shared memory (the default) against
    the automatic choice for 11 members, one member per block, whose shared work array has the member
    stride 1 instead of 9: so the stride changes nothing either. With the work in global memory
    (WARPFRIC_TEAM_SHARED_WORK=0) against the layout of a block per member
    (WARPFRIC_TEAM_BLOCK_MEMBERS=1: one team of lanes a block, its work in global memory). The
    automatic choice is min(8, ceil(members / SMs)): one member more than the GPU has SMs runs two
    per block."""
    values = {"eccentricity": np.linspace(-0.3, 0.3, 11), "normal_force": np.geomspace(300.0, 3000.0, 11)}
    monkeypatch.delenv("WARPFRIC_TEAM_BLOCK_MEMBERS", raising=False)
    monkeypatch.delenv("WARPFRIC_TEAM_SHARED_WORK", raising=False)
    sms = wp.get_device(DEVICE).sm_count
    many = {"eccentricity": np.linspace(-0.3, 0.3, sms + 1)}
    assert run(many, nodes=40, rtol=1e-4).attrs["block_members"] == 2
    h100_sized = wp.get_device(DEVICE).max_shared_memory_per_block >= 232_448  # 8 members' work fits at N = 200 and 40

    def outputs(nodes, block_members, shared_work):
        for name, value in (("WARPFRIC_TEAM_BLOCK_MEMBERS", block_members), ("WARPFRIC_TEAM_SHARED_WORK", shared_work)):
            if value is None:
                monkeypatch.delenv(name, raising=False)
            else:
                monkeypatch.setenv(name, value)
        # lanes pinned: for 11 members lanes=None takes a team of several warps at N = 200
        return run(values, nodes=nodes, rtol=1e-5, fronts=wf.Fronts(), lanes=min(32, nodes // 2))

    for nodes, lanes in ((200, 32), (40, 20)):
        for shared_work in (None, "0"):
            together = outputs(nodes, "8", shared_work)
            alone = outputs(nodes, None if shared_work is None else "1", shared_work)
            assert together.attrs["lanes"] == alone.attrs["lanes"] == lanes
            assert together.attrs["work_memory"] == alone.attrs["work_memory"]
            if shared_work is None:
                assert together.attrs["block_members"] == 8 or not h100_sized
            else:
                assert together.attrs["work_memory"] == "global" and together.attrs["block_members"] == 8
            assert alone.attrs["block_members"] == 1
            assert (alone.status.values == 0).all()
            for name, var in alone.data_vars.items():
                np.testing.assert_array_equal(together[name].values, var.values,
                                              err_msg=f"N = {nodes}, shared work {shared_work}: {name}")


@pytest.mark.skipif(not DEVICE.startswith("cuda"), reason="the blocked kernel's shared work array needs a GPU")
@pytest.mark.parametrize("nodes, gate, method, lanes", [
    (200, "stress", "tr_bdf2", 32), (40, "stress", "tr_bdf2", 20), (300, "stress", "tr_bdf2", 32),
    (200, "none", "esdirk4", 32), (100, "velocity", "tr_bdf2", 32), (200, "stress", "tr_bdf2", 96)])
def test_shared_work_array_gives_the_global_work_array_outputs(nodes, gate, method, lanes, monkeypatch):
    """The work array in shared memory (the default where it fits) against the same kernel with its
    work in global memory (WARPFRIC_TEAM_SHARED_WORK=0): the same arithmetic, but the compiler fuses a
    few multiply-adds differently (1,643 against 1,640 DFMA at N = 200 on sm_90), so equal to
    round-off, not bit for bit: the same statuses, steps, rejections and Newton iterations, mu_s
    and mu_s_time within 1e-11 relative (2e-12 seen on the H100, 300 members with the contact
    front). And with the shared array filled with NaN at every launch's start
    (WARPFRIC_TEAM_POISON_SHARED_WORK=1), which a value read before its attempt wrote it would carry
    into the outputs: the same to round-off again. 11 members in blocks of 8 (requested; 7 at N =
    300, where 8 do not fit: stride 7, the largest shared array), the contact front with the stress
    gate; both integrators; the three laws. And a team of several warps (96 lanes, one member a
    block, stride 1: kernels/team.py make_warps_team), whose work sits beside its team buffer."""
    values = {"eccentricity": np.linspace(-0.3, 0.3, 11), "normal_force": np.geomspace(300.0, 3000.0, 11)}
    per_block = 8 if lanes <= 32 else 1
    if lanes <= 32:
        monkeypatch.setenv("WARPFRIC_TEAM_BLOCK_MEMBERS", "8")
    model = wf.Model(relaxation_gate=gate)
    fronts = wf.Fronts() if gate == "stress" else None
    runs = {}
    for name, shared, poison in (("shared", "1", "0"), ("poisoned", "1", "1"), ("global", "0", "0")):
        monkeypatch.setenv("WARPFRIC_TEAM_SHARED_WORK", shared)
        monkeypatch.setenv("WARPFRIC_TEAM_POISON_SHARED_WORK", poison)
        runs[name] = run(values, nodes=nodes, rtol=1e-5, fronts=fronts, model=model, method=method, lanes=lanes)
    assert runs["global"].attrs["work_memory"] == "global" and runs["global"].attrs["block_members"] == per_block
    if runs["shared"].attrs["work_memory"] != "shared":
        pytest.skip(f"the work array of N = {nodes} does not fit this GPU's shared memory")
    if nodes == 300 and wp.get_device(DEVICE).max_shared_memory_per_block >= 232_448:
        assert runs["shared"].attrs["block_members"] == 7
    assert (runs["global"].status.values == 0).all()
    for other in ("shared", "poisoned"):
        for name, var in runs["global"].data_vars.items():
            if var.dtype.kind in "iu":
                np.testing.assert_array_equal(runs[other][name].values, var.values, err_msg=f"{other}: {name}")
        for name in ("mu_s", "mu_s_time"):
            np.testing.assert_allclose(runs[other][name].values, runs["global"][name].values, rtol=1e-11, atol=0,
                                       err_msg=f"{other}: {name}")
