"""warpfric.simulate: run an ensemble of pads on the CPU or a GPU and return an xarray Dataset."""

from __future__ import annotations

import contextlib
import dataclasses
import re
import sys
import time
import warnings
from typing import Any

import numpy as np
import xarray as xr

from . import __version__
from .device import check_device, init_warp
from .members import resolve_members
from .fronts import SEGMENT_NAMES
from .front_outputs import detachment_not_over, front_variables, fronts_attrs
from .parameters import (CONTACT_WITHOUT_GATE, DETACHMENT_NOT_OVER, DISC_BEFORE_FULL_LOAD, ENSEMBLE_WARNINGS, FRONT_EVENTS, FRONTS_SETTINGS_UNUSED, LIFT_OFF_UNDAMPED, LOAD_ABOVE_HARDNESS, MEMBERS_NOT_OK,
                         MEMBER_NUMBER_LIMIT, MEMBERS_NOT_OK_HINT, PARAMETERS_UNUSED, RECORD_PAST_END, Fronts, Model,
                         Parameters, Record, Solver, check_fronts_method, check_precision, parameter_long_name, parameter_units)
from .progress import check_memory, first_few, shown


def simulate(
    members: Any = None,
    *,
    scene: Parameters = Parameters(),
    model: Model = Model(),
    solver: Solver = Solver(),
    fronts: Fronts | None = Fronts(),
    record: Record | None = None,
    device: str | None = None,
    progress: bool | str | None = None,
    member_offset: int = 0,
    workers: int | None = None,
) -> xr.Dataset:
    """Simulate an ensemble of pads through the load protocol; return the results as a Dataset.

    members:  None (one member: the scene), a mapping ``name -> array`` or an xarray Dataset with
              dim ``member``. Arrays broadcast together (e.g. shapes (3, 1) and (5,) give 15
              members, flattened in C order); names are those of :class:`Parameters`.
    scene:    :class:`Parameters` with the values of every parameter not given per member.
    model:    :class:`Model` switches (each combination compiles its own kernel).
    solver:   :class:`Solver` settings (grid, precision, tolerances, step bounds).
    device:   Warp device ('cpu', 'cuda:0', ...); None: the CPU for a lone member (a CPU core ties
              a GPU there and starts sooner; up to 32 members where the GPU would run the
              thread-per-member kernel: float32, lanes=1, fewer than 16 nodes), else the first CUDA
              device if any, else 'cpu'.
    fronts:   :class:`Fronts`: which detachment front (default: the contact front, each node's
              stick-to-slip transition, in the one integration pass; event='velocity' costs a
              second pass) and how it is segmented; None skips the front metrics.
    record:   :class:`Record`: fields of chosen members on a time grid; None (default) records nothing.
    progress: progress line on stderr; None: only when stderr is a terminal; a string: on, with
              that label.
    member_offset: number of the first member (coordinate ``member`` = offset, offset + 1, ...), so
              that the files of separate runs combine without repeated member numbers.
    workers:  worker processes on the CPU (Warp runs a CPU launch on one core). None: all cores for
              an ensemble large enough to pay (one core: >= ~2.5 s, pool.MIN_CPU_SECONDS), else this process; 1: this process;
              an integer: that many (more than the cores: started, with a warning that they share
              the cores). Outputs equal one process's bit for bit, except which members the
              straggler rule stops (warpfric/pool.py). A process runs a CPU ensemble in blocks of
              CPU_MEMBER_BLOCK members, one after the other (faster: the caches hold a block).

    Returns an ``xarray.Dataset`` with dims ``member`` and ``x`` (node position, m): every input
    parameter along ``member``; ``mu_s``, ``mu_s_time`` (s), ``status`` (flag values, see its
    attrs), ``lift_off``, ``steps_accepted``, ``steps_rejected`` (by cause: ``rejected_error_test``,
    ``rejected_newton``, ``rejected_switch``; and ``missed_predictions``), ``newton_iterations``,
    ``final_time`` (s), ``detachment_end_time`` (s: when the automatic end's conditions first held,
    NaN where the run ended before them or the member's status is not ok), ``plate_compression`` (m),
    ``plate_tilt`` (rad), ``mu_final``, ``working_precision`` (bits), ``gate_switches`` and
    ``unlocated_switches``, and the final
    state along (member, x): ``displacement`` (m), ``velocity`` (m/s), ``elastic_stress`` (Pa),
    ``contact_age`` (s), ``normal_stress`` (Pa), ``friction_stress`` (Pa); the stress gate adds
    ``yield_time`` (s) and ``yield_gate`` (member, x). With fronts, for the first event (others
    prefixed with the event's name, e.g. ``strength_v_main``): ``arrival_time`` and
    ``arrival_time_error`` (member, x; s), ``nucleation_position`` (m), ``nucleation_edge``,
    ``front_start_time``, ``front_end_time`` (s), ``detached_fraction``; per segment of the first
    front (left, middle, right by position; precursor, main, far from where it starts)
    ``*_front_start``, ``*_front_end`` (m: its smaller and larger x), ``*_front_length`` (m), ``v_*``
    and ``v_*_error`` (m/s; NaN where a segment is absent); the fronts as wholes (``first``, ``second``: ``first_front_start``
    ... ``v_second_error``), ``front_count``, where and when the first meets another
    (``collision_position`` (m), ``collision_time`` (s)) and where and when a second starts
    (``second_nucleation_position`` (m), ``second_front_start_time`` (s)); each output's
    ``long_name`` says what it is. A member whose status is not ok has NaN ``mu_s`` and front
    outputs (``mu_final`` too, but for ``no_peak``); its final fields, plate state, ``lift_off``
    and step counts are its state where its run stopped, at ``final_time`` (docs/model.md,
    "Statuses"). A front output is NaN also where the member has no such front or segment, or its
    run ended before its detachment was over. The velocity event adds
    ``event_max_velocity`` (m/s), the strength event ``strength_peak`` (member, x) (``strength_``
    prefixed again where it is not the first event: ``strength_strength_peak``); ``grid_check``
    adds ``mu_s_grid_error`` and ``v_*_grid_error``. With record:
    ``velocity_history``, ``slip_rate_history``, ``normal_stress_history``,
    ``friction_stress_history`` along (recorded, time, x) and ``friction_coefficient_history``
    (recorded, time): mu(t) of the recorded fields (:func:`friction_coefficient_history`),
    coordinates ``recorded_member`` and ``time``. Raises ValueError on invalid input before any kernel runs.
    """
    if not isinstance(model, Model):
        raise ValueError(f"model: expected a warpfric.Model, got {type(model).__name__}")
    if progress is not None and not isinstance(progress, (bool, np.bool_, str)):
        raise ValueError(f"progress = {progress!r} is invalid; valid: None (a line where stderr is a terminal or a "
                         "notebook), True, False or a string (on, with that label)")
    if not isinstance(solver, Solver):
        raise ValueError(f"solver: expected a warpfric.Solver, got {type(solver).__name__}")
    check_precision(model, solver)
    if fronts is not None and not isinstance(fronts, Fronts):
        hint = (f" (for that event: fronts=warpfric.Fronts(event={fronts!r}))"
                if isinstance(fronts, str) and fronts in FRONT_EVENTS else "")
        raise ValueError(f"fronts: expected a warpfric.Fronts or None, got {type(fronts).__name__}{hint}")
    if record is not None and not isinstance(record, Record):
        raise ValueError(f"record: expected a warpfric.Record or None, got {type(record).__name__}")
    if isinstance(member_offset, bool) or not isinstance(member_offset, (int, np.integer)) or not (
        0 <= member_offset < MEMBER_NUMBER_LIMIT
    ):
        raise ValueError(f"member_offset = {member_offset!r} is invalid; valid: an integer in [0, {MEMBER_NUMBER_LIMIT})")
    member_offset = int(member_offset)  # a numpy integer's own width overflowed in the worker split (np.int8(126) + 4)
    check_fronts_method(fronts, solver)
    if fronts is not None and "contact" in fronts.events and model.relaxation_gate != "stress":
        warnings.warn(f"{CONTACT_WITHOUT_GATE}{model.relaxation_gate!r}: this law has no yield threshold, so the "
                      "contact area falls everywhere as soon as the disc moves and there is no stick-to-slip front; "
                      "its outputs say none (speeds and positions NaN, nucleation_edge -2, detached_fraction 0; "
                      "event='strength' exists under every law)", stacklevel=2)
    unused = fronts.unused_settings() if fronts is not None else []
    if unused:  # asked for, and silently without effect
        warnings.warn(f"{FRONTS_SETTINGS_UNUSED}: {', '.join(unused)} (event={fronts.event!r}); "
                      "they set the velocity front's arrival level and sign: Fronts(event=('contact', 'velocity')) "
                      "reads both fronts", stacklevel=2)
    if fronts is not None and fronts.grid_check and solver.nodes < GRID_CHECK_MIN_NODES:
        raise ValueError(f"fronts setting 'grid_check' needs solver setting 'nodes' >= "
                         f"{GRID_CHECK_MIN_NODES} (got {solver.nodes}): the check compares with (nodes + 1)//2 nodes")
    # the memory a run of that many members needs, checked before their arrays are built (on the
    # host, and the kernels' arrays too where the device is the CPU; pool.plan checks again once the
    # device is chosen)
    values, varying = resolve_members(members, scene, before_building=lambda n, shape: check_memory(
        n, solver, device if device is not None and str(device).startswith("cpu") else "host",
        f"the members' arrays broadcast to shape {shape}: this run" if len(shape) > 1 else "this run"))
    n_members = values["normal_force"].shape[0]
    if member_offset > MEMBER_NUMBER_LIMIT - n_members:  # as a sweep's check_member_offset
        raise ValueError(f"member_offset = {member_offset} is invalid for {n_members} members; valid: an integer in "
                         f"[0, {MEMBER_NUMBER_LIMIT - n_members}] (member numbers are int32, below {MEMBER_NUMBER_LIMIT})")
    unused = model.unused_parameters(values)
    if unused:  # set, and silently without effect
        warnings.warn(f"{PARAMETERS_UNUSED}: {', '.join(unused)}; they differ from the default scene but change "
                      "nothing in this model", stacklevel=2)
    if np.any(values["rest_until"] < values["force_ramp_time"]):  # allowed, but rarely meant
        warnings.warn(DISC_BEFORE_FULL_LOAD, stacklevel=2)
    _warn_load_above_hardness(values)
    device = check_device(device, n_members, solver)
    from . import pool  # a CPU ensemble large enough to pay: its members split over worker processes

    from .progress import end_time_attempts

    n_workers = pool.plan(workers, device, n_members, solver, fronts, record, model,
                          end_time_attempts(values["end_time"], values["rest_until"]))
    if n_workers > 1:
        ds = pool.run(n_workers, values, scene=scene, model=model, solver=solver, fronts=fronts,
                      record=record, device=device, progress=progress, member_offset=member_offset,
                      runner=simulate, x=_x_coordinate(values["length"], solver.nodes),
                      varying_parameters=_varying_parameters(values, varying))
    elif _in_member_blocks(device, solver, n_members):
        ds = _run_member_blocks(values, varying, scene, model, solver, fronts, record, device, progress, member_offset)
    else:
        ds = _run_members(values, varying, scene, model, solver, fronts, record, device, progress, member_offset)
    # the ensemble's warnings, once (those of the workers' chunks and of the blocks are dropped)
    if record is not None:
        _warn_record_past_end(ds, record, member_offset)
    warn_detachment_not_over(ds)
    _warn_members_not_ok(ds, solver)
    warn_lift_off_undamped(ds)
    return _short_long_names(ds)


