"""How fast a GPU evaluates the default law's node rows and stage derivatives on their own, at
each register cap: the floor that the node work of the on-chip redesign (docs/performance.md, "A
kernel with the member on chip: what it rests on") would stand on if it kept today's node code.

    python studies/row_throughput.py [--device cuda:0] [--members 10000] [--nodes 200]
                                     [--lanes 32 64] [--caps 255 200 168 128]
                                     [--pieces rows derivatives] [--launches 20] [--jsonl FILE]

Each piece is the kernel of studies/stage_registers.py (a team of ``lanes`` threads a member, a
block a member, the arrays member-major in global memory as the team kernel's), launched
``launches`` times over ``members`` members of the benchmark's draw (studies/bench_engine.py
members) with a synthetic pad state: small displacements and velocities, every node in contact,
a third of the gates open, none sliding (the friction law then runs its common path; its FP64
arithmetic does not depend on the values). Prints the time a node row (or a node's stage
derivatives) takes, all SMs together, and what the 10,000-member benchmark's rows would take at
that rate: 1,094.8 Newton iterations a member (studies/results/h100/targets_88e8bd2.jsonl, mean
over members) x 200 nodes x 10,000 members = 2.19e9 node rows, and ~2 converged stages an
attempt, 389.5 attempts a member: 1.56e9 nodes' stage derivatives, half of them a step's last stage
(derivatives: with the stress gate's switch test) and half the stage inside it (derivatives_mid);
NaN below 1,000 members, whose launches time their latency, not the GPU's throughput (one member's
pieces are timed by Nsight Compute's kernel durations instead: docs/performance.md). A timing, not
a test.
"""

import argparse
import json
import os
import sys
import time

import numpy as np
import warp as wp

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import warpfric as wf  # noqa: E402
from bench_engine import members  # noqa: E402
from stage_registers import piece_kernel  # noqa: E402

BENCH_ROWS = 1094.8 * 200 * 10_000  # node rows of the 10,000-member benchmark (module docstring)
BENCH_DERIVATIVES = 2 * 389.5 * 200 * 10_000  # its nodes' stage derivatives (about)
BULK_MEMBERS = 1_000  # fewer members: no benchmark time (NaN), the launch is not a throughput


