"""warpfric command line.

  warpfric run [SWEEP.toml] [-o OUT.nc] [--device D] [--cpu-workers N] [--chunk M] [--member-offset K]
               [--resume | --overwrite] [--quiet] [--scheduler ADDR | --local-cluster [--workers N]]
  warpfric info OUT.nc [MORE.nc ...]
  warpfric plot OUT.nc [--outdir DIR]
  warpfric sensitivity OUT.nc [--output mu_s --output v_middle ...] [--on-failure refuse|fill-mean] [--log]
                       [-o RESULT.nc] [--overwrite]

Without a sweep file, ``run`` simulates the paper's default scene (one member, F = 1000 N, e = 0,
changeable with --normal-force, --eccentricity, --disc-velocity, ...) and prints mu_s and the front
speeds. Negative values may follow their option: --disc-velocity -1e-4.

Exit codes (one line on stderr for each fault):
  0    success
  1    some members failed (status not ok), chunks failed on a Dask cluster (the finished ones are
       kept for --resume), or `info` on an incomplete run
  2    bad input, an output folder that cannot be written, or a --scheduler that does not answer
       (checked before anything runs; nothing is written)
  3    an output could not be written: disk full (before the run when the free space is below
       half the estimated size) or another I/O error (no partial file stays; a sweep's finished
       chunks are kept for --resume)
  4    another run is writing the same output (its OUT.nc.lock exists)
  5    a CPU worker process died (killed: the out-of-memory killer, kill -9); a sweep's finished
       chunks are kept for --resume
  130  interrupted (Ctrl-C, or SIGTERM)
"""

from __future__ import annotations

import argparse
import contextlib
import difflib
import io
import os
import re
import shlex
import signal
import sys
import threading
import warnings
from pathlib import Path

import numpy as np

from .parameters import (MAX_RECORD_TIMES, MEMBERS_NOT_OK_HINT, RECORD_COUNT, RELAXATION_GATES, Fronts, Model,
                         Parameters, Record, Solver, detachment_start, recording_text, units_text)
from .progress import member_range, plural as _plural, seconds_text as _seconds, status_name


EXIT_FAILED_MEMBERS = 1
NOT_OK_SHOWN = 10  # members not ok that `info` names, per status
EXIT_BAD_INPUT = 2
EXIT_WRITE_FAILED = 3
EXIT_OUTPUT_BUSY = 4
EXIT_WORKER_DIED = 5
EXIT_INTERRUPTED = 130

# options of the default scene -> where a sweep file sets them (refused together with a sweep file)
SCENE_OPTIONS = {
    "normal_force": ("--normal-force", "[scene] normal_force"),
    "eccentricity": ("--eccentricity", "[scene] eccentricity"),
    "disc_velocity": ("--disc-velocity", "[scene] disc_velocity"),
    "end_time": ("--end-time", "[scene] end_time"),
    "nodes": ("--nodes", "[solver] nodes"),
    "dtype": ("--dtype", "[solver] dtype"),
    "rtol": ("--rtol", "[solver] rtol"),
    "relaxation_gate": ("--relaxation-gate", "[model] relaxation_gate"),
    "front_event": ("--front-event", "[fronts] event"),
    "grid_check": ("--grid-check", "[fronts] grid_check"),
}
FRONT_EVENTS = ("contact", "strength", "velocity", "off")  # --front-event; off: no front metrics (fronts=None)
# a negative number as an option's value: argparse takes "-1e-4" for an option (it knows only -1 and -1.5)
NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-inf(inity)?$", re.IGNORECASE)


class UsageError(ValueError):
    pass


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> int:
    print(f"warpfric: error: {message}", file=sys.stderr)
    return code


@contextlib.contextmanager
def one_line_warnings(output: str | None = None):
    """While a command runs: each Python warning as one line on stderr, ``warpfric: warning: <message>``
    (no file, line number or source line), each distinct message once. The warning of members not
    ok points to ``warpfric info OUTPUT`` for their numbers where the command writes ``output``, and
    drops the Python API's hint otherwise (a single scene prints its status). The filters are left
    as they are (-W, PYTHONWARNINGS); the Python API keeps Python's usual warnings."""
    seen = set()
    hint = (f"their numbers: warpfric info {shlex.quote(str(output))} (docs/model.md, \"Statuses\")"
            if output else None)

    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        text = text.replace(MEMBERS_NOT_OK_HINT, hint) if hint else text.replace("; " + MEMBERS_NOT_OK_HINT, "")
        if text in seen:
            return
        seen.add(text)
        try:
            print(f"warpfric: warning: {text}", file=sys.stderr, flush=True)
        except (OSError, ValueError):  # stderr closed: a warning is not worth a traceback
            pass

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def _fmt(value, unit="", spec=".4g") -> str:
    v = float(value)
    if not np.isfinite(v):
        return "absent"
    text = f"{v:{spec}}"
    if text.startswith("-") and float(text) == 0.0:  # -0.000000: a round-off below the shown digits
        text = text[1:]
    return text + (f" {unit}" if unit else "")


def _grid_error(m, name: str) -> str:
    """'+- change' of a front speed from Fronts(grid_check=True), '' without it or where the speed is
    absent; inf (absent on the coarse grid) as '+- ?'."""
    if f"{name}_grid_error" not in m or not np.isfinite(float(m[name])):
        return ""
    change = float(m[f"{name}_grid_error"])
    return f"+- {change:.2g} m/s" if np.isfinite(change) else "+- ? (not on the coarse grid)"


