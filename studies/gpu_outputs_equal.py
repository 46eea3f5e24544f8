"""Refactor guard on a GPU: every output of GPU-sized runs, saved or compared bit for bit.

    python studies/gpu_outputs_equal.py save FILE.npz [--device cuda:0]
    python studies/gpu_outputs_equal.py compare BEFORE.npz AFTER.npz

The runs: the engine benchmark's members (studies/bench_engine.py ``members``), the default law and
Solver, the contact front (the default ``simulate``): 1,100 at N = 200 (8 members a block on an
H100, member stride 9), 1,000 at N = 300 (7 a block, stride 7: the largest shared array), 300 at N =
40 (3 a block, stride 3) and the first member alone at N = 200 (stride 1), so that the cooperative
kernel runs in blocks of many members, a few and one (docs/model.md, "Time integration"). studies/outputs_equal.py is the CPU's guard (smaller scenes,
every law and model switch); this one checks what only a GPU runs: the blocked kernel, its
shared work array. ``compare`` prints how many arrays differ (integer outputs by name) and the
largest relative difference of mu_s; it exits 1 if any array differs.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_engine import members  # noqa: E402

import warpfric as wf  # noqa: E402

RUNS = ((200, 1100), (300, 1000), (40, 300), (200, 1))  # (nodes, members)


def save(path: str, device: str) -> None:
    out = {}
    for nodes, m in RUNS:
        ds = wf.simulate(members(m), solver=wf.Solver(nodes=nodes), device=device, progress=False, fronts=wf.Fronts())
        print(f"N = {nodes}, {m} members: {ds.attrs['block_members']} a block, work in {ds.attrs['work_memory']} memory")
        out.update({f"{nodes}_{m}_{name}": var.values for name, var in ds.data_vars.items()})
    np.savez(path, **out)
    print(f"saved {len(out)} arrays to {path}")


def compare(before: str, after: str) -> int:
    a, b = np.load(before), np.load(after)
    differ, worst_mu = [], 0.0
    for key in a.files:
        x, y = a[key], b[key]
        if not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            differ.append(key)
            if x.dtype.kind in "iu":
                print(f"integer output differs: {key}")
        if key.endswith("_mu_s"):
            worst_mu = max(worst_mu, float(np.nanmax(np.abs(x - y) / np.abs(x))))
    print(f"{len(a.files)} arrays compared, {len(differ)} differ {differ[:6]}; largest relative mu_s difference "
          f"{worst_mu:.3g}")
    return 1 if differ else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mode", choices=("save", "compare"))
    ap.add_argument("files", nargs="+")
    ap.add_argument("--device", default="cuda:0")
    args = ap.parse_args(argv)
    if args.mode == "save":
        save(args.files[0], args.device)
        return 0
    return compare(*args.files[:2])


if __name__ == "__main__":
    sys.exit(main())
