"""warpfric.pool: all cores of a CPU for one ensemble.

Warp runs a launch on the CPU on one core. ``simulate(..., workers=None)`` (the default) therefore
splits a CPU ensemble that is large enough to pay (one core would take at least MIN_CPU_SECONDS by
warpfric.progress.cpu_seconds) into contiguous chunks of members, runs the chunks in worker
processes, one per core, and joins their Datasets in member order. ``workers=1`` runs in this
process, an integer runs that many workers. Only the process that the user started splits (not a
worker of this pool or of a Dask cluster, nor a thread other than the main one).

Each member's integration is independent of the others, so the outputs equal one process's bit for
bit, with one exception: the straggler rule (Solver.stall_factor) compares a member with the other
members of its chunk, not of the whole ensemble, so a member far slower than its peers may stop as
``stalled`` in one and not in the other (and the float32 fallback reruns a chunk's failed members
together). Records (``record``) and ``member_offset`` work as in one process.

The pool: 'spawn' worker processes (a fork would copy Warp's runtime, and CUDA's where there is
one, from a process that may be using it), started with the first ensemble that needs them and
kept for the next ones. A worker's start (~1.5 s on this project's 2-core machine: numpy, xarray
and Warp imported, Warp initialised, the kernels loaded from Warp's cache, xarray's first Dataset)
is paid once per process; a warm pool costs ~20 ms a chunk. The workers do not run the parent's ``__main__`` script (a script
without ``if __name__ == "__main__":`` works) and see no CUDA device. Ctrl-C stops them at once.

Attributes of a split run: ``workers``, ``worker_chunks``, ``worker_start_time_s`` (starting the
processes in the call that created the pool, until the last of them that said it was ready during
that call; 0 in the calls after it), ``wall_time_s`` (the parent's time from the split
to the joined Dataset, worker start included, the slowest worker's kernel loads not) and
``kernel_build_time_s`` (the slowest worker's).
"""

from __future__ import annotations

import atexit
import concurrent.futures as cf
import contextlib
import dataclasses
import itertools
import multiprocessing as mp
import multiprocessing.context as mpc
import os
import queue as queue_module
import signal
import sys
import threading
import time
import types
import warnings

import numpy as np

from . import progress as progress_module
from .device import init_warp
from .parameters import ENSEMBLE_WARNINGS

# split when one core would take at least this long (s, by progress.cpu_seconds). Measured on this
# project's 2-core machine (studies/bench_cpu_workers.py, fronts on, N = 100, fresh processes): 100
# members (3.6 s by the estimate of that time) 4.3 s in one process, 3.5 s on 2 new workers (they start in ~0.6 s,
# and their first run pays ~1 s more: xarray's first Dataset imports dask where it is installed,
# the kernels' modules are built), 2.3 s on a warm pool; 400 members 15.9 s, 9.5 s and 7.8 s
MIN_CPU_SECONDS = 2.5
# chunks per worker (so that a worker whose chunks run faster takes more of them) and the fewest
# members in a chunk
CHUNKS_PER_WORKER = 4
# a parent whose workers have reported nothing this long after the start says why (their start, ~1.5 s
# on this project's CPU, and the kernels' load, or once their compilation, ~8 s)
WORKERS_QUIET_NOTE_S = 5.0
MIN_CHUNK_MEMBERS = 4


def cpu_cores() -> int:
    """The cores this process may run on."""
    if hasattr(os, "process_cpu_count"):  # Python >= 3.13
        n = os.process_cpu_count()
    elif hasattr(os, "sched_getaffinity"):
        n = len(os.sched_getaffinity(0))
    else:  # pragma: no cover
        n = os.cpu_count()
    return max(1, n or 1)


_IN_WORKER = False  # True in a worker process of this pool


def _top_level() -> bool:
    return not _IN_WORKER and mp.parent_process() is None and threading.current_thread() is threading.main_thread()


