"""Converged float64 reference for a fixed set of scenes: e = -0.2, 0, 0.2;
F = 500, 1000, 5000 N; viscous_coefficient 2.7e13 Pa s/m (27 MPa s/um) and 0: 18 scenes.

    python studies/reference_scenes.py [--nodes 100 200 400] [--rtols 1e-6 1e-7 1e-8]
                                       [--end-time 20.6] [--device cpu]
                                       [--relaxation-gate none] [--front-event velocity]
                                       [--viscous-only] [--error-filter-nodes 0]
                                       [--out studies/reference/reference_scenes.nc]

The defaults are those of the committed studies/reference/reference_scenes.nc: the gate-less law
and the velocity front, and each grid's own velocity error filter (--error-filter-nodes 0, as
before Solver.error_filter_nodes existed; the package default, 800, would not resolve the inviscid
pad's vibration at rtol 1e-8, docs/performance.md "Known limits"). The stress gate without velocity
strengthening is a dynamic rupture: with the default filter 1.1-1.35x the steps of the viscous
scenes at rtol 1e-5 and 1.3-1.8x at 1e-6 (docs/performance.md, "Known limits"). The run replaces --out: give another file to
compare with the committed one. The file's attributes reference_relaxation_gate and
reference_front_event name the law and the event (studies/work_precision.py simulates with them; the
committed file predates them and is the gate-less law and the velocity front).
--viscous-only refines the 9 scenes with velocity strengthening alone (the others under the stress
gate are a dynamic rupture whose refinement costs far more).

The runs end at 20.6 s: mu_s is reached by ~20.28 s and the fronts are over by ~20.35 s.
The scenes with viscous_coefficient = 0 are refined to rtol 1e-7 only: without the viscous
friction nothing damps the pad's shear oscillation (~24 kHz) that the force ramp excites, and at
rtol <= 1e-8 the error control with each grid's own filter resolves it through the 20 s of loading
(1e6 steps at N = 40; with the default filter from rtol 1e-9 on; docs/performance.md, "Known
limits").

Refines the grid at the tightest tolerance and the tolerance on the finest grid, and stores the
finest run's mu_s, mu_s_time and front metrics with, per quantity, the change from the
next-coarser grid and from the next-looser tolerance (the digits that stopped changing).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import xarray as xr

import warpfric as wf
from warpfric.io import write_ensemble

QUANTITIES = ("mu_s", "mu_s_time", "v_left", "v_middle", "v_right", "left_front_end", "right_front_start",
              "nucleation_position")


def scenes() -> dict:
    e, f, eta = np.meshgrid([-0.2, 0.0, 0.2], [500.0, 1000.0, 5000.0], [2.7e13, 0.0], indexing="ij")
    return {"eccentricity": e.ravel(), "normal_force": f.ravel(), "viscous_coefficient": eta.ravel()}


def run(members: dict, nodes: int, rtol: float, device: str, end_time: float, model: wf.Model,
        fronts: wf.Fronts, error_filter_nodes: int = 0) -> xr.Dataset:
    t0 = time.perf_counter()
    ds = wf.simulate(members, scene=wf.Parameters(end_time=end_time), model=model, fronts=fronts,
                     solver=wf.Solver(nodes=nodes, rtol=rtol, max_steps=10**7, error_filter_nodes=error_filter_nodes),
                     device=device, progress=False)
    if (ds.status.values != 0).any():
        raise SystemExit(f"N = {nodes}, rtol = {rtol:g}: members failed: {ds.status.values}")
    print(f"  {len(ds.member)} members, N = {nodes:4d}, rtol = {rtol:.0e}: {time.perf_counter() - t0:7.1f} s, "
          f"mean steps {float(ds.steps_accepted.mean()):.0f}", flush=True)
    return ds


def refine(members: dict, nodes, rtols, device, end_time, model, fronts, error_filter_nodes: int = 0):
    """{('N', n): ds at the tightest rtol} and {('rtol', r): ds on the finest grid}."""
    rt = min(rtols)
    fine = max(nodes)
    out = {("N", n): run(members, n, rt, device, end_time, model, fronts, error_filter_nodes) for n in sorted(nodes)}
    for r in sorted(rtols, reverse=True):
        out[("rtol", r)] = (out[("N", fine)] if r == rt
                            else run(members, fine, r, device, end_time, model, fronts, error_filter_nodes))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, nargs="+", default=[100, 200, 400])
    ap.add_argument("--rtols", type=float, nargs="+", default=[1e-6, 1e-7, 1e-8],
                    help="tolerances for the scenes with velocity strengthening")
    ap.add_argument("--rtols-inviscid", type=float, nargs="+", default=[1e-5, 1e-6, 1e-7],
                    help="tolerances for viscous_coefficient = 0 (see the module docstring)")
    ap.add_argument("--end-time", type=float, default=20.6)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--relaxation-gate", default="none", choices=["none", "stress", "velocity"],
                    help="the law (default none: the committed file's)")
    ap.add_argument("--front-event", default="velocity", choices=["velocity", "contact", "strength"],
                    help="the front event (default velocity: the committed file's)")
    ap.add_argument("--viscous-only", action="store_true",
                    help="only the 9 scenes with viscous_coefficient > 0 (see the module docstring)")
    ap.add_argument("--error-filter-nodes", type=int, default=0,
                    help="Solver.error_filter_nodes of every run (default 0, each grid's own filter: the committed "
                         "references' setting; see the module docstring)")
    ap.add_argument("--out", default="studies/reference/reference_scenes.nc")
    args = ap.parse_args(argv)
    model, fronts = wf.Model(relaxation_gate=args.relaxation_gate), wf.Fronts(event=args.front_event)
    all_members = scenes()
    ns = sorted(args.nodes)
    parts = []
    groups = ((True, args.rtols),) if args.viscous_only else ((True, args.rtols), (False, args.rtols_inviscid))
    for viscous, rtols in groups:
        sel = (all_members["viscous_coefficient"] > 0) == viscous
        members = {k: v[sel] for k, v in all_members.items()}
        runs = refine(members, ns, rtols, args.device, args.end_time, model, fronts, args.error_filter_nodes)
        rtols = sorted(rtols, reverse=True)
        best = runs[("N", ns[-1])]
        out = best.drop_vars([v for v in best.data_vars if "x" in best[v].dims]).drop_dims("x")
        out = out.assign_coords(member=np.flatnonzero(sel))
        out["reference_rtol"] = xr.DataArray(np.full(sel.sum(), min(rtols)), dims=("member",), attrs={"units": "1"})
        for q in QUANTITIES:
            units = best[q].attrs.get("units", "1")
            grid_change = np.abs(runs[("N", ns[-1])][q].values - runs[("N", ns[-2])][q].values)
            tol_change = np.abs(runs[("rtol", rtols[-1])][q].values - runs[("rtol", rtols[-2])][q].values)
            out[f"{q}_grid_change"] = xr.DataArray(grid_change, dims=("member",), attrs={
                "units": units, "long_name": f"|{q}(N={ns[-1]}) - {q}(N={ns[-2]})| at the reference rtol"})
            out[f"{q}_tolerance_change"] = xr.DataArray(tol_change, dims=("member",), attrs={
                "units": units, "long_name": f"|{q}(reference rtol) - {q}(10x looser)| at N = {ns[-1]}"})
            out[f"{q}_by_nodes"] = xr.DataArray(np.stack([runs[("N", n)][q].values for n in ns], axis=1),
                                                dims=("member", "refinement_nodes"),
                                                attrs={"units": units, "long_name": f"{q} at the reference rtol against N"})
        parts.append(out)
    out = xr.concat(parts, dim="member", data_vars="all", coords="different", compat="equals").sortby("member")
    out = out.assign_coords(refinement_nodes=("refinement_nodes", np.array(ns)))
    out.attrs["title"] = "warpfric converged float64 reference scenes"
    out.attrs["command"] = "python studies/reference_scenes.py " + " ".join(argv or sys_argv())
    out.attrs["varying_parameters"] = "viscous_coefficient normal_force eccentricity"
    # the law and the front event, said outright (studies/work_precision.py simulates with them)
    out.attrs["reference_relaxation_gate"] = model.relaxation_gate
    out.attrs["reference_front_event"] = fronts.events[0]
    out.attrs["reference_scenes"] = "viscous only" if args.viscous_only else "all"
    out.attrs["reference_error_filter_nodes"] = args.error_filter_nodes
    write_ensemble(out, args.out, varying=("eccentricity", "normal_force", "viscous_coefficient", "reference_rtol"))
    print(f"wrote {args.out}")
    print(f"\n{'e':>5} {'F':>6} {'eta':>8} {'rtol':>6} {'mu_s':>12} {'d_grid':>8} {'d_tol':>8} {'t_s':>10} {'v_left':>8} "
          f"{'v_mid':>8} {'v_right':>8} {'dv_mid grid':>11} {'dv_mid tol':>10}")
    for m in range(out.sizes["member"]):
        r = out.isel(member=m)
        print(f"{float(r.eccentricity):5.1f} {float(r.normal_force):6.0f} {float(r.viscous_coefficient):8.1e} "
              f"{float(r.reference_rtol):6.0e} {float(r.mu_s):12.9f} {float(r.mu_s_grid_change):8.1e} "
              f"{float(r.mu_s_tolerance_change):8.1e} {float(r.mu_s_time):10.6f} {float(r.v_left):8.3g} "
              f"{float(r.v_middle):8.3g} {float(r.v_right):8.3g} {float(r.v_middle_grid_change):11.2e} "
              f"{float(r.v_middle_tolerance_change):10.2e}")


def sys_argv():
    import sys

    return sys.argv[1:]


if __name__ == "__main__":
    main()
