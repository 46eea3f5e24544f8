"""Engine benchmark: wall time, realisations/s and node-steps/s of warpfric.simulate for ensembles
of M = 1, 100, 1000, 10000 members, N = 200 nodes, the full protocol (t = 0..22 s), and the
accuracy of mu_s against a converged float64 run of the same members.

    python studies/bench_engine.py [--device cpu|cuda:0] [--members 1 100 1000 10000]
                                   [--dtypes float64 float32] [--rtol 1e-5] [--nodes 200]
                                   [--fronts] [--relaxation-gate stress|none|velocity] [--out bench_engine.json]
                                   [--lanes 1 32] [--predict-switches on off] [--methods tr_bdf2 esdirk4]
                                   [--steps-per-launch 500 100] [--launch-log FILE.jsonl] [--cuda-profile-range]

--fronts adds the front metrics (a second integration pass plus the segmentation kernel); without
it the engine alone is timed (simulate(fronts=None)).

Members vary: eccentricity uniform in [-0.2, 0.2] and normal force log-uniform in [500, 5000] N
(seed 0), so the steps differ between members as in a real study. The accuracy column is the
largest relative error of mu_s over the first 16 members against a converged float64 run
(rtol = 1e-9, same N, same friction law), stored in studies/reference/ and made with --make-reference.
--lanes: threads per member (Solver.lanes; 1 the thread-per-member kernel, > 1 the cooperative
kernel, float64 only; default: the automatic choice). --predict-switches: Solver.predict_switches
values to time (stress gate; default: on). --methods: Solver.method values to time. --steps-per-launch: Solver.steps_per_launch values.
--launch-log: where the kernel time goes, launch by launch (one more, synchronised run per timing).
--cuda-profile-range: only the timed runs are profiled by `ncu --profile-from-start off`.
--lineinfo: the kernels carry line information (for Nsight Compute's source view). Compilation is
excluded: before the first timed run of each kernel, a warm-up run of the same members to
t = 20.01 s compiles it (or loads it from Warp's cache); the kernel depends on the member count
through the team size and the block's layout. float32 is skipped with the stress gate, which
refuses it (docs/model.md, "Precision").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np
import warp as wp

import warpfric as wf
from warpfric.engine import run_layout


def reference_path(gate: str, nodes: int = 200) -> str:
    """The gate-less reference keeps its original name (made before the gate existed); N other than
    200 adds _n{N}."""
    suffix = ("" if gate == "none" else f"_{gate}") + ("" if nodes == 200 else f"_n{nodes}")
    return str(Path(__file__).with_name("reference") / f"bench_members_mu_s{suffix}.json")


def members(m: int, seed: int = 0) -> dict:
    """The first k members are the same whatever m (one random stream per parameter)."""
    return {
        "eccentricity": np.random.default_rng([seed, 0]).uniform(-0.2, 0.2, m),
        "normal_force": np.exp(np.random.default_rng([seed, 1]).uniform(np.log(500.0), np.log(5000.0), m)),
    }


def kernel_key(solver, device: str, m: int) -> tuple:
    """What of the integrate kernel a run of m members decides: its lanes and its shared work
    array's (nodes, member stride), as warpfric.engine.run chooses them (run_layout)."""
    lanes, layout = run_layout(solver, device, m)
    return lanes, layout.shared_work


def tree_commit() -> str:
    """The commit of the timed tree for a result row: WARPFRIC_COMMIT, which names the tree where
    there is no git (a GPU host that got a copy of it), else git's short HEAD, with "+modified" where
    the tracked files of warpfric/, kernels/ or studies/ (but its results) differ from it (a copy of a newer tree over
    an older git folder named the older commit), else "unknown"."""
    if os.environ.get("WARPFRIC_COMMIT"):
        return os.environ["WARPFRIC_COMMIT"]
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                              cwd=root).stdout.strip()
        changed = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "warpfric", "kernels",
                                  "studies", ":(exclude)studies/results"], capture_output=True, text=True,
                                 cwd=root).stdout.strip()
    except OSError:  # no git on this host
        return "unknown"
    return (head + ("+modified" if changed else "")) if head else "unknown"


