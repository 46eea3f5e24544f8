"""The team's two lane exchanges on a GPU, side by side: Warp's tiles against warp shuffles
(kernels/team.py; WARPFRIC_TEAM_EXCHANGE). The same members (those of bench_engine.py) run with
each; the script prints the largest relative difference of mu_s, mu_s_time and the contact front's
speeds, whether the statuses agree and how far the accepted steps differ. The exchanges sum in
other orders and solve the separators by other algorithms (twisted factorisation, parallel cyclic
reduction), so outputs agree within the error control, not bit for bit.
docs/performance.md, "Warp shuffles".

    python studies/team_exchange.py [--device cuda:0] [--members 1000] [--relaxation-gate stress]
"""

import argparse
import os

import numpy as np

import warpfric as wf
from bench_engine import members


def run(exchange: str, values: dict, gate: str, device: str, nodes: int, lanes: int):
    os.environ["WARPFRIC_TEAM_EXCHANGE"] = exchange
    try:
        return wf.simulate(values, model=wf.Model(relaxation_gate=gate),
                           solver=wf.Solver(nodes=nodes, rtol=1e-5, lanes=lanes), fronts=wf.Fronts(),
                           device=device, progress=False)
    finally:
        del os.environ["WARPFRIC_TEAM_EXCHANGE"]


def largest_difference(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = np.isfinite(a) & np.isfinite(b)
    if (np.isfinite(a) != np.isfinite(b)).any():
        return float("inf")
    return float(np.max(np.abs(a[both] - b[both]) / np.maximum(np.abs(b[both]), 1e-300), initial=0.0))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--members", type=int, default=1000)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, default=32)
    ap.add_argument("--relaxation-gate", default="stress")
    ap.add_argument("--exchange", default="shuffle", help="the exchange compared with the tiles' (emulated: on the CPU)")
    args = ap.parse_args(argv)
    values = members(args.members)
    tile = run("tile", values, args.relaxation_gate, args.device, args.nodes, args.lanes)
    shuffle = run(args.exchange, values, args.relaxation_gate, args.device, args.nodes, args.lanes)
    print(f"{args.members} members, N = {args.nodes}, {args.lanes} lanes, {args.relaxation_gate} gate, "
          f"rtol 1e-5, contact front: {args.exchange} against tile")
    print(f"statuses equal: {bool((tile.status.values == shuffle.status.values).all())}")
    for name in ("mu_s", "mu_s_time", "front_start_time", "v_main", "v_left", "v_right"):
        print(f"{name:10s} largest relative difference {largest_difference(shuffle[name].values, tile[name].values):.2e}")
    steps = np.abs(shuffle.steps_accepted.values.astype(int) - tile.steps_accepted.values.astype(int))
    print(f"accepted steps: largest difference {steps.max()}, members that differ {(steps > 0).sum()}")


if __name__ == "__main__":
    main()