# on the CPU the thread kernel runs its members one after the other over arrays laid out member
# fastest (for a GPU's coalesced loads), a few attempts a member per launch where the ensemble is big
# (progress.launch_steps): each launch goes through every member's data again, and past a few dozen
# members it leaves the caches. Blocks of this many members, run one after the other, keep it there:
# on this project's CPU 2,048 members at N = 41 in 8.3 s against 21.1 s in one launch, 512 at N = 100
# 4.6 against 8.8 s, 256 at N = 200 4.8 against 7.9 s (`python studies/cpu_member_blocks.py`; blocks
# of 16-64 alike), outputs bit for bit those of one launch but for which members the straggler rule
# stops, as in the worker processes' chunks (docs/performance.md, "CPU")
CPU_MEMBER_BLOCK = 32


def _in_member_blocks(device, solver: Solver, n_members: int) -> bool:
    """Whether this process runs the members in blocks of CPU_MEMBER_BLOCK: the CPU's thread kernel
    (a team runs its blocks on Warp's fibers), more members than one block."""
    return str(device).startswith("cpu") and solver.lanes in (None, 1) and n_members > CPU_MEMBER_BLOCK


def _run_member_blocks(values, varying, scene, model, solver, fronts, record, device, progress, member_offset):
    """_run_members on blocks of CPU_MEMBER_BLOCK members one after the other, joined as the worker
    processes' chunks are (pool.join): one progress line for the ensemble, or, in a worker process
    (progress.SINK set), the chunk's progress to its parent, which draws the line; each block's
    warnings once (the ensemble's own are the caller's)."""
    from . import pool
    from . import progress as progress_module

    t0 = time.perf_counter()
    n = values["normal_force"].shape[0]
    bounds = [(start, min(start + CPU_MEMBER_BLOCK, n)) for start in range(0, n, CPU_MEMBER_BLOCK)]
    show = shown(progress)
    saved_sink = progress_module.SINK  # a worker's: its parent draws the ensemble's line
    line = (progress_module.Line(n, progress if isinstance(progress, str) else "")
            if show and saved_sink is None else None)
    # where the ensemble's progress goes, sink(fraction, done, final): this process's line, or the parent's
    ensemble_sink = saved_sink if line is None else (lambda fraction, done, final: line.show(fraction, done))
    parts, chosen, caught_all = [], [], []
    try:
        for start, stop in bounds:
            if show:  # the block's engine reports its fraction of the whole, not on a line of its own
                sink = (lambda fraction, done, final, start=start, size=stop - start, last=stop == n:
                        ensemble_sink((start + fraction * size) / n, start + done, final and last))
                sink.draws_here = line is not None  # this process's line (progress.building_note speaks)
                progress_module.SINK = sink
            block_record, block_chosen = pool.chunk_record(record, start, stop)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                part = _run_members({name: v[start:stop] for name, v in values.items()}, varying, scene, model, solver,
                                    fronts, block_record, device, show, member_offset + start)
            parts.append(part)
            chosen.append(block_chosen)
            caught_all += pool.chunk_warnings(caught)
    except BaseException:
        if line is not None:
            line.stop()
        raise
    finally:
        progress_module.SINK = saved_sink
    ds = pool.join(parts, chosen, _x_coordinate(values["length"], solver.nodes), _varying_parameters(values, varying))
    build = sum(float(p.attrs.get("kernel_build_time_s", 0.0)) for p in parts)
    ds.attrs["kernel_build_time_s"] = build
    ds.attrs["wall_time_s"] = max(time.perf_counter() - t0 - build, 0.0)
    if line is not None:
        line.close()
    pool.warn_once(caught_all, stacklevel=4)
    return ds