def synthetic_state(ft, arrays, n_members: int, n: int):
    """Fill the work array's stage slots and the gates with a synthetic pad (module docstring)."""
    from warpfric.kernels.types import G_GATE, G_SLIDE, W_V, W_ZP, W_ZT, W_ZU, W_ZV

    array3 = wp.array3d(dtype=ft)

    @wp.kernel(module="unique", enable_backward=False)
    def fill(work: array3, gates: array3):
        i, m = wp.tid()
        x = ft(i) * ft(0.031) + ft(m % 97) * ft(0.1)
        work[W_ZU, i, m] = ft(1.0e-6) * wp.sin(x)
        work[W_V, i, m] = ft(1.0e-4) * (ft(1.5) + wp.cos(x))
        work[W_ZV, i, m] = ft(1.0e-4) * (ft(1.4) + wp.cos(x))
        work[W_ZT, i, m] = ft(2.0e4) * (ft(1.0) + ft(0.3) * wp.sin(ft(2.0) * x))
        work[W_ZP, i, m] = ft(3.0) + wp.cos(x)
        gates[G_GATE, i, m] = ft(0.0)
        if i % 3 == 0:
            gates[G_GATE, i, m] = ft(1.0)
        gates[G_SLIDE, i, m] = ft(0.0)

    wp.launch(fill, dim=(n, n_members), inputs=[arrays.work, arrays.gates])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default="cuda:0")
    ap.add_argument("--members", type=int, default=10_000)
    ap.add_argument("--nodes", type=int, default=200)
    ap.add_argument("--lanes", type=int, nargs="+", default=[32, 64])
    ap.add_argument("--caps", type=int, nargs="+", default=[255, 200, 168, 128])
    ap.add_argument("--pieces", nargs="+", default=["rows", "derivatives"],
                    choices=["rows", "derivatives", "derivatives_mid", "start"])
    ap.add_argument("--launches", type=int, default=20)
    ap.add_argument("--jsonl", default=None, help="append a JSON line per row")
    args = ap.parse_args(argv)
    from warpfric import engine
    from warpfric.kernels.types import IntegratorState, MemberParams, allocate

    wp.config.quiet = True
    wp.init()
    wp.set_device(args.device)
    ft = wp.float64
    model = wf.Model()  # the default law: the stress gate
    solver = wf.Solver(nodes=args.nodes)
    values, _ = wf.members.resolve_members(members(args.members), wf.Parameters())
    params = wp.array(engine.member_params(values), dtype=MemberParams)
    arrays = allocate(ft, params, args.nodes, True, False, [], 0, member_major=True)
    synthetic_state(ft, arrays, args.members, args.nodes)
    st = engine.initial_states(args.members, solver, np.full(args.members, -1, dtype=np.int32))
    st["t"] = 20.13
    st["h"] = 1.0e-4
    st["restart"] = 0
    st["delta0"] = 2.0e-5
    st["tilt"] = 1.0e-5
    member_states = wp.array(st, dtype=IntegratorState)
    settings = engine.solver_settings(solver)
    outputs = engine.output_settings(None)
    print(f"{args.device} ({wp.get_device(args.device).name}), {args.members} members, N = {args.nodes}, "
          f"{args.launches} launches a row")
    print(f"{'piece':>12s} {'lanes':>5s} {'cap':>4s} {'launch ms':>10s} {'ps a node':>10s} {'bench s':>8s}")
    for piece in args.pieces:
        # the benchmark's evaluations of the piece: the rows; the derivatives of a step's last
        # stage, or of the other; none of the start (every launch's fixed cost: NaN)
        total = {"rows": BENCH_ROWS, "start": float("nan")}.get(piece, BENCH_DERIVATIVES / 2)
        for lanes in args.lanes:
            for cap in args.caps:
                kernel = piece_kernel(piece, lanes, cap, model)
                kernel.module.options["block_dim"] = lanes
                coeffs = wp.zeros(1, dtype=kernel.adj.args[-2].type.dtype)  # coeff_table, unused here
                result = wp.zeros((args.members, lanes), dtype=wp.float64)
                inputs = [params, settings, outputs, arrays.record_times, member_states, arrays.state, arrays.stages,
                          arrays.work, arrays.step_end, arrays.gates, arrays.record_previous, arrays.arrival,
                          arrays.arrival_error, arrays.strength, arrays.yield_time, arrays.record, result, coeffs,
                          arrays.step_end]
                launch = wp.launch(kernel, dim=(args.members, lanes), inputs=inputs, block_dim=lanes,
                                   record_cmd=True)
                launch.launch()  # compile and load
                wp.synchronize_device()
                start = time.perf_counter()
                for _ in range(args.launches):
                    launch.launch()
                wp.synchronize_device()
                per_launch = (time.perf_counter() - start) / args.launches
                nodes = args.members * args.nodes
                checksum = float(np.abs(result.numpy()).sum())
                # the benchmark's time at this rate: a rate of the bulk only (a launch of fewer
                # members waits on its own latency and its launch, not on the GPU's throughput)
                bench_s = per_launch / nodes * total if args.members >= BULK_MEMBERS else float("nan")
                row = dict(piece=piece, device=wp.get_device(args.device).name, members=args.members,
                           nodes=args.nodes, lanes=lanes, max_registers=cap, launch_s=per_launch,
                           ps_per_node=per_launch / nodes * 1e12, bench_s=bench_s,
                           checksum_finite=bool(np.isfinite(checksum)))
                print(f"{piece:>12s} {lanes:>5d} {cap:>4d} {per_launch * 1e3:10.3f} {row['ps_per_node']:10.2f} "
                      f"{row['bench_s']:8.3f}" + ("" if row["checksum_finite"] else "  (non-finite result)"),
                      flush=True)
                if args.jsonl:
                    with open(args.jsonl, "a") as f:
                        f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
