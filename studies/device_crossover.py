"""Where ``device=None`` should switch from the CPU to the GPU: small ensembles timed on both
(docs/performance.md, "Where device=None runs").

    python studies/device_crossover.py [--members 1 2 4 8 16 32 64] [--repeat 3] [--dtype float64]
                                       [--lanes L] [--jsonl FILE]

The engine benchmark's first M members (studies/bench_engine.py ``members``: e and F drawn), the
default law, N = 200, rtol 1e-5, float64 (``--dtype``), the default front (the contact front): what
``simulate(members)`` does when the caller names no device. On a GPU float64 runs the cooperative
kernel (a team of lanes per member), float32 or ``--lanes 1`` the thread-per-member kernel; the CPU
always runs the thread kernel. Each M on each device is timed twice:

* warm: in this process, after a first run that compiles or loads the kernels (a notebook's second
  call); the best of ``--repeat``;
* fresh: a new Python process that imports warpfric and runs the ensemble once, the kernels already
  in Warp's cache (the command line's ``warpfric run``): from before ``import warpfric`` to after
  ``simulate`` returns, so Warp's start-up (on a GPU host it initialises CUDA whatever the device)
  and the module load count; the best of ``--repeat`` processes.

The CPU runs as ``device='cpu'`` with the default workers (this process below ~2.5 s of work,
warpfric.pool), the GPU as ``device='cuda:0'``. Prints a table and, with --jsonl, one JSON line per
timing with the benchmark rows' fields (device, members, nodes, dtype, rtol, relaxation_gate,
fronts, method, wall_s, mu_s_error, commit), ``lanes`` (the Dataset's attribute: the lanes that ran)
and ``mode`` (warm / fresh). mu_s_error is against the first member's float64 rtol 1e-9 reference.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from bench_engine import members, reference_path, tree_commit  # noqa: E402

NODES = 200
RTOL = 1e-5

FRESH = """
import time
t0 = time.perf_counter()
import warpfric as wf
values = {values!r}
ds = wf.simulate(values, solver=wf.Solver(nodes={nodes}, rtol={rtol}, dtype={dtype!r}, lanes={lanes!r}), device={device!r},
                 progress=False)
print(time.perf_counter() - t0, int(ds.attrs["lanes"]), float(ds.mu_s.values[0]))
"""


def warm_time(m: int, device: str, repeat: int, dtype: str, lanes):
    """(best wall s, lanes, mu_s of the first member) of simulate() of m members in this process."""
    import warpfric as wf

    solver = wf.Solver(nodes=NODES, rtol=RTOL, dtype=dtype, lanes=lanes)
    values = members(m)
    ds = wf.simulate(values, solver=solver, device=device, progress=False)  # compile or load
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        ds = wf.simulate(values, solver=solver, device=device, progress=False)
        best = min(best, time.perf_counter() - t0)
    return best, int(ds.attrs["lanes"]), float(ds.mu_s.values[0])


def fresh_time(m: int, device: str, repeat: int, dtype: str, lanes):
    """(best wall s, lanes, mu_s of the first member) of a new process's import and simulate()."""
    best, ran, mu = float("inf"), 0, float("nan")
    values = {name: column.tolist() for name, column in members(m).items()}  # repr of a float is exact
    code = FRESH.format(values=values, nodes=NODES, rtol=RTOL, device=device, dtype=dtype, lanes=lanes)
    for _ in range(repeat):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
        best, ran, mu = min(best, float(out[-3])), int(out[-2]), float(out[-1])
    return best, ran, mu


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    ap.add_argument("--devices", nargs="+", default=["cpu", "cuda:0"])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dtype", default="float64", choices=["float64", "float32"])
    ap.add_argument("--lanes", type=int, default=None, help="Solver.lanes (default: automatic)")
    ap.add_argument("--jsonl", default=None)
    args = ap.parse_args(argv)
    commit = tree_commit()
    with open(reference_path("stress")) as f:
        reference = float(json.load(f)["mu_s"][0])  # the first member at rtol 1e-9, N = 200
    rows = []
    for m in args.members:
        for device in args.devices:
            for mode, timer in (("warm", warm_time), ("fresh", fresh_time)):
                wall, lanes, mu = timer(m, device, args.repeat, args.dtype, args.lanes)
                rows.append(dict(device=device, members=m, nodes=NODES, dtype=args.dtype, lanes=lanes, rtol=RTOL,
                                 relaxation_gate="stress", fronts="contact", method="tr_bdf2", wall_s=wall,
                                 mu_s_error=abs(mu - reference), commit=commit, mode=mode))
                print(json.dumps(rows[-1]), flush=True)
    if args.jsonl:
        with open(args.jsonl, "a") as f:
            for row in rows:
                f.write(json.dumps(row) + "\n")
    columns = [(d, mode) for mode in ("warm", "fresh") for d in args.devices]
    print("\n" + f"{'members':>7}" + "".join(f" {d + ' ' + mode:>13}" for d, mode in columns) + "  (wall s)")
    for m in args.members:
        cell = {(r["device"], r["mode"]): r["wall_s"] for r in rows if r["members"] == m}
        print(f"{m:>7}" + "".join(f" {cell[c]:>13.3f}" for c in columns))

if __name__ == "__main__":
    main()