def _print_member(ds, solver: Solver) -> None:
    from .simulate import GRID_CHECK_MIN_NODES, not_over_groups

    m = ds.isel(member=0)
    not_over = {key: bool(which[0]) for key, which in not_over_groups(ds.isel(member=[0])).items()}
    print(f"scene: F = {float(m.normal_force):g} N, 2e/L = {float(m.eccentricity):g}, "
          f"v_d = {float(m.disc_velocity):g} m/s, relaxation gate {ds.attrs['model_relaxation_gate']}, "
          f"N = {solver.nodes}, {solver.dtype}, rtol = {solver.rtol:g}, device {ds.attrs['device']}")
    grid = f" +- {_fmt(m.mu_s_grid_error, '', '.2g')} (grid)" if "mu_s_grid_error" in m else ""
    print(f"mu_s      = {_fmt(m.mu_s, spec='.6f')}{grid}  (static friction coefficient)")
    print(f"mu_s_time = {_fmt(m.mu_s_time, 's', '.5f')}")
    print(f"mu_final  = {_fmt(m.mu_final, spec='.6f')}  (at t = {float(m.final_time):g} s)")
    event = ds.attrs.get("fronts_event", "").split()[:1]
    gate = ds.attrs["model_relaxation_gate"]
    if "v_middle" not in m:
        print("front     : not computed (--front-event off)")
    elif event == ["contact"] and gate != "stress" and not np.isfinite(float(m.front_start_time)):
        print(f"front     : absent: the contact front needs the yield gate (--relaxation-gate stress); under "
              f"relaxation gate {gate} --front-event strength reads a front")
    elif int(m.status) != 0:
        print(f"front     : not given: the member did not end ok ({status_name(ds, m.status)}), so its front outputs "
              "are NaN")
    elif any(not_over.values()):
        advice = {"plateau": "at max_end_time, the automatic end's cap: mu never fell 1 % below its maximum",
                  "front": "at max_end_time, the automatic end's cap: mu fell, but the front event was not over",
                  "cut": "(a later --end-time, or none: the automatic end)"}[next(k for k, v in not_over.items() if v)]
        print(f"front     : not given: the run ended at t = {float(m.final_time):g} s, before the detachment was over "
              f"{advice}, so its front outputs are NaN")
    elif not np.isfinite(float(m.nucleation_position)):
        print(f"front     : absent: no node reached the {event[0] + ' ' if event else ''}front's event in the run")
    else:
        edge = {-1: "left edge", 0: "interior", 1: "right edge", -2: "none", -3: "unknown"}[int(m.nucleation_edge)]
        what = f"{event[0]} front " if event else ""
        print(f"front     : {what}nucleates at x = {_fmt(float(m.nucleation_position) * 1e3, 'mm', '.1f')} ({edge}), "
              f"t = {_fmt(m.front_start_time, 's', '.5f')} .. {_fmt(m.front_end_time, 's', '.5f')}")
        two = "front_count" in m and float(m.front_count) > 1 and np.isfinite(float(m.second_nucleation_position))
        if "v_first" in m and np.isfinite(float(m.first_front_start)):  # the front whole, then its segments
            print(f"  {'first' if two else 'the'} front x = {float(m.first_front_start) * 1e3:.1f} .. "
                  f"{float(m.first_front_end) * 1e3:.1f} mm, v_first = {_fmt(m.v_first, 'm/s', '.3g')} "
                  f"{_grid_error(m, 'v_first')}".rstrip() + "; its segments:")
        width = 14 if "v_middle_grid_error" in m else 10  # the '+- 0.69 m/s' column
        nucleation = float(m.nucleation_position)
        for seg in ("left", "middle", "right"):
            start, end = float(m[f"{seg}_front_start"]), float(m[f"{seg}_front_end"])
            where = f"x = {start * 1e3:.1f} .. {end * 1e3:.1f} mm" if np.isfinite(start) else "absent"
            if int(m.nucleation_edge) == 0 and start < nucleation < end:  # both branches, from the nucleation out
                where += ": holds the nucleation point (its speed: the spreading from it, not a propagation speed)"
            print(f"  v_{seg:<6} = {_fmt(m[f'v_{seg}'], 'm/s', '.3g'):>10} {_grid_error(m, f'v_{seg}'):<{width}} {where}")
        if two:
            print(f"  v_second = {_fmt(m.v_second, 'm/s', '.3g'):>10} {_grid_error(m, 'v_second'):<{width}} "
                  f"x = {float(m.second_front_start) * 1e3:.1f} .. {float(m.second_front_end) * 1e3:.1f} mm: a second "
                  f"front from x = {float(m.second_nucleation_position) * 1e3:.1f} mm at t = "
                  f"{float(m.second_front_start_time):.5f} s")
            more = f" ({int(m.front_count)} fronts in all)" if float(m.front_count) > 2 else ""
            if np.isfinite(float(m.collision_position)):
                print(f"  the first front meets another at x = {float(m.collision_position) * 1e3:.1f} mm, "
                      f"t = {float(m.collision_time):.5f} s{more}")
        if "v_middle_grid_error" in m:
            print("  (+- : the change on a grid of half the nodes, an estimate of the spatial error)")
        elif solver.nodes < GRID_CHECK_MIN_NODES:  # too coarse for the check itself
            print(f"  (no error estimate: N = {solver.nodes} is too coarse for --grid-check, which needs "
                  f"--nodes >= {GRID_CHECK_MIN_NODES}; how the speeds move with N: docs/performance.md, "
                  "\"Fronts: cost and convergence\")")
        else:
            print("  (no error estimate: --grid-check estimates the speeds' spatial error, usually the largest)")
    print(f"status    = {status_name(ds, m.status)}; steps accepted {int(m.steps_accepted)}, rejected "
          f"{int(m.steps_rejected)}; lift-off {'yes' if int(m.lift_off) else 'no'}; "
          f"wall {_seconds(ds.attrs['wall_time_s'])} s for the run and its outputs (the progress line's time is "
          f"the integration's; + {_seconds(ds.attrs.get('kernel_build_time_s', 0.0))} s compiling/loading kernels; "
          f"{ds.attrs.get('device_bytes_per_member', 0.0) / 1024:.1f} KiB device memory per member)")


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)


