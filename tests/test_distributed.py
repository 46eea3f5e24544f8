"""Sweeps on a Dask cluster (warpfric.runner): a LocalCluster of 2 CPU worker processes gives the
single-process result bit for bit; a worker killed mid-sweep costs only its chunk; a killed client
leaves a run that --resume completes; an interrupted run (Ctrl-C, SIGTERM) ends in warpfric's lines
only, with its finished chunks' warnings and a true count of the chunks kept. CPU only (CI)."""

import os
import re
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import xarray as xr

distributed = pytest.importorskip("distributed")

from warpfric.io import parts_dir  # noqa: E402
from warpfric.runner import run_sweep  # noqa: E402

SWEEP = """
title = "dask test"
[solver]
nodes = 24
rtol = 1e-4
[grid]
eccentricity = [-0.2, -0.1, 0.0, 0.1, 0.2]
normal_force = [800.0, 1200.0]
[run]
chunk = 2
"""
TIMING_ATTRS = ("wall_time_s", "device", "history")


def _outputs(path):
    """The file's variables; its member labels (<run id>:<number>) differ between runs by design, so
    they are checked here to name one run (a resumed one too) and then left out."""
    with xr.open_dataset(path) as ds:
        ds = ds.load()
    for key in TIMING_ATTRS:
        ds.attrs.pop(key, None)
    runs = {label.split(":")[0] for label in ds.member.values}
    assert len(runs) == 1, runs
    return ds.swap_dims(member="member_number").drop_vars("member")


