"""The measurements behind docs/performance.md, "Known limits" (CPU, float64 unless stated):

    python studies/known_limits.py vibration     # inviscid pad vibration: steps against rtol and damping
    python studies/known_limits.py float32       # float32 at low disc velocity against float64
    python studies/known_limits.py float32-wide  # float32 against float64 over members drawn wider
    python studies/known_limits.py stop-lift-off # a sudden stop of eccentric pads that lift off, with damping
    python studies/known_limits.py fronts-wide   # the contact front of 300 wide-range members at rtol 1e-5
    python studies/known_limits.py soft-interface  # steps of loaded pads with a soft interface (mu0/h)
    python studies/known_limits.py soft-interface-conditioning  # its ill-conditioned member against the width
    python studies/known_limits.py soft-interface-widths  # all 120 members' errors and conditioning by width
    python studies/known_limits.py soft-interface-flags  # whether outputs flag the ill-conditioned members
    python studies/known_limits.py default-stiffness-widths  # the sliding width at the default interface stiffness
    python studies/known_limits.py all
    (also: python studies/bench.py limits vibration|float32|all)
"""

from __future__ import annotations

import sys
import time

import warpfric as wf


def vibration():
    """The gate-less law (relaxation_gate 'none'), viscous_coefficient = 0, N = 40, protocol to 20.6
    s, fronts off, no straggler rule: accepted steps (in all, and before the disc starts at 20 s)
    and mu_s against rtol, with damping at rtol 1e-7, and with every grid's own velocity error
    filter (Solver.error_filter_nodes 0) against the filter of 200 nodes (the default from 9acd1f2
    to 38f2938) and today's default (800), with which rtol 1e-9 as well. The member that ends at
    20 s has no mu_s (NaN, a warning): it counts the steps of the loading."""
    import warnings

    print(f"{'filter':>6} {'rtol':>6} {'damping Pa s/m':>15} {'accepted':>9} {'by 20 s':>9} {'rejected':>9} "
          f"{'mu_s':>12} {'wall s':>7}")
    for filter_nodes in (0, 200, 800):
        rows = ((1e-5, 0.0), (1e-6, 0.0), (1e-7, 0.0), (1e-8, 0.0), (1e-7, 1e5), (1e-7, 1e6))
        if filter_nodes == 800:  # where the default filter lets the error control resolve the vibration
            rows += ((1e-9, 0.0),)
        for rtol, damping in rows:
            t0 = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the loading's member: no peak
                ds = wf.simulate({"viscous_coefficient": 0.0, "damping": damping, "end_time": [20.6, 20.0 + 1e-9]},
                                 model=wf.Model(relaxation_gate="none"), fronts=None, device="cpu",
                                 solver=wf.Solver(nodes=40, rtol=rtol, max_steps=10**7, stall_factor=float("inf"),
                                                  error_filter_nodes=filter_nodes))
            print(f"{filter_nodes:6d} {rtol:6.0e} {damping:15.0e} {int(ds.steps_accepted[0]):9d} "
                  f"{int(ds.steps_accepted[1]):9d} {int(ds.steps_rejected[0]):9d} {float(ds.mu_s[0]):12.9f} "
                  f"{time.perf_counter() - t0:7.2f}")


def float32():
    """Default scene (F = 1000 N) under the gate-less law (the stress gate refuses float32), N = 100,
    rtol 1e-5, fronts off, float32 and float64 at several disc velocities; mu_s error against
    float64 at rtol 1e-8."""
    print(f"{'v_d m/s':>8} {'f32 status':>10} {'f32 steps':>9} {'f32 mu_s err':>12} {'f64 mu_s err':>12}")
    law = wf.Model(relaxation_gate="none")
    for v in (1e-6, 1e-5, 1e-4, 1e-3):
        m = {"disc_velocity": [v]}
        a = wf.simulate(m, model=law, solver=wf.Solver(nodes=100, dtype="float32", max_steps=20000), fronts=None,
                        device="cpu")
        b = wf.simulate(m, model=law, solver=wf.Solver(nodes=100, dtype="float64", max_steps=20000), fronts=None,
                        device="cpu")
        c = wf.simulate(m, model=law, solver=wf.Solver(nodes=100, dtype="float64", rtol=1e-8, max_steps=10**6),
                        fronts=None, device="cpu")
        ref = float(c.mu_s[0])
        print(f"{v:8.0e} {int(a.status[0]):10d} {int(a.steps_accepted[0]):9d} {float(a.mu_s[0]) / ref - 1:12.2e} "
              f"{float(b.mu_s[0]) / ref - 1:12.2e}")


