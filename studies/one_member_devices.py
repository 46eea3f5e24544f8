"""One member on a CPU core against the GPU: the same member, the same settings, in one process
(docs/performance.md, "One member: a CPU core against the GPU").

    python studies/one_member_devices.py [--devices cpu cuda:0] [--repeat 10] [--jsonl FILE]

Two members, each alone in simulate(), fronts off, the default law, N = 200, rtol 1e-5, float64:
the default scene (Parameters()) and the engine benchmark's first member (studies/bench_engine.py
``members``: e and F drawn, 417 attempts). Each is run once to compile, then timed ``--repeat``
times; the best wall time is kept. On the CPU it is Warp's thread kernel on one core
(``workers=1``); on a GPU the automatic team. Prints a table and, with --jsonl, one JSON line per
timing: device, members, nodes, dtype, rtol, relaxation_gate, fronts, method, wall_s, mu_s_error,
commit (the fields of the benchmark rows), and member, lanes, attempts, mu_s (mu_s_error against
the benchmark's rtol 1e-9 reference for its member; none for the default scene).
"""

import argparse
import json
import sys
import time
from pathlib import Path

import warp as wp

import warpfric as wf
from warpfric.device import init_warp

sys.path.insert(0, str(Path(__file__).parent))
from bench_engine import members, reference_path, tree_commit  # noqa: E402


def timed(member, solver, device, repeat):
    """(best wall s, the last Dataset) of simulate() of one member."""
    kwargs = dict(solver=solver, fronts=None, device=device, progress=False)
    if device == "cpu":
        kwargs["workers"] = 1
    ds = wf.simulate(member, **kwargs)  # compile or load the kernels
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        ds = wf.simulate(member, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return best, ds


def main(argv=None):
    wp.config.quiet = True
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", nargs="+", default=["cpu"] + (["cuda:0"] if init_warp().get_cuda_device_count() else []))
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--jsonl", default=None)
    args = ap.parse_args(argv)
    commit = tree_commit()
    solver = wf.Solver(nodes=200, rtol=1e-5)
    with open(reference_path("stress")) as f:
        reference = {"bench member 0": json.load(f)["mu_s"][0]}  # rtol 1e-9, N = 200 (no reference for the scene)
    scenes = {"default scene": None, "bench member 0": {k: v[:1] for k, v in members(1).items()}}
    print(f"{'member':>15} {'device':>7} {'lanes':>5} {'wall ms':>8} {'attempts':>8} {'mu_s':>10}")
    for label, member in scenes.items():
        for device in args.devices:
            wall, ds = timed(member, solver, device, args.repeat)
            attempts = int(ds.steps_accepted.values[0] + ds.steps_rejected.values[0])
            print(f"{label:>15} {device:>7} {int(ds.attrs['lanes']):>5} {wall * 1e3:8.2f} {attempts:>8} "
                  f"{float(ds.mu_s.values[0]):10.6f}")
            if args.jsonl:
                row = dict(member=label, device=device, members=1, nodes=200, dtype="float64", rtol=1e-5,
                           relaxation_gate="stress", fronts="off", method="tr_bdf2", lanes=int(ds.attrs["lanes"]),
                           wall_s=wall, attempts=attempts, mu_s=float(ds.mu_s.values[0]),
                           mu_s_error=(abs(float(ds.mu_s.values[0]) / reference[label] - 1) if label in reference else None),
                           commit=commit)
                with open(args.jsonl, "a") as f:
                    f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
