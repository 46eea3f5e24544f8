"""The cooperative kernel against the thread-per-member kernel on the same device: the members of
studies/outputs_equal.py (e = 0, -0.2, 0.3, 0.6 with lift-off) under each relaxation law, mu_s,
front speeds and statuses for several team sizes (lanes), and the largest relative difference
(they agree within the error control, not bit for bit).

    python studies/team_check.py [--device cuda:0] [--nodes 30] [--lanes 4 7 8 15]
                                   [--gates none velocity stress] [--out team_check.json]
"""

import argparse
import json

import numpy as np

import warpfric as wf
from outputs_equal import MEMBERS


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--nodes", type=int, default=30)
    ap.add_argument("--lanes", type=int, nargs="+", default=[4, 7, 8, 15])
    ap.add_argument("--gates", nargs="+", default=["none", "velocity", "stress"])
    ap.add_argument("--out", default="team_check.json")
    args = ap.parse_args(argv)
    device = args.device or wf.default_device()
    rows = []
    for gate in args.gates:
        fronts = wf.Fronts() if gate == "stress" else None
        model = wf.Model(relaxation_gate=gate)
        ref = wf.simulate(MEMBERS, model=model, solver=wf.Solver(nodes=args.nodes, lanes=1), fronts=fronts,
                          device=device, progress=False)
        for lanes in args.lanes:
            ds = wf.simulate(MEMBERS, model=model, solver=wf.Solver(nodes=args.nodes, lanes=lanes), fronts=fronts,
                             device=device, progress=False)
            row = dict(gate=gate, lanes=lanes, status=ds.status.values.tolist(), status_ref=ref.status.values.tolist(),
                       mu_s_rel=float(np.nanmax(np.abs(ds.mu_s.values / ref.mu_s.values - 1))),
                       steps=ds.steps_accepted.values.tolist(), steps_ref=ref.steps_accepted.values.tolist())
            if fronts is not None:
                row["v_middle_rel"] = float(np.nanmax(np.abs(ds.v_middle.values / ref.v_middle.values - 1)))
            rows.append(row)
            print(json.dumps(row), flush=True)
    with open(args.out, "w") as f:
        json.dump(dict(device=device, nodes=args.nodes, rows=rows), f, indent=1)
    print(f"\n{'gate':>9} {'lanes':>5} {'mu_s rel diff':>13}  status (team / thread)")
    for r in rows:
        print(f"{r['gate']:>9} {r['lanes']:>5} {r['mu_s_rel']:13.2e}  {r['status']} / {r['status_ref']}")


if __name__ == "__main__":
    main()