def profiler(on: bool, what: str):
    """cuProfilerStart / cuProfilerStop of the CUDA driver (the current context), when ``on``."""
    if on:
        import ctypes

        wp.synchronize()
        getattr(ctypes.CDLL("libcuda.so.1"), "cuProfilerStart" if what == "start" else "cuProfilerStop")()


def write_launch_log(path: str, row: dict, values: dict, model, solver, fronts, device: str):
    """Where the kernel time goes, launch by launch: one more run of the ensemble with every
    integrate launch synchronised and timed (warpfric.engine.LAUNCH_LOG), appended to ``path`` as
    JSON lines (the timed row's settings, then per launch: kernel_s, running_members, attempts,
    max_member_attempts, newton_iterations), and a one-line summary: the kernel time, and the share
    of it spent in launches where fewer members ran than the GPU holds at once (tail)."""
    from warpfric import engine

    engine.LAUNCH_LOG = []
    try:
        wf.simulate(values, model=model, solver=solver, fronts=fronts, device=device, progress=False)
        log = [dataclasses.asdict(r) for r in engine.LAUNCH_LOG]
    finally:
        engine.LAUNCH_LOG = None
    resident = None
    if str(device).startswith("cuda"):
        # one-warp blocks, register-limited to 8 per SM (255 registers per thread; ncu)
        resident = wp.get_device(device).sm_count * 8
    keys = ("members", "nodes", "lanes", "relaxation_gate", "fronts", "steps_per_launch", "device", "commit")
    with open(path, "a") as f:
        for r in log:
            f.write(json.dumps({**{k: row[k] for k in keys}, **r}) + "\n")
    total = sum(r["kernel_s"] for r in log)
    tail = sum(r["kernel_s"] for r in log if resident is not None and r["running_members"] < resident)
    tail_text = (f", in launches with fewer running members than the {resident} the GPU holds: {tail:.3f} s"
                 if resident is not None else "")
    print(f"launch log: {len(log)} launches, kernel {total:.3f} s{tail_text}", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--members", type=int, nargs="+", default=[1, 100, 1000, 10000])
    ap.add_argument("--dtypes", nargs="+", default=["float64", "float32"])
    ap.add_argument("--rtol", type=float, default=1e-5)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--fronts", action="store_true", help="front metrics on (the default event, contact); same as --front-events contact")
    ap.add_argument("--front-events", nargs="+", default=None, choices=["off", "contact", "strength", "velocity"],
                    help="time each of these front settings (off: fronts=None; velocity costs a second pass)")
    ap.add_argument("--repeat", type=int, default=1, help="timed repetitions (the best is kept)")
    ap.add_argument("--out", default="bench_engine.json")
    ap.add_argument("--relaxation-gate", default="stress", choices=["stress", "none", "velocity"])
    ap.add_argument("--lanes", type=int, nargs="+", default=[None], help="Solver.lanes values to time (default: auto)")
    ap.add_argument("--predict-switches", nargs="+", default=["on"], choices=["on", "off"],
                    help="Solver.predict_switches values to time (the stress gate's predicted switches)")
    ap.add_argument("--methods", nargs="+", default=["tr_bdf2"], choices=["tr_bdf2", "esdirk4"],
                    help="Solver.method values to time")
    ap.add_argument("--reference", default=None,
                    help="JSON with mu_s of the first 16 members (float64, rtol 1e-9); made with --make-reference "
                         "(default: studies/reference/bench_members_mu_s[_GATE].json)")
    ap.add_argument("--jsonl", default=None, help="also append each timing as a JSON line to this file")
    ap.add_argument("--make-reference", action="store_true", help="compute the reference (on --device) and exit")
    ap.add_argument("--steps-per-launch", type=int, nargs="+", default=[None],
                    help="Solver.steps_per_launch values to time (default: the Solver's)")
    ap.add_argument("--cuda-profile-range", action="store_true",
                    help="wrap each timed run in cuProfilerStart/Stop, for `ncu --profile-from-start off` "
                         "(the warm-up's compile run is then not profiled)")
    ap.add_argument("--host-profile", action="store_true",
                    help="after each timing, profile one more run with cProfile and print its 20 costliest calls "
                         "(cumulative) and 15 costliest functions (own time): where the host time around the kernels goes")
    ap.add_argument("--launch-log", default=None,
                    help="after each timing, run the same ensemble once more with every launch synchronised and "
                         "timed (warpfric.engine.LAUNCH_LOG) and append its launches as JSON lines to this file")
    ap.add_argument("--lineinfo", action="store_true",
                    help="compile the kernels with line information (wp.config.lineinfo: Nsight Compute's source "
                         "view, studies/stall_sites.py); a kernel of its own, same code")
    args = ap.parse_args(argv)
    if args.lineinfo:
        wp.config.lineinfo = True
    device = args.device or wf.default_device()
    n_check = 16
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    args.reference = args.reference or reference_path(args.relaxation_gate, args.nodes)

    if args.make_reference:
        t0 = time.perf_counter()
        ref = wf.simulate(members(n_check), model=model, solver=wf.Solver(nodes=args.nodes, rtol=1e-9, max_steps=10**6),
                          fronts=None, device=device, progress=False)
        with open(args.reference, "w") as f:
            json.dump(dict(nodes=args.nodes, rtol=1e-9, dtype="float64", device=device, relaxation_gate=args.relaxation_gate,
                           wall_s=time.perf_counter() - t0, mu_s=ref.mu_s.values.tolist(),
                           steps_accepted=ref.steps_accepted.values.tolist()), f, indent=1)
        print(f"wrote {args.reference}")
        return
    with open(args.reference) as f:
        reference = json.load(f)
    if reference["nodes"] != args.nodes:
        raise SystemExit(f"--reference was made with nodes={reference['nodes']}, not {args.nodes}")
    ref_mu = np.asarray(reference["mu_s"])
    rows = []
    front_events = args.front_events or (["contact"] if args.fronts else ["off"])
    commit = tree_commit()
    for dtype, lanes, predict, method, event, spl in [(d, k, p, me, ev, sp) for d in args.dtypes for k in args.lanes
                                                      for p in args.predict_switches for me in args.methods
                                                      for ev in front_events for sp in args.steps_per_launch]:
        fronts = None if event == "off" else wf.Fronts(event=event)
        if dtype == "float32" and args.relaxation_gate == "stress":
            print("float32 skipped: the stress gate needs float64")
            continue
        if dtype == "float32" and lanes not in (None, 1):
            continue  # the cooperative kernel is float64 only
        solver = wf.Solver(nodes=args.nodes, dtype=dtype, rtol=args.rtol, lanes=lanes, predict_switches=predict == "on",
                           method=method, **({} if spl is None else dict(steps_per_launch=spl)))
        build_s_of = {}  # the kernel's (lanes, shared work array) -> the warm-up's kernel build time (s)
        for m in args.members:
            # compile (or load) the kernel this member count runs: the automatic team size and the
            # block's shared work array (its member stride) depend on the members, so a warm-up of
            # one member would leave a timed run of another size to compile its own kernel
            key = kernel_key(solver, device, m)
            if key not in build_s_of:
                with warnings.catch_warnings():  # it ends before any peak: no_peak by design, not a failure to report
                    warnings.simplefilter("ignore")
                    warm = wf.simulate(members(m), scene=wf.Parameters(end_time=20.01), model=model, solver=solver,
                                       fronts=fronts, device=device, progress=False)
                build_s_of[key] = float(warm.attrs.get("kernel_build_time_s", float("nan")))
                print(f"kernel build, {key[0]} lanes, shared work {key[1]} (compile, or load from Warp's cache): "
                      f"{build_s_of[key]:.1f} s", flush=True)
            build_s = build_s_of[key]
            best = None
            for _ in range(args.repeat):
                profiler(args.cuda_profile_range, "start")
                t0 = time.perf_counter()
                ds = wf.simulate(members(m), model=model, solver=solver, fronts=fronts, device=device, progress=False)
                wall = time.perf_counter() - t0
                profiler(args.cuda_profile_range, "stop")
                best = wall if best is None else min(best, wall)
            k = min(m, n_check)
            err = float(np.max(np.abs(ds.mu_s.values[:k] / ref_mu[:k] - 1)))
            steps = ds.steps_accepted.values + ds.steps_rejected.values
            row = dict(
                members=m, nodes=args.nodes, dtype=dtype, device=device, lanes=int(ds.attrs["lanes"]),
                team_exchange=ds.attrs.get("team_exchange", "none"), rtol=args.rtol, fronts=event,
                integration_passes=int(ds.attrs.get("integration_passes", 1)), commit=commit, mu_s_error=err,
                relaxation_gate=args.relaxation_gate, predict_switches=predict, method=method,
                lineinfo=bool(args.lineinfo), block_members=int(ds.attrs.get("block_members", 1)),
                work_memory=ds.attrs.get("work_memory", "global"), member_order=ds.attrs.get("member_order", "given"),
                mean_newton_iterations=float(ds.newton_iterations.values.mean()),
                wall_s=best,
                realisations_per_s=m / best, node_steps_per_s=float(steps.sum()) * args.nodes / best,
                mean_accepted_steps=float(ds.steps_accepted.values.mean()),
                mean_rejected_steps=float(ds.steps_rejected.values.mean()),
                mean_newton_per_step=float(ds.newton_iterations.values.sum() / max(steps.sum(), 1)),
                status_ok=int((ds.status.values == 0).sum()), mu_s_max_rel_error=err,
                steps_per_launch=solver.steps_per_launch, kernel_build_s=build_s,
                mean_rejected_error_test=float(ds.rejected_error_test.values.mean()),
                mean_rejected_newton=float(ds.rejected_newton.values.mean()),
                mean_rejected_switch=float(ds.rejected_switch.values.mean()),
                mean_missed_predictions=float(ds.missed_predictions.values.mean()),
                max_attempts=int(steps.max()), median_attempts=float(np.median(steps)),
                rerun_in_float64=int((ds.working_precision.values == 64).sum()) if dtype == "float32" else 0,
            )
            rows.append(row)
            print(json.dumps(row), flush=True)
            if args.host_profile:
                import cProfile
                import pstats

                with cProfile.Profile() as prof:
                    wf.simulate(members(m), model=model, solver=solver, fronts=fronts, device=device, progress=False)
                pstats.Stats(prof).sort_stats("cumulative").print_stats(20)
                pstats.Stats(prof).sort_stats("tottime").print_stats(15)
            if args.launch_log:
                write_launch_log(args.launch_log, row, members(m), model, solver, fronts, device)
            if args.jsonl:
                with open(args.jsonl, "a") as f:
                    f.write(json.dumps(row) + "\n")
    meta = dict(platform=platform.platform(), processor=platform.processor(), warpfric=wf.__version__,
                command="python studies/bench_engine.py " + " ".join(argv or []))
    with open(args.out, "w") as f:
        json.dump(dict(meta=meta, rows=rows), f, indent=1)
    print(f"\n{'M':>6} {'N':>4} {'dtype':>8} {'method':>8} {'lanes':>5} {'pred':>4} {'fronts':>8} {'device':>7} {'wall s':>8} {'real/s':>9} {'node-steps/s':>13} "
          f"{'acc steps':>9} {'rej':>5} {'ok':>6} {'mu_s err':>9}")
    for r in rows:
        print(f"{r['members']:>6} {r['nodes']:>4} {r['dtype']:>8} {r['method']:>8} {r['lanes']:>5} {r['predict_switches']:>4} {str(r['fronts']):>8} {r['device']:>7} {r['wall_s']:8.3f} "
              f"{r['realisations_per_s']:9.1f} {r['node_steps_per_s']:13.3e} {r['mean_accepted_steps']:9.1f} "
              f"{r['mean_rejected_steps']:5.1f} {r['status_ok']:>6} {r['mu_s_max_rel_error']:9.2e}")


if __name__ == "__main__":
    main()
