"""Newton iterations per attempted step and the errors they leave: the bench members (those of
bench_engine.py; default 16) at N = 200 on the CPU, with the contact front, against a converged run
of the same members (rtol 1e-9, computed here first). docs/performance.md, "Newton's contraction".

    python studies/newton_iterations.py [--relaxation-gate stress] [--rtols 1e-4 1e-5 1e-6]
                                        [--members 16] [--nodes 200]

Prints, per rtol: Newton iterations per attempted step, attempts per member, and the largest
relative error of mu_s, mu_s_time, the main front's speed and its start time against the
converged run (with the count of members where one of the two has no value and the other has).
Run it at two commits to compare them.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import warpfric as wf  # noqa: E402
from bench_engine import members  # noqa: E402

OUTPUTS = ("mu_s", "mu_s_time", "v_main", "front_start_time")


def run(values, gate: str, nodes: int, rtol: float):
    return wf.simulate(values, model=wf.Model(relaxation_gate=gate),
                       solver=wf.Solver(nodes=nodes, rtol=rtol, max_steps=10**6), fronts=wf.Fronts(), device="cpu",
                       progress=False)


def largest_error(ds, ref, name: str):
    a, b = ds[name].values, ref[name].values
    both = np.isfinite(a) & np.isfinite(b)
    err = float(np.max(np.abs(a[both] / b[both] - 1))) if both.any() else float("nan")
    return err, int((np.isfinite(a) != np.isfinite(b)).sum())


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--relaxation-gate", default="stress")
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-4, 1e-5, 1e-6])
    ap.add_argument("--members", type=int, default=16)
    ap.add_argument("--nodes", type=int, default=200)
    args = ap.parse_args(argv)
    values = members(args.members)
    ref = run(values, args.relaxation_gate, args.nodes, 1e-9)
    print(f"{args.relaxation_gate} gate, {args.members} members, N = {args.nodes}, against rtol 1e-9")
    for rtol in args.rtols:
        ds = run(values, args.relaxation_gate, args.nodes, rtol)
        attempts = ds.steps_accepted.values + ds.steps_rejected.values
        errors = " ".join("{} {:.2e} ({} unmatched)".format(name, *largest_error(ds, ref, name)) for name in OUTPUTS)
        print(f"rtol {rtol:g}: Newton per attempt {ds.newton_iterations.values.sum() / attempts.sum():.3f}, "
              f"attempts per member {attempts.mean():.1f}; {errors}")


if __name__ == "__main__":
    main()