def plan(workers, device, n_members: int, solver, fronts, record, model=None, extra: float = 0.0) -> int:
    """How many worker processes run the ensemble (1: this process). Validates ``workers`` and
    ``record``'s members, and warns (progress.SizeWarning) before a run far beyond the usual size;
    ``extra``: the attempts a member needs beyond the automatic end (progress.end_time_attempts)."""
    from .engine import record_slots

    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise ValueError(f"workers = {workers!r} is invalid; valid: None (all cores of a CPU for an ensemble large "
                         "enough to pay) or an integer >= 1 (1: this process)")
    cpu = str(device).startswith("cpu")
    if workers is not None and workers > 1 and not cpu:
        raise ValueError(f"workers = {workers} is invalid with device {device!r}; valid there: None or 1 (worker "
                         "processes serve the CPU, where Warp runs a launch on one core)")
    record_slots(record, n_members)  # a recorded member beyond the ensemble: the same error as in one process
    passes = progress_module.front_passes(fronts)
    if workers is None:
        pays = progress_module.cpu_seconds(n_members, solver, passes, model, extra) >= MIN_CPU_SECONDS
        n = min(cpu_cores(), n_members) if cpu and n_members > 1 and pays and _top_level() else 1
    else:
        n = min(int(workers), n_members)
        if cpu and n > cpu_cores() and not _IN_WORKER:  # allowed (as asked), but it buys nothing
            warnings.warn(f"workers = {n} on {cpu_cores()} CPU cores: the processes share the cores and run no "
                          f"faster than {cpu_cores()} would (Warp runs a CPU launch on one core)", stacklevel=3)
    if not _IN_WORKER:
        progress_module.check_memory(n_members, solver, device)
        progress_module.size_warning(n_members, solver, passes, device, n, extra)
    return n


