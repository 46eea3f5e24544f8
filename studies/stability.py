"""Hard-case stability map: a grid over viscous_coefficient, normal_force,
eccentricity, disc_velocity and damping, in float64 and float32; status counts, non-finite
results, rejected-step fraction and where lift-off happens.

    python studies/stability.py [--device cuda:0] [--quick] [--nodes 100] [--rtol 1e-5]
                                [--out studies/results/stability.nc]
    python studies/stability.py --summarise studies/results/stability.nc

Grid (full): viscous_coefficient 0, 2.7e11, 2.7e12, 2.7e13 Pa s/m (0..27 MPa s/um);
normal_force 100, 316, 1000, 3162, 10000 N; eccentricity -0.35, -0.2, 0, 0.2, 0.35;
disc_velocity 1e-6 .. 1e-2 m/s (5 values); damping 0, 1e5, 1e6 Pa s/m: 1500 members per dtype.
--quick: 2 x 3 x 3 x 3 x 1 = 54 members per dtype (a 2-core CPU in about a minute).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import xarray as xr

import warpfric as wf
from warpfric.io import write_ensemble

FULL = dict(
    viscous_coefficient=[0.0, 2.7e11, 2.7e12, 2.7e13],
    normal_force=[100.0, 316.0, 1000.0, 3162.0, 10000.0],
    eccentricity=[-0.35, -0.2, 0.0, 0.2, 0.35],
    disc_velocity=[1e-6, 1e-5, 1e-4, 1e-3, 1e-2],
    damping=[0.0, 1e5, 1e6],
)
QUICK = dict(
    viscous_coefficient=[0.0, 2.7e13],
    normal_force=[100.0, 1000.0, 10000.0],
    eccentricity=[-0.35, 0.0, 0.35],
    disc_velocity=[1e-6, 1e-4, 1e-2],
    damping=[0.0],
)


def grid(axes: dict) -> dict:
    mesh = np.meshgrid(*axes.values(), indexing="ij")
    return {k: m.ravel() for k, m in zip(axes, mesh)}


def summarise(ds: xr.Dataset, axes=None) -> str:
    axes = axes or {k: sorted(set(np.atleast_1d(ds[k].values).tolist())) for k in FULL if k in ds}
    meanings = ds.status.attrs["flag_meanings"].split()
    status = ds.status.values
    steps = ds.steps_accepted.values + ds.steps_rejected.values
    lines = [f"{ds.sizes['member']} members ({ds.attrs.get('solver_dtype')}, N = {ds.attrs.get('solver_nodes')}, "
             f"rtol {ds.attrs.get('solver_rtol')}): " + ", ".join(
                 f"{meanings[k]} {int((status == k).sum())}" for k in range(len(meanings)) if (status == k).any())]
    if ds.attrs.get("solver_dtype") == "float32" and "working_precision" in ds:
        lines.append(f"  re-run in float64 (Solver.float32_fallback): {int((ds.working_precision.values == 64).sum())} "
                     "members (their float32 run failed)")
    finite = np.isfinite(ds.mu_s.values) | (status != 0)
    lines.append(f"  non-finite mu_s among ok members: {int((~np.isfinite(ds.mu_s.values) & (status == 0)).sum())}; "
                 f"rejected-step fraction: median {np.median(ds.steps_rejected.values / steps):.3f}, "
                 f"max {np.max(ds.steps_rejected.values / steps):.3f}; lift-off in {int(ds.lift_off.values.sum())} members")
    assert finite.all()
    for name, values in axes.items():
        cells = []
        for v in values:
            sel = np.atleast_1d(ds[name].values) == v
            cells.append(f"{v:g}: {int((status[sel] != 0).sum())} fail, {int(ds.lift_off.values[sel].sum())} lift-off")
        lines.append(f"  {name:<20} " + " | ".join(cells))
    bad = np.flatnonzero(status != 0)
    for m in bad[:20]:
        r = ds.isel(member=m)
        lines.append("  failed: " + ", ".join(f"{k}={float(r[k]):g}" for k in axes) + f" -> {meanings[int(r.status)]} "
                     f"at t = {float(r.final_time):.6g} s after {int(r.steps_accepted)}+{int(r.steps_rejected)} steps")
    if len(bad) > 20:
        lines.append(f"  ... and {len(bad) - 20} more")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--device", default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--nodes", type=int, default=100)
    ap.add_argument("--rtol", type=float, default=1e-5)
    ap.add_argument("--max-steps", type=int, default=50_000)
    ap.add_argument("--dtypes", nargs="+", default=["float64", "float32"])
    ap.add_argument("--out", default="stability.nc")
    ap.add_argument("--relaxation-gate", default="stress", choices=["stress", "none", "velocity"],
                    help="friction law (float32 is skipped with the stress gate, which refuses it)")
    ap.add_argument("--stall-factor", type=float, default=float("inf"),
                    help="Solver.stall_factor (default inf: a map counts every member's own outcome)")
    ap.add_argument("--summarise", default=None, help="print the summary of an existing file and exit")
    args = ap.parse_args(argv)
    if args.summarise:
        for group in ("float64", "float32"):
            try:
                print(summarise(xr.load_dataset(args.summarise, group=group)))
            except OSError:
                pass
        return
    axes = QUICK if args.quick else FULL
    members = grid(axes)
    mode = "w"
    model = wf.Model(relaxation_gate=args.relaxation_gate)
    dtypes = [d for d in args.dtypes if not (d == "float32" and args.relaxation_gate == "stress")]
    for dtype in dtypes:
        solver = wf.Solver(nodes=args.nodes, rtol=args.rtol, dtype=dtype, max_steps=args.max_steps,
                           stall_factor=args.stall_factor)
        t0 = time.perf_counter()
        ds = wf.simulate(members, model=model, solver=solver, device=args.device, progress=True)
        print(f"{dtype}: {time.perf_counter() - t0:.1f} s")
        print(summarise(ds, axes), flush=True)
        ds.to_netcdf(args.out, mode=mode, group=dtype)
        mode = "a"
    print(f"wrote {args.out} (groups {', '.join(dtypes)}; relaxation gate {args.relaxation_gate})")


if __name__ == "__main__":
    main()
