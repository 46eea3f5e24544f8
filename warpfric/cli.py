"""warpfric command line.

  warpfric run [SWEEP.toml] [-o OUT.nc] [--device D] [--chunk M] [--member-offset K] [--resume | --overwrite]
  warpfric info OUT.nc [MORE.nc ...]
  warpfric plot OUT.nc [--outdir DIR]
  warpfric sensitivity OUT.nc [--output mu_s --output v_middle ...] [--on-failure refuse|fill-mean]

Without a sweep file, ``run`` simulates the paper's default scene (one member, F = 1000 N, e = 0,
changeable with --normal-force, --eccentricity, --disc-velocity) and prints mu_s and the front
speeds. Exit codes: 0 success, 1 some members failed (or ``info`` on an incomplete run), 2 bad
input (nothing is written).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

import numpy as np

from .parameters import RELAXATION_GATES, Fronts, Model, Parameters, Solver


class UsageError(ValueError):
    pass


def _fail(message: str) -> int:
    print(f"warpfric: error: {message}", file=sys.stderr)
    return 2


def _status_name(ds, code: int) -> str:
    return ds.status.attrs["flag_meanings"].split()[int(code)]


def _fmt(value, unit="", spec=".4g") -> str:
    v = float(value)
    return "absent" if not np.isfinite(v) else f"{v:{spec}}{(' ' + unit) if unit else ''}"


def _print_member(ds, solver: Solver) -> None:
    m = ds.isel(member=0)
    print(f"scene: F = {float(m.normal_force):g} N, 2e/L = {float(m.eccentricity):g}, "
          f"v_d = {float(m.disc_velocity):g} m/s, relaxation gate {ds.attrs['model_relaxation_gate']}, "
          f"N = {solver.nodes}, {solver.dtype}, rtol = {solver.rtol:g}, device {ds.attrs['device']}")
    print(f"mu_s      = {_fmt(m.mu_s, spec='.6f')}  (static friction coefficient)")
    print(f"mu_s_time = {_fmt(m.mu_s_time, 's', '.5f')}")
    print(f"mu_final  = {_fmt(m.mu_final, spec='.6f')}  (at t = {float(m.final_time):g} s)")
    if "v_middle" in m:
        edge = {-1: "left edge", 0: "interior", 1: "right edge", -2: "none"}[int(m.nucleation_edge)]
        print(f"front     : nucleates at x = {_fmt(float(m.nucleation_position) * 1e3, 'mm', '.1f')} ({edge}), "
              f"t = {_fmt(m.front_start_time, 's', '.5f')} .. {_fmt(m.front_end_time, 's', '.5f')}")
        for seg in ("left", "middle", "right"):
            start, end = float(m[f"{seg}_front_start"]), float(m[f"{seg}_front_end"])
            where = f"x = {start * 1e3:.1f} .. {end * 1e3:.1f} mm" if np.isfinite(start) else "absent"
            err = f"+- {_fmt(m[f'v_{seg}_error'], '', '.2g')}" if f"v_{seg}_error" in m and np.isfinite(float(m[f"v_{seg}"])) else ""
            if f"v_{seg}_grid_error" in m and np.isfinite(float(m[f"v_{seg}"])):
                err += f" (grid: {_fmt(m[f'v_{seg}_grid_error'], '', '.2g')})"
            print(f"  v_{seg:<6} = {_fmt(m[f'v_{seg}'], 'm/s', '.3g'):>10} {err:<10} {where}")
        if "v_middle_grid_error" not in m:
            print("  (+- : time-discretisation error only; --grid-check adds the grid's, usually the larger)")
    print(f"status    = {_status_name(ds, m.status)}; steps accepted {int(m.steps_accepted)}, rejected "
          f"{int(m.steps_rejected)}; lift-off {'yes' if int(m.lift_off) else 'no'}; wall {ds.attrs['wall_time_s']:.2f} s "
          f"(+ {ds.attrs.get('kernel_build_time_s', 0.0):.2f} s compiling/loading kernels; "
          f"{ds.attrs.get('device_bytes_per_member', 0.0) / 1024:.1f} KiB device memory per member)")


def _check_output(path: Path, resume: bool, overwrite: bool) -> None:
    from .runner import check_output

    check_output(path, resume, overwrite)


def _run_default(args) -> int:
    from .io import write_ensemble
    from .simulate import simulate
    from .sweep_file import check_member_offset

    scene = Parameters(normal_force=args.normal_force, eccentricity=args.eccentricity, disc_velocity=args.disc_velocity,
                       end_time=args.end_time)
    model = Model(relaxation_gate=args.relaxation_gate)
    solver = Solver(nodes=args.nodes, dtype=args.dtype, rtol=args.rtol)
    if args.output:
        _check_output(Path(args.output), args.resume, args.overwrite)
    offset = args.member_offset or 0
    check_member_offset(offset, 1, "--member-offset")
    ds = simulate(scene=scene, model=model, solver=solver, fronts=Fronts(grid_check=args.grid_check), device=args.device,
                  progress=not args.quiet, member_offset=offset)
    _print_member(ds, solver)
    if args.output:
        write_ensemble(ds, args.output, command=args.command_line)
        print(f"wrote {args.output}")
    return 0 if int(ds.status[0]) == 0 else 1


def _run_sweep(args) -> int:
    from .runner import run_sweep

    report = run_sweep(args.sweep, args.output, chunk=args.chunk, member_offset=args.member_offset, device=args.device,
                       resume=args.resume, overwrite=args.overwrite, scheduler=args.scheduler,
                       local=True if args.local_cluster else None, workers=args.workers, quiet=args.quiet,
                       command=args.command_line)
    return 0 if report.output is not None and report.failed_members == 0 else 1


def _run(args) -> int:
    if args.chunk is not None and args.chunk < 1:
        raise UsageError(f"--chunk {args.chunk}: expected an integer >= 1 (members per chunk file)")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers {args.workers}: expected an integer >= 1")
    if args.scheduler and args.local_cluster:
        raise UsageError("--scheduler and --local-cluster exclude each other (an existing cluster, or a new one)")
    if args.sweep is None:
        for flag, given in (("--scheduler", args.scheduler), ("--local-cluster", args.local_cluster),
                            ("--workers", args.workers is not None)):
            if given:
                raise UsageError(f"{flag} runs the chunks of a sweep file; give one (warpfric run SWEEP.toml ...)")
        return _run_default(args)
    if args.grid_check:
        raise UsageError("--grid-check is for the default scene; in a sweep file write [fronts] grid_check = true")
    return _run_sweep(args)


def resume_command(store, path: Path) -> str:
    """The command that finishes an interrupted chunked run (chunk size and member offset come
    from the manifest)."""
    words = ["warpfric", "run", store.manifest.get("sweep_file", "SWEEP.toml"), "-o", str(path), "--resume"]
    if store.manifest.get("device"):
        words += ["--device", store.manifest["device"]]
    return shlex.join(words)


def _info(args) -> int:
    from .io import ChunkStore, open_ensemble, open_ensembles, parts_dir

    if len(args.file) > 1:  # several files: their combination (refused when member numbers repeat)
        ds = open_ensembles(args.file)
        print(summary(ds, " + ".join(args.file)))
        return 0
    path = Path(args.file[0])
    if not path.exists() and parts_dir(path).exists():
        store = ChunkStore.load(parts_dir(path))
        print(f"{path}: INCOMPLETE run: {store.done_count()}/{store.n_chunks} chunks of <= {store.chunk} members "
              f"finished ({store.n_members} members in all) in {parts_dir(path)}; finish it with "
              f"`{resume_command(store, path)}`")
        return 1
    ds = open_ensemble(path)
    print(summary(ds, str(path)))
    return 0


def summary(ds, name: str) -> str:
    """Text summary of an ensemble: members, swept parameters, status counts, mu_s and fronts."""
    numbers = ds.member.values
    lines = [f"{name}: {ds.sizes['member']} members (numbers {numbers.min()}..{numbers.max()}), "
             f"{ds.sizes.get('x', 0)} nodes, complete"]
    lines.append(f"  title: {ds.attrs.get('title', '')}; device {ds.attrs.get('device')}, warpfric "
                 f"{ds.attrs.get('warpfric_version')}, warp {ds.attrs.get('warp_version')}, "
                 f"wall {float(ds.attrs.get('wall_time_s', float('nan'))):.1f} s")
    swept = ds.attrs.get("varying_parameters", "").split()
    lines.append("  swept parameters:" + ("" if swept else " none"))
    for pname in swept:
        v = ds[pname].values
        lines.append(f"    {pname:<22} {np.unique(v).size:>6} values in [{v.min():.6g}, {v.max():.6g}] "
                     f"{ds[pname].attrs.get('units', '')}")
    meanings = ds.status.attrs["flag_meanings"].split()
    counts = {meanings[int(k)]: int((ds.status.values == k).sum()) for k in np.unique(ds.status.values)}
    lines.append("  status: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    mu = ds.mu_s.values
    good = np.isfinite(mu)
    if good.any():
        lines.append(f"  mu_s: mean {mu[good].mean():.6f}, std {mu[good].std():.3g}, min {mu[good].min():.6f}, "
                     f"max {mu[good].max():.6f} ({good.sum()} members)")
    if "v_middle" in ds:
        for seg in ("left", "middle", "right"):
            v = ds[f"v_{seg}"].values
            ok = np.isfinite(v)
            text = f"median {np.median(v[ok]):.3g} m/s, range [{v[ok].min():.3g}, {v[ok].max():.3g}]" if ok.any() else ""
            lines.append(f"  {seg} front present in {ok.sum()}/{v.size} members {text}")
    if "sensitivity_design" in ds.attrs:
        import json

        d = json.loads(ds.attrs["sensitivity_design"])
        lines.append(f"  sensitivity design: {d['method']}, base size {d['n']}, seed {d['seed']}, "
                     f"{len(d['names'])} parameters ({', '.join(d['names'])}); analyse with `warpfric sensitivity`")
    if "recorded_member" in ds.coords:
        lines.append(f"  recorded fields: members {list(map(int, ds.recorded_member.values))} at "
                     f"{ds.sizes['time']} times in [{ds.time.values.min():g}, {ds.time.values.max():g}] s")
    return "\n".join(lines)


def _plot(args) -> int:
    from .io import open_ensemble
    from .plots import quick_look

    ds = open_ensemble(args.file)
    outdir = Path(args.outdir) if args.outdir else Path(args.file).with_suffix("")
    outdir.mkdir(parents=True, exist_ok=True)
    for path in quick_look(ds, outdir):
        print(f"wrote {path}")
    return 0


def _sensitivity(args) -> int:
    from .io import open_ensemble
    from .sensitivity import analyse, bar_plot

    ds = open_ensemble(args.file)
    res = analyse(ds, outputs=tuple(args.output or ["mu_s"]), on_failure=args.on_failure, log=args.log)
    out = Path(args.out) if args.out else Path(args.file).with_name(Path(args.file).stem + "_sensitivity.nc")
    res.to_netcdf(out)
    bar_plot(res, out.with_suffix(".png"))
    for o in res.output.values:
        r = res.sel(output=o)
        print(f"{'log ' if args.log else ''}{o}: ({int(r.filled_members)} members filled with the mean)")
        if "S1" in res:
            print(f"  {'parameter':<22} {'S1':>7} {'+-':>6} {'ST':>7} {'+-':>6}")
            for p in res.parameter.values:
                q = r.sel(parameter=p)
                print(f"  {p:<22} {float(q.S1):7.3f} {float(q.S1_conf):6.3f} {float(q.ST):7.3f} {float(q.ST_conf):6.3f}")
        else:
            print(f"  {'parameter':<22} {'mu*':>10} {'+-':>9} {'sigma':>10}")
            for p in res.parameter.values:
                q = r.sel(parameter=p)
                print(f"  {p:<22} {float(q.mu_star):10.3g} {float(q.mu_star_conf):9.2g} {float(q.sigma):10.3g}")
    print(f"wrote {out} and {out.with_suffix('.png')}")
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="warpfric", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run a sweep file, or the paper's default scene without one")
    run.add_argument("sweep", nargs="?", help="sweep file (TOML, see docs/sweeps.md); none: the default scene")
    run.add_argument("-o", "--output", help="netCDF file to write (sweeps: default SWEEP.nc)")
    run.add_argument("--device", default=None, help="Warp device: cpu, cuda:0, ... (default: first GPU, else cpu)")
    run.add_argument("--chunk", type=int, default=None,
                     help="members per chunk file (default: all in one; with --resume: the interrupted run's)")
    run.add_argument("--member-offset", type=int, default=None, metavar="K",
                     help="number of the first member (default 0): give runs to be combined distinct numbers")
    run.add_argument("--resume", action="store_true", help="finish an interrupted run of the same sweep")
    run.add_argument("--overwrite", action="store_true", help="replace an existing output (and interrupted parts)")
    run.add_argument("--quiet", action="store_true", help="no progress line")
    dask = run.add_argument_group("Dask (sweeps; pip install 'warpfric[distributed]', docs/sweeps.md)")
    dask.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="run the chunks on the Dask scheduler at ADDRESS (e.g. tcp://host:8786), one task each")
    dask.add_argument("--local-cluster", action="store_true",
                      help="start a local Dask cluster: one worker per GPU (dask-cuda if installed), else CPU processes")
    dask.add_argument("--workers", type=int, default=None, metavar="N",
                      help="workers of --local-cluster (default: the GPU count, else the core count)")
    scene = run.add_argument_group("default scene (without a sweep file)")
    scene.add_argument("--normal-force", type=float, default=Parameters.normal_force, help="N (default 1000)")
    scene.add_argument("--eccentricity", type=float, default=Parameters.eccentricity, help="2e/L (default 0)")
    scene.add_argument("--disc-velocity", type=float, default=Parameters.disc_velocity, help="m/s (default 1e-4)")
    scene.add_argument("--nodes", type=int, default=Solver.nodes, help=f"grid nodes (default {Solver.nodes})")
    scene.add_argument("--dtype", default=Solver.dtype, choices=("float64", "float32"))
    scene.add_argument("--rtol", type=float, default=Solver.rtol, help=f"relative tolerance (default {Solver.rtol:g})")
    scene.add_argument("--end-time", type=float, default=None,
                       help="s (default: when the detachment is over, at most max_end_time = 80 s)")
    scene.add_argument("--grid-check", action="store_true",
                       help="also run on about half the nodes and report each front speed's change (its grid error)")
    scene.add_argument("--relaxation-gate", default=Model.relaxation_gate, choices=RELAXATION_GATES,
                       help="friction law's gate (default stress: GRL 2012; none: the SPEC v1 law)")
    info = sub.add_parser("info", help="summary of an ensemble file (or of an interrupted run, or of several files combined)")
    info.add_argument("file", nargs="+")
    plot = sub.add_parser("plot", help="quick-look PNGs of an ensemble file")
    plot.add_argument("file")
    plot.add_argument("--outdir", default=None, help="folder for the PNGs (default: OUT next to OUT.nc)")
    sens = sub.add_parser("sensitivity", help="Sobol (Saltelli design) or Morris indices of a design's outputs (needs SALib)")
    sens.add_argument("file")
    sens.add_argument("--output", action="append", help="per-member output to analyse (repeatable; default mu_s)")
    sens.add_argument("--on-failure", default="refuse", choices=("refuse", "fill-mean"),
                      help="members that failed or lack an output: refuse (default) or replace by the mean")
    sens.add_argument("--log", action="store_true", help="analyse the log of each output (heavy-tailed outputs: front speeds)")
    sens.add_argument("-o", "--out", default=None, help="result file (default OUT_sensitivity.nc, and .png)")
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    args.command_line = shlex.join(["warpfric", *map(str, argv)])  # the files' history attribute
    handlers = {"run": _run, "info": _info, "plot": _plot, "sensitivity": _sensitivity}
    try:
        return handlers[args.command](args)
    except ValueError as err:  # bad input: one line, exit 2
        return _fail(str(err))
    except KeyboardInterrupt:
        print("warpfric: interrupted; finished chunks are kept, continue with --resume", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
