"""Work-precision study: error of mu_s, mu_s_time and the middle front speed against the
converged reference (studies/reference/reference_scenes.nc) versus wall time, over tolerances,
grids and precisions.

    python studies/work_precision.py run  [--device cpu|cuda:0] [--members 18|10000]
                                          [--nodes 25 50 100 200] [--rtols 1e-3 ... 1e-8]
                                          [--dtypes float64 float32] [--out FILE.nc]
                                          [--error-filter-nodes 800]   (Solver.error_filter_nodes)
    python studies/work_precision.py plot FILE.nc [FILE2.nc ...] [--outdir docs/figures]
    python studies/work_precision.py collect LOG --out FILE.nc     (rows of a cut-off run's log)

`run` simulates the reference's scenes (18 in the committed file; tiled to --members; fronts on)
with the reference's law and front event (read from --reference, never the package defaults: a
run cannot compare two laws; it prints them and puts them in every row) for every (dtype, nodes,
rtol) and stores, per setting, the largest error over the scenes: relative for mu_s and v_middle,
absolute (s) for mu_s_time, the wall time and the wall time per realisation.
On the CPU (Warp's CPU kernels run the members one after another) the per-realisation time of
18 members is the M = 1 cost; on the GPU use --members 10000. `plot` draws error against time,
one line per (dtype, nodes) family, like SciMLBenchmarks' work-precision diagrams, and prints the
cheapest setting that keeps mu_s within 1e-4 of the reference. float32 rows are skipped where the
reference's law refuses float32 (the stress gate).

References: studies/reference/reference_scenes.nc (gate-less law, velocity front) and
studies/reference/reference_scenes_stress.nc (stress gate, contact front; the defaults now).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import time
import warnings
from pathlib import Path

import numpy as np
import xarray as xr

import warpfric as wf
from warpfric.io import open_ensemble

REFERENCE = Path(__file__).with_name("reference") / "reference_scenes.nc"
TARGET = 1e-4
# The law and front event of a reference file without the attributes that name them: the committed
# reference_scenes.nc predates model_relaxation_gate and fronts_event (its attrs have model_inertia,
# model_tilt, model_poisson_coupling, model_viscous_friction and fronts_threshold, ... but neither),
# and was made with the defaults of its time, the gate-less law and the velocity front
# (docs/performance.md, "Reference scenes"; reference_scenes.py's defaults).
OLD_RELAXATION_GATE = "none"
OLD_FRONT_EVENT = "velocity"


def reference_law(ref: xr.Dataset) -> tuple[wf.Model, wf.Fronts]:
    """The Model and Fronts the reference was made with, from its attributes: the relaxation gate from
    reference_relaxation_gate (reference_scenes.py), else model_relaxation_gate (simulate's), else the
    old default "none"; the front event likewise from reference_front_event, else fronts_event (its
    first word: the primary event), else "velocity"; the other model_* and fronts_* settings from
    their attributes where present (grid_check off: it is a cost, not a part of the front)."""
    a = ref.attrs
    gate = str(a.get("reference_relaxation_gate", a.get("model_relaxation_gate", OLD_RELAXATION_GATE)))
    event = str(a.get("reference_front_event", a.get("fronts_event", OLD_FRONT_EVENT))).split()[0]
    model = {}
    for f in dataclasses.fields(wf.Model):
        if f"model_{f.name}" in a and f.name != "relaxation_gate":
            model[f.name] = type(f.default)(a[f"model_{f.name}"]) if isinstance(f.default, bool) else a[f"model_{f.name}"]
    fronts = {}
    for f in dataclasses.fields(wf.Fronts):
        if f"fronts_{f.name}" in a and f.name not in ("event", "grid_check"):
            v = a[f"fronts_{f.name}"]
            fronts[f.name] = str(v) if isinstance(f.default, str) else type(f.default)(v)
    return wf.Model(relaxation_gate=gate, **model), wf.Fronts(event=event, **fronts)


def scene_members(ref: xr.Dataset, m: int) -> tuple[dict, np.ndarray]:
    k = ref.sizes["member"]
    idx = np.arange(m) % k
    names = ("eccentricity", "normal_force", "viscous_coefficient")
    return {n: np.broadcast_to(ref[n].values, (k,))[idx] for n in names}, idx


def run(args):
    # open_ensemble: today's files (write_ensemble) hold every parameter along member and the members
    # as labels; it gives the constant ones (end_time) back as scalars and the members as numbers
    ref = open_ensemble(args.reference)
    device = args.device or wf.default_device()
    members, idx = scene_members(ref, args.members)
    scene = wf.Parameters(end_time=float(ref.end_time))  # the reference's protocol window
    model, fronts = reference_law(ref)  # the reference's law and front event, never today's defaults
    gate, event = model.relaxation_gate, fronts.events[0]
    print(f"reference {args.reference}: {ref.sizes['member']} scenes; simulating with its law "
          f"(relaxation_gate={gate!r}) and front event ({event!r})", flush=True)
    rows = []
    for dtype in args.dtypes:
        for nodes in args.nodes:
            for rtol in args.rtols:
                if dtype == "float32" and rtol < wf.parameters.FLOAT32_MIN_RTOL:
                    continue
                # stall_factor inf: under the stress gate the scenes without velocity strengthening are a
                # dynamic rupture (up to 20-330x the steps of the others at rtol 1e-6, docs/performance.md
                # "Known limits"); the straggler rule would stop them and the errors would be those of the
                # other half
                solver = wf.Solver(nodes=nodes, dtype=dtype, rtol=rtol, max_steps=10**6, stall_factor=float("inf"),
                                   error_filter_nodes=args.error_filter_nodes)
                try:
                    wf.parameters.check_precision(model, solver)
                except ValueError as err:
                    print(f"skipped {dtype}, N = {nodes}, rtol = {rtol:g}: {err}", flush=True)
                    continue
                with warnings.catch_warnings():  # the short warm-up ends before the peak (no_peak): not news
                    warnings.simplefilter("ignore")
                    # compile outside the timing: all the members, since the kernel depends on their count
                    # (the team size and the block's layout; one member compiled another kernel, and the
                    # first timed row of each N held a compilation)
                    wf.simulate(members=members, scene=wf.Parameters(end_time=20.01), model=model, fronts=fronts,
                                solver=solver, device=device, progress=False)
                t0 = time.perf_counter()
                ds = wf.simulate(members, scene=scene, model=model, fronts=fronts, solver=solver, device=device,
                                 progress=False)
                wall = time.perf_counter() - t0
                r = {q: ref[q].values[idx] for q in ("mu_s", "mu_s_time", "v_middle")}
                ok = ds.status.values == 0
                row = dict(
                    dtype=dtype, nodes=nodes, rtol=rtol, members=args.members, device=device,
                    relaxation_gate=gate, front_event=event, error_filter_nodes=args.error_filter_nodes, wall_s=wall,
                    wall_s_per_realisation=wall / args.members, ok=int(ok.sum()),
                    mu_s_error=float(np.nanmax(np.abs(ds.mu_s.values / r["mu_s"] - 1))),
                    mu_s_time_error=float(np.nanmax(np.abs(ds.mu_s_time.values - r["mu_s_time"]))),
                    v_middle_error=float(np.nanmax(np.abs(ds.v_middle.values / r["v_middle"] - 1))),
                    mean_steps=float((ds.steps_accepted + ds.steps_rejected).mean()),
                )
                # the same by scene group: with velocity strengthening (viscous_coefficient > 0) and
                # without it (under the stress gate a dynamic rupture, whose cost and error differ)
                viscous = members["viscous_coefficient"] > 0
                steps = (ds.steps_accepted + ds.steps_rejected).values
                for group, chosen in (("viscous", viscous), ("inviscid", ~viscous)):
                    if chosen.any():
                        row[f"mu_s_error_{group}"] = float(np.nanmax(np.abs(ds.mu_s.values / r["mu_s"] - 1)[chosen]))
                        row[f"mean_steps_{group}"] = float(steps[chosen].mean())
                rows.append(row)
                print(json.dumps(row), flush=True)
    meta = dict(platform=platform.platform(), warpfric=wf.__version__, device=device,
                command="python studies/work_precision.py " + " ".join(args.argv),
                reference=str(args.reference), relaxation_gate=gate, front_event=event)
    if not rows:
        raise SystemExit("no setting ran (float32 alone under the stress gate?)")
    out = to_dataset(rows, meta)
    out.to_netcdf(args.out)
    Path(args.out).with_suffix(".json").write_text(json.dumps(dict(meta=meta, rows=rows), indent=1))
    print(f"wrote {args.out}")
    table(rows)


GROUP_KEYS = ("mu_s_error_viscous", "mu_s_error_inviscid", "mean_steps_viscous", "mean_steps_inviscid")


def to_dataset(rows, meta) -> xr.Dataset:
    keys = ("wall_s", "wall_s_per_realisation", "mu_s_error", "mu_s_time_error", "v_middle_error", "mean_steps", "ok")
    keys += tuple(k for k in GROUP_KEYS if all(k in r for r in rows))  # rows of an earlier log lack them
    dtypes = sorted({r["dtype"] for r in rows})
    nodes = sorted({r["nodes"] for r in rows})
    rtols = sorted({r["rtol"] for r in rows})
    data = {k: np.full((len(dtypes), len(nodes), len(rtols)), np.nan) for k in keys}
    for r in rows:
        i, j, k = dtypes.index(r["dtype"]), nodes.index(r["nodes"]), rtols.index(r["rtol"])
        for key in keys:
            data[key][i, j, k] = r[key]
    units = {"wall_s": "s", "wall_s_per_realisation": "s", "mu_s_error": "1", "mu_s_time_error": "s",
             "v_middle_error": "1", "mean_steps": "1", "ok": "1", **{k: "1" for k in GROUP_KEYS}}
    ds = xr.Dataset({k: (("dtype", "nodes", "rtol"), v, {"units": units[k]}) for k, v in data.items()},
                    coords={"dtype": dtypes, "nodes": nodes, "rtol": rtols})
    ds.attrs.update({k: str(v) for k, v in meta.items()})
    ds.attrs["members"] = rows[0]["members"]
    for key in ("relaxation_gate", "front_event", "error_filter_nodes"):  # rows of a log from before these keys: not said
        values = {str(r[key]) for r in rows if key in r}
        if len(values) == 1 and key not in meta:
            ds.attrs[key] = values.pop()
    return ds


def table(rows):
    laws = {(r.get("relaxation_gate", "?"), r.get("front_event", "?")) for r in rows}
    print("\nlaw: " + "; ".join(f"relaxation_gate {g!r}, front event {e!r}" for g, e in sorted(laws)))
    print(f"{'dtype':>8} {'N':>4} {'rtol':>7} {'s/real.':>10} {'mu_s err':>9} {'t_s err s':>9} {'v_mid err':>9} {'steps':>7} {'ok':>5}")
    for r in rows:
        print(f"{r['dtype']:>8} {r['nodes']:>4} {r['rtol']:7.0e} {r['wall_s_per_realisation']:10.3e} {r['mu_s_error']:9.1e} "
              f"{r['mu_s_time_error']:9.1e} {r['v_middle_error']:9.1e} {r['mean_steps']:7.0f} {r['ok']:>5}")


def recommend(ds: xr.Dataset):
    """The cheapest (dtype, nodes, rtol) whose mu_s error is within TARGET (all scenes ok)."""
    best = None
    for dt in ds.dtype.values:
        for n in ds.nodes.values:
            for r in ds.rtol.values:
                sel = ds.sel(dtype=dt, nodes=n, rtol=r)
                err, cost = float(sel.mu_s_error), float(sel.wall_s_per_realisation)
                if np.isfinite(err) and err <= TARGET and (best is None or cost < best[3]):
                    best = (str(dt), int(n), float(r), cost, err, float(sel.v_middle_error))
    return best


def plot(args):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    outdir = Path(args.outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    for path in args.files:
        ds = xr.load_dataset(path)
        law = (f", relaxation_gate {ds.attrs['relaxation_gate']}, {ds.attrs['front_event']} front"
               if "relaxation_gate" in ds.attrs else "")
        label = f"{ds.attrs['device']}, {int(ds.attrs['members'])} members{law}"
        stem = Path(path).stem
        fig, axes = plt.subplots(1, 3, figsize=(13, 4))
        for ax, (q, name) in zip(axes, (("mu_s_error", "mu_s relative error"), ("mu_s_time_error", "mu_s_time error (s)"),
                                       ("v_middle_error", "v_middle relative error"))):
            for dt in ds.dtype.values:
                for n in ds.nodes.values:
                    sel = ds.sel(dtype=dt, nodes=n)
                    ok = np.isfinite(sel[q].values)
                    if ok.any():
                        ax.loglog(sel.wall_s_per_realisation.values[ok], sel[q].values[ok],
                                  "o-" if dt == "float64" else "s--", ms=4, label=f"{dt}, N={int(n)}")
            if q == "mu_s_error":
                ax.axhline(TARGET, color="k", lw=0.8, ls=":")
            ax.set_xlabel("wall time per realisation (s)")
            ax.set_ylabel(name)
            ax.grid(True, which="both", alpha=0.3)
        axes[0].legend(fontsize=7)
        fig.suptitle(f"work-precision ({label}); points along a line: rtol from loose (left) to tight")
        fig.tight_layout()
        fig.savefig(outdir / f"{stem}.png", dpi=110)
        plt.close(fig)
        best = recommend(ds)
        if best is None:
            print(f"{path}: no setting keeps mu_s error <= {TARGET:g}; figure {outdir / (stem + '.png')}")
            continue
        print(f"{path}: cheapest setting with mu_s error <= {TARGET:g}: dtype {best[0]}, N = {best[1]}, "
              f"rtol = {best[2]:g}: {best[3]:.3e} s per realisation, mu_s error {best[4]:.1e}, "
              f"v_middle error {best[5]:.1e}; figure {outdir / (stem + '.png')}")


def main(argv=None):
    import sys

    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("--device", default=None)
    r.add_argument("--members", type=int, default=18)
    r.add_argument("--nodes", type=int, nargs="+", default=[25, 50, 100, 200])
    r.add_argument("--rtols", type=float, nargs="+", default=[1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8])
    r.add_argument("--dtypes", nargs="+", default=["float64", "float32"])
    r.add_argument("--reference", default=str(REFERENCE))
    r.add_argument("--out", default="work_precision.nc")
    r.add_argument("--error-filter-nodes", type=int, default=wf.Solver().error_filter_nodes,
                   help="Solver.error_filter_nodes of every run (default: the package's)")
    c = sub.add_parser("collect", help="build the .nc/.json from the JSON lines of a run's log (a cut-off run)")
    c.add_argument("log")
    c.add_argument("--out", required=True)
    c.add_argument("--command", default="", help="the command that produced the log")
    p = sub.add_parser("plot")
    p.add_argument("files", nargs="+")
    p.add_argument("--outdir", default="docs/figures")
    args = ap.parse_args(argv)
    args.argv = argv
    {"run": run, "plot": plot, "collect": collect}[args.cmd](args)


def collect(args):
    rows = [json.loads(line) for line in Path(args.log).read_text().splitlines() if line.startswith("{")]
    meta = dict(platform="see the log", warpfric=wf.__version__, device=rows[0]["device"],
                command=args.command or f"rows collected from {args.log}")
    to_dataset(rows, meta).to_netcdf(args.out)
    Path(args.out).with_suffix(".json").write_text(json.dumps(dict(meta=meta, rows=rows), indent=1))
    print(f"wrote {args.out} ({len(rows)} settings)")


if __name__ == "__main__":
    main()
