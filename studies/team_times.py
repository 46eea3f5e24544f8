"""Wall time of warpfric.simulate for the bench_engine members (fronts off, compile excluded) with
given team sizes, nodes, rtols and ensemble sizes; mu_s of the first members is printed so that the
error can be read against another run of the same members (e.g. baseline_diffrax.py's warpfric rows).

    python studies/team_times.py --device cuda:0 --nodes 40 --lanes 1 16 --members 1 100 --rtols 1e-5 1e-6 --out T.json
"""
import argparse
import json
import time

import warpfric as wf
from bench_engine import members


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--device", default=None)
    ap.add_argument("--nodes", type=int, default=40)
    ap.add_argument("--lanes", type=int, nargs="+", default=[1, 16])
    ap.add_argument("--members", type=int, nargs="+", default=[1, 100])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-5, 1e-6])
    ap.add_argument("--relaxation-gate", default="none")
    ap.add_argument("--end-time", type=float, default=20.6)
    ap.add_argument("--out", default="team_times.json")
    args = ap.parse_args()
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    scene = wf.Parameters(end_time=args.end_time)
    rows = []
    for lanes in args.lanes:
        wf.simulate(members(1), scene=wf.Parameters(end_time=20.01), model=model,
                    solver=wf.Solver(nodes=args.nodes, lanes=lanes), device=args.device, progress=False)  # compile
        for rtol in args.rtols:
            for m in args.members:
                solver = wf.Solver(nodes=args.nodes, rtol=rtol, lanes=lanes)
                t0 = time.perf_counter()
                ds = wf.simulate(members(m), scene=scene, model=model, solver=solver, device=args.device, progress=False)
                row = dict(lanes=lanes, nodes=args.nodes, rtol=rtol, members=m, wall_s=time.perf_counter() - t0,
                           mu_s=ds.mu_s.values[:4].tolist(), ok=int((ds.status.values == 0).sum()))
                rows.append(row)
                print(json.dumps(row), flush=True)
    with open(args.out, "w") as f:
        json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
