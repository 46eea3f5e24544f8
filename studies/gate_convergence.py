"""Work against error of the stress gate's switch location (docs/model.md, "Gate switches").

    python studies/gate_convergence.py [--device cpu] [--nodes 100] [--out studies/results/gate_convergence_cpu.json]

For the default scene and e = +-0.2 (1000 N), against a float64 reference at rtol 1e-8 with located
switches: mu_s, mu_s_time and v_middle errors, accepted/rejected steps and wall time, for rtol
1e-4..1e-7, with the switches predicted and located (switch_tol = 1, predict_switches = True: the
default), located only by rejected steps (predict_switches = False) and not located (switch_tol =
inf: each switch at the end of the step in which it happens), and the gate-less law for the step
count it costs. Also the grid: mu_s at N = 25, 50, 100, 200 (rtol 1e-8). Prints a table last.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np

import warpfric as wf

MEMBERS = {"eccentricity": [0.0, 0.2, -0.2]}


def run(device, nodes, rtol, switch_tol=1.0, gate="stress", predict=True):
    t0 = time.perf_counter()
    ds = wf.simulate(MEMBERS, model=wf.Model(relaxation_gate=gate),
                     solver=wf.Solver(nodes=nodes, rtol=rtol, switch_tol=switch_tol, predict_switches=predict),
                     device=device, progress=False)
    return ds, time.perf_counter() - t0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--nodes", type=int, default=100)
    ap.add_argument("--out", default=str(Path(__file__).with_name("results") / "gate_convergence_cpu.json"))
    args = ap.parse_args(argv)
    run(args.device, 10, 1e-4)  # compile outside the timings
    ref, _ = run(args.device, args.nodes, 1e-8, predict=False)
    assert (ref.status.values == 0).all(), ref.status.values
    rows = []
    cases = [("predicted", 1.0, "stress", True), ("located", 1.0, "stress", False), ("unlocated", float("inf"), "stress", True),
             ("no gate", 1.0, "none", True)]
    for label, switch_tol, gate, predict in cases:
        for rtol in (1e-4, 1e-5, 1e-6, 1e-7):
            ds, wall = run(args.device, args.nodes, rtol, switch_tol, gate, predict)
            row = dict(case=label, rtol=rtol, status=ds.status.values.tolist(), wall_s=wall,
                       steps_accepted=ds.steps_accepted.values.tolist(), steps_rejected=ds.steps_rejected.values.tolist())
            if gate == "stress":
                row["mu_s_error"] = float(np.abs(ds.mu_s.values - ref.mu_s.values).max())
                row["mu_s_time_error"] = float(np.abs(ds.mu_s_time.values - ref.mu_s_time.values).max())
                row["v_middle_rel_error"] = float(np.nanmax(np.abs(ds.v_middle.values / ref.v_middle.values - 1)))
            rows.append(row)
    grid = []
    for n in (25, 50, 100, 200):
        ds, wall = run(args.device, n, 1e-8)
        grid.append(dict(nodes=n, mu_s=ds.mu_s.values.tolist(), v_middle=ds.v_middle.values.tolist(), wall_s=wall))
    out = dict(command="python studies/gate_convergence.py " + " ".join(argv or []), device=args.device, nodes=args.nodes,
               reference=dict(mu_s=ref.mu_s.values.tolist(), mu_s_time=ref.mu_s_time.values.tolist(),
                              v_middle=ref.v_middle.values.tolist(), steps=ref.steps_accepted.values.tolist()),
               rows=rows, grid=grid, warpfric=wf.__version__)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(out, indent=1))
    print(f"reference (N = {args.nodes}, rtol 1e-8): mu_s {np.round(ref.mu_s.values, 7)}")
    print(f"{'case':>10} {'rtol':>6} {'mu_s err':>9} {'t err':>9} {'v_mid err':>9} {'acc (e=0)':>9} {'rej (e=0)':>9} {'wall s':>7}")
    for r in rows:
        err = [f"{r[k]:9.1e}" if k in r else f"{'-':>9}" for k in ("mu_s_error", "mu_s_time_error", "v_middle_rel_error")]
        print(f"{r['case']:>10} {r['rtol']:6.0e} {' '.join(err)} {r['steps_accepted'][0]:9d} {r['steps_rejected'][0]:9d} {r['wall_s']:7.2f}")
    for g in grid:
        print(f"grid N = {g['nodes']:4d}: mu_s {np.round(g['mu_s'], 7)}  v_middle {np.round(g['v_middle'], 2)}")


if __name__ == "__main__":
    main()