def _assert_same_outputs(a, b):
    """Every variable and coordinate equal, bit for bit (NaN where NaN); the timing attributes aside."""
    da, db = _outputs(a), _outputs(b)
    assert sorted(da.data_vars) == sorted(db.data_vars)
    for name in da.variables:
        np.testing.assert_array_equal(da[name].values, db[name].values, err_msg=name)
    assert np.array_equal(da.member_number.values, np.arange(da.sizes["member_number"]))  # every member once


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The sweep run in this process (it also fills Warp's kernel cache for the workers)."""
    folder = tmp_path_factory.mktemp("ref")
    sweep = folder / "s.toml"
    sweep.write_text(SWEEP)
    report = run_sweep(sweep, folder / "single.nc", device="cpu", quiet=True)
    assert report.output is not None and report.failed_members == 0
    return sweep, folder / "single.nc"


@pytest.fixture
def client():
    # CPU workers even on a GPU host (the reference runs on the CPU; the GPU test asks for cuda:0 explicitly)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                       env={"CUDA_VISIBLE_DEVICES": ""})
    c = distributed.Client(cluster, set_as_default=False)  # a sweep takes its client by name, as warpfric's own
    yield c
    c.close()
    cluster.close()


def test_a_local_cluster_gives_the_single_process_result(reference, client, tmp_path):
    sweep, single = reference
    report = run_sweep(sweep, tmp_path / "dask.nc", client=client, quiet=True)
    assert report.output == tmp_path / "dask.nc" and not report.errors
    assert len(report.chunks) == 5 and sum(c["members"] for c in report.chunks) == 10
    assert os.getpid() not in {c["pid"] for c in report.chunks}  # the workers ran them, not this process
    _assert_same_outputs(single, tmp_path / "dask.nc")
    # the same through the command line and the scheduler's address
    from warpfric.cli import main

    code = main(["run", str(sweep), "-o", str(tmp_path / "cli.nc"), "--scheduler", client.scheduler.address, "--quiet"])
    assert code == 0
    _assert_same_outputs(single, tmp_path / "cli.nc")


def test_a_worker_killed_mid_sweep_costs_only_its_chunk(reference, client, tmp_path):
    """One worker is killed (SIGKILL, by its PID) while it holds a chunk; the nanny starts a new one,
    Dask runs the chunk again, and the sweep completes with every member exactly once."""
    sweep, single = reference
    pids = client.run(os.getpid)  # worker address -> pid
    result = {}
    thread = threading.Thread(target=lambda: result.update(report=run_sweep(sweep, tmp_path / "k.nc", client=client,
                                                                            quiet=True)))
    thread.start()
    killed = None
    deadline = time.time() + 60
    while killed is None and time.time() < deadline:
        busy = {addr for addr, keys in client.processing().items()
                if any(str(k).startswith("warpfric-chunk") for k in keys)}  # a chunk, not the warm-up
        if busy:
            address = sorted(busy)[0]
            killed = pids[address]
            os.kill(killed, signal.SIGKILL)
        else:
            time.sleep(0.02)
    thread.join(timeout=180)
    assert killed is not None and not thread.is_alive()
    report = result["report"]
    assert report.output is not None and not report.errors
    # every chunk reported once (the one the killed worker held was run again), none by the dead pid
    assert len(report.chunks) == 5 and sum(c["members"] for c in report.chunks) == 10
    assert sorted(c["index"] for c in report.chunks) == [0, 1, 2, 3, 4]
    client.wait_for_workers(2, timeout=60)
    restarted = client.run(os.getpid)
    assert len(restarted) == 2 and killed not in restarted.values()  # the nanny started a new worker
    assert not parts_dir(tmp_path / "k.nc").exists()
    _assert_same_outputs(single, tmp_path / "k.nc")


def test_a_killed_client_leaves_a_run_that_resume_completes(reference, tmp_path):
    """`warpfric run --local-cluster` is killed (SIGKILL to its PID) after its first chunk; its worker
    processes are stopped too; `--resume` in one process finishes the same run."""
    psutil = pytest.importorskip("psutil")
    sweep, single = reference
    out = tmp_path / "c.nc"
    slow = tmp_path / "slow.toml"  # more, smaller chunks: the kill lands while chunks remain
    slow.write_text(SWEEP.replace("chunk = 2", "chunk = 1"))
    proc = subprocess.Popen([sys.executable, "-m", "warpfric", "run", str(slow), "-o", str(out), "--local-cluster",
                             "--workers", "2", "--device", "cpu", "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    parts = parts_dir(out)
    deadline = time.time() + 120
    while time.time() < deadline and not list(parts.glob("chunk-*.nc")):
        time.sleep(0.05)
    children = psutil.Process(proc.pid).children(recursive=True)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    for child in children:  # the cluster's processes, started by the killed client
        try:
            child.kill()
        except psutil.NoSuchProcess:
            pass
    assert not out.exists()
    finished = len(list(parts.glob("chunk-*.nc")))
    assert 1 <= finished < 10, finished
    report = run_sweep(slow, out, resume=True, device="cpu", quiet=True)
    assert report.output == out and len(report.chunks) == 10 - finished
    _assert_same_outputs(single, out)


def test_a_chunk_that_fails_is_reported_by_member_range(reference, client, tmp_path):
    """Chunks asking for a GPU on CPU-only workers raise on the worker: each is reported with its
    member range and error, nothing is combined, and, none having finished, no parts folder is kept
    (it blocked the next plain run, and a --resume could only fail again)."""
    sweep, _ = reference
    out = tmp_path / "gpu.nc"
    report = run_sweep(sweep, out, client=client, device="cuda:0", quiet=True)
    assert report.output is None and not out.exists() and not parts_dir(out).exists()
    assert [(e["start"], e["stop"]) for e in sorted(report.errors, key=lambda e: e["start"])] == [
        (0, 2), (2, 4), (4, 6), (6, 8), (8, 10)]
    assert all("has no CUDA device" in e["error"] for e in report.errors)


def test_the_command_s_workers_leave_warpfric_s_own_faults_to_its_one_line(reference, tmp_path):
    """A worker of the command's local cluster logged each chunk's RunError as distributed's 6-line
    "Compute Failed" record with its traceback (~500 lines for the 63 chunks of sweeps.md's example
    on a host without a GPU), beside warpfric's line naming the chunk; those records are dropped, and
    an exception that is not warpfric's own keeps its record (its traceback tells where it came from).
    In a process of its own: the workers' stderr is the terminal's, which pytest does not capture."""
    import logging

    from warpfric.cluster_worker import own_fault

    sweep, _ = reference
    script = f"""
import distributed
from warpfric.cluster_worker import LocalClusterWorker
from warpfric.runner import run_sweep
if __name__ == "__main__":
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                       env={{"CUDA_VISIBLE_DEVICES": ""}})
    client = distributed.Client(cluster, set_as_default=False)
    if {{plugin}}:
        client.register_plugin(LocalClusterWorker(), name="warpfric-local-cluster-worker")
    report = run_sweep({str(sweep)!r}, {str(tmp_path / "gpu.nc")!r}, client=client, device="cuda:0", quiet=True)
    assert len(report.errors) == 5
    client.close()
    cluster.close()
"""
    errs = []
    for plugin in (True, False):
        path = tmp_path / f"run_{plugin}.py"
        path.write_text(script.replace("{plugin}", str(plugin)))
        run = subprocess.run([sys.executable, str(path)], capture_output=True, text=True, timeout=240)
        assert run.returncode == 0, run.stderr
        errs.append(run.stderr)
    assert errs[0].count("FAILED: RunError") == 5 and "Compute Failed" not in errs[0], errs[0]
    assert errs[1].count("Compute Failed") == 6  # without the plugin: the records it drops (5 chunks, 1 warm-up)

    def record(exception_text: str) -> logging.LogRecord:  # as distributed.worker logs a failed task
        return logging.LogRecord("distributed.worker", logging.ERROR, "worker.py", 1,
                                 "Compute Failed\nKey:       %s\nState:     %s\nTask:  %s\nException: %r\nTraceback: %r\n",
                                 ("k", "executing", "task", exception_text, "tb"), None)

    assert own_fault(record("RunError('chunk 1/63 (members 0..999): device cuda:0 asked for')"))
    assert own_fault(record("OutputWriteError(\"chunk 2: no space left\")"))
    assert not own_fault(record("TypeError('a bug')"))
    assert not own_fault(logging.LogRecord("distributed.scheduler", logging.ERROR, "s.py", 1, "Compute Failed", (), None))


@pytest.mark.parametrize("argv, words", [
    (["run", "--local-cluster"], ["--local-cluster", "sweep file"]),
    (["run", "--scheduler", "tcp://127.0.0.1:1"], ["--scheduler", "sweep file"]),
    (["run", "SWEEP", "--scheduler", "tcp://127.0.0.1:1", "--local-cluster"], ["exclude"]),
    (["run", "SWEEP", "--local-cluster", "--workers", "0"], ["--workers 0", ">= 1"]),
    (["run", "SWEEP", "--grid-check"], ["--grid-check", "grid_check = true"]),
    # a device this host lacks failed every chunk of a new local cluster on it, after it started
    (["run", "SWEEP", "--local-cluster", "--device", "cuda:999"], ["device 'cuda:999' is not available"]),
])
def test_cluster_options_that_cannot_work_are_refused(reference, tmp_path, capsys, argv, words):
    from warpfric.cli import main

    sweep, _ = reference
    argv = [str(sweep) if a == "SWEEP" else a for a in argv] + ["-o", str(tmp_path / "x.nc")]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(w in err[0] for w in words), err


def test_workers_warnings_are_raised_once_by_the_client(client, tmp_path, capfd):
    """Each Dask worker process would print a chunk's warning itself, raw and once per worker: the
    chunks return them and the command prints each distinct one once, as its one-line warning."""
    from warpfric.cli import main

    sweep = tmp_path / "gateless.toml"
    sweep.write_text(SWEEP.replace('title = "dask test"', 'title = "dask test"\n[model]\nrelaxation_gate = "none"'))
    code = main(["run", str(sweep), "-o", str(tmp_path / "g.nc"), "--scheduler", client.scheduler.address, "--quiet"])
    err = capfd.readouterr().err
    assert code == 0
    warned = [line for line in err.splitlines() if "Warning" in line or line.startswith("warpfric: warning:")]
    assert len(warned) == 1 and warned[0].startswith("warpfric: warning: fronts event 'contact'"), err


# A sweep that runs for a while on 2 CPU workers (80 chunks of 10 members, ~0.2 s a chunk), so that an
# interrupt after its first chunk leaves chunks running and queued. Each chunk warns once (the contact
# front under relaxation_gate = "none") and holds one member not ok (eccentricity -0.3 needs more
# than 150 steps: max_steps_reached); a run to its end reports both once.
INTERRUPTED_SWEEP = f"""
title = "interrupted on a cluster"
[model]
relaxation_gate = "none"
[solver]
nodes = 121
max_steps = 150
[grid]
normal_force = [{", ".join(f"{300.0 + 40.0 * i:.1f}" for i in range(80))}]
eccentricity = [-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.25, -0.25, 0.15]
[run]
chunk = 10
"""
CUDA_BANNER = "Warp CUDA warning"  # Warp's own line on a host without a GPU, in a run to its end too


def _interrupt(argv, sig, cwd, again_after: float | None = None):
    """`warpfric run ARGV` in a session of its own, sent ``sig`` (to its whole process group, its local
    cluster's workers too, as a terminal's Ctrl-C or a batch system's SIGTERM) once its first chunk is
    reported done, and once more ``again_after`` s later if it still runs (an impatient user): (exit
    code, stderr lines, worker pids named in the progress lines)."""
    # Python's own Ctrl-C in the command even where this test runs with SIGINT ignored (a job started
    # with & from a script), which the command would inherit and keep, as a background job should
    proc = subprocess.Popen([sys.executable, "-m", "warpfric", "run", *map(str, argv)], cwd=cwd, text=True,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
                            env={**os.environ, "CUDA_VISIBLE_DEVICES": ""})
    lines, first_chunk = [], threading.Event()

    def read():
        for line in proc.stderr:
            lines.append(line.rstrip("\n"))
            if " chunks done (" in line:
                first_chunk.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    started = first_chunk.wait(timeout=180)
    if proc.poll() is None:
        os.killpg(proc.pid, sig)
    if again_after is not None:
        time.sleep(again_after)
        if proc.poll() is None:
            os.kill(proc.pid, sig)  # the command only: its workers ignore it anyway
    code = proc.wait(timeout=120)
    reader.join(timeout=30)
    assert started, lines
    pids = {int(p) for line in lines for p in re.findall(r"\(pid (\d+)\)", line)}
    return code, lines, pids


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process, given that number since
        return True
    return True


def _kept(line: str) -> int:
    """N of the interrupt line's 'the N finished chunks are kept'."""
    found = re.search(r"the (\d+) finished chunks? (?:is|are) kept", line)
    assert found, line
    return int(found.group(1))


@pytest.fixture(scope="module", params=["SIGINT", "SIGTERM"])
def interrupted_local_cluster(request, tmp_path_factory):
    """`warpfric run --local-cluster --workers 2` interrupted by Ctrl-C (SIGINT) or SIGTERM to its
    process group; the chunk files as they are 2 s after it exited (a chunk takes about 0.2 s: one
    written late would be there)."""
    folder = tmp_path_factory.mktemp(f"interrupted-{request.param}")
    sweep = folder / "slow.toml"
    sweep.write_text(INTERRUPTED_SWEEP)
    out = folder / "i.nc"
    code, err, pids = _interrupt([sweep, "-o", out, "--local-cluster", "--workers", 2], getattr(signal, request.param),
                                 folder)
    time.sleep(2)
    return dict(code=code, err=err, pids=pids, chunks=sorted(parts_dir(out).glob("chunk-*.nc")), out=out)


def test_an_interrupted_local_cluster_prints_warpfric_lines_only(interrupted_local_cluster):
    """The workers got the signal too, and each printed a traceback of its event loop (about 30
    lines a worker) or its nanny logged a restart; the scheduler and the workers logged the tasks
    cancelled by the close. The workers now leave the signal to the command, which closes its client,
    then the cluster, with distributed's shutdown warnings dropped."""
    run = interrupted_local_cluster
    assert run["code"] == 130, run["err"]
    foreign = [line for line in run["err"] if not line.startswith(("warpfric", CUDA_BANNER))]
    assert foreign == [], "\n".join(run["err"])
    assert run["err"][-1].startswith("warpfric: interrupted; ")


def test_an_interrupted_cluster_run_warns_of_its_finished_chunks(interrupted_local_cluster):
    """The chunks' warnings came back with their reports and were said once the run ended, and the
    members not ok once the file was combined: an interrupted run said neither. It says each once,
    the members not ok counted in the chunks it kept (one a chunk here)."""
    run = interrupted_local_cluster
    kept = _kept(run["err"][-1])
    warned = [line for line in run["err"] if line.startswith("warpfric: warning:")]
    assert len(warned) == 2, "\n".join(run["err"])
    assert warned[0].startswith("warpfric: warning: fronts event 'contact' with relaxation_gate='none'")
    assert warned[1].startswith(f"warpfric: warning: members that did not end ok have NaN mu_s and fronts: {kept} of "
                                f"{10 * kept} members in the {kept} finished chunks: {kept} max_steps_reached ")
    assert warned[1].endswith(f"their numbers: `warpfric info {run['out']}` once --resume has finished the run")


def test_an_interrupted_local_cluster_keeps_the_chunks_it_counts(interrupted_local_cluster):
    """The chunks running at the interrupt were written while the cluster closed, after the kept
    chunks were counted: the line said 2 fewer than the folder held. The cluster is stopped first,
    then the chunks are counted, and no worker outlives the command."""
    run = interrupted_local_cluster
    assert "; the local cluster is stopped, so no chunk is written after this; " in run["err"][-1]
    assert _kept(run["err"][-1]) == len(run["chunks"]) >= 1
    assert run["pids"] and not any(_alive(pid) for pid in run["pids"])


def test_a_second_ctrl_c_while_the_cluster_closes_keeps_the_interrupt_line(tmp_path):
    """The local cluster takes up to ~4 s to close; a second Ctrl-C then ended the run in a bare
    'warpfric: interrupted', without the kept chunks and the resume command. The line is said."""
    sweep = tmp_path / "slow.toml"
    sweep.write_text(INTERRUPTED_SWEEP)
    code, err, _ = _interrupt([sweep, "-o", tmp_path / "i.nc", "--local-cluster", "--workers", 2], signal.SIGINT,
                              tmp_path, again_after=0.3)
    assert code == 130, err
    assert err[-1].startswith("warpfric: interrupted; ") and "--resume" in err[-1], "\n".join(err)


def test_an_interrupted_scheduler_run_says_that_running_chunks_may_still_be_written(client, tmp_path):
    """--scheduler: the workers are not the command's; the chunks they run at the interrupt are
    written after it exits, which the line said nothing of. It says so, and those chunks are
    complete and of this run: --resume takes them as done."""
    from warpfric.io import ChunkStore

    sweep = tmp_path / "slow.toml"
    sweep.write_text(INTERRUPTED_SWEEP)
    out = tmp_path / "s.nc"
    code, err, _ = _interrupt([sweep, "-o", out, "--scheduler", client.scheduler.address], signal.SIGINT, tmp_path)
    assert code == 130, err
    assert [line for line in err if not line.startswith(("warpfric", CUDA_BANNER))] == [], "\n".join(err)
    assert ", and chunks that were running on the cluster's workers may still be written there; " in err[-1]
    kept = _kept(err[-1])
    deadline = time.time() + 60  # the workers end the chunks they were running
    while time.time() < deadline and any(client.run(lambda dask_worker: len(dask_worker.state.executing)).values()):
        time.sleep(0.1)
    written = sorted(parts_dir(out).glob("chunk-*.nc"))
    assert len(written) >= kept
    assert ChunkStore.load(parts_dir(out)).done_count() == len(written)  # complete, of this run: --resume skips them
    assert not list(parts_dir(out).glob("*.tmp"))


def test_distributeds_sync_cancel_error_is_dropped_and_nothing_else():
    """A Ctrl-C that lands in distributed.utils.sync before its coroutine starts logs (through tornado)
    a NameError traceback of sync's own `cancel` callback, seen once in a fresh clone's run of the
    interrupt tests: that record is dropped, any other passes."""
    import logging

    from warpfric.runner import drop_sync_cancel_error

    def record_of(filename: str, name: str) -> logging.LogRecord:
        scope: dict = {}
        source = f"def {name}():\n    if future is not None:\n        pass\n    future = 1\n"
        exec(compile(source, filename, "exec"), scope)  # noqa: S102 - a frame named as distributed's
        try:
            scope[name]()
        except NameError:
            return logging.LogRecord("tornado.application", logging.ERROR, filename, 1, "Exception in callback",
                                     None, sys.exc_info())
        raise AssertionError("no NameError")

    assert not drop_sync_cancel_error(record_of("/site-packages/distributed/utils.py", "cancel"))
    assert drop_sync_cancel_error(record_of("/site-packages/distributed/utils.py", "other"))
    assert drop_sync_cancel_error(record_of("/site-packages/mypackage/utils.py", "cancel"))
    assert drop_sync_cancel_error(logging.LogRecord("tornado.application", logging.ERROR, "f", 1, "m", None, None))


def test_a_ctrl_c_while_the_cluster_closes_after_the_file_is_written_keeps_the_run(reference, tmp_path,
                                                                                   monkeypatch):
    """The local cluster takes seconds to close after the file is written; a Ctrl-C then ended the
    command in 'interrupted' (exit 130) although its output was complete: the run's report stands."""
    import warpfric.runner as runner

    sweep, single = reference
    made = []

    def in_process_cluster(workers=None):
        made.append(distributed.Client(distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                                                dashboard_address=None), set_as_default=False))
        return made[-1]

    def interrupted_close(client, interrupted=False):
        cluster = client.cluster
        client.close()
        cluster.close()
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "local_cluster", in_process_cluster)
    monkeypatch.setattr(runner, "close_local_cluster", interrupted_close)
    try:
        report = run_sweep(sweep, tmp_path / "local.nc", local=True, device="cpu", quiet=True)
    except KeyboardInterrupt:  # (not raised on: it would stop the whole test session)
        pytest.fail("a Ctrl-C while the cluster closed ended a run whose file was written")
    assert made and report.output == tmp_path / "local.nc" and report.failed_members == 0
    _assert_same_outputs(single, tmp_path / "local.nc")


def test_a_ctrl_c_while_the_local_cluster_starts_is_held_until_it_has_started(tmp_path, monkeypatch, request):
    """A terminal's Ctrl-C reaches the workers that the local cluster is still starting: they died
    mid-import, and ~70 lines of their and distributed's tracebacks came before warpfric's line (or
    the start raised 'Nanny failed to start', exit 1). The command holds the Ctrl-C until the start
    has ended, closes the cluster and ends in 'interrupted' (KeyboardInterrupt), also where a worker
    it hit failed the start; the workers started meanwhile ignore it from their import of warpfric."""
    import warpfric.runner as runner

    # Python's own Ctrl-C, as in a terminal, also where the tests run with SIGINT ignored (started with
    # & from a script: the Ctrl-C was not held, and the processes it starts inherited the ignoring)
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    request.addfinalizer(lambda: signal.signal(signal.SIGINT, inherited))

    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    closed = []

    def start(ends):
        def local_cluster(workers=None):
            assert os.environ[runner.STARTING_WORKER] == str(os.getpid())  # for the workers it starts
            os.kill(os.getpid(), signal.SIGINT)  # the Ctrl-C, held: nothing raised here
            time.sleep(0.05)
            if ends == "raises":  # a worker the Ctrl-C hit before it ignored it
                raise RuntimeError("Nanny failed to start.")
            return "client"
        return local_cluster

    monkeypatch.setattr(runner, "close_local_cluster", lambda client, interrupted=False: closed.append(client))
    for ends in ("started", "raises"):
        monkeypatch.setattr(runner, "local_cluster", start(ends))
        with pytest.raises(KeyboardInterrupt):
            run_sweep(sweep, tmp_path / f"{ends}.nc", local=True, quiet=True)
        assert runner.STARTING_WORKER not in os.environ and not list(tmp_path.glob("*.parts"))
    assert closed == ["client"]  # the cluster that started is closed; the failed start left none
    # a process that a warpfric process starts with the variable naming it ignores Ctrl-C once it has
    # imported warpfric; any other process keeps Python's handler
    code = ("import signal, warpfric; print(signal.getsignal(signal.SIGINT) is signal.SIG_IGN "
            "and signal.getsignal(signal.SIGTERM) is signal.SIG_IGN)")
    for value, ignored in ((str(os.getpid()), "True"), ("1", "False")):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                             env={**os.environ, runner.STARTING_WORKER: value})
        assert out.stdout.strip() == ignored, (value, out.stderr)


def test_a_sweeps_cluster_leaves_dasks_default_scheduler_to_the_caller(reference, tmp_path):
    """The sweep's own client (a local cluster, or one connected to --scheduler) submits its chunks
    by name and is not made dask's default: while it is open and after, the caller's dask work runs
    on the scheduler it had (as default, distributed's Client sets dask's 'scheduler' to itself, and
    one whose close is cut short leaves that setting behind: the caller's next xarray compute then
    fails with 'Requested dask.distributed scheduler but no Client active'). A sweep on a client
    that is not the default runs (its chunks are gathered on that client's loop)."""
    import dask
    import dask.array as da

    import warpfric.runner as runner

    before = dask.config.get("scheduler", None)
    client = runner.local_cluster(workers=1)
    try:
        assert dask.config.get("scheduler", None) == before
        assert float(da.ones(4, chunks=2).sum().compute()) == 4.0  # the caller's own scheduler
        sweep, single = reference
        report = run_sweep(sweep, tmp_path / "own.nc", client=client, quiet=True)
        assert report.failed_members == 0
        _assert_same_outputs(single, tmp_path / "own.nc")
    finally:
        runner.close_local_cluster(client)
    assert dask.config.get("scheduler", None) == before
