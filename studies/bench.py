"""One entry point for every measurement that docs/performance.md quotes.

    python studies/bench.py [--jsonl FILE] SUBCOMMAND [its options ...]
    python studies/bench.py SUBCOMMAND --help          # the options of one subcommand

Subcommands (each forwards its options unchanged to the script that does the work, so the
commands quoted in the docs with the script's own name keep working too):

  engine             wall time, members/s and mu_s error of simulate     studies/bench_engine.py
  cpu-workers        one process against the CPU worker processes        studies/bench_cpu_workers.py
  work-precision     error against time over rtol, N and precision       studies/work_precision.py
  stability          the hard-case map (status counts, lift-off)         studies/stability.py
  peers scipy|diffrax  the same equations in scipy BDF / JAX + diffrax   studies/baseline_scipy.py,
                                                                         studies/baseline_diffrax.py
  profile            one member: attempts and time per attempt against N (here)
  one-member         run one member's simulate a few times, untimed: the process a profiler
                     (Nsight Compute) attaches to (here; studies/gpu_bench.sh ncu-one)
  launch-chunks      outputs with launches of 7 attempts equal those of one launch (here)
  front-grid         v_left/v_middle/v_right against N and rtol          studies/front_grid.py
  front-events-grid  each front event's speeds against N (here)
  gate-convergence   the stress gate's switch treatments against rtol    studies/gate_convergence.py
  reference-scenes   the converged reference of the 18 scenes            studies/reference_scenes.py
  limits vibration|float32   the known limits' spot measurements         studies/known_limits.py

Every call appends one JSON line to --jsonl (default studies/results/bench.jsonl): the
subcommand, its arguments, the commit, the host, the wall time, the exit status, and the
script's own JSON result where it writes one (its rows), so that runs on several hosts can be
collected in one file. On a GPU host: `bash studies/gpu_bench.sh MODE` runs the presets that
produced the GPU numbers of docs/performance.md.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
DEFAULT_JSONL = HERE / "results" / "bench.jsonl"

from bench_engine import tree_commit  # noqa: E402  (WARPFRIC_COMMIT, else git's short HEAD)


def _option(argv: list[str], name: str) -> str | None:
    """The value of --name in argv (either '--name v' or '--name=v'), or None."""
    for i, a in enumerate(argv):
        if a == name and i + 1 < len(argv):
            return argv[i + 1]
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
    return None


def _read_json(path: str | None):
    if not path or not os.path.exists(path) or os.path.getsize(path) > 2_000_000:
        return None
    text = Path(path).read_text()
    if path.endswith(".jsonl"):
        lines = [json.loads(x) for x in text.splitlines() if x.strip()]
        return lines[-1] if lines else None
    try:
        return json.loads(text)
    except ValueError:
        return None


# --- measurements that live here --------------------------------------------------------------

def profile(argv):
    """One member of the default scene: wall time, attempts and Newton iterations against N."""
    import warpfric as wf

    ap = argparse.ArgumentParser(prog="bench.py profile", description=profile.__doc__)
    ap.add_argument("--device", default=None)
    ap.add_argument("--nodes", type=int, nargs="+", default=[64, 128, 200, 400, 800])
    ap.add_argument("--lanes", type=int, default=None, help="Solver.lanes (default: automatic)")
    ap.add_argument("--relaxation-gate", default="stress", choices=["stress", "none", "velocity"])
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions per N (the best is kept)")
    args = ap.parse_args(argv)
    kw = dict(device=args.device, progress=False, fronts=None, model=wf.Model(relaxation_gate=args.relaxation_gate))
    wf.simulate(solver=wf.Solver(nodes=args.nodes[0], lanes=args.lanes), **kw)  # compile
    rows = []
    print(f"{'N':>5} {'wall s':>8} {'attempts':>8} {'newton':>7} {'us/attempt':>10} {'us/newton':>9}")
    for n in args.nodes:
        best, ds = None, None
        for _ in range(args.repeat):
            t0 = time.perf_counter()
            ds = wf.simulate(solver=wf.Solver(nodes=n, lanes=args.lanes), **kw)
            wall = time.perf_counter() - t0
            best = wall if best is None else min(best, wall)
        att = int(ds.steps_accepted[0] + ds.steps_rejected[0])
        nw = int(ds.newton_iterations[0])
        row = dict(nodes=n, lanes=int(ds.attrs["lanes"]), device=str(ds.attrs.get("device", args.device)), wall_s=best,
                   attempts=att, newton_iterations=nw, us_per_attempt=1e6 * best / att, us_per_newton=1e6 * best / nw)
        rows.append(row)
        print(f"{n:5d} {best:8.3f} {att:8d} {nw:7d} {row['us_per_attempt']:10.1f} {row['us_per_newton']:9.1f}")
    return dict(relaxation_gate=args.relaxation_gate, rows=rows)


def one_member(argv):
    """Run one member of the default scene --times times (untimed): the target of a profiler."""
    import warpfric as wf

    ap = argparse.ArgumentParser(prog="bench.py one-member", description=one_member.__doc__)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, default=32)
    ap.add_argument("--times", type=int, default=2)
    ap.add_argument("--lineinfo", action="store_true", help="compile with line information (wp.config.lineinfo)")
    args = ap.parse_args(argv)
    if args.lineinfo:
        import warp as wp

        wp.config.lineinfo = True
    for _ in range(args.times):
        wf.simulate(solver=wf.Solver(nodes=args.nodes, lanes=args.lanes), device=args.device, progress=False, fronts=None)
    return None


def launch_chunks(argv):
    """Queued launches: 64 members with fronts, launches of 7 attempts against one launch of
    100,000; every output must be equal bit for bit."""
    import numpy as np

    import warpfric as wf

    ap = argparse.ArgumentParser(prog="bench.py launch-chunks", description=launch_chunks.__doc__)
    ap.add_argument("--device", default=None)
    ap.add_argument("--nodes", type=int, default=200)
    args = ap.parse_args(argv)
    m = {"eccentricity": np.linspace(-0.2, 0.2, 64), "normal_force": np.geomspace(500, 5000, 64)}
    runs = [wf.simulate(m, solver=wf.Solver(nodes=args.nodes, steps_per_launch=k), fronts=wf.Fronts(),
                        device=args.device, progress=False) for k in (100_000, 7)]
    bad = [v for v in runs[0].data_vars if np.issubdtype(runs[0][v].dtype, np.number)
           and not np.array_equal(runs[0][v].values, runs[1][v].values, equal_nan=True)]
    ok = int((runs[1].status.values == 0).sum())
    print(f"launches of 7 vs 100000 attempts, lanes {runs[0].attrs['lanes']}: differing outputs: {bad or 'none'}; "
          f"ok members: {ok} of 64")
    return dict(lanes=int(runs[0].attrs["lanes"]), nodes=args.nodes, differing_outputs=bad, ok_members=ok)


def front_events_grid(argv):
    """Each front event's precursor / main / far speeds of the first front, and the first and second
    fronts' whole speeds (m/s), against N, default scene at e = -0.2 and 0, stress gate, rtol 1e-5
    (docs/performance.md, "Fronts: cost and convergence")."""
    import warpfric as wf

    ap = argparse.ArgumentParser(prog="bench.py front-events-grid", description=front_events_grid.__doc__)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--nodes", type=int, nargs="+", default=[50, 100, 200, 400])
    ap.add_argument("--out", default=str(HERE / "results" / "front_speeds_by_nodes_cpu.json"))
    args = ap.parse_args(argv)
    events = ("contact", "strength", "velocity")
    rows = []
    for n in args.nodes:
        ds = wf.simulate({"eccentricity": [-0.2, 0.0]}, solver=wf.Solver(nodes=n), fronts=wf.Fronts(event=events),
                         device=args.device, progress=False)
        for k, e in enumerate(ds.eccentricity.values):
            row = dict(nodes=n, e=float(e))
            for i, ev in enumerate(events):
                pre = "" if i == 0 else ev + "_"
                row[ev] = {seg: float(ds[f"{pre}v_{seg}"].values[k])
                           for seg in ("precursor", "main", "far", "first", "second")}
                row[ev]["collision_position"] = float(ds[f"{pre}collision_position"].values[k])
            rows.append(row)
            print(json.dumps(row), flush=True)
    Path(args.out).write_text(json.dumps(rows, indent=1))
    print(f"wrote {args.out}")
    return rows


# --- the subcommands ----------------------------------------------------------------------------

SCRIPTS = {
    "engine": ("bench_engine", "--out"),
    "cpu-workers": ("bench_cpu_workers", "--out"),
    "work-precision": ("work_precision", "--out"),
    "stability": ("stability", None),
    "front-grid": ("front_grid", "--out"),
    "gate-convergence": ("gate_convergence", "--out"),
    "reference-scenes": ("reference_scenes", None),
}
HERE_FUNCS = {"profile": profile, "one-member": one_member, "launch-chunks": launch_chunks,
              "front-events-grid": front_events_grid}
PEERS = {"scipy": "baseline_scipy", "diffrax": "baseline_diffrax"}


def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--jsonl", default=str(DEFAULT_JSONL), help="append one JSON line per call here")
    ap.add_argument("subcommand", choices=sorted([*SCRIPTS, *HERE_FUNCS, "peers", "limits"]))
    ap.add_argument("args", nargs=argparse.REMAINDER, help="the subcommand's own options")
    args = ap.parse_args(argv)
    sub, rest = args.subcommand, list(args.args)
    if sub == "peers" and rest in (["-h"], ["--help"]):
        print("bench.py peers scipy|diffrax [options]: the peer baselines (`bench.py peers scipy --help` lists "
              "each one's options)")
        return
    if sub == "peers" and (not rest or rest[0] not in PEERS):
        ap.error("peers needs 'scipy' or 'diffrax' first, e.g. bench.py peers scipy --nodes 40")
    result, out_path, tmp = None, None, None
    t0 = time.perf_counter()
    status = 0
    try:
        if sub in HERE_FUNCS:
            result = HERE_FUNCS[sub](rest)
        elif sub in SCRIPTS:
            module, out_flag = SCRIPTS[sub]
            if sub == "engine" and _option(rest, "--out") is None and "-h" not in rest and "--help" not in rest:
                # bench_engine.py writes bench_engine.json into the working directory by default;
                # through bench.py its rows go into the JSON line instead
                tmp = tempfile.NamedTemporaryFile(suffix=".json", delete=False).name
                rest += ["--out", tmp]
            __import__(module).main(rest)
            if out_flag:
                out_path = _option(rest, out_flag)
                if sub == "cpu-workers" and out_path is None:
                    out_path = str(HERE / "results" / "bench_cpu_workers.jsonl")
        elif sub == "peers":
            which, rest = rest[0], rest[1:]
            __import__(PEERS[which]).main(rest)
            out_path = _option(rest, "--out")
        elif sub == "limits":
            import known_limits

            known_limits.main(rest)
    except SystemExit as exc:  # argparse's --help or an error inside a script
        status = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if "-h" in rest or "--help" in rest or status == 2:  # help, or argparse's usage error: nothing was run
            return status
    if result is None:
        result = _read_json(tmp or out_path)
    if tmp:
        os.unlink(tmp)
        out_path = None
    line = dict(bench=sub, args=rest if tmp is None else rest[:-2], command="python studies/bench.py " + " ".join(argv),
                commit=tree_commit(), time=time.strftime("%Y-%m-%d %H:%M:%S"), host=platform.node(),
                platform=platform.platform(), wall_s=time.perf_counter() - t0, exit=status, output_file=out_path,
                result=result)
    Path(args.jsonl).parent.mkdir(parents=True, exist_ok=True)
    with open(args.jsonl, "a") as f:
        f.write(json.dumps(line, default=str) + "\n")
    print(f"appended to {args.jsonl}")
    return status


if __name__ == "__main__":
    sys.exit(main())