def chunk_bounds(n_members: int, n_workers: int) -> list[tuple[int, int]]:
    """Contiguous (start, stop) member ranges: CHUNKS_PER_WORKER per worker, of at least
    MIN_CHUNK_MEMBERS members (at least one chunk per worker), sizes differing by at most one."""
    n_chunks = max(n_workers, min(n_workers * CHUNKS_PER_WORKER, n_members // MIN_CHUNK_MEMBERS))
    n_chunks = min(n_chunks, n_members)
    edges = [k * n_members // n_chunks for k in range(n_chunks + 1)]
    return list(zip(edges[:-1], edges[1:]))


# --- the worker side ---
_INBOX = None  # the parent's message queue (progress and readiness), in a worker


def _init_worker(inbox) -> None:
    """A worker's start: Ctrl-C is the parent's to handle, no CUDA device, Warp initialised
    (its "no CUDA driver" notice, which the parent has printed, not repeated)."""
    global _IN_WORKER, _INBOX
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, args=(os.getppid(),), daemon=True).start()
    os.environ["CUDA_VISIBLE_DEVICES"] = ""
    _IN_WORKER, _INBOX = True, inbox
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 2)
            init_warp()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
    inbox.put(("ready", os.getpid()))


PARENT_POLL_S = 0.5  # how often a worker looks whether the process that started it still lives


def _exit_with_parent(parent: int) -> None:
    """In a worker, on a thread of its own: end the worker once the process that started it is gone.
    A parent that is killed (SIGTERM, SIGKILL, out of time) cannot stop its workers, which then went
    on computing and held their memory, re-parented, until someone killed them."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


class _Sink:
    """Where a worker's engine reports progress (warpfric.progress.SINK): to the parent, at most every
    0.2 s, and at the end."""

    def __init__(self, run_id: int, chunk: int):
        self.run_id, self.chunk, self.last = run_id, chunk, -1.0

    def __call__(self, fraction: float, done: int, final: bool) -> None:
        now = time.monotonic()
        if final or now - self.last >= 0.2:
            self.last = now
            _INBOX.put(("progress", self.run_id, self.chunk, float(fraction), int(done)))


def warning_pairs(caught) -> list:
    """Warnings recorded in another process (``warnings.catch_warnings(record=True)``) as picklable
    (message, category) pairs, for the process that started it to raise with :func:`warn_once`."""
    return [(str(w.message), w.category) for w in caught]


def warn_once(pairs, stacklevel: int = 1) -> None:
    """Raise each distinct (message, category) of ``pairs`` once, in order: the warnings of several
    worker processes, which would each print their own, with their own source line.
    ``stacklevel`` as for warnings.warn, counted from the caller of this function."""
    for message, category in dict.fromkeys(pairs):
        warnings.warn(message, category, stacklevel=stacklevel + 1)


def chunk_warnings(caught) -> list:
    """A chunk's own warnings (warning_pairs of ``caught``), less ENSEMBLE_WARNINGS, which the caller
    raises once for the joined ensemble: a worker's chunk, or a CPU block of simulate."""
    return [(m, c) for m, c in warning_pairs(caught) if not m.startswith(ENSEMBLE_WARNINGS)]


def _run_chunk(runner, run_id: int, chunk: int, members: dict, record, member_offset: int, show: bool, common: dict):
    """In a worker: one chunk's Dataset and the warnings it raised ((message, category) each, for the
    parent to raise: a worker's own would print once per worker, with its source line), ``runner``
    being warpfric.simulate.simulate (passed by the parent, pickled by reference, so that this module
    imports no simulate)."""
    progress_module.SINK = _Sink(run_id, chunk) if show else None
    try:
        with warnings.catch_warnings(record=True) as caught:
            ds = runner(members, record=record, member_offset=member_offset, progress=show, workers=1, **common)
        return ds, chunk_warnings(caught)
    finally:
        progress_module.SINK = None


# --- the parent side ---
@contextlib.contextmanager
def _main_hidden():
    """While a worker process starts: a bare ``__main__``, so that the worker does not import the
    parent's script again (spawn would, and run its top level where it has no __main__ guard)."""
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


class _Process(mpc.SpawnProcess):
    @staticmethod
    def _Popen(process_obj):
        with _main_hidden():
            return mpc.SpawnProcess._Popen(process_obj)


class _Context(mpc.SpawnContext):
    Process = _Process


@dataclasses.dataclass
class _Pool:
    workers: int
    executor: cf.ProcessPoolExecutor
    inbox: object
    ready_at: float | None = None  # when the parent last read a worker's "ready" message (perf_counter, s)


_POOL: _Pool | None = None
_RUN_IDS = itertools.count()


class WorkerDied(RuntimeError):
    """A worker process ended abruptly while the pool ran an ensemble (killed: by the system's
    out-of-memory killer where memory ran short, or by kill -9). The ensemble's run is stopped, its
    workers with it; ``warpfric run`` keeps a sweep's finished chunks and exits with code 5."""


def _worker_processes(pool: _Pool) -> list:
    """The worker processes of ``pool``'s executor (CPython keeps them in ``_processes``; none where
    it does not)."""
    return list((getattr(pool.executor, "_processes", None) or {}).values())


def _dead_workers(pool: _Pool) -> list[tuple[int, int]]:
    """(pid, exit code) of each worker process of ``pool`` that has ended (a worker ends only with
    the pool, so any that has during a run died)."""
    return [(process.pid, process.exitcode) for process in _worker_processes(pool) if process.exitcode is not None]


def _worker_died_text(dead: list) -> str:
    """What a user reads where workers died: which, how, why that happens and what to do."""
    # the executor stops the other workers with SIGTERM once it sees one die: name the one that died
    dead = [(pid, code) for pid, code in dead if code != -signal.SIGTERM] or dead
    how, signals = [], set()
    for pid, code in dead:
        if code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
            signals.add(name)
            how.append(f"pid {pid}, killed by {name}")
        else:
            how.append(f"pid {pid}, exit code {code}")
    which = (f"{len(dead)} CPU worker processes ended" if len(dead) > 1 else "a CPU worker process ended") + (
        f" abruptly ({'; '.join(how)})" if how else " abruptly")
    why = ("; the system's out-of-memory killer ends a process so where memory runs short" if "SIGKILL" in signals
           else "; a crash (its error, if any, is printed above)" if signals - {"SIGTERM"}
           else "; something outside the pool sent it SIGTERM" if signals
           else "; it ended on its own (its error, if any, is printed above)")
    return (f"{which} while the pool ran the ensemble, so the run is stopped{why}. Fewer worker processes at once "
            "hold less memory and show a worker's error: workers=1 (warpfric run --cpu-workers 1, which --resume "
            "takes too)")


def _get_pool(n_workers: int) -> tuple[_Pool, bool]:
    """(the kept pool of n_workers processes, True where it was created in this call)."""
    global _POOL
    if _POOL is not None and (_dead_workers(_POOL) or getattr(_POOL.executor, "_broken", False)):
        shutdown(terminate=True)  # a kept worker killed between runs (or the pool broken): a new pool
    if _POOL is not None and _POOL.workers != n_workers:
        shutdown()
    if _POOL is not None:
        return _POOL, False
    ctx = _Context()
    inbox = ctx.Queue()
    executor = cf.ProcessPoolExecutor(n_workers, mp_context=ctx, initializer=_init_worker, initargs=(inbox,))
    _POOL = _Pool(n_workers, executor, inbox)
    return _POOL, True


def shutdown(terminate: bool = False) -> None:
    """Stop the worker processes (they start again with the next ensemble that needs them);
    ``terminate``: at once, dropping what they run."""
    global _POOL
    pool, _POOL = _POOL, None
    if pool is None:
        return
    processes = _worker_processes(pool)
    results = getattr(pool.executor, "_result_queue", None)  # (shutdown forgets it)
    if terminate:
        for process in processes:
            process.terminate()
    pool.executor.shutdown(wait=not terminate, cancel_futures=True)
    for process in processes:
        process.join(5)
        if process.exitcode is None:  # a worker that did not end on SIGTERM
            process.kill()
            process.join(5)
    if terminate and results is not None:
        # a worker killed while it sent its result left half a message in the result pipe; the executor's
        # thread then waited in recv for the rest, forever, and the interpreter, which joins that thread
        # at exit, hung after the run (SIGTERM said "interrupted" and nothing ended). With every worker
        # gone, closing this process's own write end gives that read end-of-file, and the thread ends
        with contextlib.suppress(AttributeError, OSError):
            results._writer.close()


# The kept pool is stopped before the interpreter tears its modules down: left to the teardown, the
# executor's own clean-up ran with the multiprocessing module already gone and printed "Exception
# ignored in ... weakref_cb ... 'NoneType' object has no attribute 'util'" at exit
atexit.register(shutdown)


def chunk_record(record, start: int, stop: int):
    """(the Record of the members of [start, stop) at their positions in the chunk, or None; their
    indices in record.members)."""
    if record is None:
        return None, []
    chosen = [k for k, member in enumerate(record.members) if start <= member < stop]
    if not chosen:
        return None, []
    return dataclasses.replace(record, members=tuple(int(record.members[k]) - start for k in chosen)), chosen


def run(n_workers: int, values: dict, *, scene, model, solver, fronts, record, device, progress,
        member_offset: int, runner, x, varying_parameters: str):
    """simulate()'s run of the resolved members ``values`` on ``n_workers`` worker processes: one
    Dataset, as one process would return it (see the module's docstring). ``runner``: the function
    each worker runs on its chunk (warpfric.simulate.simulate); ``x``: the ensemble's x coordinate;
    ``varying_parameters``: the ensemble's attribute of that name (a chunk may hold one length, or
    one value of a swept parameter)."""
    t0 = time.perf_counter()
    n = values["normal_force"].shape[0]
    bounds = chunk_bounds(n, n_workers)
    sizes = np.array([stop - start for start, stop in bounds])
    show = progress_module.shown(progress)
    line = progress_module.Line(n, progress if isinstance(progress, str) else "") if show else None
    run_id = next(_RUN_IDS)
    common = dict(scene=scene, model=model, solver=solver, fronts=fronts, device=device)
    records = [chunk_record(record, start, stop) for start, stop in bounds]
    fractions, done = np.zeros(len(bounds)), np.zeros(len(bounds), dtype=np.int64)
    noted = False  # the note of workers quiet at the start (WORKERS_QUIET_NOTE_S)
    try:
        # started here: the processes of a pool created in this call (a kept pool's worker may still
        # say it is ready in a later call, when its first call ended before its message was read:
        # that is no start of this call's); inside the try, so that a Ctrl-C before the first
        # submit stops the new pool instead of keeping it without processes
        pool, started_here = _get_pool(n_workers)
        try:
            futures = [pool.executor.submit(_run_chunk, runner, run_id, k,
                                            {name: v[start:stop] for name, v in values.items()},
                                            records[k][0], member_offset + start, show, common)
                       for k, (start, stop) in enumerate(bounds)]
            while True:
                _read_inbox(pool, run_id, fractions, done, timeout=0.25)
                finished = 0
                for k, future in enumerate(futures):
                    if future.done():
                        future.result()  # a chunk that raised: raise here
                        fractions[k], done[k] = 1.0, sizes[k]
                        finished += 1
                if line is not None:
                    line.show(float(fractions @ sizes) / n, int(done.sum()), f"{n_workers} workers")
                    if not noted and not fractions.any() and time.perf_counter() - t0 > WORKERS_QUIET_NOTE_S:
                        noted = True  # the workers compile where Warp's cache lacks the kernels: seconds at 0 %
                        progress_module.write_note("warpfric: the worker processes start and load the kernels "
                                                   "(the first time, they compile them; Warp keeps them in its cache) ...")
                if finished == len(futures):
                    break
                # a worker that died while chunks are left: said here, also where the executor did not
                # notice (it waited for the rest of a result that the worker was sending when it was
                # killed, and the run hung)
                dead = _dead_workers(pool)
                if dead:
                    raise WorkerDied(_worker_died_text(dead))
            results = [future.result() for future in futures]
        except cf.process.BrokenProcessPool:
            raise WorkerDied(_worker_died_text(_dead_workers(pool))) from None
    except BaseException:
        if line is not None:
            line.stop()
        shutdown(terminate=True)
        raise
    parts = [part for part, _ in results]
    ds = join(parts, [chosen for _, chosen in records], x, varying_parameters)
    build = max(float(p.attrs.get("kernel_build_time_s", 0.0)) for p in parts)
    ds.attrs["kernel_build_time_s"] = build
    ds.attrs["wall_time_s"] = max(time.perf_counter() - t0 - build, 0.0)
    ds.attrs["workers"] = n_workers
    ds.attrs["worker_chunks"] = len(bounds)
    ds.attrs["worker_start_time_s"] = (pool.ready_at - t0) if started_here and pool.ready_at is not None else 0.0
    if line is not None:
        line.close(f"{n_workers} workers")
    warn_once((w for _, caught in results for w in caught), stacklevel=3)  # at simulate()'s caller, after the line
    return ds


def _read_inbox(pool: _Pool, run_id: int, fractions: np.ndarray, done: np.ndarray, timeout: float) -> None:
    """Take the workers' messages (waiting up to ``timeout`` s for the first): readiness, and this
    run's progress per chunk (never backwards; a chunk's later engine runs, e.g. its grid check,
    restart at 0)."""
    block = True
    while True:
        try:
            message = pool.inbox.get(block, timeout)
        except queue_module.Empty:
            return
        block = False
        if message[0] == "ready":
            pool.ready_at = time.perf_counter()
        elif message[1] == run_id:
            _, _, chunk, fraction, members_done = message
            fractions[chunk] = max(fractions[chunk], fraction)
            done[chunk] = max(done[chunk], members_done)


def join(parts: list, chosen: list, x, varying_parameters: str):
    """The chunks' Datasets as one: every variable along ``member`` concatenated in member order, the
    recorded members in the order of record.members (``chosen``: each chunk's indices there), the
    ensemble's x coordinate ``x``, its ``varying_parameters`` attribute and the chunks' member_order
    ("mixed" where they differ)."""
    import xarray as xr

    recorded = [name for p in parts for name, var in p.variables.items() if "recorded" in var.dims or name == "time"]
    recorded = list(dict.fromkeys(recorded))
    ds = xr.concat([p.drop_vars([name for name in recorded if name in p.variables]) for p in parts], dim="member",
                   data_vars="minimal", coords="minimal", compat="override", join="override",
                   combine_attrs="override")
    ds = ds.assign_coords(x=x)
    with_record = [(p, c) for p, c in zip(parts, chosen) if c]
    if with_record:
        order = np.argsort([k for _, c in with_record for k in c], kind="stable")
        first = with_record[0][0]
        for name in recorded:
            var = first.variables[name]
            if "recorded" in var.dims:
                data = np.concatenate([p.variables[name].values for p, _ in with_record], axis=0)[order]
                var = xr.Variable(var.dims, data, var.attrs)
            if name in first.coords:
                ds = ds.assign_coords({name: var})
            else:
                ds[name] = var
        ds = ds[list(first.data_vars)]  # the variables in one process's order
    ds.attrs["varying_parameters"] = varying_parameters
    orders = {p.attrs.get("member_order", "given") for p in parts}  # each chunk's engine chose its own
    ds.attrs["member_order"] = orders.pop() if len(orders) == 1 else "mixed"
    return ds