def _run_default(args) -> int:
    from .io import (OutputWriteError, check_free_space, estimate_bytes, history_time, output_lock,
                     remove_stale_temporaries, write_ensemble)
    from .runner import check_output, check_output_name, detachment_runs
    from .simulate import simulate
    from .sweep_file import check_member_offset

    started = history_time()  # the file's history line: when the command started, as a sweep's says
    given = {name: getattr(args, name) for name in SCENE_OPTIONS}
    scene = Parameters(**{k: given[k] for k in ("normal_force", "eccentricity", "disc_velocity", "end_time")
                          if given[k] is not None})
    model = Model(**({"relaxation_gate": given["relaxation_gate"]} if given["relaxation_gate"] else {}))
    solver = Solver(**{k: given[k] for k in ("nodes", "dtype", "rtol") if given[k] is not None})
    event = given["front_event"]
    if event == "off" and args.grid_check:
        raise UsageError("--grid-check checks the front speeds; --front-event off computes none (give --front-event "
                         "contact, strength or velocity, or leave --grid-check out)")
    fronts = None if event == "off" else Fronts(**({"event": event} if event else {}),
                                                grid_check=bool(args.grid_check))
    offset = args.member_offset or 0
    check_member_offset(offset, 1, "--member-offset")
    output = Path(args.output) if args.output else None
    record = _record_option(args.record)
    if args.record is not None and output is None:
        raise UsageError("--record writes the member's fields into the file of -o; give -o OUT.nc (without it "
                         "nothing is written)")
    record_times = RECORD_COUNT if record is None and args.record is not None else \
        len(record.times) if record is not None else 0
    with contextlib.ExitStack() as stack:
        if output is not None:  # before the run: the folder takes the file, and no other run writes it
            check_output_name(output)
            stack.enter_context(output_lock(output, args.command_line))
            check_output(output, False, args.overwrite)
            check_free_space(output, estimate_bytes(1, solver.nodes, front_events=0 if fronts is None else
                                                    len(fronts.events), recorded=1 if record_times else 0,
                                                    times=record_times), "the file")
            remove_stale_temporaries(output)
        try:
            run = dict(scene=scene, model=model, solver=solver, device=args.device, progress=not args.quiet,
                       member_offset=offset, workers=args.cpu_workers)
            if args.record is not None and record is None:  # --record alone: find the detachment first
                # two runs, two progress lines: each says which it is
                found, final_time = detachment_runs(None, fronts=fronts,
                                                    **{**run, "progress": not args.quiet and "first run"})
                run["progress"] = not args.quiet and "recording"
                record = Record.detachment(found, member_offset=offset, final_time=final_time)
                what = ("the detachment found by a first run" if detachment_start(found, 0, final_time[0]) is not None
                        else "the disc's start to the end: a first run found no detachment (status "
                        f"{status_name(found, found.status[0])})")
                print(f"{recording_text(record.times)}, {what} (the last run records; its outputs are those of a run "
                      "without recording)")
            ds = simulate(fronts=fronts, record=record, **run)
            failed_write = None
            if output is not None:  # written before anything is printed; a failed write still shows the run
                try:
                    write_ensemble(ds, output, command=args.command_line, started=started)
                except OutputWriteError as err:
                    failed_write = err
            _print_member(ds, solver)
            if failed_write is not None:
                raise failed_write
            if output is not None:
                print(f"wrote {output}" + (f" (with the recorded fields: warpfric plot {shlex.quote(str(output))} draws "
                                           "them)" if record is not None else ""))
        except KeyboardInterrupt:  # one scene: no chunks to keep, nothing to resume
            raise KeyboardInterrupt("interrupted" + ("; nothing was written" if output is not None else "")) from None
    return 0 if int(ds.status[0]) == 0 else EXIT_FAILED_MEMBERS


def _record_option(values: list | None) -> Record | None:
    """--record START STOP [COUNT] as a Record of member 0 (None: not given, or given alone: the
    detachment's window, found by a first run)."""
    if not values:
        return None
    usage = ("--record takes no values (the detachment) or START STOP [COUNT]: times in s, START < STOP, COUNT an "
             f"integer in [2, {MAX_RECORD_TIMES:,}] (default {RECORD_COUNT})")
    sweep = next((v for v in values if v.endswith(".toml")), None)
    if sweep is not None:  # `warpfric run --record SWEEP.toml`: the file taken as a value
        raise UsageError(f"--record {' '.join(values)}: {sweep!r} is a sweep file, not a time: --record is for the "
                         "default scene; a sweep file records with its own [record] table (docs/sweeps.md)")
    if len(values) not in (2, 3):
        raise UsageError(f"--record {' '.join(values)}: {usage}")
    try:
        start, stop = float(values[0]), float(values[1])
        count = int(values[2]) if len(values) == 3 else RECORD_COUNT
    except ValueError:
        raise UsageError(f"--record {' '.join(values)}: {usage}") from None
    if not (np.isfinite(start) and np.isfinite(stop) and 0.0 <= start < stop):
        raise UsageError(f"--record {' '.join(values)}: START and STOP must be finite times, 0 <= START < STOP (s)")
    try:
        return Record.window(start, stop, count)
    except ValueError as err:
        raise UsageError(f"--record {' '.join(values)}: {err}") from None


