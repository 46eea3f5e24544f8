"""Team sizes give the same member (GPU): the four members of tests/test_team.py (e = 0, -0.2, 0.3,
0.6; the last lifts off), the default law with the contact front, rtol 1e-5, integrated with each
given Solver.lanes (1: the thread kernel; 32: one warp; 64, 96: teams of several warps,
kernels/team.py make_warps_team). Prints, per team size, the statuses, the accepted and rejected
steps, and mu_s and mu_s_time's largest relative difference from the first team size's.

    python studies/team_lanes.py [--nodes 200] [--lanes 1 32 64 96] [--device cuda:0]

WARPFRIC_TEAM_EXCHANGE picks the lane exchange (e.g. tile). docs/performance.md, "Teams of several
warps".
"""

import argparse
import warnings

import numpy as np

import warpfric as wf

MEMBERS = {"eccentricity": [0.0, -0.2, 0.3, 0.6], "normal_force": [1000.0, 1000.0, 300.0, 3000.0]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, nargs="+", default=[1, 32, 64, 96])
    ap.add_argument("--device", default="cuda:0")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    first = None
    for lanes in args.lanes:
        ds = wf.simulate(MEMBERS, model=wf.Model(), solver=wf.Solver(nodes=args.nodes, rtol=1e-5, lanes=lanes),
                         fronts=wf.Fronts(), device=args.device)
        first = ds if first is None else first
        d_mu = np.max(np.abs(ds.mu_s.values / first.mu_s.values - 1))
        d_time = np.max(np.abs(ds.mu_s_time.values / first.mu_s_time.values - 1))
        print(f"N={args.nodes} lanes={lanes} exchange={ds.attrs.get('team_exchange')} status={ds.status.values} "
              f"accepted={ds.steps_accepted.values} rejected={ds.steps_rejected.values} mu_s {d_mu:.1e} "
              f"mu_s_time {d_time:.1e} v_middle={ds.v_middle.values}")


if __name__ == "__main__":
    main()
