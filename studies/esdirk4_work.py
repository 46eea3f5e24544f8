"""ESDIRK4 against TR-BDF2: work and mu_s error of one member of the default scene (docs/model.md,
"Time integration", the ESDIRK4 table).

    python studies/esdirk4_work.py [--nodes 40] [--out studies/results/esdirk4_work_cpu.json]

CPU, fronts off, N = 40 by default; relative mu_s error against TR-BDF2 at rtol 1e-10 of the same law;
Newton iterations = bordered tridiagonal solves; wall of a second run (compiled kernels).
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import warpfric as wf

ROWS = {"none": {"tr_bdf2": (1e-6, 1e-7, 1e-8), "esdirk4": (1e-5, 1e-6, 1e-7)},
        "stress": {"tr_bdf2": (1e-6, 1e-7, 1e-8), "esdirk4": (1e-5, 1e-6, 1e-7, 1e-8)}}


def simulate(gate: str, method: str, rtol: float, nodes: int):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return wf.simulate(model=wf.Model(relaxation_gate=gate), fronts=None, device="cpu", progress=False, workers=1,
                           solver=wf.Solver(nodes=nodes, rtol=rtol, method=method, max_steps=10**7))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=40)
    ap.add_argument("--out", default=str(Path(__file__).with_name("results") / "esdirk4_work_cpu.json"))
    args = ap.parse_args(argv)
    rows = []
    print("| law | method | rtol | mu_s error | Newton it. | accepted + rejected | wall s |")
    print("|---|---|---|---|---|---|---|")
    for gate, methods in ROWS.items():
        ref = float(simulate(gate, "tr_bdf2", 1e-10, args.nodes).mu_s[0])
        for method, rtols in methods.items():
            for rtol in rtols:
                simulate(gate, method, rtol, args.nodes)  # compile, warm
                t0 = time.perf_counter()
                ds = simulate(gate, method, rtol, args.nodes)
                wall = time.perf_counter() - t0
                row = dict(law=gate, method=method, rtol=rtol, mu_s_error=abs(float(ds.mu_s[0]) / ref - 1),
                           newton_iterations=int(ds.newton_iterations[0]), accepted=int(ds.steps_accepted[0]),
                           rejected=int(ds.steps_rejected[0]), wall_s=wall, status=int(ds.status[0]))
                rows.append(row)
                print(f"| {gate} | {method} | {rtol:.0e} | {row['mu_s_error']:.1e} | {row['newton_iterations']} | "
                      f"{row['accepted']} + {row['rejected']} | {wall:.3f} |", flush=True)
    Path(args.out).write_text(json.dumps(dict(command="python studies/esdirk4_work.py " + " ".join(argv or []),
                                              nodes=args.nodes, rows=rows), indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