def _run_sweep(args) -> int:
    from .runner import run_sweep

    report = run_sweep(args.sweep, args.output, chunk=args.chunk, member_offset=args.member_offset, device=args.device,
                       resume=args.resume, overwrite=args.overwrite, scheduler=args.scheduler,
                       local=True if args.local_cluster else None, workers=args.workers, quiet=args.quiet,
                       command=args.command_line, cpu_workers=args.cpu_workers)
    failed = report.file_failed_members if report.file_failed_members is not None else report.failed_members
    return 0 if report.output is not None and failed == 0 else EXIT_FAILED_MEMBERS  # the whole file's (resumed too)


def _run(args) -> int:
    if args.output is not None and not args.output.strip():  # -o "$OUT" with OUT unset wrote nothing, silently
        raise UsageError(f"-o {args.output!r}: an empty file name; expected a file name ending in .nc")
    if args.chunk is not None and args.chunk < 1:
        raise UsageError(f"--chunk {args.chunk}: expected an integer >= 1 (members per chunk file)")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers {args.workers}: expected an integer >= 1")
    if args.cpu_workers is not None and args.cpu_workers < 1:
        raise UsageError(f"--cpu-workers {args.cpu_workers}: expected an integer >= 1 (1: this process only)")
    if args.scheduler and args.local_cluster:
        raise UsageError("--scheduler and --local-cluster exclude each other (an existing cluster, or a new one)")
    if args.resume and args.overwrite:
        raise UsageError("--resume and --overwrite exclude each other")
    if args.sweep is None:
        for flag, given in (("--scheduler", args.scheduler), ("--local-cluster", args.local_cluster),
                            ("--workers", args.workers is not None), ("--chunk", args.chunk is not None),
                            ("--resume", args.resume)):
            if given:
                raise UsageError(f"{flag} applies to the chunks of a sweep file; give one (warpfric run SWEEP.toml "
                                 f"{flag} ...), the default scene runs as one member")
        if args.overwrite and not args.output:
            raise UsageError("--overwrite replaces the file of -o; give -o OUT.nc (without it nothing is written)")
        return _run_default(args)
    given = [(flag, key, getattr(args, name)) for name, (flag, key) in SCENE_OPTIONS.items()
             if getattr(args, name) not in (None, False)]
    if given or args.record is not None:  # every such option in one line, --record among them
        flags = ", ".join([flag for flag, _, _ in given] + (["--record"] if args.record is not None else []))
        if ("--front-event", "off") in [(flag, value) for flag, _, value in given]:
            given = [g for g in given if g[0] != "--grid-check"]  # no fronts: nothing to check on a grid
        keys = ", ".join(["fronts = false (top level)" if (flag, value) == ("--front-event", "off") else
                          f"{key} = {_toml_value(value)}" for flag, key, value in given]
                         + (["a [record] table of members and times (or start, stop, count; or window = "
                             "\"detachment\", as --record alone)"]
                            if args.record is not None else []))
        swept = any(key.startswith("[scene]") for _, key, _ in given)
        where = ", or change the values where the file sweeps the parameter" if swept else ""
        raise UsageError(f"{flags}: for the default scene only; a sweep file sets its own (write {keys} in "
                         f"{args.sweep}{where}), so that the file it writes can be run again from its sweep_toml")
    return _run_sweep(args)  # (--cpu-workers on a Dask cluster: refused by run_sweep, whatever names the cluster)


# what `warpfric info` and `plot` read of every file, and of a file with front outputs (its varying
# parameters too): found by dropping each output of a file with the contact front in turn
RUN_OUTPUTS = ("status", "mu_s", "mu_s_time", "mu_final", "final_time")
FRONT_OUTPUTS_READ = ("front_start_time", "front_end_time", "v_left", "v_middle", "v_right", "collision_time",
                      "arrival_time")


def _whole_run(ds, name: str, command: str):
    """``ds`` where it holds the outputs that `warpfric info` and `plot` read; a file without some
    (e.g. written from a selection of a run's Dataset: ``write_ensemble(ds[["mu_s", "status"]], ...)``)
    raises UsageError naming them, instead of a traceback from deep inside info or plot."""
    from .fronts import FRONT_METRIC_NAMES

    needed = list(RUN_OUTPUTS) + ds.attrs.get("varying_parameters", "").split()
    if any(output in ds for output in FRONT_METRIC_NAMES):
        needed += FRONT_OUTPUTS_READ
    missing = [output for output in dict.fromkeys(needed) if output not in ds]
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        raise UsageError(f"{name} lacks {shown}, which `warpfric {command}` reads (a file written from a selection "
                         "of a run's Dataset, or by another version of warpfric?); read it with "
                         "warpfric.io.open_ensemble and xarray")
    return ds


