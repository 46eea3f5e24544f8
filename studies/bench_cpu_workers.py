"""CPU worker processes against one process: wall time of warpfric.simulate for the same ensemble
with workers=1 and with the default (workers=None: all cores of the CPU), each in a fresh Python
process, so that the first call pays what a user's first call pays (the worker processes' start,
Warp's init and the kernels loaded from Warp's cache; not a compile: a warm-up run fills the cache
first), and a second call in the same process shows the warm pool.

    python studies/bench_cpu_workers.py [--members 400] [--nodes 100] [--no-fronts]
                                        [--out studies/results/bench_cpu_workers.jsonl]

Members as in studies/bench_engine.py (eccentricity uniform in [-0.2, 0.2], normal force
log-uniform in [500, 5000] N, seed 0), the default friction law and solver, the default fronts (the
contact front) unless --no-fronts. Prints the times and the speed-ups, checks that both give the same outputs
(a SHA-256 over every variable's bytes) and appends one JSON line to --out.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time


def run_child(members: int, nodes: int, fronts: bool, workers: int | None) -> dict:
    """In this (fresh) process: two calls of simulate; their wall times and the outputs' hash."""
    import warpfric as wf
    from bench_engine import members as make_members

    kw = dict(solver=wf.Solver(nodes=nodes), fronts=wf.Fronts() if fronts else None, device="cpu", progress=False,
              workers=workers)
    times, runs = [], []
    for _ in range(2):
        t0 = time.perf_counter()
        runs.append(wf.simulate(make_members(members), **kw))
        times.append(time.perf_counter() - t0)
    ds = runs[0]
    digest = hashlib.sha256()
    for name in sorted(ds.variables):
        digest.update(name.encode())
        digest.update(ds[name].values.tobytes())
    return dict(first_s=times[0], second_s=times[1], workers=int(ds.attrs.get("workers", 1)),
                worker_start_s=float(ds.attrs.get("worker_start_time_s", 0.0)), sha256=digest.hexdigest(),
                status_ok=int((ds.status.values == 0).sum()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--members", type=int, default=400)
    ap.add_argument("--nodes", type=int, default=100)
    ap.add_argument("--no-fronts", action="store_true", help="fronts=None (one pass)")
    ap.add_argument("--out", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "results",
                                                  "bench_cpu_workers.jsonl"))
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)  # 'none' or an integer: one mode, JSON on stdout
    args = ap.parse_args(argv)
    fronts = not args.no_fronts
    if args.child is not None:
        workers = None if args.child == "none" else int(args.child)
        print(json.dumps(run_child(args.members, args.nodes, fronts, workers)))
        return

    def child(mode: str) -> dict:
        cmd = [sys.executable, os.path.abspath(__file__), "--child", mode, "--members", str(args.members),
               "--nodes", str(args.nodes)] + (["--no-fronts"] if args.no_fronts else [])
        res = subprocess.run(cmd, capture_output=True, text=True, check=True)
        return json.loads(res.stdout.strip().splitlines()[-1])

    subprocess.run([sys.executable, "-c", "import warpfric as wf; wf.simulate(solver=wf.Solver(nodes=%d), "
                    "device='cpu', progress=False)" % args.nodes], check=True, capture_output=True)  # fill the cache
    one = child("1")
    split = child("none")
    from warpfric.pool import cpu_cores

    row = dict(members=args.members, nodes=args.nodes, fronts=fronts, cores=cpu_cores(),
               one_process_s=one["first_s"], one_process_second_s=one["second_s"],
               workers=split["workers"], workers_first_s=split["first_s"], workers_second_s=split["second_s"],
               worker_start_s=split["worker_start_s"],
               speedup_first=one["first_s"] / split["first_s"], speedup_second=one["second_s"] / split["second_s"],
               equal_outputs=one["sha256"] == split["sha256"], status_ok=split["status_ok"],
               load_average=os.getloadavg()[0], platform=platform.platform(), time=time.strftime("%Y-%m-%d %H:%M:%S"),
               command="python studies/bench_cpu_workers.py " + " ".join(argv if argv is not None else sys.argv[1:]))
    print(f"{args.members} members, N = {args.nodes}, fronts {'on' if fronts else 'off'}, {row['cores']} cores")
    print(f"  one process : {one['first_s']:6.2f} s (second call {one['second_s']:6.2f} s)")
    print(f"  {row['workers']} workers   : {split['first_s']:6.2f} s (second call {split['second_s']:6.2f} s; "
          f"worker start {split['worker_start_s']:.2f} s)")
    print(f"  speed-up    : {row['speedup_first']:.2f}x first call, {row['speedup_second']:.2f}x warm pool; "
          f"outputs {'equal bit for bit' if row['equal_outputs'] else 'DIFFER'}")
    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    with open(args.out, "a") as f:
        f.write(json.dumps(row) + "\n")
    print(f"appended to {args.out}")


if __name__ == "__main__":
    main()
