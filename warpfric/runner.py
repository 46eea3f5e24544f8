"""Running a sweep file in chunks: in this process, or each chunk as one Dask task on a cluster
(docs/sweeps.md, "Several GPUs and clusters").

The unit of work is a chunk: a slice of the sweep's members, simulated and written atomically to
``OUT.nc.parts/chunk-NNNNNN.nc`` (a ``.tmp`` file renamed on completion). Whoever runs the chunks
(this process, or Dask workers on one host or many) the chunk files, the manifest, ``--resume``,
``warpfric info`` and the combined file are the same, and so are the outputs, bit for bit (each
member is integrated alone by the same kernels; only the timing attributes differ).

Dask (``pip install warpfric[distributed]``): each chunk is one task (``pure=False``, one retry
budget per chunk, Dask's default of 3 worker deaths). A worker that dies mid-chunk leaves at most a
``.tmp`` file; Dask runs the chunk again elsewhere, so a chunk is never written half and a finished
chunk is never written again. A chunk that raises is reported with its member range and the run
goes on; its chunk file is missing, so ``--resume`` runs it again later. Workers keep their
compiled kernels between chunks (one Warp module cache per process).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import re
import shlex
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np

from .parameters import DETACHMENT_NOT_OVER, LIFT_OFF_UNDAMPED, MEMBERS_NOT_OK, RECORD_PAST_END, recording_text
from .pool import WorkerDied, chunk_record, cpu_cores, warn_once, warning_pairs
from .progress import (SizeWarning, check_memory, first_few, front_passes, member_range, plural, seconds_text,
                       size_warning, status_name)

FINAL_FIELDS = ("displacement", "velocity", "elastic_stress", "contact_age", "normal_stress", "friction_stress")


class RunError(ValueError):
    """A sweep run that cannot start or finish as asked (one line, for the command line's exit 2)."""


@dataclasses.dataclass(frozen=True)
class ChunkJob:
    """Everything a worker needs to run one chunk (plain values: it travels to Dask workers)."""

    sweep_text: str
    sweep_name: str
    index: int
    n_chunks: int
    start: int
    stop: int
    member_offset: int
    path: str
    device: str | None  # None: the worker's own device (its GPU if it has one, else the CPU)
    command: str | None
    progress: bool
    cpu_workers: int | None = None  # simulate(workers=...): CPU worker processes for this chunk
    run_id: str | None = None  # the run's id in the member labels (warpfric.io.member_labels)
    started: str | None = None  # when the run started (warpfric.io.history_time): the chunk's history line
    # [record] window = "detachment": the recording times the run found (find_record_times), the same
    # for every chunk; None where the sweep's [record] gives its times itself
    record_times: tuple | None = None
    # set by run_on_client: a chunk run in another process returns its warnings in the report, for
    # that process to raise each once (a worker's own would print once per worker, with its source line)
    parent_pid: int | None = None


def _members(start: int, stop: int) -> str:
    """The members of a chunk, as a person reads them: 'members 0..1199', 'member 7'."""
    return f"members {start}..{stop - 1}" if stop - start != 1 else f"member {start}"


def _chunk_label(job: ChunkJob) -> str:
    """'chunk 2/5 (members 1200..2399)': the chunk's member numbers, the run's member offset included."""
    first = job.member_offset + job.start
    return f"chunk {job.index + 1}/{job.n_chunks} ({_members(first, first + job.stop - job.start)})"


def worker_device(worker=None) -> str:
    """The Warp device of this process: cuda:0 where CUDA_VISIBLE_DEVICES lists this worker's GPU first
    (dask-cuda's LocalCUDACluster, a SLURM GPU job); on a plain LocalCluster of a multi-GPU host, where
    every worker sees every GPU, the GPU numbered by the worker's name modulo the GPU count; else the
    first CUDA device, else the CPU. ``worker``: the Dask worker (found from the running task when None)."""
    from .device import default_device

    device = default_device()
    if not device.startswith("cuda") or os.environ.get("CUDA_VISIBLE_DEVICES", "").strip():
        return device
    try:
        if worker is None:
            from distributed import get_worker

            worker = get_worker()
        name = worker.name
    except (ImportError, ValueError):
        return device
    import warp as wp

    count = wp.get_cuda_device_count()
    if count > 1 and isinstance(name, (int, np.integer)):
        return f"cuda:{int(name) % count}"
    return device


def run_chunk(job: ChunkJob) -> dict:
    """Simulate the members of one chunk and write its file atomically; return a report (chunk
    index, members, failed members, device, wall time, process id)."""
    from .io import write_ensemble
    from .simulate import simulate
    from .sweep_file import parse_sweep

    t0 = time.perf_counter()
    sweep = parse_sweep(job.sweep_text, job.sweep_name)
    device = _worker_device_for(job.device, _chunk_label(job))
    sl = slice(job.start, job.stop)
    record, _ = chunk_record(sweep_record(sweep, job.record_times), sl.start, sl.stop)
    label = _chunk_label(job) if job.progress else False
    collect = job.parent_pid is not None and job.parent_pid != os.getpid()  # not a thread of the parent
    with warnings.catch_warnings(record=True) if collect else contextlib.nullcontext() as caught:
        with warnings.catch_warnings():  # the size warning and the members not ok are the whole sweep's,
            warnings.filterwarnings("ignore", category=SizeWarning)  # said once by run_sweep
            for said_from_the_file in (MEMBERS_NOT_OK, DETACHMENT_NOT_OVER, LIFT_OFF_UNDAMPED):  # (on_combined)
                warnings.filterwarnings("ignore", message=re.escape(said_from_the_file))
            if job.record_times is not None:  # the detachment window: said by find_record_times, and
                # the warning's advice (a later end_time) would move the window, not fill it
                warnings.filterwarnings("ignore", message=re.escape(RECORD_PAST_END))
            ds = simulate(sweep.member_slice(sl) or None, scene=sweep.scene, model=sweep.model, solver=sweep.solver,
                          fronts=sweep.fronts, record=record, device=device, progress=label,
                          member_offset=job.member_offset + job.start, workers=job.cpu_workers)
    if record is not None:  # member numbers, as the member coordinate
        ds = ds.assign_coords(recorded_member=ds.recorded_member.copy(data=ds.member.values[list(record.members)]))
    ds.attrs["title"] = sweep.title or ds.attrs["title"]
    ds.attrs["sweep_file"] = job.sweep_name
    ds.attrs["sweep_toml"] = sweep.text
    ds.attrs["chunk_index"] = job.index
    if sweep.design is not None:
        import json

        from .sensitivity import DESIGN_ATTR

        ds.attrs[DESIGN_ATTR] = json.dumps(sweep.design)
    failed = int((ds.status.values != 0).sum())
    if not sweep.run.get("final_fields", True):
        ds = ds.drop_vars([v for v in FINAL_FIELDS if v in ds])
    # a Ctrl-C during the write keeps the whole chunk (for a GPU chunk, minutes of work), then stops
    write_ensemble(ds, job.path, varying=sweep.varying, command=job.command, run_id=job.run_id, started=job.started,
                   keep_interrupted=True)
    return dict(index=job.index, members=job.stop - job.start, failed=failed, device=device,
                wall_s=time.perf_counter() - t0, pid=os.getpid(),
                warnings=warning_pairs(caught) if collect else [])


def _worker_device_for(device: str | None, what: str) -> str:
    """The device this worker runs ``what`` on: ``device``, or its own (worker_device); RunError where a
    GPU is asked for that this worker does not have (none at all, or not that one: a worker of
    dask-cuda sees its own GPU only, as cuda:0), one line, told by the command for each chunk."""
    device = device or worker_device()
    if device.startswith("cuda"):
        import warp as wp

        wp.init()
        if wp.get_cuda_device_count() == 0:
            raise RunError(f"{what}: device {device} asked for, but this worker (pid {os.getpid()}) has no CUDA device")
        names = [str(d) for d in wp.get_cuda_devices()]
        if device != "cuda" and device not in names:
            raise RunError(f"{what}: device {device} asked for, but this worker (pid {os.getpid()}) has "
                           f"{', '.join(names)} only")
    return device


def sweep_record(sweep, record_times):
    """The sweep's Record: its [record] table's own, or for ``window = "detachment"`` its members at
    ``record_times`` (s; found by find_record_times). None without [record]."""
    from .sweep_file import RecordDetachment

    if not isinstance(sweep.record, RecordDetachment):
        return sweep.record
    if record_times is None:  # a caller that skipped find_record_times: no times to make up
        raise RunError("[record] window = \"detachment\": the recording times are found by the sweep's run "
                       "(warpfric run SWEEP.toml, warpfric.sweep.run), not given to this chunk")
    return sweep.record.with_times(record_times)


def _automatic_end_reads(fronts) -> tuple:
    """What of ``fronts`` (a Fronts or None) the automatic end waits for (kernels/observers.py,
    detachment_over): every node past its strength peak (the strength front), the velocity front's
    detachment velocity below half its arrival level (its settings); the contact front, whose
    arrivals come before the mu_s peak, not at all."""
    events = () if fronts is None else fronts.events
    velocity = (fronts.threshold, fronts.direction, fronts.min_event_fraction) if "velocity" in events else None
    return "strength" in events, velocity


def detachment_runs(members, *, fronts, model, **run) -> tuple:
    """The first runs of a recording of the detachment (`warpfric run --record`, `[record] window =
    "detachment"`): (the outputs that locate the detachment, of a run with ``detachment_fronts``'s
    event; the final times (s, along member) of a run with ``fronts``, the recording run's own, which
    ends where the recording run will: recording changes no output). One run where the two fronts
    end a run alike (_automatic_end_reads), else a second with ``fronts`` (without its grid check):
    the automatic end waits for the strength and velocity fronts a run reads, so under the gate-less
    laws a run with the contact front or none ended ~12 ms before the strength front's run at
    N = 40, and the last 13 % of the recording's times were NaN. ``run``: simulate's other arguments."""
    from .parameters import detachment_fronts
    from .simulate import simulate

    located = detachment_fronts(model)
    found = simulate(members, fronts=located, model=model, **run)
    if _automatic_end_reads(fronts) == _automatic_end_reads(located):
        return found, found.final_time.values
    if isinstance(run.get("progress"), str):  # a labelled line: the second run says it is the second
        run = {**run, "progress": "second run (its end)"}
    own = simulate(members, fronts=None if fronts is None else dataclasses.replace(fronts, grid_check=False),
                   model=model, **run)
    return found, own.final_time.values


def find_record_times(sweep, device: str | None, offset: int, quiet: bool) -> tuple:
    """The recording times of ``[record] window = "detachment"``: a first run of the recorded members
    alone (in this process, on ``device``; None: this host's choice for so few members), with the
    front of ``detachment_fronts``, then Record.detachment over them, as ``warpfric run --record``
    does for one scene. It says where it ran, the window, the recorded members that are not ok in
    it (they widen the window neither way) and those that end before the window does (their times
    after their own end are NaN). A member's outputs do not depend on the members run with it, but
    for the straggler rule (Solver.stall_factor), which compares a member with them: a member can
    stall in its chunk and not alone, and its times after that end are NaN."""
    from .device import check_device
    from .parameters import Record

    chosen = list(sweep.record.members)
    numbers = [offset + m for m in chosen]
    values = {name: column[chosen] for name, column in sweep.members.items()} or None
    device = check_device(device, len(chosen), sweep.solver)
    _say(f"finding the detachment of the recorded {plural(len(chosen), 'member')} ({first_few(numbers)}): a first run of "
         f"{'them' if len(chosen) > 1 else 'it'} alone on {device}", quiet)
    with warnings.catch_warnings():  # their chunks give these members' warnings
        warnings.simplefilter("ignore")
        found, final_time = detachment_runs(values, fronts=sweep.fronts, scene=sweep.scene, model=sweep.model,
                                            solver=sweep.solver, device=device,
                                            progress=False if quiet else "first run", workers=1)
    times = Record.detachment(found, count=sweep.record.count, final_time=final_time).times
    status = found.status.values
    not_ok = [f"{numbers[k]} ({status_name(found, status[k])})" for k in range(len(chosen)) if status[k] != 0]
    early = [numbers[k] for k in range(len(chosen)) if status[k] == 0 and float(final_time[k]) < times[-1]]
    what = ("the detachment found by the first run" if len(not_ok) < len(chosen) else
            "the disc's start to the end: the first run found no detachment")
    one = {True: ("member", "ends", "its"), False: ("members", "end", "their")}
    notes = ([f"not ok there, so not in the window: {one[len(not_ok) == 1][0]} {first_few(not_ok)}"] if not_ok else []) + (
        ["{0} {3} {1} before the window does: NaN after {2} end".format(*one[len(early) == 1], first_few(early))]
        if early else [])
    _say(f"{recording_text(times)}, {what}"
         + "".join(f"; {note}" for note in notes), False)
    return times


def prepare_worker(sweep_text: str, sweep_name: str, device: str | None) -> dict:
    """Load this worker's kernels before the timed run (compile or read Warp's cache, load the
    modules on its device): one member, two steps, no fallback or grid check. Returns its device,
    pid and the seconds it took."""
    import dataclasses as dc

    from .simulate import simulate
    from .sweep_file import parse_sweep

    t0 = time.perf_counter()
    sweep = parse_sweep(sweep_text, sweep_name)
    device = _worker_device_for(device, "loading the kernels")
    fronts = dc.replace(sweep.fronts, grid_check=False) if sweep.fronts is not None else None
    with warnings.catch_warnings():  # the chunks give the run's warnings; the warm-up would repeat them
        warnings.simplefilter("ignore")
        simulate(sweep.member_slice(slice(0, 1)) or None, scene=sweep.scene, model=sweep.model,
                 solver=dc.replace(sweep.solver, max_steps=2, float32_fallback=False), fronts=fronts, device=device,
                 progress=False, workers=1)
    return dict(device=device, pid=os.getpid(), seconds=time.perf_counter() - t0)


@dataclasses.dataclass
class RunReport:
    """What a sweep run did: chunk reports of the chunks run now, the chunks that raised (with their
    member ranges and errors), the output path (None while chunks are missing) and the wall time."""

    chunks: list
    errors: list
    output: Path | None
    wall_s: float
    file_failed_members: int | None = None  # the written file's members not ok (a resumed run's too)

    @property
    def failed_members(self) -> int:
        return sum(c["failed"] for c in self.chunks)


def _say(message: str, quiet: bool) -> None:
    if not quiet:
        print(f"warpfric: {message}", file=sys.stderr, flush=True)


def run_local(jobs: list) -> tuple[list, list]:
    """Run the chunks one after the other in this process (progress: each job's own line)."""
    return [run_chunk(job) for job in jobs], []


def run_on_client(jobs: list, client, quiet: bool = False) -> tuple[list, list]:
    """Run each chunk as one Dask task on ``client``'s cluster; progress (chunks done, in flight,
    members/s) on stderr as they finish. Returns (reports, errors): a chunk that raised is reported by
    its member range and the others go on. A chunk that could not write its file (OutputWriteError: a
    full disk) is raised once every chunk has ended, as on a single host (exit code 3, the finished
    chunks kept for --resume)."""
    from distributed import as_completed

    from .io import OutputWriteError

    if not jobs:
        return [], []
    t0 = time.perf_counter()
    futures = {}
    for job in jobs:
        key = f"warpfric-chunk-{job.index:06d}-{Path(job.path).parent.name}-{os.getpid()}-{time.time_ns()}"
        futures[client.submit(run_chunk, dataclasses.replace(job, parent_pid=os.getpid()), key=key, pure=False)] = job
    reports, errors = [], []
    write_error = None
    members_done = 0
    try:
        for future in as_completed(list(futures), loop=client.loop):  # the client is not dask's default
            job = futures[future]
            try:
                report = future.result()
            except Exception as err:  # noqa: BLE001 - reported by member range, the rest goes on
                errors.append(dict(index=job.index, start=job.start, stop=job.stop, error=f"{type(err).__name__}: {err}"))
                _say(f"{_chunk_label(job)} FAILED: "
                     f"{type(err).__name__}: {err}", False)
                if isinstance(err, OutputWriteError):
                    # raised below, once every chunk has ended: not cancelled, since a chunk still being
                    # written would race the handler's reads of the parts folder (HDF5 is not
                    # thread-safe, and a cluster may run in this process)
                    write_error = write_error or err
                continue
            reports.append(report)
            members_done += report["members"]
            elapsed = time.perf_counter() - t0
            in_flight = len(jobs) - len(reports) - len(errors)
            _say(f"{len(reports)}/{plural(len(jobs), 'chunk')} done ({plural(members_done, 'member')}, "
                 f"{members_done / elapsed:.1f} members/s), "
                 f"{in_flight} to go; chunk {job.index + 1} ran on {report['device']} (pid {report['pid']}) in "
                 f"{report['wall_s']:.1f} s", quiet)
    except BaseException:  # Ctrl-C, SIGTERM: the queued chunks are cancelled, not left to run after the exit
        client.cancel([f for f in futures if not f.done()])
        # the finished chunks' warnings, as a run to its end gives them (--resume does not run them again)
        warn_once((w for report in reports for w in report["warnings"]), stacklevel=2)
        raise
    warn_once((w for report in reports for w in report["warnings"]), stacklevel=2)
    if write_error is not None:
        raise write_error
    return reports, errors


def local_cluster(workers: int | None = None):
    """A Dask client on a new local cluster: one worker per CUDA device (dask-cuda's LocalCUDACluster
    when it is installed, else a LocalCluster whose workers pick their GPU by name) when GPUs are
    present, else a LocalCluster of ``workers`` single-threaded CPU processes (default: the core
    count). Its workers ignore Ctrl-C and SIGTERM (warpfric.cluster_worker): the caller stops them, in
    order, with close_local_cluster."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise RunError("a Dask cluster needs the distributed package: pip install 'warpfric[distributed]'") from None
    from .device import init_warp

    wp = init_warp()  # quietly: no banner on stdout (Warp 1.19 reads its log level, not config.quiet)
    n_gpus = wp.get_cuda_device_count()
    if workers is not None and (isinstance(workers, bool) or workers < 1):
        raise RunError(f"--workers {workers}: expected an integer >= 1")
    if n_gpus > 0:
        if workers is not None and workers > n_gpus:
            raise RunError(f"--workers {workers}: this host has {n_gpus} GPUs; a local cluster runs at most one "
                           "worker per GPU")
        try:
            from dask_cuda import LocalCUDACluster  # each worker: its GPU first in CUDA_VISIBLE_DEVICES

            cluster = LocalCUDACluster(n_workers=workers or n_gpus, threads_per_worker=1)
        except ImportError:
            cluster = LocalCluster(n_workers=workers or n_gpus, threads_per_worker=1, processes=True)
    else:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True)
    # not dask's default: the sweep submits and gathers on this client by name, and a caller's own
    # dask work in the same process (an xarray compute after the run) keeps the scheduler it had
    client = Client(cluster, set_as_default=False)
    from .cluster_worker import LocalClusterWorker  # Ctrl-C and SIGTERM left to this process: close_local_cluster

    client.register_plugin(LocalClusterWorker(), name="warpfric-local-cluster-worker")
    return client


STARTING_WORKER = "WARPFRIC_STARTING_CLUSTER_WORKER"  # environment: see warpfric/__init__.py


@contextlib.contextmanager
def _ctrl_c_after_start():
    """A Ctrl-C (or the command line's SIGTERM) while a local cluster starts, held until it has
    started (yields a list that holds True once one came), so that the cluster can be closed. A
    terminal's Ctrl-C, like a batch system's SIGTERM, goes to every process of the command, the
    workers still starting among them, which ignore it only once started (warpfric.cluster_worker):
    one that landed inside the start left a half-started cluster, and its dying workers and
    distributed's own exit handler printed ~70 lines of tracebacks. So the workers started
    meanwhile ignore both from their first import of warpfric on (the environment variable
    STARTING_WORKER names this process as their parent; the interpreter's own start, tens of ms,
    stays open), and this process holds them (warpfric.io.sigint_held). Main thread only;
    elsewhere the block runs as it is."""
    from .io import sigint_held

    if threading.current_thread() is not threading.main_thread():
        yield []
        return
    before = os.environ.get(STARTING_WORKER)
    os.environ[STARTING_WORKER] = str(os.getpid())
    try:
        with sigint_held() as interrupted:
            yield interrupted
    finally:
        if before is None:
            os.environ.pop(STARTING_WORKER, None)
        else:
            os.environ[STARTING_WORKER] = before


def close_local_cluster(client, interrupted: bool = False) -> None:
    """Close ``client`` (from local_cluster), then its cluster. When it returns, every worker process
    has ended (asked to stop, then killed after distributed's close timeout of about 4 s), so no
    chunk is written after it: a chunk running at the close is written if it ends within that time,
    else lost (a ``.tmp`` file that the next run removes). The client goes first, so that the
    scheduler forgets its tasks before their workers go. ``interrupted``: distributed's log lines
    in this process (the scheduler's and the nannies') are dropped while it closes: they tell of the
    shutdown asked for (workers removed with results, a worker killed after the timeout)."""
    cluster = client.cluster
    with _distributed_logs_quiet() if interrupted else contextlib.nullcontext():
        client.close()
        if cluster is not None:
            cluster.close()


def _close_own_client(client, local: bool, interrupted: bool = False) -> None:
    """Close the client that the sweep opened itself: with its local cluster (close_local_cluster),
    or, connected to a scheduler (--scheduler), the client alone."""
    if local:
        close_local_cluster(client, interrupted=interrupted)
    else:
        client.close()


@contextlib.contextmanager
def _distributed_logs_quiet():
    """distributed's loggers in this process (those with a level of their own: dask's logging
    configuration gives "distributed" and "distributed.client" one, each with its handler) at
    CRITICAL while the block runs."""
    loggers = [logging.getLogger(name) for name in list(logging.root.manager.loggerDict)
               if name == "distributed" or name.startswith("distributed.")]
    levels = {lg: lg.level for lg in loggers if lg.level != logging.NOTSET}
    for lg in levels:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in levels.items():
            lg.setLevel(level)


def drop_sync_cancel_error(record) -> bool:
    """A logging filter (False: drop) for one record of distributed's own: a Ctrl-C that lands in
    ``distributed.utils.sync`` before its coroutine has started schedules a ``cancel`` callback that
    fails with NameError (its ``future`` is not yet bound), which tornado logs as a 13-line traceback
    before warpfric's interrupt line. Harmless: the run is being interrupted anyway. Every other
    record passes."""
    exc = record.exc_info[1] if record.exc_info else None
    if not isinstance(exc, NameError) or exc.__traceback__ is None:
        return True
    last = exc.__traceback__
    while last.tb_next is not None:
        last = last.tb_next
    code = last.tb_frame.f_code
    return not (code.co_name == "cancel" and code.co_filename.replace("\\", "/").endswith("distributed/utils.py"))


CONNECT_TIMEOUT_S = 30.0  # the whole of connecting, the scheduler's handshake included


def connect(address: str):
    """A Dask client of the scheduler at ``address`` (e.g. tcp://host:8786); RunError where none
    answers within CONNECT_TIMEOUT_S. Distributed's own timeout (20 s) covers the connection, not the
    handshake: an address that answers but is no Dask scheduler (its dashboard's port, a web server)
    hung for good, or ended in a MemoryError reading a reply that is not a Dask frame."""
    import threading

    try:
        from distributed import Client
    except ImportError:
        raise RunError("--scheduler needs the distributed package: pip install 'warpfric[distributed]'") from None
    outcome = {}

    def attempt():  # in a daemon thread: one that never returns does not hold the command's exit
        try:
            outcome["client"] = Client(address, timeout="20s", set_as_default=False)  # as local_cluster's
        except BaseException as err:  # noqa: BLE001 - reported below, in this thread
            outcome["error"] = err

    thread = threading.Thread(target=attempt, name="warpfric-connect", daemon=True)
    thread.start()
    thread.join(CONNECT_TIMEOUT_S)
    if thread.is_alive():
        raise RunError(f"scheduler {address!r}: no Dask scheduler answered within {CONNECT_TIMEOUT_S:g} s (is it the "
                       "scheduler's address? its dashboard has another port)")
    err = outcome.get("error")
    if isinstance(err, OSError):
        raise RunError(f"scheduler {address!r}: cannot connect ({err})") from None
    if err is not None:
        raise RunError(f"scheduler {address!r}: not a Dask scheduler ({type(err).__name__}: "
                       f"{' '.join(str(err).split())[:120]}); expected a scheduler's address such as "
                       "'tcp://host:8786' (--scheduler, [run] scheduler), or 'local' in a sweep file for a local "
                       "cluster (--local-cluster)") from None
    return outcome["client"]


def check_output_name(path: Path) -> None:
    """Refuse an output name that cannot be a file: not .nc, a folder, in a folder that does not exist."""
    if path.suffix != ".nc":
        raise RunError(f"output {str(path)!r}: expected a file name ending in .nc")
    if not path.parent.is_dir():
        raise RunError(f"output {str(path)!r}: folder {str(path.parent)!r} does not exist")
    if path.is_dir():
        raise RunError(f"output {str(path)!r} is a folder; give a file name ending in .nc")


def check_output(path: Path, resume: bool, overwrite: bool) -> None:
    """Refuse an output that would lose results: an existing file without overwrite, an interrupted
    run's parts without resume or overwrite (RunError, one line). Call it holding the output's lock
    (warpfric.io.output_lock): the parts of a run that is still going are not an interrupted run."""
    from .io import parts_dir

    if resume and overwrite:
        raise RunError("--resume and --overwrite exclude each other")
    check_output_name(path)
    parts = parts_dir(path)
    if parts.is_dir() and not any(parts.iterdir()):  # killed before its manifest: nothing to resume or lose
        parts.rmdir()
    # a file beside parts is one that an interrupted --overwrite run is replacing: --resume goes on
    if path.exists() and not overwrite and not (resume and parts.exists()):
        raise RunError(f"output {str(path)!r} exists; pass --overwrite to replace it"
                       + (" (it is complete: nothing to resume)" if resume else ""))
    if parts.exists() and not parts.is_dir():  # no run's: --resume and --overwrite could do nothing with it
        raise RunError(f"{str(parts)!r} is a file, where a chunked run keeps its finished chunks in a folder of "
                       "that name: remove or rename it")
    if parts.exists() and not (resume or overwrite):
        from .io import ChunkStore

        ChunkStore.load(parts)  # an unreadable manifest: nothing to resume, which its ValueError says
        raise RunError(f"{str(parts)!r} holds an interrupted run; pass --resume to finish it "
                       "or --overwrite to start again")


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C during a sweep, with what was kept (``message``, one line for the command line)."""

    def __init__(self, message: str):
        super().__init__(message)
        self.message = message


def sweep_bytes(sweep, n_members: int, files: int = 1) -> int:
    """Estimated bytes of ``files`` files of a sweep holding ``n_members`` members, before compression
    (see warpfric.io.estimate_bytes)."""
    from .io import estimate_bytes

    record = sweep.record
    times = 0 if record is None else getattr(record, "count", None) or len(record.times)
    return estimate_bytes(n_members, sweep.solver.nodes, final_fields=sweep.run.get("final_fields", True),
                          front_events=len(sweep.fronts.events) if sweep.fronts is not None else 0,
                          recorded=len(record.members) if record else 0, times=times, files=files)


def run_sweep(sweep_file, output=None, *, chunk: int | None = None, member_offset: int | None = None,
              device: str | None = None, resume: bool = False, overwrite: bool = False, client=None,
              scheduler: str | None = None, local: bool | None = None, workers: int | None = None,
              quiet: bool = False, command: str | None = None, cpu_workers: int | None = None) -> RunReport:
    """Run a sweep file in resumable chunks into ``output`` (default: the sweep's name with .nc).

    Where the chunks run: ``client`` (a ``distributed.Client``), else ``scheduler`` (an address), else
    ``local=True`` (a new local cluster: one worker per GPU, or ``workers`` CPU processes), else the
    sweep's ``[run] scheduler`` ("local" or an address), else this process. ``chunk``,
    ``member_offset`` and ``device`` default to the interrupted run's (resume), then the sweep's
    ``[run]`` table; ``device`` None on a cluster: each worker's own GPU (or CPU). ``cpu_workers``:
    ``simulate(workers=...)`` of each chunk run in this process (None: all cores where it pays).
    Returns a RunReport; ``output`` is written once every chunk exists (else report.output is None
    and ``resume=True`` finishes the run).

    Before anything runs: RunError/SweepError (ValueError) for bad input, OutputUnwritable (a
    ValueError) for a folder that cannot be written, OutputBusy while another run holds the output's
    lock, OutputWriteError when the folder has clearly too little free space. During the run: an
    OutputWriteError (disk full) keeps the finished chunks; RunInterrupted (a KeyboardInterrupt) on
    Ctrl-C. A parts folder that this call created is removed again when it ends without a finished
    chunk, so that nothing half written blocks the next run."""
    from .io import check_free_space, output_lock, parts_dir, probe_writable, remove_stale_temporaries
    from .sweep_file import load_sweep

    sweep = load_sweep(sweep_file)
    out = Path(output) if output else Path(sweep_file).with_suffix(".nc")
    if resume and overwrite:
        raise RunError("--resume and --overwrite exclude each other")
    if chunk is not None and (isinstance(chunk, bool) or not isinstance(chunk, (int, np.integer)) or chunk < 1):
        raise RunError(f"--chunk {chunk}: expected an integer >= 1 (members per chunk file)")
    check_output_name(out)
    with output_lock(out, command):  # the folder is writable, and no other run writes this output
        check_output(out, resume, overwrite)
        if resume and parts_dir(out).exists():
            probe_writable(parts_dir(out), out)
            if out.exists():
                _say(f"{str(out)!r} is replaced when the interrupted run it belongs to ends (that run was started "
                     "with --overwrite)", quiet)
        stale = remove_stale_temporaries(out)
        if stale:
            _say(f"removed {len(stale)} temporary files that an interrupted run left ({stale[0].name}, ...)", quiet)
        return _run_locked(sweep, sweep_file, out, chunk=chunk, member_offset=member_offset, device=device,
                           resume=resume, client=client, scheduler=scheduler, local=local, workers=workers,
                           quiet=quiet, command=command, check_space=check_free_space, cpu_workers=cpu_workers)


def _run_locked(sweep, sweep_file, out: Path, *, chunk, member_offset, device, resume, client, scheduler, local,
                workers, quiet, command, check_space, cpu_workers) -> RunReport:
    import shutil

    from .io import (SWEEP_COPY, ChunkStore, ChunksDoNotCombine, OutputWriteError, free_bytes, history_time, new_run_id,
                     parts_dir, resume_command, sweep_digest, write_failure)
    from .device import check_device
    from .sweep_file import RecordDetachment, check_member_offset

    parts = parts_dir(out)
    previous = ChunkStore.load(parts) if resume and parts.exists() else None
    # an omitted option takes, in this order: the interrupted run's value (resume), the sweep's [run]
    chunk = chunk or (previous.chunk if previous else None) or sweep.run.get("chunk") or sweep.n_members
    offset = next(v for v in (member_offset, previous and previous.member_offset, sweep.run.get("member_offset"), 0)
                  if v is not None)
    check_member_offset(offset, sweep.n_members, "--member-offset")
    if sweep.record is not None and max(sweep.record.members) >= sweep.n_members:
        raise RunError(f"[record] members: index {max(sweep.record.members)} but the sweep has "
                       f"{sweep.n_members} members (valid 0..{sweep.n_members - 1})")
    where = scheduler or sweep.run.get("scheduler")
    use_cluster = client is not None or bool(local) or (where is not None and local is not False)
    new_local_cluster = use_cluster and client is None and bool(local or where == "local")
    # workers size a new local cluster, nothing else: given for a run that starts none, they were
    # ignored without a word. The file's own stay unused where the caller runs it on another
    # cluster (client, --scheduler): refused only where the run uses no cluster at all
    if workers is not None and not new_local_cluster:
        raise RunError(f"--workers = {workers}: the number of workers of a new local Dask cluster (--local-cluster, "
                       "or [run] scheduler = \"local\"), which this run does not start; --cpu-workers splits a run "
                       "in this process")
    if sweep.run.get("workers") is not None and not use_cluster:
        raise RunError(f"[run] workers = {sweep.run['workers']}: the number of workers of a new local Dask cluster, "
                       "which this run does not start (it runs in this process); add [run] scheduler = \"local\" "
                       "or run with --local-cluster, or leave workers out")
    if cpu_workers is not None and use_cluster:  # a worker's daemonic process cannot start processes of its own
        cluster = ("--scheduler" if scheduler else "--local-cluster" if local else "a client" if client is not None
                   else f"the sweep file's [run] scheduler = {where!r}")
        raise RunError(f"--cpu-workers {cpu_workers}: splits a run in this process; on a Dask cluster ({cluster}) each "
                       "worker runs its chunk in one process: leave it out")
    workers = workers or sweep.run.get("workers")
    if device is None and previous is not None:
        device = previous.manifest.get("device")  # a resumed run keeps its device: one file, one device
    if device is None and sweep.run.get("device"):
        device = sweep.run["device"]
        if use_cluster:
            _say(f"[run] device = {device!r} pins every worker to that device (--device to choose another; "
                 "leave it out to let each worker use its own GPU)", False)
    if not use_cluster:  # on a cluster, each worker checks its own device
        device = check_device(device, sweep.n_members, sweep.solver)  # None: as simulate's (a lone member: the CPU)
    elif new_local_cluster and device is not None:
        check_device(device)  # its workers run on this host: a device it lacks fails every chunk, so say it here
    digest = sweep_digest(f"{sweep.text}\nchunk={chunk}" + (f"\nmember_offset={offset}" if offset else ""))
    if previous is not None and previous.digest != digest:
        differ = ([f"chunk size ({previous.chunk}, now {chunk})"] if chunk != previous.chunk else []) + (
            [f"member offset ({previous.member_offset}, now {offset})"] if offset != previous.member_offset else [])
        what = " and ".join(differ) or "sweep file (its text changed)"
        kept = parts / SWEEP_COPY
        back = (f" (the interrupted run's sweep file is kept as {str(kept)!r}: `cp {shlex.quote(str(kept))} "
                f"{shlex.quote(str(sweep_file))}` puts it back)" if not differ and kept.exists() else "")
        raise RunError(f"{str(parts)!r} belongs to a run with another {what}; resume with the interrupted run's "
                       f"settings{back}, or run with --overwrite to start again")
    # the chunk files and the combined file exist side by side until the parts are removed; a resumed
    # run's finished chunks are on the disk already
    done = sum(previous.members(i).stop - previous.members(i).start for i in range(previous.n_chunks)
               if previous.is_done(i)) if previous is not None else 0
    remaining = sweep.n_members - done
    chunk_files = -(-remaining // chunk)  # at least (a resumed run's missing chunks may be short ones)
    check_space(out, sweep_bytes(sweep, remaining, chunk_files) + sweep_bytes(sweep, sweep.n_members),
                f"this run ({remaining} members of {sweep.solver.nodes} nodes to run, chunks and combined file)")
    try:  # a chunk's members are held at once: more than this machine has is refused before any file
        if not use_cluster:  # (on a cluster, by the workers' machines)
            check_memory(min(chunk, remaining), sweep.solver, device or "cuda", "a chunk")
    except ValueError as err:
        raise RunError(str(err)) from None
    # for the members still to run, once (each chunk's own is dropped: run_chunk), on this process's
    # cores where it runs here
    size_warning(sweep.n_members - done, sweep.solver, front_passes(sweep.fronts), device or "cuda",
                 1 if use_cluster else (cpu_workers or cpu_cores()))
    # [record] window = "detachment": the interrupted run's times, else a first run of the recorded
    # members, before any file (a Ctrl-C there leaves nothing) and kept in the manifest for --resume
    record_times = None
    if isinstance(sweep.record, RecordDetachment):
        kept = previous.manifest.get("record_times") if previous is not None else None
        if kept:
            record_times = tuple(kept)
            _say(f"{recording_text(kept)}, the interrupted run's detachment window", False)
        else:  # on the device asked for where it is this host's (a --scheduler's workers may have others)
            here = device if device is not None and (not use_cluster or new_local_cluster) else None
            record_times = find_record_times(sweep, here, offset, quiet)
    own_client = None
    if use_cluster and client is None:  # before any file: an unreachable scheduler leaves nothing behind
        if new_local_cluster:
            with _ctrl_c_after_start() as interrupted:
                try:
                    own_client = local_cluster(workers)
                except Exception:  # noqa: BLE001 - a worker that the Ctrl-C hit before it ignored it
                    if not interrupted:
                        raise
            if interrupted:
                if own_client is not None:
                    close_local_cluster(own_client, interrupted=True)
                raise KeyboardInterrupt
        else:
            own_client = connect(where)
        client = own_client
    tornado_log = logging.getLogger("tornado.application")
    if use_cluster:
        tornado_log.addFilter(drop_sync_cancel_error)
    store = previous
    try:
        if store is None:
            if resume:  # a mistyped output ran the whole sweep without a word: said (after every check that
                # could refuse the run), even with --quiet: a script that always passes --resume gets its run
                _say(f"no interrupted run to resume: {str(parts)!r} does not exist, so the whole sweep runs now", False)
            try:
                store = ChunkStore.create(parts, digest, sweep.n_members, chunk, member_offset=offset,
                                          sweep_file=str(Path(sweep_file).resolve()), device=device,
                                          run_id=new_run_id(),
                                          **({"record_times": list(record_times)} if record_times else {}))
                (parts / SWEEP_COPY).write_text(sweep.text)  # the text --resume needs, should the file change
            except OSError as err:
                shutil.rmtree(parts, ignore_errors=True)
                raise write_failure(parts, err, free_bytes(out.parent)) from None
        started = history_time()  # this run's history line, in its chunks and in the file that combines them
        reports, errors, wall = _run_chunks(sweep, sweep_file, store, chunk, offset, device, client, quiet, command,
                                            cpu_workers, started, record_times)
        missing = [i for i in range(store.n_chunks) if not store.is_done(i)]
        if errors or missing:
            ranges = ", ".join(_members(offset + store.members(i).start, offset + store.members(i).stop) for i in missing)
            kept = len(_keep_or_remove(store, previous is None))  # none finished: no parts folder to block the next run
            what = (f"the finished chunks are kept in {parts}: `{resume_command(store, out)}` runs the rest" if kept else
                    "no chunk finished, nothing was kept")
            _say(f"{plural(len(missing), 'chunk')} missing ({ranges}; {len(errors)} raised, see above); {what}", False)
            return RunReport(chunks=reports, errors=errors, output=None, wall_s=wall)
        in_file = []

        def on_combined(ds):
            """The sweep's one warning of its runs ended before the detachment was over, of its
            members not ok and of its members lifted off undamped, from the combined file (each
            chunk's own is dropped: a run of many chunks printed one per chunk)."""
            from .simulate import _warn_members_not_ok, warn_detachment_not_over, warn_lift_off_undamped

            in_file.append(int((ds.status.values != 0).sum()))
            warn_detachment_not_over(ds, stacklevel=2)
            _warn_members_not_ok(ds, sweep.solver)
            warn_lift_off_undamped(ds, stacklevel=2)

        t_combine = time.perf_counter()
        if store.n_chunks > 1:  # ~0.1 s a chunk file: tens of seconds for hundreds of chunks
            _say(f"combining the {store.n_chunks:,} chunk files into {out}", quiet)
        try:
            store.combine(out, command=command, on_combined=on_combined, started=started)
            combine_s = time.perf_counter() - t_combine
        except ChunksDoNotCombine as err:  # no bad input (refused before any chunk runs): chunks that differ
            # (written by another warpfric version for --resume) are left where they are
            raise OutputWriteError(f"the chunks in {str(parts)!r} do not combine into one file ({err}; remove the "
                                   "chunk files it names and --resume runs them again)", False) from None
    except BaseException as err:  # noqa: BLE001 - cleaned up, then raised again
        interrupted = isinstance(err, KeyboardInterrupt)
        # the command's own local cluster is stopped before the finished chunks are counted: the chunks
        # its workers are running are written meanwhile (or lost), none after the count. The workers of
        # another cluster go on with theirs, which may be written after the exit (said below)
        cluster_stopped = False
        if own_client is not None:
            closing, own_client = own_client, None
            try:
                _close_own_client(closing, new_local_cluster, interrupted)
                cluster_stopped = new_local_cluster
            except BaseException:  # noqa: BLE001 - a cluster that did not stop (a second Ctrl-C while it closed:
                pass  # the line is still said) may still write chunks: said below
        late_writes = interrupted and client is not None and not cluster_stopped
        kept = _keep_or_remove(store, previous is None)
        if not isinstance(err, (OutputWriteError, KeyboardInterrupt, WorkerDied)):
            raise
        if interrupted and kept:  # a run to its end warns of them once, from its file
            _warn_members_not_ok_kept(store, kept, sweep.solver, out)
        first = "free some space, then " if getattr(err, "disk_full", False) else ""
        late = ", and chunks that were running on the cluster's workers may still be written there" if late_writes else ""
        what = (f"the {plural(len(kept), 'finished chunk')} {'is' if len(kept) == 1 else 'are'} kept in "
                f"{str(parts)!r}{late}; {first}`{resume_command(store, out)}` goes on from them"
                if kept else "nothing was kept")
        if interrupted and not kept and store is not None and store.n_chunks == 1 and sweep.n_members > 1:
            what += (f" (the sweep ran as one chunk of {sweep.n_members:,} members: with --chunk N, or [run] chunk = N, "
                     "each N members are kept once they finish, and --resume goes on from them)")
        if interrupted:
            stopped = "the local cluster is stopped, so no chunk is written after this; " if cluster_stopped else ""
            raise RunInterrupted(f"interrupted; {stopped}{what}") from None
        if isinstance(err, WorkerDied):
            raise WorkerDied(f"{err}; {what}") from None
        raise OutputWriteError(f"{err}; {what}", err.disk_full) from None
    finally:
        if own_client is not None:  # the run is written here (the except block closes and forgets it first)
            try:
                _close_own_client(own_client, new_local_cluster)
            except KeyboardInterrupt:  # a Ctrl-C while the cluster closes stops the close, not the written run
                pass
        tornado_log.removeFilter(drop_sync_cancel_error)
    report = RunReport(chunks=reports, errors=[], output=out, wall_s=wall, file_failed_members=in_file[0])
    resumed = f", {report.file_failed_members} in the file" if previous is not None else ""
    combined = f" and {seconds_text(combine_s)} s combining {store.n_chunks:,} chunk files" if store.n_chunks > 1 else ""
    _say(f"wrote {out} ({plural(sweep.n_members, 'member')}, {seconds_text(wall)} s running chunks now{combined}, "
         f"{plural(report.failed_members, 'failed member')} in the chunks run now{resumed})", False)
    return report


def _keep_or_remove(store, created: bool) -> list:
    """The indices of the finished chunks of ``store``; a parts folder created by this run that holds
    none is removed (so that the next plain run is not told to --resume)."""
    import shutil

    if store is None:
        return []
    done = [i for i in range(store.n_chunks) if store.is_done(i)] if store.directory.exists() else []
    if not done and created:
        shutil.rmtree(store.directory, ignore_errors=True)
    return done


def _warn_members_not_ok_kept(store, kept: list, solver, out: Path) -> None:
    """The warning of members not ok of an interrupted run, for its finished chunks (``kept``, their
    indices): a run to its end gives it once, from its combined file, which an interrupted run
    lacks; the kept chunks are not run again by --resume, whose combined file warns of them again."""
    import xarray as xr

    from .simulate import members_not_ok_text

    names = ("status", "disc_velocity", "lift_off", "working_precision")
    columns: dict = {name: [] for name in names}
    meanings = ""
    for i in kept:  # read when is_done counted them (netCDF4: xarray's open takes ~10x as long a file)
        try:
            summary = store.summary_columns(i)
        except ValueError:  # changed or gone since it was counted: not worth a traceback in place of the line
            continue
        meanings = summary["flag_meanings"]
        for name in names:
            columns[name].append(summary[name])
    if not columns["status"]:
        return
    ds = xr.Dataset({name: ("member", np.concatenate(parts)) for name, parts in columns.items()})
    ds["status"].attrs["flag_meanings"] = meanings
    text = members_not_ok_text(ds, solver, where=f" in the {plural(len(kept), 'finished chunk')}")
    if text is not None:
        warnings.warn(f"{text}; their numbers: `warpfric info {shlex.quote(str(out))}` once --resume has finished "
                      "the run", stacklevel=2)


def _run_chunks(sweep, sweep_file, store, chunk, offset, device, client, quiet, command, cpu_workers, started,
                record_times=None):
    """Run the chunks that ``store`` lacks (here or on ``client``): (reports, errors, wall seconds)."""
    todo = [i for i in range(store.n_chunks) if not store.is_done(i)]
    place = "this process, device " + str(device)
    if client is not None:
        n_workers = len(client.scheduler_info().get("workers", {}))
        place = f"Dask cluster {client.scheduler.address} ({plural(n_workers, 'worker')}, dashboard {client.dashboard_link})"
    swept = [name for name in sweep.members if name in sweep.varying]  # the sweep file's order
    _say(f"{member_range(sweep.n_members, offset, offset + sweep.n_members - 1)} in {plural(store.n_chunks, 'chunk')} "
         f"of <= {plural(chunk, 'member')}, {len(todo)} of them to run on {place}; swept: {', '.join(swept) or 'nothing'}", False)
    if client is not None and todo:
        t_ready = time.perf_counter()
        try:  # every worker loads its kernels once, outside the timed run (a task each: heartbeats go on)
            addresses = list(client.scheduler_info().get("workers", {}))
            # loose restriction: a worker that dies meanwhile must not leave its warm-up unrunnable
            warm_ups = [client.submit(prepare_worker, sweep.text, str(sweep_file), device, workers=[a],
                                      allow_other_workers=True, pure=False) for a in addresses]
            # each result in turn, not client.gather: a gather that Ctrl-C leaves pending ends, once the
            # client closes, in asyncio's "Task exception was never retrieved" tracebacks (AllExit)
            ready = [future.result() for future in warm_ups]
            devices = sorted({r["device"] for r in ready})
            _say(f"{plural(len(ready), 'worker')} ready in {time.perf_counter() - t_ready:.1f} s (kernels loaded on "
                 f"{', '.join(devices)})", quiet)
        except Exception as err:  # noqa: BLE001 - the chunks report it by member range
            _say(f"preparing the workers failed ({type(err).__name__}: {err}); running the chunks anyway", quiet)
    elif todo:  # compile (or load from Warp's cache) before the timed run, and say how long it took
        ready = prepare_worker(sweep.text, str(sweep_file), device)
        _say(f"kernels ready on {ready['device']} in {ready['seconds']:.1f} s", quiet)
    t0 = time.perf_counter()
    jobs = [ChunkJob(sweep_text=sweep.text, sweep_name=str(sweep_file), index=i, n_chunks=store.n_chunks,
                     start=store.members(i).start, stop=store.members(i).stop, member_offset=offset,
                     path=str(store.chunk_path(i).resolve()), device=device, command=command,
                     progress=not quiet and client is None, cpu_workers=cpu_workers,
                     run_id=store.manifest.get("run_id"), started=started, record_times=record_times)
            for i in todo]
    reports, errors = run_local(jobs) if client is None else run_on_client(jobs, client, quiet)
    return reports, errors, time.perf_counter() - t0