def _info(args) -> int:
    from .io import ChunkStore, open_ensemble, open_ensembles, parts_dir, resume_command, running_writer

    def chunks_done(store, path: Path, sizes: bool) -> tuple[str, str | None]:
        """How far the parts of ``path`` are ('3/8 chunks finished in ...', with the chunk and member
        counts where ``sizes``) and the running writer's description, None where it was interrupted."""
        of = f" of <= {_plural(store.chunk, 'member')}" if sizes else ""
        total = f" ({_plural(store.n_members, 'member')} in all)" if sizes else ""
        return (f"{store.done_count()}/{_plural(store.n_chunks, 'chunk')}{of} finished{total} in {parts_dir(path)}",
                running_writer(path))

    def unfinished(path: Path) -> str | None:
        """The line of a sweep that is still running or was interrupted (no file yet, its parts), or None."""
        if path.exists() or not parts_dir(path).exists():
            return None
        store = ChunkStore.load(parts_dir(path))
        done, writer = chunks_done(store, path, sizes=True)
        if writer is not None:  # not interrupted: still being written
            return f"{path}: RUNNING: being written by warpfric run ({writer}); {done} so far"
        return f"{path}: INCOMPLETE run: {done}; finish it with `{resume_command(store, path)}`"

    lines = [line for line in map(unfinished, map(Path, args.file)) if line]
    if lines:  # exit 1, as for one file, with each unfinished file's line
        print("\n".join(lines))
        return 1
    if len(args.file) > 1:  # several files: their combination (refused when member numbers repeat)
        ds = _whole_run(open_ensembles(args.file), " + ".join(args.file), "info")
        print(summary(ds, " + ".join(args.file)))
        return 0
    path = Path(args.file[0])
    ds = _whole_run(open_ensemble(path), str(path), "info")
    print(summary(ds, str(path)))
    try:  # a --overwrite run replacing it, running or interrupted (a parts folder without a manifest: none)
        store = ChunkStore.load(parts_dir(path)) if parts_dir(path).is_dir() else None
    except ValueError:
        store = None
    if store is not None:
        done, writer = chunks_done(store, path, sizes=False)
        if writer is not None:
            print(f"  being replaced by a running warpfric run ({writer}): {done} so far")
        else:
            print(f"  an interrupted run that replaces it: {done}; `{resume_command(store, path)}` finishes it and "
                  "replaces this file")
    return 0


def file_order(names, sweep_toml: str | None = None) -> list:
    """The swept parameters ``names`` in their sweep file's order (its [grid], [zip], [sample] keys and
    [design.parameters], as written) where the file's text ``sweep_toml`` is at hand; the others after
    them, as given."""
    import tomllib

    order = []
    try:
        doc = tomllib.loads(sweep_toml) if sweep_toml else {}
    except tomllib.TOMLDecodeError:
        doc = {}
    for table in (doc.get("grid"), doc.get("zip"), doc.get("sample"), (doc.get("design") or {}).get("parameters")):
        if isinstance(table, dict):
            order += [key for key in table if key in names and key not in order]
    return order + [key for key in names if key not in order]


