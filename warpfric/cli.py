"""Command line: ``warpfric run`` simulates the paper's default scene (or one given by options)
and prints mu_s; ``-o OUT.nc`` also writes the result as netCDF."""

from __future__ import annotations

import argparse
import sys

from .parameters import Model, Parameters, Solver


def _run(args) -> int:
    from .simulate import simulate

    try:
        scene = Parameters(normal_force=args.normal_force, eccentricity=args.eccentricity,
                           disc_velocity=args.disc_velocity)
        solver = Solver(nodes=args.nodes, dtype=args.dtype, rtol=args.rtol)
        ds = simulate(scene=scene, model=Model(), solver=solver, device=args.device, progress=True)
    except ValueError as err:
        print(f"warpfric: error: {err}", file=sys.stderr)
        return 2
    m = ds.isel(member=0)
    status = ds.status.attrs["flag_meanings"].split()[int(m.status)]
    print(f"scene: F = {float(m.normal_force):g} N, 2e/L = {float(m.eccentricity):g}, "
          f"v_d = {float(m.disc_velocity):g} m/s, N = {solver.nodes}, {solver.dtype}, rtol = {solver.rtol:g}, "
          f"device {ds.attrs['device']}")
    print(f"mu_s      = {float(m.mu_s):.6f}  (static friction coefficient)")
    print(f"mu_s_time = {float(m.mu_s_time):.5f} s")
    print(f"mu_final  = {float(m.mu_final):.6f}  (at t = {float(m.final_time):g} s)")
    print(f"status    = {status}; steps accepted {int(m.steps_accepted)}, rejected {int(m.steps_rejected)}; "
          f"lift-off {'yes' if int(m.lift_off) else 'no'}; wall {ds.attrs['wall_time_s']:.2f} s")
    if args.output:
        ds.to_netcdf(args.output)
        print(f"wrote {args.output}")
    return 0 if int(m.status) == 0 else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="warpfric", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate one pad (the paper's default scene unless options say otherwise)")
    run.add_argument("-o", "--output", help="write the result to this netCDF file")
    run.add_argument("--device", default=None, help="Warp device: cpu, cuda:0, ... (default: first GPU, else cpu)")
    run.add_argument("--normal-force", type=float, default=Parameters.normal_force, help="N (default 1000)")
    run.add_argument("--eccentricity", type=float, default=Parameters.eccentricity, help="2e/L (default 0)")
    run.add_argument("--disc-velocity", type=float, default=Parameters.disc_velocity, help="m/s (default 1e-4)")
    run.add_argument("--nodes", type=int, default=Solver.nodes, help=f"grid nodes (default {Solver.nodes})")
    run.add_argument("--dtype", default=Solver.dtype, choices=("float64", "float32"))
    run.add_argument("--rtol", type=float, default=Solver.rtol, help=f"relative tolerance (default {Solver.rtol:g})")
    args = parser.parse_args(argv)
    return _run(args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