def float32_wide():
    """float32 against float64 over members drawn wider (12 members: e uniform in [-0.5, 0.5], F
    log-uniform in [100, 1e4] N, |v_max| log-uniform in [1e-6, 1e-2] m/s, the last 6 negative; numpy's
    default_rng(0), drawn in that order), N = 40, the gate-less law and the velocity gate, fronts off:
    the largest and median relative difference of mu_s at rtol 1e-4 and 1e-5."""
    import numpy as np

    rng = np.random.default_rng(0)
    n = 12
    members = {"eccentricity": rng.uniform(-0.5, 0.5, n), "normal_force": 10 ** rng.uniform(2, 4, n),
               "disc_velocity": np.r_[10 ** rng.uniform(-6, -2, n // 2), -10 ** rng.uniform(-6, -2, n - n // 2)]}
    print(f"{'gate':>9} {'rtol':>6} {'both ok':>8} {'largest':>9} {'median':>9}")
    for gate in ("none", "velocity"):
        for rtol in (1e-4, 1e-5):
            r = {dt: wf.simulate(members, model=wf.Model(relaxation_gate=gate), fronts=None, device="cpu", workers=1,
                                 solver=wf.Solver(nodes=40, rtol=rtol, dtype=dt, stall_factor=float("inf")))
                 for dt in ("float64", "float32")}
            ok = (r["float64"].status.values == 0) & (r["float32"].status.values == 0)
            d = np.abs(r["float32"].mu_s.values / r["float64"].mu_s.values - 1)[ok]
            print(f"{gate:>9} {rtol:6.0e} {int(ok.sum()):8d} {d.max():9.2e} {np.median(d):9.1e}")


def stop_lift_off():
    """A sudden stop at 21 s of eccentric pads that lift off (end 22 s, N = 40, rtol 1e-5, max_steps
    20,000, no straggler rule), without and with damping 1e6 Pa s/m: status, final time, accepted
    steps, mu at 22 s."""
    print(f"{'damping':>8} {'2e/L':>6} {'status':>7} {'final t s':>10} {'accepted':>9} {'mu_final':>11}")
    for damping in (0.0, 1e6):
        ds = wf.simulate({"eccentricity": [-0.35, -0.25, 0.45]}, fronts=None, device="cpu", workers=1,
                         scene=wf.Parameters(stop_time=21.0, end_time=22.0, damping=damping),
                         solver=wf.Solver(nodes=40, max_steps=20000, stall_factor=float("inf")))
        for m in range(ds.sizes["member"]):
            print(f"{damping:8.0e} {float(ds.eccentricity[m]):6.2f} {int(ds.status[m]):7d} {float(ds.final_time[m]):10.6f} "
                  f"{int(ds.steps_accepted[m]):9d} {float(ds.mu_final[m]):11.8f}")


def fronts_wide():
    """The contact front over 300 random members (seed 7: 2e/L uniform in [-0.6, 0.6], F log-uniform
    in 10 N-300 kN, |v| log-uniform in 1e-6-0.3 m/s with a random sign; N = 30, automatic end)
    with TR-BDF2 and ESDIRK4 at rtol 1e-5 against TR-BDF2 at rtol 1e-7: members whose front
    nucleates at another node, whose v_first is off by more than 10 %, whose mu_s is off by more
    than 1e-4 (relative), the attempted steps of all members (the reference's on its own line), and
    the moved members' first openings."""
    import warnings

    import numpy as np

    rng = np.random.default_rng(7)
    m = 300
    members = {"eccentricity": rng.uniform(-0.6, 0.6, m),
               "normal_force": np.exp(rng.uniform(np.log(10.0), np.log(3e5), m)),
               "disc_velocity": np.exp(rng.uniform(np.log(1e-6), np.log(0.3), m)) * rng.choice([-1, 1], m)}
    runs = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for method, rtol in (("tr_bdf2", 1e-7), ("tr_bdf2", 1e-5), ("esdirk4", 1e-5)):
            runs[method, rtol] = wf.simulate(members, solver=wf.Solver(nodes=30, method=method, rtol=rtol),
                                             device="cpu", progress=False)
    ref = runs["tr_bdf2", 1e-7]
    print(f"reference (tr_bdf2, rtol 1e-7): {int((ref.status.values == 0).sum())} ok, "
          f"{int((ref.steps_accepted + ref.steps_rejected).sum())} attempts")
    start = np.broadcast_to(np.asarray(ref.rest_until.values, dtype=float), (m,))
    print(f"{'method':>8} {'rtol':>6} {'ok':>4} {'nucleation moved':>17} {'v_first >10 %':>14} {'mu_s >1e-4 rel':>15} {'attempts':>9}")
    for (method, rtol), ds in runs.items():
        if ds is ref:
            continue
        moved = np.abs(ds.nucleation_position.values - ref.nucleation_position.values) > 1e-9
        moved &= np.isfinite(ds.nucleation_position.values) | np.isfinite(ref.nucleation_position.values)
        off = np.abs(ds.v_first.values / ref.v_first.values - 1) > 0.1
        mu_off = np.abs(ds.mu_s.values / ref.mu_s.values - 1) > 1e-4
        print(f"{method:>8} {rtol:6.0e} {int((ds.status.values == 0).sum()):4d} {int(moved.sum()):17d} "
              f"{int(off.sum()):14d} {int(mu_off.sum()):15d} {int((ds.steps_accepted + ds.steps_rejected).sum()):9d}  "
              f"(largest mu_s error {np.nanmax(np.abs(ds.mu_s.values / ref.mu_s.values - 1)):.1e})")
        for i in np.flatnonzero(moved):
            first = np.nanmin(ds.yield_time.values[i]) - start[i]
            first_ref = np.nanmin(ref.yield_time.values[i]) - start[i]
            print(f"    member {i:3d}: 2e/L {members['eccentricity'][i]:+.2f}, F {members['normal_force'][i]:9.1f} N, "
                  f"v {members['disc_velocity'][i]:+.2e} m/s: first opening {first * 1e3:8.3f} ms "
                  f"(rtol 1e-7: {first_ref * 1e3:8.3f} ms), v_first {float(ds.v_first[i]):.3g} "
                  f"({float(ref.v_first[i]):.3g}) m/s")


def soft_interface_members(seed=11, m=120):
    """The 120 members of soft_interface (seed 11; another seed or count: another sample of the same
    distribution), {parameter: (m,) array}."""
    import numpy as np

    rng = np.random.default_rng(seed)
    return {"eccentricity": rng.uniform(-0.6, 0.6, m),
            "normal_force": np.exp(rng.uniform(np.log(3e4), np.log(3e5), m)),
            "disc_velocity": np.exp(rng.uniform(np.log(1e-5), np.log(0.3), m)) * rng.choice([-1, 1], m),
            "interface_stiffness": np.exp(rng.uniform(np.log(1e12), np.log(1e14), m))}


F_FACTORS = (1.0, 1 + 1e-10, 1 + 1e-8, 1 + 1e-6)  # the normal force perturbed (relative) in the conditioning rows


def unlimited(values, width, rtol, nodes=30, max_steps=1_000_000, **options):
    """wf.simulate of ``values`` on the CPU without the straggler limit, its warnings silenced (the
    soft-interface checks: N = ``nodes``, sliding width ``width``, fronts off; ``options`` to simulate)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return wf.simulate(values, solver=wf.Solver(nodes=nodes, rtol=rtol, sliding_width=width, stall_factor=float("inf"),
                                                    max_steps=max_steps),
                           device="cpu", progress=False, fronts=None, **options)


def with_force_factors(values, k):
    """Member ``k`` of ``values`` four times, its normal force times each of F_FACTORS."""
    import numpy as np

    perturbed = {key: np.full(len(F_FACTORS), value[k]) for key, value in values.items()}
    perturbed["normal_force"] = values["normal_force"][k] * np.array(F_FACTORS)
    return perturbed


def with_force_nudged(values, factor=1 + 1e-10):
    """``values`` with every member's normal force times ``factor`` (the conditioning probe)."""
    return dict(values, normal_force=values["normal_force"] * factor)


def spread(x, above=()):
    """'median ..., 90th ..., largest ...' of the finite values of ``x``, then for each threshold of
    ``above`` how many lie above it ('3 above 1e-05' written as '3 above 1e-5')."""
    import numpy as np

    x = x[np.isfinite(x)]
    counts = "".join(f", {int((x > level).sum())} above {level:.0e}".replace("e-0", "e-") for level in above)
    return f"median {np.median(x):.1e}, 90th {np.percentile(x, 90):.1e}, largest {x.max():.1e}{counts}"


def soft_interface():
    """Steps of 120 loaded random members with a soft interface (seed 11: 2e/L uniform in [-0.6, 0.6],
    F log-uniform in 30-300 kN, |v| log-uniform in 1e-5-0.3 m/s with a random sign, interface_stiffness
    log-uniform in 1e12-1e14 Pa/m, 3-300x below the default 3e14; N = 30, rtol 1e-5, automatic end):
    the statuses, the accepted steps' median and 90th percentile, the costliest members, and for the
    costliest the steps and rejections by reason up to fractions of its time from the disc start to its
    automatic end (runs to fixed ends); then the three costliest at sliding widths 1e-2, 1e-3, 1e-4
    and at rtol 1e-5 to 1e-8; then the conditioning of the one whose mu_s moves most from rtol 1e-7
    to 1e-8: its normal force perturbed, at widths 1e-3 and 1e-2, and where two runs 1e-10 apart in F
    part (recorded fields)."""
    import warnings

    import numpy as np

    members = soft_interface_members()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = wf.simulate(members, solver=wf.Solver(nodes=30), device="cpu", progress=False, fronts=None)
    steps = ds.steps_accepted.values
    statuses = {name: int((ds.status.values == code).sum()) for code, name in
                enumerate(ds.status.attrs["flag_meanings"].split()) if (ds.status.values == code).any()}
    print(f"statuses {statuses}; accepted steps: median {np.median(steps):.0f}, 90th percentile "
          f"{np.percentile(steps, 90):.0f}, largest {steps.max()}")
    for i in np.argsort(steps)[::-1][:8]:
        print(f"    member {i:3d}: 2e/L {members['eccentricity'][i]:+.3f}, F {members['normal_force'][i] / 1e3:6.1f} kN, "
              f"v {members['disc_velocity'][i]:+.2e} m/s, mu0/h {members['interface_stiffness'][i]:.2e} Pa/m: "
              f"{steps[i]} steps, status {ds.status.values[i]}")
    worst = int(np.argmax(steps))
    one = {key: [value[worst]] for key, value in members.items()}
    start = float(np.asarray(ds.rest_until.values).ravel()[0])
    span = float(ds.final_time.values[worst]) - start
    print(f"  member {worst} to fixed ends (ms after the disc start; its automatic end at {span * 1e3:.1f} ms): "
          f"accepted, rejected by the error test / Newton / a switch, gate switches")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for after in span * np.array([0.25, 0.5, 0.75, 0.9, 1.0]):
            run = wf.simulate(one, scene=wf.Parameters(end_time=start + after), solver=wf.Solver(nodes=30),
                              device="cpu", progress=False, fronts=None).isel(member=0)
            print(f"    {after * 1e3:7.2f}: {int(run.steps_accepted):6d} {int(run.rejected_error_test):6d} "
                  f"{int(run.rejected_newton):6d} {int(run.rejected_switch):6d} {int(run.gate_switches):6d}")
    top = [int(i) for i in np.argsort(steps)[::-1][:3]]
    three = {key: value[top] for key, value in members.items()}
    print(f"  members {top} against the sliding gate's width (Solver.sliding_width; no straggler limit): "
          f"status, accepted steps, mu_s")
    by_width = {width: unlimited(three, width, 1e-5) for width in (1e-2, 1e-3, 1e-4)}
    for width, run in by_width.items():
        print(f"    {width:.0e}: {run.status.values.tolist()} {run.steps_accepted.values.tolist()} "
              f"{np.round(run.mu_s.values, 6).tolist()}")
    print(f"  the same members against rtol (width 1e-3, no straggler limit): status, accepted steps, mu_s")
    by_rtol = {}
    for rtol in (1e-5, 1e-6, 1e-7, 1e-8):
        run = by_width[1e-3] if rtol == 1e-5 else unlimited(three, 1e-3, rtol)  # rtol 1e-5: the width row's run
        by_rtol[rtol] = run.mu_s.values
        print(f"    {rtol:.0e}: {run.status.values.tolist()} {run.steps_accepted.values.tolist()} "
              f"{np.round(run.mu_s.values, 6).tolist()}")
    # the conditioning of the member whose mu_s moves most from rtol 1e-7 to 1e-8: its normal force
    # perturbed by 1e-10, 1e-8 and 1e-6 (relative), at two widths
    k = int(np.argmax(np.abs(by_rtol[1e-8] / by_rtol[1e-7] - 1)))
    perturbed = with_force_factors(three, k)
    print(f"  member {top[k]} with F times 1, 1 + 1e-10, 1 + 1e-8, 1 + 1e-6 (no straggler limit): mu_s, "
          f"accepted steps")
    for width, rtol in ((1e-3, 1e-7), (1e-3, 1e-8), (1e-2, 1e-7), (1e-2, 1e-8)):
        run = unlimited(perturbed, width, rtol)
        print(f"    width {width:.0e}, rtol {rtol:.0e}: {np.round(run.mu_s.values, 7).tolist()} "
              f"{run.steps_accepted.values.tolist()}")
        if width == 1e-3 and rtol == 1e-7:
            peak = float(run.mu_s_time.values[0])
    # where the two runs of F and F (1 + 1e-10) part: their friction stress fields recorded from the
    # disc start to the peak; a flip of a discrete decision would jump, an unstable mode grows
    pair = {key: value[:2] for key, value in perturbed.items()}
    times = wf.Record.window(start - 1e-3, peak, 2000, members=(0, 1))
    run = unlimited(pair, 1e-3, 1e-7, scene=wf.Parameters(end_time=peak + 1e-4), record=times)
    stress = run.friction_stress_history.values
    apart = np.abs(stress[0] - stress[1]).max(axis=1) / np.abs(stress[0]).max()
    when = ", ".join(f"{level:.0e} at {(run.time.values[np.argmax(apart > level)] - start) * 1e3:.1f} ms"
                     if (apart > level).any() else f"{level:.0e} never" for level in (1e-10, 1e-8, 1e-6, 1e-4, 1e-2))
    print(f"  F against F (1 + 1e-10), width 1e-3, rtol 1e-7: the friction stress fields' largest difference "
          f"(relative to the field's largest value) first exceeds {when} after the disc start (the peak at "
          f"{(peak - start) * 1e3:.1f} ms)")


def soft_interface_conditioning():
    """Whether the ill-conditioning of soft_interface's member 73 (2e/L -0.578, F 196 kN, v -0.075
    m/s, mu0/h 8.2e13 Pa/m: the member whose mu_s moves most from rtol 1e-7 to 1e-8 there) is the
    regularised sliding gate's or the sharp law's: its normal force times 1, 1 + 1e-10, 1 + 1e-8,
    1 + 1e-6 at rtol 1e-7 (no straggler limit), against Solver.sliding_width from 1e-2 to 1e-4 at
    N = 30 and at two widths at N = 60: mu_s, their spread (largest less smallest, relative to their
    mean), accepted steps, the wall time of the four; then soft_interface's three costliest members
    (113, 73, 85) at the width 3e-3 and rtol 1e-5 and 1e-7 (~4-5 minutes in all on a 2-core CPU)."""
    import numpy as np

    members = soft_interface_members()
    perturbed = with_force_factors(members, 73)
    print("  N  width   mu_s at F times 1, 1 + 1e-10, 1 + 1e-8, 1 + 1e-6                spread (rel.)  accepted "
          "steps                     wall s")
    for nodes, width in ((30, 1e-2), (30, 3e-3), (30, 1e-3), (30, 3e-4), (30, 1e-4), (60, 3e-3), (60, 3e-4)):
        t0 = time.perf_counter()
        run = unlimited(perturbed, width, 1e-7, nodes=nodes, max_steps=3_000_000)
        mu = run.mu_s.values
        print(f"  {nodes:2d}  {width:.0e}  {np.round(mu, 7).tolist()}  {(mu.max() - mu.min()) / mu.mean():.2e}       "
              f"{run.steps_accepted.values.tolist()}  {time.perf_counter() - t0:.0f}")
    three = {key: value[[113, 73, 85]] for key, value in members.items()}
    print("  members [113, 73, 85] at the width 3e-3, N = 30 (no straggler limit): rtol, status, accepted steps, mu_s")
    for rtol in (1e-5, 1e-7):
        run = unlimited(three, 3e-3, rtol)
        print(f"    {rtol:.0e}: {run.status.values.tolist()} {run.steps_accepted.values.tolist()} "
              f"{np.round(run.mu_s.values, 6).tolist()}")


def soft_interface_widths(widths=(1e-2, 3e-3, 1e-3)):
    """All 120 members of soft_interface at each sliding width (N = 30, no straggler limit): at rtol
    1e-5 and 1e-7, and at rtol 1e-7 with the normal force times 1 + 1e-10. Per width: the statuses,
    the accepted steps at rtol 1e-5 (median, largest, sum), mu_s's error at rtol 1e-5 against rtol
    1e-7 and its change under the perturbation (both relative: median, 90th percentile, largest,
    members above 1e-5 and 1e-4), and mu_s at rtol 1e-7 against the narrowest width's (its bias:
    median and largest). ~8 minutes on a 2-core CPU."""
    import numpy as np

    members = soft_interface_members()
    nudged = with_force_nudged(members)
    fine = {}
    for width in widths:
        t0 = time.perf_counter()
        coarse, ref, other = (unlimited(values, width, rtol, max_steps=3_000_000)
                              for values, rtol in ((members, 1e-5), (members, 1e-7), (nudged, 1e-7)))
        steps = coarse.steps_accepted.values
        ok = [int((r.status.values == 0).sum()) for r in (coarse, ref, other)]
        fine[width] = ref.mu_s.values
        print(f"  width {width:.0e} ({time.perf_counter() - t0:.0f} s): ok {ok[0]} / {ok[1]} / {ok[2]} of 120 "
              f"(rtol 1e-5 / 1e-7 / 1e-7 nudged); accepted steps at 1e-5: median {np.median(steps):.0f}, largest "
              f"{steps.max()}, sum {steps.sum()}")
        print(f"    mu_s at rtol 1e-5 against 1e-7: "
              f"{spread(np.abs(coarse.mu_s.values / ref.mu_s.values - 1), above=(1e-5, 1e-4))}")
        print(f"    mu_s at rtol 1e-7, F times 1 + 1e-10: "
              f"{spread(np.abs(other.mu_s.values / ref.mu_s.values - 1), above=(1e-5, 1e-4))}")
    narrow = min(widths)
    for width in widths:
        if width != narrow:
            bias = np.abs(fine[width] / fine[narrow] - 1)
            bias = bias[np.isfinite(bias)]
            print(f"  width {width:.0e} against {narrow:.0e} at rtol 1e-7: median {np.median(bias):.1e}, "
                  f"90th {np.percentile(bias, 90):.1e}, largest {bias.max():.1e}")


def soft_interface_flags(seeds=(11, 12)):
    """Whether outputs flag the ill-conditioned soft-interface members: for soft_interface's 120
    members (seed 11) and 120 more of the same distribution (seed 12), width 1e-3, N = 30, no
    straggler limit. Labels: mu_s at rtol 1e-7 moving by more than 1e-5 (relative) with the normal
    force times 1 + 1e-10. Rules read from the run at rtol 1e-5: the accepted steps against the
    ensemble's median (3x, 4x, 8x), the same perturbation at rtol 1e-5 (a second run), and the status
    stalled under simulate's straggler limit. Flagged members: caught (ill-conditioned) / false. ~9
    minutes on a 2-core CPU."""
    import warnings

    import numpy as np

    for seed in seeds:
        t0 = time.perf_counter()
        members = soft_interface_members(seed)
        nudged = with_force_nudged(members)
        fine, fine_nudged, run, run_nudged = (unlimited(values, 1e-3, rtol, max_steps=3_000_000)
                                              for values, rtol in ((members, 1e-7), (nudged, 1e-7), (members, 1e-5),
                                                                   (nudged, 1e-5)))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            default = wf.simulate(members, solver=wf.Solver(nodes=30), device="cpu", progress=False, fronts=None)
        change = np.abs(fine_nudged.mu_s.values / fine.mu_s.values - 1)
        ill = change > 1e-5
        order = np.argsort(-change)[:int(ill.sum())]
        print(f"  seed {seed} ({time.perf_counter() - t0:.0f} s): {int(ill.sum())} of 120 ill-conditioned "
              f"({int((change > 1e-4).sum())} above 1e-4): members {', '.join(map(str, sorted(order)))}; "
              f"changes {', '.join(f'{change[k]:.1e}' for k in order)}; the largest below 1e-5: "
              f"{change[~ill].max():.1e}")
        steps = run.steps_accepted.values
        ratio = steps / np.median(steps)
        probe = np.abs(run_nudged.mu_s.values / run.mu_s.values - 1)
        meanings = default.status.attrs["flag_meanings"].split()
        stalled = default.status.values == meanings.index("stalled")
        rules = [(f"steps >= {k} x the median", ratio >= k) for k in (3, 4, 8)]
        rules += [("a second run with F x (1 + 1e-10) at rtol 1e-5: mu_s moves >= 3e-6", probe >= 3e-6),
                  ("status stalled, simulate's straggler limit", stalled)]
        for text, flagged in rules:
            print(f"    {text}: {int((flagged & ill).sum())} / {int((flagged & ~ill).sum())}")
        ratios = ", ".join(f"{ratio[k]:.1f}" for k in order)
        print(f"    the ill-conditioned members' steps against the median: {ratios}")


def default_stiffness_widths(widths=(1e-4, 1e-3, 3e-3, 1e-2)):
    """The sliding width at the default interface stiffness (3e14 Pa/m): the engine benchmark's first
    60 members (2e/L in [-0.2, 0.2], F 500-5000 N, seed 0) and 60 wide loaded members (seed 21:
    soft_interface's distribution of 2e/L, F and v without its interface stiffness), N = 30, rtol
    1e-7, no straggler limit. Per width: accepted steps (median, sum) and mu_s against the narrowest
    width (relative: median, 90th percentile, largest); the members whose mu_s and steps are the
    same at every width; mu_s's change under F times 1 + 1e-10 at the default width; the wide
    members' grid error (N = 100 against N = 30, 12 members) beside the width's. ~2 minutes on a
    2-core CPU."""
    import numpy as np
    from bench_engine import members as bench_members  # (studies/, the script's folder, is on the path)

    wide = soft_interface_members(seed=21, m=60)
    del wide["interface_stiffness"]  # drawn last: the other draws are as without it
    samples = {"benchmark": bench_members(60), "wide loaded": wide}
    narrow, default = min(widths), wf.Solver().sliding_width

    for name, members in samples.items():
        t0 = time.perf_counter()
        runs = {width: unlimited(members, width, 1e-7, max_steps=3_000_000) for width in widths}
        nudged = unlimited(with_force_nudged(members), default, 1e-7, max_steps=3_000_000)
        ok = [int((run.status.values == 0).sum()) for run in runs.values()]
        print(f"  {name} ({time.perf_counter() - t0:.0f} s): ok {' / '.join(map(str, ok))} of 60 at widths "
              f"{' / '.join(f'{w:.0e}' for w in widths)}")
        same = np.ones(60, bool)
        for width, run in runs.items():
            steps = run.steps_accepted.values
            same &= (steps == runs[narrow].steps_accepted.values) & (run.mu_s.values == runs[narrow].mu_s.values)
            bias = "" if width == narrow else \
                f"; mu_s against {narrow:.0e}: {spread(np.abs(run.mu_s.values / runs[narrow].mu_s.values - 1))}"
            print(f"    width {width:.0e}: accepted steps median {np.median(steps):.0f}, sum {steps.sum()}{bias}")
        change = np.abs(nudged.mu_s.values / runs[default].mu_s.values - 1)
        print(f"    the same mu_s and steps at every width: {int(same.sum())} of 60; F times 1 + 1e-10 at "
              f"{default:.0e}: mu_s moves {spread(change)}")
        if name == "wide loaded":
            first = {key: value[:12] for key, value in members.items()}
            fine = unlimited(first, default, 1e-7, nodes=100, max_steps=3_000_000)
            grid = np.abs(fine.mu_s.values / runs[default].mu_s.values[:12] - 1)
            print(f"    its first 12 at N = 100 against N = 30 (width {default:.0e}): {spread(grid)}")


def main(argv=None):
    import argparse

    checks = {"vibration": vibration, "float32": float32, "float32-wide": float32_wide,
              "stop-lift-off": stop_lift_off, "fronts-wide": fronts_wide, "soft-interface": soft_interface,
              "soft-interface-conditioning": soft_interface_conditioning,
              "soft-interface-widths": soft_interface_widths, "soft-interface-flags": soft_interface_flags,
              "default-stiffness-widths": default_stiffness_widths}
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("check", nargs="?", default="all", choices=[*checks, "all"], help="which measurement (default all)")
    name = ap.parse_args(sys.argv[1:] if argv is None else argv).check
    for key in (checks if name == "all" else [name]):
        print(f"== {key}: {checks[key].__doc__.split(chr(10))[0]}")
        checks[key]()


if __name__ == "__main__":
    main()