def _run_members(values, varying, scene, model, solver, fronts, record, device, progress, member_offset):
    """The members of ``values`` (resolved) in this process: the engine's run, its outputs as the
    Dataset, the float32 fallback and the grid check; simulate gives the ensemble's warnings."""
    from warpfric.kernels.types import STATUS_MEANINGS

    from . import engine

    init_warp()
    show = shown(progress)
    t_start = time.perf_counter()
    try:
        result = engine.run(values, model, solver, fronts, record, device, show,
                            progress if isinstance(progress, str) else "")
    except BaseException:  # Ctrl-C, SIGTERM, an error: the line ends before the message that follows
        from .progress import stop_open_lines

        stop_open_lines()
        raise
    front = None
    if fronts is not None:
        front = _front_metrics(fronts, model, values, result, device)
    wall = time.perf_counter() - t_start - result.kernel_build_s
    st = result.member_states
    status = _member_status(st, values, STATUS_MEANINGS, solver.rtol)
    # the Dataset is built once, with every variable: each later addition is a merge over all of them
    # (~5 ms for the front outputs of one member)
    extra = {}
    if result.yield_time is not None:
        extra.update(_yield_variables(status, result.yield_time, result.yield_gate, STATUS_MEANINGS))
    if front is not None:
        # a front is measured only where the run saw the detachment through (an explicit end_time
        # may cut it off: a part of the front, or for the velocity and strength fronts another event)
        extra.update(front_variables(front, fronts, (status != 0) | ~np.isfinite(st["detachment_end"])))
    ds = _to_dataset(values, varying, st, status, result.fields, result.normal_stress, result.friction_stress, model,
                     solver, device, wall, STATUS_MEANINGS, member_offset, extra)
    ds.attrs["kernel_build_time_s"] = result.kernel_build_s
    ds.attrs["device_bytes_per_member"] = result.device_bytes_per_member
    ds.attrs["lanes"] = result.lanes
    ds.attrs["team_exchange"] = result.team_exchange
    ds.attrs["block_members"] = result.block_members
    ds.attrs["work_memory"] = result.work_memory
    ds.attrs["member_order"] = result.member_order
    ds.attrs["integration_passes"] = result.passes
    if front is not None:
        ds.attrs.update(fronts_attrs(fronts))
    if record is not None:
        _add_record(ds, record, result.record, ds.x, member_offset)
    if solver.dtype == "float32" and solver.float32_fallback:
        _rerun_failed_in_float64(ds, values, scene, model, solver, fronts, record, device)
    if fronts is not None and fronts.grid_check:
        _add_grid_check(ds, values, scene, model, solver, fronts, device, progress)
    return ds


GRID_CHECK_MIN_NODES = 5  # Fronts(grid_check=True) compares with a run on (nodes + 1)//2 >= 3 nodes
LONG_NAME_MAX = 60  # characters: xarray labels a plot's axis with long_name [units], in lines of 30