def summary(ds, name: str) -> str:
    """Text summary of an ensemble: members, swept parameters, status counts, mu_s and fronts."""
    numbers = ds.member.values
    lines = [f"{name}: {member_range(ds.sizes['member'], numbers.min(), numbers.max())}, "
             f"{ds.sizes.get('x', 0)} nodes, complete"]
    lines.append(f"  title: {ds.attrs.get('title', '')}; device {ds.attrs.get('device')}, warpfric "
                 f"{ds.attrs.get('warpfric_version')}, warp {ds.attrs.get('warp_version')}, "
                 f"wall {_seconds(ds.attrs.get('wall_time_s', float('nan')))} s")
    swept = file_order(ds.attrs.get("varying_parameters", "").split(), ds.attrs.get("sweep_toml"))
    lines.append("  swept parameters:" + ("" if swept else " none"))
    for pname in swept:
        v = ds[pname].values
        n_values = np.unique(v).size
        units = units_text(ds[pname].attrs.get("units", ""))
        lines.append(f"    {pname:<22} {n_values:>6} value{'s' if n_values != 1 else ' '} in [{v.min():.6g}, {v.max():.6g}]"
                     + (f" {units}" if units else " (dimensionless)"))
    codes = np.unique(ds.status.values)
    counts = {status_name(ds, k): int((ds.status.values == k).sum()) for k in codes}
    lines.append("  status: " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    def members_line(what: str, which: np.ndarray) -> str:
        """'    <what>: members 3, 7 and 12 more': the first NOT_OK_SHOWN numbers of ``which``."""
        more = f" and {which.size - NOT_OK_SHOWN:,} more" if which.size > NOT_OK_SHOWN else ""
        return (f"    {what}: member{'s' if which.size > 1 else ''} "
                f"{', '.join(str(k) for k in which[:NOT_OK_SHOWN])}{more}")

    for code in codes:
        if int(code) != 0:  # the members not ok, by number
            lines.append(members_line(status_name(ds, code), numbers[ds.status.values == code]))
    from .simulate import not_over_groups

    groups = not_over_groups(ds)
    whys = {"plateau": "at max_end_time (mu never fell 1 % below its maximum; mu_s may be a plateau's)",
            "front": "at max_end_time (mu fell, but the front event was not over; their fronts are NaN)",
            "cut": "at end_time (their fronts are NaN)"}
    for key, which in groups.items():
        if which.any():  # ok members whose run ended before their detachment was over, by number
            lines.append(members_line(f"ok, but ended before the detachment was over {whys[key]}", numbers[which]))
    mu = ds.mu_s.values
    good = np.isfinite(mu)
    if good.any():
        lines.append(f"  mu_s: mean {mu[good].mean():.6f}, std {mu[good].std():.3g}, min {mu[good].min():.6f}, "
                     f"max {mu[good].max():.6f} ({_plural(int(good.sum()), 'member')})")
    if "v_middle" in ds:
        rows = [(f"first front's {seg} segment", f"v_{seg}") for seg in ("left", "middle", "right")]
        if "v_second" in ds:
            rows.append(("second front", "v_second"))
        # over the members whose fronts were read: not those not ok or cut off, whose fronts are unknown
        read = (ds.status.values == 0) & ~np.logical_or.reduce(list(groups.values()))
        unread = f" ({int((~read).sum())} more not read: not ok or cut off)" if not read.all() else ""
        for what, var in rows:
            v = ds[var].values
            ok = np.isfinite(v)
            text = (f": median {np.median(v[ok]):.3g} m/s, range [{v[ok].min():.3g}, {v[ok].max():.3g}]"
                    if ok.any() else "")
            if read.any():
                lines.append(f"  {what} present in {ok.sum()}/{_plural(int(read.sum()), 'member')}{text}{unread}")
            else:
                lines.append(f"  {what}: no member's front was read ({int((~read).sum())} not ok or cut off)")
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
    from .io import PARTS_SUFFIX, open_ensemble, os_error_reason
    from .plots import quick_look

    outdir = Path(args.outdir) if args.outdir else Path(args.file).with_suffix("")
    if outdir.exists() and not outdir.is_dir():
        raise UsageError(f"figure folder {str(outdir)!r} is a file; give another with --outdir DIR")
    if args.outdir and not outdir.parent.is_dir():  # as -o: a mistyped path is refused, not created folder by folder
        raise UsageError(f"figure folder {str(outdir)!r}: folder {str(outdir.parent)!r} does not exist; give a folder "
                         "in an existing one with --outdir DIR (plot creates only the last folder)")
    parts = next((f for f in (outdir.resolve(), *outdir.resolve().parents) if f.name.endswith(".nc" + PARTS_SUFFIX)),
                 None)
    if parts is not None:  # a chunk's figures would go with the folder when the run ends
        raise UsageError(f"figure folder {str(outdir)!r} lies in {str(parts)!r}, the chunks of a sweep, which is "
                         "removed when the sweep ends; give a folder outside it with --outdir DIR")
    ds = _whole_run(open_ensemble(args.file), str(args.file), "plot")
    try:
        outdir.mkdir(exist_ok=True)
        for path in quick_look(ds, outdir):
            print(f"wrote {path}")
        if ds.sizes["member"] == 1 and "velocity_history" not in ds:
            how = ("a [record] table in its sweep file records them (docs/sweeps.md)" if ds.attrs.get("sweep_file")
                   else "warpfric run -o OUT.nc --record records them")
            print(f"(one member without recorded fields: {how}, and plot then draws its space-time map and mu(t))")
    except OSError as err:
        raise UsageError(f"figure folder {str(outdir)!r}: cannot write in it ({os_error_reason(err)}); give another "
                         "with --outdir DIR") from None
    return 0


def _sensitivity(args) -> int:
    from .io import history_line, open_ensemble, probe_writable, replace_atomically
    from .runner import check_output_name
    from .sensitivity import analyse, bar_plot, design_outputs

    source = Path(args.file)
    out = Path(args.out) if args.out else source.with_name(source.stem + "_sensitivity.nc")
    figure = out.with_suffix(".png")
    check_output_name(out)
    if out.exists() and source.exists() and out.samefile(source):
        raise UsageError(f"output {str(out)!r} is the ensemble being analysed; give another -o OUT.nc")
    ds = open_ensemble(source)
    outputs = tuple(args.output or ["mu_s"])
    # the design's own faults (a wrong name, members that lack an output) before "exists" (and
    # --overwrite to learn them), and an unwritable folder before the analysis
    design_outputs(ds, outputs, args.on_failure, args.log)
    for path in (out, figure):
        if path.is_dir():  # --overwrite cannot replace a folder: found after the analysis had written the .nc
            raise UsageError(f"output {str(path)!r} is a folder; give -o another name (the figure goes beside the "
                             "file, with .png)")
        if path.exists() and not args.overwrite:
            raise UsageError(f"output {str(path)!r} exists; pass --overwrite to replace it")
    probe_writable(out.parent, out)
    res = analyse(ds, outputs=outputs, on_failure=args.on_failure, log=args.log)
    res.attrs["history"] = history_line(args.command_line)
    replace_atomically(out, res.to_netcdf)
    replace_atomically(figure, lambda tmp: bar_plot(res, tmp), suffix=".png")
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


class _Parser(argparse.ArgumentParser):
    """argparse's parser with one-line errors (``warpfric: error: ...``, exit code 2, as every other
    fault), an unknown option answered with the closest known ones, and no abbreviated options (a
    script that writes ``--over`` for ``--overwrite`` would break, or change meaning, the day another
    option starts alike: it gets the "did you mean" hint instead)."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def error(self, message):
        if message.startswith("unrecognized arguments:"):
            known = sorted({o for a in self._actions for o in a.option_strings if o.startswith("--")})  # noqa: SLF001
            unknown = [w for w in message.split(":", 1)[1].split() if w.startswith("-")]
            close = {w: difflib.get_close_matches(w.split("=")[0], known, n=1) for w in unknown}
            hints = [f"did you mean {c[0]}?" for c in close.values() if c]
            if hints:
                message += " (" + "; ".join(hints) + ")"
        command = self.prog if self.prog != "warpfric" else "warpfric COMMAND"
        self.exit(2, f"warpfric: error: {message} (`{command} --help` lists the options)\n")


def _subcommand_parser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    """The parser of subcommand ``command`` of ``parser``."""
    subcommands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))  # noqa: SLF001
    return subcommands.choices[command]


def build_parser() -> tuple[argparse.ArgumentParser, set]:
    """The argument parser, and the option strings that take a value (for negative numbers)."""
    value_options: set = set()

    def add(group, *names, **kwargs):
        action = group.add_argument(*names, **kwargs)
        if action.option_strings and action.nargs != 0:
            value_options.update(action.option_strings)
        return action

    parser = _Parser(prog="warpfric", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND",
                                help="run, info, plot or sensitivity (warpfric COMMAND --help)")
    run = sub.add_parser("run", help="run a sweep file, or the paper's default scene without one",
                         description="Run a sweep file in resumable chunks, or the paper's default scene without "
                                     "one. Exit codes: 0 ok, 1 members failed, 2 bad input (nothing written), "
                                     "3 output not written (disk full), 4 output busy, 5 a CPU worker process died, 130 interrupted.")
    add(run, "sweep", nargs="?", metavar="SWEEP.toml",
        help="sweep file (TOML, see docs/sweeps.md); none: the default scene")
    add(run, "-o", "--output", metavar="OUT.nc", help="netCDF file to write (sweeps: default SWEEP.nc; "
        "the default scene writes one only with -o)")
    add(run, "--device", default=None, help="Warp device: cpu, cuda:0, ... (default: the first GPU if any, else cpu; a "
        "lone member, or up to 32 members where the GPU would run one member a thread (float32, [solver] lanes = 1, or "
        "--nodes below 16), on the cpu)")
    add(run, "--cpu-workers", type=int, default=None, metavar="N",
        help="worker processes on the CPU (default: all cores for an ensemble that pays, else 1; 1: this process)")
    add(run, "--member-offset", type=int, default=None, metavar="K",
        help="number of the first member (default 0): give runs to be combined distinct numbers")
    add(run, "--overwrite", action="store_true", help="replace an existing output (and interrupted parts)")
    add(run, "--quiet", action="store_true", help="no progress line")
    chunks = run.add_argument_group("sweeps (with a sweep file only)")
    add(chunks, "--chunk", type=int, default=None, metavar="M",
        help="members per chunk file (default: all in one; with --resume: the interrupted run's)")
    add(chunks, "--resume", action="store_true", help="finish an interrupted run of the same sweep")
    dask = run.add_argument_group("Dask (sweeps; pip install 'warpfric[distributed]', docs/sweeps.md)")
    add(dask, "--scheduler", default=None, metavar="ADDRESS",
        help="run the chunks on the Dask scheduler at ADDRESS (e.g. tcp://host:8786), one task each")
    add(dask, "--local-cluster", action="store_true",
        help="start a local Dask cluster: one worker per GPU (dask-cuda if installed), else CPU processes")
    add(dask, "--workers", type=int, default=None, metavar="N",
        help="workers of --local-cluster (default: the GPU count, else the core count)")
    scene = run.add_argument_group("default scene (without a sweep file; a sweep file sets these itself)")
    add(scene, "--normal-force", type=float, default=None, metavar="F",
        help=f"normal force, N (default {Parameters.normal_force:g})")
    add(scene, "--eccentricity", type=float, default=None, metavar="E",
        help=f"normalised eccentricity 2e/L, dimensionless, in [-0.6, 0.6] (default {Parameters.eccentricity:g})")
    add(scene, "--disc-velocity", type=float, default=None, metavar="V",
        help=f"disc velocity, m/s; negative: the other way (default {Parameters.disc_velocity:g})")
    add(scene, "--end-time", type=float, default=None, metavar="T",
        help="end of the run, s (default: when the detachment is over, at most max_end_time = 80 s)")
    add(scene, "--nodes", type=int, default=None, help=f"grid nodes, >= 3 (default {Solver.nodes})")
    add(scene, "--dtype", default=None, choices=("float64", "float32"),
        help=f"floating-point precision of the state (default {Solver.dtype}; float32 needs "
             "--relaxation-gate none or velocity)")
    add(scene, "--rtol", type=float, default=None,
        help=f"relative tolerance of the adaptive step, in [1e-12, 0.1] (default {Solver.rtol:g})")
    add(scene, "--grid-check", action="store_true",
        help="also run on about half the nodes and report each front speed's change (its grid error)")
    add(scene, "--record", nargs="*", default=None, metavar="T",
        help="record the member's fields (pad velocity, slip rate, pressure, friction stress, mu(t)) into the file "
             "of -o: alone, over the detachment (a first run finds it), at "
             f"{RECORD_COUNT} times; or --record START STOP [COUNT] (s; default COUNT {RECORD_COUNT}); warpfric "
             "plot draws them")
    add(scene, "--relaxation-gate", default=None, choices=RELAXATION_GATES,
        help=f"what gates the friction law's relaxation and rejuvenation (default {Model.relaxation_gate}): "
             "stress: the yield gate (Bar-Sinai et al., GRL 2012), only where the friction stress exceeds the "
             "shear strength; none: the friction law without the yield gate, relaxation and rejuvenation at "
             "every stress; velocity: a smooth gate sqrt(s^2 + v0^2) of the slip rate s (PRE 2013)")
    add(scene, "--front-event", default=None, choices=FRONT_EVENTS,
        help=f"which detachment front is read (default {Fronts.event}): contact: each node's stick-to-slip "
             "transition (the stress gate only: the other laws have none); strength: each node's peak of "
             "tau_f/sigma_n, under every law; velocity: the paper's 40 %% velocity rule (a second pass); "
             "off: no front metrics")
    info = sub.add_parser("info", help="summary of an ensemble file (or of an interrupted run, or of several files combined)")
    add(info, "file", nargs="+", metavar="FILE",
        help="ensemble file (OUT.nc, or the OUT.nc of an interrupted run); several: their combination")
    plot = sub.add_parser("plot", help="quick-look PNGs of an ensemble file")
    add(plot, "file", metavar="FILE", help="ensemble file (netCDF, from warpfric run)")
    add(plot, "--outdir", default=None,
        help="folder for the PNGs, created if its parent exists (default: OUT next to OUT.nc); PNGs of the same names "
             "there are replaced, others are left")
    sens = sub.add_parser("sensitivity", help="Sobol (Saltelli design) or Morris indices of a design's outputs (needs SALib)")
    add(sens, "file", metavar="FILE", help="ensemble file of a sweep with a [design] table")
    add(sens, "--output", action="append", help="per-member output to analyse (repeatable; default mu_s)")
    add(sens, "--on-failure", default="refuse", choices=("refuse", "fill-mean"),
        help="members that failed or lack an output: refuse (default) or replace by the mean")
    add(sens, "--log", action="store_true", help="analyse the log of each output (heavy-tailed outputs: front speeds)")
    add(sens, "-o", "--out", default=None, help="result file (default OUT_sensitivity.nc, and .png)")
    add(sens, "--overwrite", action="store_true", help="replace an existing result file and figure")
    return parser, value_options


def join_negative_values(argv: list, value_options: set) -> list:
    """``--disc-velocity -1e-4`` -> ``--disc-velocity=-1e-4``: argparse would take the number for an
    option (it only knows negative numbers of the forms -1 and -1.5)."""
    out = []
    for word in argv:
        if out and out[-1] in value_options and NEGATIVE_NUMBER.match(word):
            out[-1] = f"{out[-1]}={word}"
        else:
            out.append(word)
    return out


@contextlib.contextmanager
def _sigterm_as_ctrl_c():
    """SIGTERM (`timeout`, `kill`, a batch system's time limit) handled as Ctrl-C: the sweep keeps its
    finished chunks, says how to resume and removes its lock (killed by SIGTERM, it left the lock
    and said nothing). It goes through SIGINT's handler of the moment where that is a Python one, else
    (SIGINT ignored, as in a job started with & from a script) raises KeyboardInterrupt itself; a
    netCDF write holds both back (warpfric.io). Only in the main thread, where signals can be handled."""
    from .io import sigterm_as_ctrl_c

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, sigterm_as_ctrl_c)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


class _PipeSafe:
    """A text stream whose writes survive its reader going away (`warpfric info OUT.nc | head -1`):
    after a BrokenPipeError the rest is dropped, its file descriptor pointed at /dev/null so that
    Python's flush at exit does not fail either, and the command goes on (a run still writes its
    file and exits with its own code). Everything else is the stream's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        try:
            return self._stream.write(text)
        except BrokenPipeError:
            self._drop()
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._drop()

    def _drop(self) -> None:
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, io.UnsupportedOperation):  # no descriptor (a test's capture): nothing to flush
            pass

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _pipe_safe_output():
    """sys.stdout and sys.stderr as _PipeSafe streams while a command runs."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _PipeSafe(out), _PipeSafe(err)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err


def main(argv=None) -> int:
    from .io import OutputBusy, OutputWriteError
    from .pool import WorkerDied

    parser, value_options = build_parser()
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    args, extra = parser.parse_known_args(join_negative_values(argv, value_options))
    if extra:  # answered by the subcommand's parser: its options, its --help
        _subcommand_parser(parser, args.command).error(f"unrecognized arguments: {' '.join(extra)}")
    args.command_line = shlex.join(["warpfric", *argv])  # the files' history attribute
    handlers = {"run": _run, "info": _info, "plot": _plot, "sensitivity": _sensitivity}
    with _pipe_safe_output():  # the error lines too: a reader gone does not turn exit 2, 3 or 4 into 1
        try:
            with one_line_warnings(args.output if args.command == "run" else None), _sigterm_as_ctrl_c():
                return handlers[args.command](args)
        except ValueError as err:  # bad input, or an output folder that cannot be written: one line, exit 2
            return _fail(str(err))
        except OutputWriteError as err:  # disk full (or another I/O error) while writing
            return _fail(str(err), EXIT_WRITE_FAILED)
        except OutputBusy as err:
            return _fail(str(err), EXIT_OUTPUT_BUSY)
        except WorkerDied as err:  # killed (out of memory?): the run stopped, a sweep's finished chunks kept
            return _fail(str(err), EXIT_WORKER_DIED)
        except KeyboardInterrupt as err:
            message = getattr(err, "message", None) or (str(err) if err.args else "interrupted")
            print(f"warpfric: {message}", file=sys.stderr)
            return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