def _short_long_names(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` (in place) with every long_name of more than LONG_NAME_MAX characters cut at its first
    ' (', ': ' or '; ' after 15 characters, the whole text kept as the variable's CF ``comment`` (a
    plot's axis label read 'time at which the detachment was over (the automatic end's criterion:
    ...' for 183 characters). Names that are short already, or that have a comment, stay."""
    for var in ds.variables.values():  # the Variables themselves (attrs in place), not DataArrays: cheaper
        text = var.attrs.get("long_name", "")
        if len(text) <= LONG_NAME_MAX or "comment" in var.attrs:
            continue
        cuts = [i for i in (text.find(mark, 15) for mark in (" (", ": ", "; ")) if i > 0]
        if cuts:
            var.attrs["long_name"], var.attrs["comment"] = text[:min(cuts)], text
    return ds


_STATUS_ADVICE = {
    "max_steps_reached": "Solver(max_steps=...) allows more than {max_steps:,} attempted steps",
    "non_finite_state": "the state became NaN or inf: a tighter rtol",
    "step_size_underflow": "the step size fell below its floor: a tighter rtol",
    "stalled": ("stopped by the straggler rule after stall_factor = {stall_factor:g} times the attempts of the "
                "typical member, or stall_min_steps = {stall_min_steps:,} where that is more: "
                "Solver(stall_factor=float('inf')), in a sweep file [solver] stall_factor = inf, "
                "runs them to their end"),
    "no_peak": ("mu was still rising at the run's end or had its largest value at the disc's stop, peaked "
                "before the disc moved, or never fell below its largest value by more than rtol (steady "
                "sliding without a static peak, e.g. aging_coefficient = 0): a later end_time or stop_time"),
}
_STILL_DISC_ADVICE = "disc_velocity = 0: the disc never moves, so there is no friction peak to find"
_LIFTED_OFF_ADVICE = ("part of the pad lifted off, where nothing damps its shear vibration (a sudden stop or the "
                      "detachment excites it): a small damping, e.g. 1e6 Pa s/m, lets the steps grow again "
                      "(docs/model.md, \"Open choices\": lift-off)")


def not_over_groups(ds: xr.Dataset) -> dict[str, np.ndarray]:
    """The members of :func:`detachment_not_over` by why, (member,) bool each: "plateau", stopped at
    max_end_time with mu never AUTO_END_PEAK_DROP below its maximum (mu_s may be a plateau's);
    "front", stopped there with mu that fell but a front event not over (a velocity front's pad
    above half its arrival level, e.g. ringing after a sudden stop; a strength front's node not past
    its peak; under the stress gate a node in contact whose gate never opened); "cut", at an explicit
    end_time with fronts on. The warning, `warpfric run` and `warpfric info` say them alike."""
    from warpfric.kernels.observers import AUTO_END_PEAK_DROP

    capped, cut = detachment_not_over(ds)
    with np.errstate(invalid="ignore"):
        fell = np.asarray(ds.mu_final.values) < (1.0 - AUTO_END_PEAK_DROP) * np.asarray(ds.mu_s.values)
    return {"plateau": capped & ~fell, "front": capped & fell, "cut": cut}


def warn_detachment_not_over(ds: xr.Dataset, stacklevel: int = 3) -> None:
    """One warning, once per simulate call, of the members of :func:`not_over_groups`: at
    max_end_time (mu_s may be a plateau's, or a front event was not over), or at an explicit
    end_time with fronts on (their front outputs are NaN)."""
    from warpfric.kernels.observers import AUTO_END_PEAK_DROP

    groups = not_over_groups(ds)
    if not any(which.any() for which in groups.values()):
        return
    texts = {"plateau": f"at max_end_time, the automatic end's cap, with mu never {AUTO_END_PEAK_DROP:.0%} below its "
                        "maximum (mu_s may be a plateau's, not a static peak: a later max_end_time)",
             "front": f"at max_end_time, the automatic end's cap, with mu {AUTO_END_PEAK_DROP:.0%} below its maximum "
                      "but the front event not over (a velocity front's pad above half its arrival level, e.g. ringing "
                      "after a sudden stop; a strength front's node not past its peak; under the stress gate a node in "
                      "contact whose gate never opened)",
             "cut": "at end_time (a later end_time, or end_time=None: the automatic end)"}
    n = ds.sizes["member"]
    parts = []
    for key, which in groups.items():
        if which.any():
            numbers = first_few(ds.member.values[which])
            parts.append(f"{int(which.sum())} {texts[key]}: member{'' if which.sum() == 1 else 's'} {numbers}")
    fronts = "; their front outputs are NaN" if "fronts_event" in ds.attrs else ""
    total = int(sum(which.sum() for which in groups.values()))
    warnings.warn(f"{DETACHMENT_NOT_OVER} (detachment_end_time NaN) in {total} of {n:,} "
                  f"member{'' if n == 1 else 's'}: {'; '.join(parts)}{fronts}", stacklevel=stacklevel)


def warn_lift_off_undamped(ds: xr.Dataset, stacklevel: int = 3) -> None:
    """One warning, once per simulate call, of the members ok whose pad lifted off (lift_off 1) with
    damping 0: the lifted part's shear vibration is undamped, and where it rings during the
    detachment the integrator's own damping (L-stable TR-BDF2 at a loose rtol) sets mu_s, which then
    depends on rtol (docs/performance.md, "Known limits"). Nothing in a run tells the members that
    ring from those that do not, so it is said at every rtol: a check passes where mu_s agrees
    between two rtols (at the default aging coefficient the lifted-off members of
    studies/sweeps/fig4_eccentricity.toml agree within 1.3e-6 between rtol 1e-5 and 1e-7)."""
    if "lift_off" not in ds or "damping" not in ds:
        return
    n = ds.sizes["member"]
    undamped = np.broadcast_to(np.asarray(ds.damping.values, dtype=float), (n,)) == 0.0
    which = (ds.status.values == 0) & (ds.lift_off.values == 1) & undamped
    if which.any():
        k = int(which.sum())
        warnings.warn(f"{LIFT_OFF_UNDAMPED} (lift_off 1, damping 0) in {k} of {n:,} member{'' if n == 1 else 's'}: "
                      f"member{'' if k == 1 else 's'} {first_few(ds.member.values[which])}: where the lifted part's "
                      "undamped shear vibration rings during the detachment, the time integrator's own damping sets "
                      "mu_s, which then depends on rtol (2e/L = 0.6, v_d = -5 mm/s, aging_coefficient 0.2, N = 50: "
                      "mu_s 0.909 at rtol 1e-5, 0.847 at 1e-6, 0.846 at 1e-8 and 1e-9; 0.909 at each with damping "
                      "1e6 Pa s/m), while most such members agree at every rtol (those of the paper's Fig. 4 within "
                      "1.3e-6). Said at any rtol, since nothing in a run tells them apart: compare their mu_s at a "
                      "second, tighter rtol (Solver(rtol=...), --rtol, [solver] rtol; with stall_factor = inf where "
                      "faster members are beside them), or give the pad a damping (Parameters(damping=...), "
                      "[scene] damping)", stacklevel=stacklevel)


def _warn_load_above_hardness(values: dict) -> None:
    """One warning where a member's mean normal stress F/(L p) reaches the hardness: its real contact
    area A = sigma_n/hardness * (1 + b ln(1 + phi/phi*)) would exceed the apparent one from the start,
    outside the friction law's validity (a force of 1e300 N passed the range check, (0, inf), and
    ended non_finite_state without a word on why). Allowed: with the defaults 1.4e7 and 3e7 N (the
    hardness at 1.3e7 N) end ok, 1e9 N max_steps_reached (N = 30)."""
    stress = values["normal_force"] / (values["length"] * values["depth"])
    above = np.flatnonzero(stress >= values["hardness"])
    if above.size:
        k = int(above[0])
        warnings.warn(f"{LOAD_ABOVE_HARDNESS} in {above.size} of {stress.size:,} member"
                      f"{'' if stress.size == 1 else 's'} (member index {k}: {stress[k]:.3g} Pa against "
                      f"{values['hardness'][k]:.3g} Pa): their real contact area would exceed the apparent one, "
                      "outside the friction law's validity, so their mu_s is the model's, not a material's; runs "
                      "far above it fail (max_steps_reached, non_finite_state)", stacklevel=3)


def _warn_members_not_ok(ds: xr.Dataset, solver: Solver) -> None:
    """One warning, once per simulate call, that counts the members whose status is not ok, by status,
    with what each means and what to change (docs/model.md, "Statuses"); their mu_s and front outputs
    are NaN. The runs inside simulate (worker processes, the float32 fallback, the grid check) leave
    it to the outer call."""
    text = members_not_ok_text(ds, solver)
    if text is not None:
        warnings.warn(f"{text}; {MEMBERS_NOT_OK_HINT}", stacklevel=3)


def members_not_ok_text(ds: xr.Dataset, solver: Solver, where: str = "") -> str | None:
    """The warning of members not ok without its hint on where to find their numbers
    ("members that did not end ok ...: 3 of 200 members{where}: 3 max_steps_reached (what to change)"),
    or None where every member of ``ds`` (a Dataset with status and disc_velocity along member, and
    lift_off where the run has it) ended ok."""
    meanings = ds.status.attrs["flag_meanings"].split()
    codes, counts = np.unique(ds.status.values, return_counts=True)
    failed = {meanings[c]: int(k) for c, k in zip(codes, counts) if meanings[c] != "ok"}
    if not failed:
        return None
    advice = {name: text.format(max_steps=solver.max_steps, stall_factor=solver.stall_factor,
                                stall_min_steps=solver.stall_min_steps)
              for name, text in _STATUS_ADVICE.items()}
    if "no_peak" in failed:
        still = int(np.sum((ds.status.values == meanings.index("no_peak")) & (np.asarray(ds.disc_velocity) == 0.0)))
        if still == failed["no_peak"]:
            advice["no_peak"] = _STILL_DISC_ADVICE
        elif still:
            advice["no_peak"] += f"; {still} of them: {_STILL_DISC_ADVICE}"
    default_floor = Solver.__dataclass_fields__["min_step"].default
    if "step_size_underflow" in failed and solver.min_step > default_floor:  # the floor set: a tighter rtol lowers
        # the steps further; the floor is what to change
        advice["step_size_underflow"] = (f"the step size fell below its floor, min_step = {solver.min_step:g} s, "
                                         f"set above its default {default_floor:g} s: a smaller min_step")
    for name in ("non_finite_state", "step_size_underflow"):  # float64 is advice for members that ran in float32
        if name in failed:
            ran = (np.asarray(ds.working_precision.values, dtype=float) if "working_precision" in ds else
                   np.full(ds.sizes["member"], np.nan))  # unknown (NaN): the precision the solver asked for
            ran = np.where(np.isnan(ran), 32.0 if solver.dtype == "float32" else 64.0, ran)
            single = np.sum((ds.status.values == meanings.index(name)) & (ran == 32))
            if single:
                advice[name] += f", or float64 ({int(single)} of them ran in float32)"
    for name in ("max_steps_reached", "stalled"):
        if name in failed and "lift_off" in ds:
            lifted = int(np.sum((ds.status.values == meanings.index(name)) & (ds.lift_off.values == 1)))
            if lifted:
                advice[name] += f"; {lifted} of them: {_LIFTED_OFF_ADVICE}"
    parts = [f"{k} {name} ({advice[name]})" for name, k in failed.items()]
    n = ds.sizes["member"]
    return (f"{MEMBERS_NOT_OK}: {sum(failed.values())} of {n:,} member{'' if n == 1 else 's'}{where}: "
            f"{'; '.join(parts)}")


def _warn_record_past_end(ds: xr.Dataset, record: Record, member_offset: int = 0) -> None:
    """One warning naming each recorded member whose run ended before some of its recording times,
    and why it ended there: those samples are NaN (nothing was integrated there), which is easy to
    mistake for a field that is NaN. The causes: the automatic end (Parameters(end_time=None): the run
    stops once the detachment is over), the member's own end_time, or a failure (its status)."""
    from warpfric.kernels.types import STATUS_MEANINGS

    members = np.asarray(record.members)
    times = np.asarray(record.times)
    final = ds.final_time.values[members]
    late = (times[None, :] > final[:, None]).sum(axis=1)
    if not late.any():
        return
    end_time = np.broadcast_to(ds.end_time.values, ds.final_time.shape)[members]
    status = ds.status.values[members]
    parts, automatic = [], False
    for m, t, n, end, code in zip(members, final, late, end_time, status):
        if not n:
            continue
        meaning = STATUS_MEANINGS[int(code)]
        if meaning not in ("ok", "no_peak"):
            why = f"status {meaning}"
        elif np.isfinite(end) and t >= end:
            why = "its end_time"
        else:
            why, automatic = "the automatic end", True
        parts.append(f"member {member_offset + m}: ended at {t:.6g} s ({why}), {n} of {times.size} times later")
    advice = ("; a run ends by itself once its detachment is over (end_time None): an end_time past the last "
              "recording time (Parameters(end_time=...), --end-time, [scene] end_time in a sweep file) records there"
              if automatic else "")
    warnings.warn(f"{RECORD_PAST_END} ({'; '.join(parts)}){advice}", stacklevel=3)


@contextlib.contextmanager
def _ensemble_warnings_dropped():
    """While a run inside simulate runs: its ENSEMBLE_WARNINGS are dropped (the outer call raises
    them once, for the whole ensemble)."""
    with warnings.catch_warnings():
        for start in ENSEMBLE_WARNINGS:
            warnings.filterwarnings("ignore", message=re.escape(start))
        yield


def _add_grid_check(ds, values, scene, model, solver, fronts, device, progress) -> None:
    """Fronts.grid_check: the same members on (N+1)//2 nodes; |change| of mu_s and of each front speed
    as ``*_grid_error`` (in place). A segment present on one grid and absent on the other: inf (not
    resolved); absent on both, or a failed member: NaN."""
    coarse_nodes = max(3, (solver.nodes + 1) // 2)
    # a team size given for N lanes may exceed the coarse grid's (at most nodes // 2 lanes): the coarse
    # run takes the largest it allows (a team size changes outputs at round-off only)
    lanes = solver.lanes if solver.lanes in (None, 1) else min(solver.lanes, coarse_nodes // 2)
    lanes = 1 if lanes is not None and lanes < 2 else lanes
    label = (progress if isinstance(progress, str) else "") + " grid check"
    with _ensemble_warnings_dropped():  # its failed members leave NaN grid errors; the outer call warns of its own
        warnings.filterwarnings("ignore", message=re.escape("Solver(lanes="))  # the outer call said it of its team
        coarse = simulate({name: values[name] for name in values}, scene=scene, model=model,
                          solver=dataclasses.replace(solver, nodes=coarse_nodes, lanes=lanes),
                          fronts=dataclasses.replace(fronts, grid_check=False), device=device,
                          progress=label.strip() if progress else progress, workers=1)
    usable = (ds.status.values == 0) & (coarse.status.values == 0)
    for name, units, what in [("mu_s", "1", "mu_s")] + [(f"v_{seg}", "m s-1", f"v_{seg}") for seg in SEGMENT_NAMES]:
        fine_v, coarse_v = ds[name].values, coarse[name].values
        change = np.abs(fine_v - coarse_v)
        change = np.where(np.isfinite(fine_v) != np.isfinite(coarse_v), np.inf, change)
        change = np.where(usable & (np.isfinite(fine_v) | np.isfinite(coarse_v)), change, np.nan)
        ds[f"{name}_grid_error"] = xr.DataArray(change, dims=("member",), attrs={
            "units": units, "long_name": f"change of {what} from the grid of {solver.nodes} nodes to {coarse_nodes} "
            "nodes (estimate of its spatial error; inf: present on one grid only)"})
    ds.attrs["grid_check_nodes"] = coarse_nodes
    ds.attrs["wall_time_s"] = ds.attrs["wall_time_s"] + coarse.attrs["wall_time_s"]


# statuses of a run that did not reach its end (ok and no_peak did)
_FAILED_RUN = ("max_steps_reached", "non_finite_state", "step_size_underflow", "stalled")


def _rerun_failed_in_float64(ds, values, scene, model, solver, fronts, record, device) -> None:
    """Solver.float32_fallback: run the float32 members that failed again in float64 and put their
    outputs into ``ds`` (in place, cast to the file's float32), with working_precision 64.

    Why: float32 round-off of the displacement excites the grid's highest elastic mode (about
    omega_max*eps*|u| of pad velocity); without damping the error control resolves it with ~1e-8 s
    steps for ever (docs/model.md, "Precision"). float64 does not see it."""
    meanings = ds.status.attrs["flag_meanings"].split()
    failed = np.isin(ds.status.values, [meanings.index(name) for name in _FAILED_RUN])
    if not failed.any():
        return
    index = np.flatnonzero(failed)
    sub_members = {name: values[name][index] for name in values}
    sub_record = None
    recorded_pos = []
    if record is not None:
        chosen = [k for k, member in enumerate(record.members) if failed[member]]
        if chosen:
            position = {int(member): j for j, member in enumerate(index)}
            sub_record = dataclasses.replace(record, members=tuple(position[int(record.members[k])] for k in chosen))
            recorded_pos = chosen
    sub_fronts = dataclasses.replace(fronts, grid_check=False) if fronts is not None else None
    with _ensemble_warnings_dropped():  # the outer call warns of late recording times and of failed members
        sub = simulate(sub_members, scene=scene, model=model, solver=dataclasses.replace(solver, dtype="float64"),
                       fronts=sub_fronts, record=sub_record, device=device, progress=False, workers=1)
    for name, var in sub.data_vars.items():
        if name not in ds.data_vars:
            continue
        target = ds[name]
        if "member" in var.dims:
            values_new = target.values.copy()
            values_new[index] = var.values.astype(values_new.dtype)
            ds[name] = target.copy(data=values_new)
        elif "recorded" in var.dims and recorded_pos:
            values_new = target.values.copy()
            values_new[recorded_pos] = var.values.astype(values_new.dtype)
            ds[name] = target.copy(data=values_new)
    precision = ds.working_precision.values.copy()
    precision[index] = 64
    ds["working_precision"] = ds.working_precision.copy(data=precision)
    ds.attrs["wall_time_s"] = ds.attrs["wall_time_s"] + sub.attrs["wall_time_s"]


def _front_metrics(fronts: Fronts, model: Model, values, result, device: str) -> dict:
    """Segment the arrival times of each requested front event (kernel launched on the simulation's
    device); return {output name: array}, the first event's names unprefixed, the others prefixed
    with the event's name (e.g. ``strength_v_main``)."""
    from warpfric.kernels.types import FRONT_EVENTS

    from .fronts import segment_nodes_first, speed_errors

    out = {}
    for k, event in enumerate(fronts.events):
        prefix = "" if k == 0 else f"{event}_"
        row = FRONT_EVENTS.index(event)
        # the engine's read-back is (node, member), the layout the segmentation kernel takes; the
        # Dataset gets its transposed view (member, x), no copy
        arrival_time = result.arrival[row].T
        metrics = segment_nodes_first(result.arrival[row], values["length"], fronts, device=device)
        metrics["arrival_time"] = arrival_time
        metrics.update(speed_errors(metrics, arrival_time, result.arrival_error[row].T, values["length"]))
        if event == "velocity":
            metrics["event_max_velocity"] = np.where(result.event, result.member_states["front_max"], np.nan)
        if event == "strength":
            metrics["strength_peak"] = result.strength_peak.T.copy()
        out.update({prefix + name: value for name, value in metrics.items()})
    return out


def _yield_variables(status: np.ndarray, yield_time: np.ndarray, yield_gate: np.ndarray, meanings) -> dict:
    """The gates' outputs as Dataset variables, {name: (dims, values, attrs)}: yield_time (s) and
    yield_gate (1), (member, node). yield_time, the engine's read-back array, is changed in place:
    NaN in the rows of failed members (a new array would cost ~50 ms of fresh pages at 100,000
    members)."""
    broken = (status != 0) & (status != meanings.index("no_peak"))
    if broken.any():  # a run cut short still has real opening times
        yield_time[broken] = np.nan
    return {
        "yield_time": (("member", "x"), yield_time, {
            "units": "s", "long_name": "time at which |tau_f|/A first reached tau_c after the disc started (the "
            "asperity-level stress: the yield gate opened, the stick-to-slip transition; NaN: never)"}),
        "yield_gate": (("member", "x"), yield_gate, {
            "units": "1", "long_name": "yield gate at the final time: 0 closed (stuck, ageing), 1 open "
            "(sliding, rejuvenating), in between: held on the yield surface |tau_f|/A = tau_c"}),
    }


def _add_record(ds: xr.Dataset, record: Record, recorded: np.ndarray, x, member_offset: int = 0) -> None:
    from warpfric.kernels.types import RECORD_FIELDS

    ds.coords["time"] = xr.DataArray(np.asarray(record.times), dims=("time",),
                                     attrs={"units": "s", "long_name": "recording time"})
    ds.coords["recorded_member"] = xr.DataArray(
        member_offset + np.asarray(record.members, dtype=np.int32), dims=("recorded",),
        attrs={"long_name": "member number of each recorded member", "units": "1"})
    for f, name in enumerate(RECORD_FIELDS):
        units, long_name = _RECORD_ATTRS[name]
        ds[f"{name}_history"] = xr.DataArray(
            np.ascontiguousarray(np.transpose(recorded[f], (2, 0, 1))), dims=("recorded", "time", "x"),
            attrs={"units": units, "long_name": long_name + " (recorded)"},
        )
    ds["friction_coefficient_history"] = friction_coefficient_history(ds)


def friction_coefficient_history(ds: xr.Dataset) -> xr.DataArray:
    """The friction coefficient mu(t) = sign(v_d) * int tau_f dx / int sigma_n+ dx of each recorded
    member at the recording times, (recorded, time), dimensionless: the engine's mu(t), whose maximum
    over time is mu_s, integrated by the trapezoid rule (the engine's quadrature) over the recorded
    fields. NaN where the normal force is zero (mu undefined; the engine counts 0 there) and where a
    time lies after the member's end. Between accepted steps the fields are interpolated linearly, so
    there mu(t) is the ratio of interpolated integrals, and its maximum over the recording times lies
    below mu_s by the sampling (the engine refines its peak between steps). NaN too for a recorded
    member that is not among ``ds.member`` (a selection), whose disc direction is unknown."""
    disc_velocity = np.broadcast_to(np.asarray(ds["disc_velocity"].values, dtype=float), (ds.sizes["member"],))
    # a recorded member that a selection of members left out: its disc's direction is not at hand
    sign = np.array([(-1.0 if disc_velocity[ds.member.values == m][0] < 0.0 else 1.0)
                     if (ds.member.values == m).any() else np.nan for m in ds.recorded_member.values])
    # the grid is uniform, so dx cancels in the ratio: trapezoid sums in node spacings, the same
    # whether x is in m or in units of L (a split run's chunks may differ there from the ensemble)
    friction, normal = (np.trapezoid(np.asarray(ds[name].values, dtype=float), axis=-1)
                        for name in ("friction_stress_history", "normal_stress_history"))
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = np.where(normal > 0.0, sign[:, None] * friction / normal, np.nan)
    return xr.DataArray(mu, dims=("recorded", "time"), attrs={
        "units": "1", "long_name": "friction coefficient mu(t) of the recorded fields",
        "comment": "sign(v_d) int tau_f dx / int sigma_n dx of the recorded fields (NaN without normal force)"})


_RECORD_ATTRS = {
    "velocity": ("m s-1", "pad velocity du/dt"),
    "slip_rate": ("m s-1", "slip rate v_d - k_if*du/dt"),
    "normal_stress": ("Pa", "interface contact pressure max(sigma_n, 0)"),
    "friction_stress": ("Pa", "friction stress tau_f"),
}


_OUTPUT_ATTRS = {
    "mu_s": ("1", "static friction coefficient mu_s (max over time of int tau_f dx / int sigma_n dx)"),
    "mu_s_time": ("s", "time of the maximum of the friction coefficient"),
    "mu_final": ("1", "friction coefficient at the end of the run"),
    "lift_off": ("1", "1 where the interface lifted off somewhere (sigma_n < 0) while loaded"),
    "steps_accepted": ("1", "accepted time steps"),
    "steps_rejected": ("1", "rejected time steps: the sum of rejected_error_test, rejected_newton and rejected_switch"),
    "rejected_error_test": ("1", "steps rejected by the error test (error norm > 1)"),
    "rejected_newton": ("1", "steps rejected because a stage's Newton solve failed (no convergence or a non-finite value)"),
    "rejected_switch": ("1", "steps rejected to locate a gate switch (retried up to just past it; relaxation_gate='stress')"),
    "missed_predictions": ("1", "accepted steps that ended at a predicted gate switch that did not happen (relaxation_gate='stress')"),
    "newton_iterations": ("1", "Newton iterations over all stages"),
    "gate_switches": ("1", "accepted switches of the nodes' yield gates (relaxation_gate='stress')"),
    "unlocated_switches": ("1", "steps accepted with a gate switch the retries could not place within its tolerance"),
    "final_time": ("s", "time reached"),
    "detachment_end_time": ("s", "time at which the detachment was over (the automatic end's criterion: mu fallen "
                            "below its peak, the fronts passed); NaN where the run ended before it, whose front "
                            "outputs are then NaN, and for a member whose status is not ok"),
    "plate_compression": ("m", "mean compression delta0 of the pad at the final time"),
    "plate_tilt": ("rad", "tilt a of the backing plate at the final time"),
    "displacement": ("m", "height-averaged x-displacement u of the pad at the final time"),
    "velocity": ("m s-1", "pad velocity du/dt at the final time"),
    "elastic_stress": ("Pa", "elastic part tau_el of the friction stress at the final time"),
    "contact_age": ("s", "contact age phi at the final time"),
    "normal_stress": ("Pa", "interface contact pressure max(sigma_n, 0) at the final time"),
    "friction_stress": ("Pa", "friction stress tau_f on the pad at the final time"),
}


def _x_coordinate(length, n: int) -> xr.DataArray:
    """Node positions (m) where every member has the same length, else positions / length."""
    x_rel = np.linspace(-0.5, 0.5, n)
    same = bool(np.all(length == length[0]))
    return xr.DataArray(x_rel * float(length[0]) if same else x_rel, dims=("x",), attrs={
        "units": "m" if same else "1",
        "long_name": "node position along the pad" if same else "node position / length (members differ in length)"})


def _varying_parameters(values, varying) -> str:
    return " ".join(v for v in varying if np.unique(values[v]).size > 1)


def _member_status(st: np.ndarray, values, meanings, rtol: float) -> np.ndarray:
    """Each member's status code (member,) int32: the kernel's, or no_peak where an ok member's mu(t)
    was still rising at its last accepted step (its maximum lies beyond end_time, and the running
    maximum, the value at the end, is not mu_s), peaked before the disc moved (load noise, not a
    friction peak), or had its largest value when the disc stopped (a stop_time before the peak,
    where mu was still rising and fell after the stop, so the value at the stop is not mu_s; or a
    stop so soon after the peak, before the next accepted step, that no step resolved the peak:
    the value at the stop is then within the step's change of mu_s, but cannot be told from a
    still rising mu, so it is not given either), or never fell below its maximum by more than the
    solver's relative tolerance ``rtol`` (at most AUTO_END_PEAK_DROP, the automatic end's own fall)
    by the end of the run (a plateau: steady sliding without a static peak, whose maximum is
    round-off or the error control's ripple, not mu_s)."""
    from warpfric.kernels.observers import AUTO_END_PEAK_DROP

    status = st["status"].astype(np.int32)
    # the fall that tells a peak from a plateau: rtol, but no more than the automatic end's own drop
    # (at rtol >= 0.01 the automatic end stops a genuine peak before mu has fallen by rtol)
    fall = min(rtol, AUTO_END_PEAK_DROP)
    with np.errstate(invalid="ignore"):
        plateau = ~(st["mu_final"] < (1.0 - fall) * st["mu_s"])
    no_peak = ((st["mu_s_time"] >= st["t"]) | (st["mu_s_time"] <= values["rest_until"])
               | (st["mu_s_time"] >= values["stop_time"]) | plateau)
    return np.where((status == 0) & no_peak, meanings.index("no_peak"), status).astype(np.int32)


def _to_dataset(values, varying, st, status, fields, sigma, tau, model, solver, device, wall, meanings, member_offset=0,
                extra=None):
    """The ensemble's Dataset: the parameters, status (:func:`_member_status`), the scalar and final
    field outputs, then ``extra`` ({name: (dims, values, attrs)}, e.g. the gates' and fronts'
    outputs), built in one construction."""
    from warpfric.kernels.types import C_PHI, C_TAU, C_U, C_V

    n_members = st.shape[0]
    n = solver.nodes
    member = xr.DataArray(
        np.arange(member_offset, member_offset + n_members, dtype=np.int32), dims=("member",),
        attrs={"long_name": "ensemble member number", "units": "1"},
    )
    length = values["length"]
    data = {}
    for name, arr in values.items():
        attrs = {"units": parameter_units(name), "long_name": parameter_long_name(name)}
        data[name] = (("member",), arr, attrs)  # (dims, data, attrs): no per-variable alignment
    data["status"] = (
        ("member",),
        status,
        {
            "long_name": "member status",
            "flag_values": np.arange(len(meanings), dtype=np.int32),
            "flag_meanings": " ".join(meanings),
        },
    )
    data["working_precision"] = (
        ("member",), np.full(n_members, 32 if solver.dtype == "float32" else 64, dtype=np.int8),
        {"long_name": "floating-point precision that produced the member's outputs (float32 runs: "
                      "64 where Solver.float32_fallback re-ran a failed member in float64)",
         "flag_values": np.array([32, 64], dtype=np.int8), "flag_meanings": "float32 float64"})
    scalars = {
        "mu_s": st["mu_s"],
        "mu_s_time": st["mu_s_time"],
        "mu_final": st["mu_final"],
        "lift_off": st["lift_off"].astype(np.int8),
        "steps_accepted": st["steps_accepted"],
        "steps_rejected": st["steps_rejected"],
        "rejected_error_test": st["rejected_error_test"],
        "rejected_newton": st["rejected_newton"],
        "rejected_switch": st["rejected_switch"],
        "missed_predictions": st["missed_predictions"],
        "newton_iterations": st["newton_iterations"],
        "gate_switches": st["gate_switches"],
        "unlocated_switches": st["unlocated_switches"],
        "final_time": st["t"],
        "detachment_end_time": np.where(np.isfinite(st["detachment_end"]), st["detachment_end"], np.nan),
        "plate_compression": st["delta0"],
        "plate_tilt": st["tilt"],
    }
    failed = status != 0
    for name, arr in scalars.items():
        arr = np.asarray(arr)
        if name in ("mu_s", "mu_s_time", "mu_final", "detachment_end_time") and failed.any():
            # a failed member is never returned as a number; no_peak keeps mu_final (a real value)
            bad = failed if name != "mu_final" else failed & (status != meanings.index("no_peak"))
            arr = np.where(bad, np.nan, arr)
        units, long_name = _OUTPUT_ATTRS[name]
        data[name] = (("member",), arr, {"units": units, "long_name": long_name})
    per_node = {
        "displacement": fields[C_U],
        "velocity": fields[C_V],
        "elastic_stress": fields[C_TAU],
        "contact_age": fields[C_PHI],
        "normal_stress": sigma,
        "friction_stress": tau,
    }
    for name, arr in per_node.items():
        units, long_name = _OUTPUT_ATTRS[name]
        data[name] = (("member", "x"), arr, {"units": units, "long_name": long_name})  # (member, node) arrays
    data.update(extra or {})
    coords = {"member": member, "x": _x_coordinate(length, n)}
    attrs = {
        "title": "warpfric ensemble",
        "Conventions": "CF-1.8",
        "warpfric_version": __version__,
        "device": device,
        "wall_time_s": wall,  # the run: allocation, integration, read-back, fronts; not kernel builds
        # parameters given per member that take more than one value
        "varying_parameters": _varying_parameters(values, varying),
    }
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        attrs[f"model_{f.name}"] = value if isinstance(value, str) else int(value)
    for f in dataclasses.fields(solver):
        value = getattr(solver, f.name)
        if value is None:
            value = "auto"  # Solver.lanes None: chosen per run (the run's choice is the attribute "lanes")
        attrs[f"solver_{f.name}"] = int(value) if isinstance(value, bool) else value  # netCDF has no bool
    try:
        import warp as wp

        attrs["warp_version"] = wp.__version__
    except Exception:  # pragma: no cover
        pass
    return xr.Dataset(data, coords=coords, attrs=attrs)
