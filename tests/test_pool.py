"""All cores of a CPU: an ensemble split over worker processes equals one process's bit for bit
(records, member_offset, fronts, a swept length included), the split is chosen where it pays, and
the workers neither run the user's script again nor outlive a Ctrl-C."""

import os
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

import warpfric as wf
from warpfric import pool
from warpfric.progress import SizeWarning
from warpfric import progress
from test_progress import FakeTerminal, drawn
from conftest import TINY_SWEEP, run_cli

TIMING = {"wall_time_s", "kernel_build_time_s", "workers", "worker_chunks", "worker_start_time_s"}


def assert_same(one, split):
    assert list(one.data_vars) == list(split.data_vars) and set(one.coords) == set(split.coords)
    for name, var in one.variables.items():
        other = split[name].variable
        assert var.dims == other.dims and var.dtype == other.dtype, name
        np.testing.assert_array_equal(var.values, other.values, err_msg=name)  # NaN == NaN here, bit for bit
        assert str(var.attrs) == str(other.attrs), name
    assert {k: v for k, v in one.attrs.items() if k not in TIMING} == \
        {k: v for k, v in split.attrs.items() if k not in TIMING}


def test_split_equals_one_process_bit_for_bit():
    """13 members in 3 chunks of 4, 4 and 5 on 2 workers: fronts (two passes) and the stress gate,
    recorded members in an order of their own, a member offset, and a length that is one value in
    the first chunks (x in m there) but two in the ensemble (x / length). No member comes near the
    straggler limit (max(2000, 10 x the median) attempts), the one output that depends on peers."""
    n = 13
    members = {"eccentricity": np.linspace(-0.2, 0.2, n), "normal_force": np.geomspace(300.0, 3000.0, n),
               "length": np.where(np.arange(n) < 10, 0.1, 0.12)}
    kw = dict(solver=wf.Solver(nodes=21, rtol=1e-5), fronts=wf.Fronts(), device="cpu", progress=False,
              record=wf.Record.window(20.2, 20.3, 11, members=(12, 0, 5)), member_offset=3)
    one = wf.simulate(members, workers=1, **kw)
    split = wf.simulate(members, workers=2, **kw)
    assert split.attrs["workers"] == 2 and split.attrs["worker_chunks"] == 3 and "workers" not in one.attrs
    assert (one.status.values == 0).all() and (one.steps_accepted + one.steps_rejected).values.max() < 2000
    assert one.x.attrs["units"] == "1" and list(split.recorded_member.values) == [15, 3, 8]
    assert set(split.attrs["varying_parameters"].split()) == {"length", "normal_force", "eccentricity"}
    assert_same(one, split)
    again = wf.simulate(members, workers=2, **kw)  # the pool is kept: no start the second time
    assert again.attrs["worker_start_time_s"] == 0.0
    assert_same(one, again)
    # the call that creates the pool reports its start; a worker whose "ready" was not read in that
    # call (its chunks done first: seen on a 16-core host) tells it in a later call, which started
    # nothing
    pool.shutdown()
    small = dict(workers=2, solver=wf.Solver(nodes=11), fronts=None, device="cpu", progress=False)
    first = wf.simulate({"eccentricity": [0.0, 0.1]}, **small)
    assert first.attrs["workers"] == 2 and first.attrs["worker_start_time_s"] > 0.0
    pool._POOL.inbox.put(("ready", 0))
    late = wf.simulate({"eccentricity": [0.0, 0.1]}, **small)
    assert late.attrs["workers"] == 2 and late.attrs["worker_start_time_s"] == 0.0


def test_failed_members_of_a_split_run_are_told_once_for_the_ensemble(recwarn):
    """Members that run out of steps on 2 workers: one warning that counts all of them (not one per
    worker chunk), with what to change."""
    members = {"eccentricity": np.linspace(-0.2, 0.2, 9)}
    ds = wf.simulate(members, solver=wf.Solver(nodes=11, max_steps=30), fronts=None, device="cpu", progress=False,
                     workers=2)
    assert ds.attrs["worker_chunks"] > 1 and (ds.status.values == 1).all()
    said = [str(w.message) for w in recwarn if "did not end ok" in str(w.message)]
    assert said == ["members that did not end ok have NaN mu_s and fronts: 9 of 9 members: 9 max_steps_reached "
                    "(Solver(max_steps=...) allows more than 30 attempted steps); their numbers: "
                    "ds.member[ds.status != 0] (docs/model.md, \"Statuses\")"]


def test_velocity_settings_without_the_velocity_event_are_told_once(recwarn):
    """Fronts(threshold=...) with the contact event (the default) changed nothing without a word; now
    one warning for the ensemble, also on 2 workers and with the grid check's second run; none
    where the velocity event is asked for."""
    members = {"eccentricity": np.linspace(-0.2, 0.2, 4)}
    solver = wf.Solver(nodes=11, rtol=1e-4)
    ds = wf.simulate(members, solver=solver, fronts=wf.Fronts(threshold=0.5, direction="absolute", grid_check=True),
                     device="cpu", progress=False, workers=2)
    assert ds.attrs["worker_chunks"] > 1
    said = [str(w.message) for w in recwarn if "velocity event only" in str(w.message)]
    assert said == ["fronts settings of the velocity event only, unused without it: threshold = 0.5, direction = "
                    "'absolute' (event='contact'); they set the velocity front's arrival level and sign: "
                    "Fronts(event=('contact', 'velocity')) reads both fronts"], said
    recwarn.clear()
    wf.simulate(members, solver=solver, fronts=wf.Fronts(event=("contact", "velocity"), threshold=0.5),
                device="cpu", progress=False, workers=1)
    assert not [w for w in recwarn if "velocity event only" in str(w.message)]


def test_workers_default_splits_where_it_pays(monkeypatch):
    monkeypatch.setattr(pool, "cpu_cores", lambda: 4)
    small, big = wf.Solver(nodes=21), wf.Solver(nodes=100)
    # one core's time from progress.cpu_seconds (this project's CPU: 0.26 us per node and attempt)
    assert pool.plan(None, "cpu", 12, small, wf.Fronts(), None) == 1  # ~0.02 s on one core: not worth a start
    assert pool.plan(None, "cpu", 400, big, wf.Fronts(), None) == 4  # ~3.2 s: all cores
    assert pool.plan(None, "cpu", 100, big, wf.Fronts(), None) == 1  # ~0.8 s: less than new workers cost here
    assert pool.plan(None, "cpu", 130, big, wf.Fronts(event="velocity"), None) == 4  # its two passes: ~2.7 s
    assert pool.plan(None, "cpu", 120, big, wf.Fronts(event="velocity"), None) == 1  # ~2.5 s, just below
    assert pool.plan(None, "cpu", 340, big, wf.Fronts(), None) == 4  # ~2.7 s
    assert pool.plan(None, "cpu", 300, big, wf.Fronts(), None) == 1  # ~2.4 s
    # without the yield gate a member takes ~0.42 of the attempts: 300 members are ~1.0 s, not split
    # (260 members split took 1.93 s against 1.53 s in one process: single runs on this CPU)
    assert pool.plan(None, "cpu", 300, big, wf.Fronts(), None, wf.Model(relaxation_gate="none")) == 1
    assert pool.plan(None, "cpu", 800, big, wf.Fronts(), None, wf.Model(relaxation_gate="none")) == 4
    assert pool.plan(None, "cpu", 3, wf.Solver(nodes=2000), None, None) == 3  # never more workers than members
    assert pool.plan(None, "cuda:0", 400, big, wf.Fronts(), None) == 1
    assert pool.plan(1, "cpu", 400, big, wf.Fronts(), None) == 1
    assert pool.plan(3, "cpu", 400, big, wf.Fronts(), None) == 3
    seen = []
    thread = threading.Thread(target=lambda: seen.append(pool.plan(None, "cpu", 400, big, wf.Fronts(), None)))
    thread.start()
    thread.join()
    assert seen == [1]  # a thread (e.g. a Dask worker's) runs in its process
    for bad in (0, -1, True, 2.0, "4"):
        with pytest.raises(ValueError, match="workers"):
            pool.plan(bad, "cpu", 400, big, None, None)
    with pytest.raises(ValueError, match="workers = 2 is invalid with device 'cuda:0'"):
        pool.plan(2, "cuda:0", 400, big, None, None)
    with pytest.raises(ValueError, match="record setting 'members' contains 400"):
        pool.plan(2, "cpu", 400, big, None, wf.Record.window(20.0, 20.1, 3, members=(400,)))
    with pytest.warns(SizeWarning):
        pool.plan(None, "cpu", 1, wf.Solver(nodes=6000), None, None)


def test_chunks_are_contiguous_and_balanced():
    assert pool.chunk_bounds(13, 2) == [(0, 4), (4, 8), (8, 13)]
    assert pool.chunk_bounds(400, 2) == [(k * 50, k * 50 + 50) for k in range(8)]
    assert pool.chunk_bounds(3, 4) == [(0, 1), (1, 2), (2, 3)]


def test_workers_do_not_run_the_users_script_again(tmp_path):
    """A script without ``if __name__ == "__main__":`` (spawn would run its top level in each worker)."""
    script = tmp_path / "no_guard.py"
    script.write_text(textwrap.dedent("""
        import warpfric as wf
        print("top level", flush=True)
        ds = wf.simulate({"eccentricity": [0.0, 0.1, 0.2]}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                         device="cpu", progress=False, workers=2)
        print("members", ds.sizes["member"], ds.attrs["workers"], flush=True)
    """))
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines() == ["top level", "members 3 2"]


def _running(pid: int) -> bool:
    """The process lives and is no zombie (a container's first process may not reap orphans)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            return not any(line.startswith("State:") and "Z" in line.split()[1] for line in status)
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_end_when_their_parent_is_killed(tmp_path):
    """A parent killed with SIGKILL (or SIGTERM, or a batch system's time limit) cannot stop its
    workers: they went on computing and held their memory, re-parented, until killed by hand."""
    import signal

    script = tmp_path / "parent.py"
    script.write_text(textwrap.dedent("""
        import time
        import warpfric as wf
        from warpfric import pool
        wf.simulate({"eccentricity": [0.0, 0.1, 0.2]}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                    device="cpu", progress=False, workers=2)
        print(*pool._POOL.executor._processes, flush=True)  # the kept pool's worker pids
        time.sleep(120)
    """))
    parent = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONWARNINGS": "ignore"})
    try:
        workers = [int(pid) for pid in parent.stdout.readline().split()]
        assert len(workers) == 2 and all(_running(pid) for pid in workers), workers
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=30)
        deadline = time.monotonic() + 10 * pool.PARENT_POLL_S + 5
        while any(_running(pid) for pid in workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(_running(pid) for pid in workers), [pid for pid in workers if _running(pid)]
    finally:
        parent.kill()
        parent.stdout.close()


def test_the_kept_pool_is_stopped_by_the_exit_handlers(tmp_path):
    """The worker pool kept between runs is stopped by an exit handler (atexit) before the modules
    are torn down (its executor's clean-up then printed "Exception ignored ... 'NoneType' object
    has no attribute 'util'" at the exit of some test sessions): a handler registered before
    warpfric's, so run after it, finds the pool gone."""
    script = tmp_path / "exit.py"
    script.write_text(textwrap.dedent("""
        import atexit
        import sys

        def report():
            print("pool stopped at exit:", sys.modules["warpfric.pool"]._POOL is None, flush=True)

        atexit.register(report)  # handlers run last-registered first: this one after warpfric's
        import warpfric as wf
        from warpfric import pool
        wf.simulate({"eccentricity": [0.0, 0.1, 0.2]}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                    device="cpu", progress=False, workers=2)
        print("workers alive:", sum(w.is_alive() for w in pool._POOL.executor._processes.values()), flush=True)
    """))
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert res.returncode == 0, res.stderr
    assert res.stdout.splitlines() == ["workers alive: 2", "pool stopped at exit: True"], res.stdout
    assert "Exception ignored" not in res.stderr, res.stderr


def test_ctrl_c_stops_the_workers_at_once(monkeypatch):
    members = {"eccentricity": np.linspace(-0.2, 0.2, 4)}
    kw = dict(solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None, device="cpu", progress=False)
    wf.simulate(members, workers=2, **kw)
    processes = list(pool._POOL.executor._processes.values())
    assert len(processes) == 2 and all(p.is_alive() for p in processes)

    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(pool, "_read_inbox", interrupt)
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        wf.simulate(members, workers=2, **kw)
    assert pool._POOL is None and time.monotonic() - t0 < 5

    def exists(pid):  # is_alive can be stale here: the executor's thread may have reaped the process
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True

    assert not any(exists(p.pid) for p in processes)


def test_a_killed_worker_stops_the_run_with_a_message_and_no_hang(monkeypatch):
    """A worker killed during a run (the out-of-memory killer, kill -9) gave a bare BrokenProcessPool
    traceback, or, where it died sending its result, a run that hung, and a process that did not
    end even on SIGTERM: the executor's thread waited for the rest of the half-sent result, and the
    interpreter joins it at exit. Now the run stops with WorkerDied naming the worker and its signal,
    the other worker and the executor's thread end, and the next run starts a new pool."""
    import signal
    import struct

    pool.shutdown()
    members = {"eccentricity": np.linspace(-0.2, 0.2, 200)}
    kw = dict(solver=wf.Solver(nodes=60, rtol=1e-6), fronts=None, device="cpu", progress=False)
    real_read, calls, seen = pool._read_inbox, [], {}

    def read_then_kill(kept, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:  # the run is going: a half-sent result, then one worker killed
            seen["processes"] = list(kept.executor._processes.values())
            seen["thread"] = kept.executor._executor_manager_thread
            writer = kept.executor._result_queue._writer
            os.write(writer.fileno(), struct.pack("!i", 1000) + b"x" * 10)  # 10 of 1,000 bytes
            victim = seen["processes"][0]
            os.kill(victim.pid, signal.SIGKILL)
            victim.join(10)
        return real_read(kept, *args, **kwargs)

    monkeypatch.setattr(pool, "_read_inbox", read_then_kill)
    t0 = time.monotonic()
    with pytest.raises(pool.WorkerDied, match=r"a CPU worker process ended abruptly \(pid \d+, killed by SIGKILL\).*"
                                              r"out-of-memory killer.*workers=1"):
        wf.simulate(members, workers=2, **kw)
    assert time.monotonic() - t0 < 30 and pool._POOL is None
    seen["thread"].join(10)
    assert not seen["thread"].is_alive()  # it waited in recv for 990 more bytes: the exit would hang
    assert all(p.exitcode is not None for p in seen["processes"])
    monkeypatch.setattr(pool, "_read_inbox", real_read)
    ds = wf.simulate({"eccentricity": [0.0, 0.1]}, workers=2, **{**kw, "solver": wf.Solver(nodes=11)})
    assert ds.attrs["workers"] == 2 and (ds.status.values == 0).all()


def test_a_dead_workers_message_says_what_its_end_points_to():
    """The out-of-memory killer was blamed for every end, a worker that failed on its own (exit code 0)
    and a crash (SIGSEGV) too, and the executor's own SIGTERM to the others was listed as a death."""
    oom = pool._worker_died_text([(11, -9), (12, -15)])
    assert oom.startswith("a CPU worker process ended abruptly (pid 11, killed by SIGKILL) while") and "pid 12" not in oom
    assert "out-of-memory killer" in oom and "workers=1" in oom
    crash = pool._worker_died_text([(11, -11), (12, -11)])
    assert crash.startswith("2 CPU worker processes ended abruptly (pid 11, killed by SIGSEGV; pid 12, killed by "
                            "SIGSEGV)") and "a crash" in crash and "out-of-memory" not in crash
    own = pool._worker_died_text([(11, 0)])
    assert "(pid 11, exit code 0)" in own and "it ended on its own" in own and "out-of-memory" not in own


def test_a_worker_killed_between_runs_is_replaced():
    """A kept pool whose worker was killed while idle made the next run fail; it starts a new pool."""
    import signal

    kw = dict(solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None, device="cpu", progress=False)
    wf.simulate({"eccentricity": [0.0, 0.1]}, workers=2, **kw)
    victim = list(pool._POOL.executor._processes.values())[0]
    os.kill(victim.pid, signal.SIGKILL)
    victim.join(10)
    ds = wf.simulate({"eccentricity": [0.0, 0.1]}, workers=2, **kw)
    assert ds.attrs["workers"] == 2 and (ds.status.values == 0).all()


# a split CPU run's warnings and progress line
def test_a_split_runs_warnings_come_once_from_the_parent():
    """Each worker's warning is raised once, in the parent, at simulate()'s caller (it printed once per
    worker process, with pool.py's source line)."""
    with pytest.warns(UserWarning) as caught:
        wf.simulate({"eccentricity": [0.0, 0.1, 0.2, 0.3]}, model=wf.Model(relaxation_gate="none"),
                    solver=wf.Solver(nodes=11), device="cpu", workers=2, progress=False)
    contact = [w for w in caught if str(w.message).startswith("fronts event 'contact'")]
    assert len(contact) == 1 and contact[0].filename == __file__


def test_a_split_sweep_on_the_command_line_warns_once(tmp_path, capsys):
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY_SWEEP.replace("fronts = false", "[model]\nrelaxation_gate = 'none'"))
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--cpu-workers", 2, "--device", "cpu",
                           "--quiet")
    warned = [line for line in err if line.startswith("warpfric: warning:") or "Warning:" in line]
    assert code == 0 and len(warned) == 1 and warned[0].startswith("warpfric: warning: fronts event 'contact'"), err


def test_the_line_of_a_split_run_counts_members_only(monkeypatch):
    """A sweep's chunk says 'chunk 1/4'; the worker processes' share of it is not another 'chunks' count."""
    terminal = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.setattr(progress.Line, "interval", 0.0)  # every update redrawn
    monkeypatch.setenv("COLUMNS", "120")  # the whole line
    wf.simulate({"eccentricity": [-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.25]}, solver=wf.Solver(nodes=61),
                device="cpu", workers=2, progress="chunk 1/4 (members 0..7)")
    frames = drawn(terminal)
    assert len(frames) >= 3 and not [text for _, text in frames if "chunks" in text], frames



def test_a_workers_member_blocks_report_to_the_parents_line(capfd):
    """A worker's chunk of more than CPU_MEMBER_BLOCK members runs in member blocks (simulate's CPU
    path), whose progress goes to the parent, which draws the ensemble's one line: each worker drew a
    line of its own over the parent's, or outside a terminal a summary line a chunk."""
    n = 8 * 33  # 8 chunks on 2 workers (pool.CHUNKS_PER_WORKER), each above a block of 32
    assert min(b - a for a, b in pool.chunk_bounds(n, 2)) > sys.modules["warpfric.simulate"].CPU_MEMBER_BLOCK
    pool.shutdown()  # workers started here write to this test's captured stderr
    wf.simulate({"eccentricity": np.linspace(-0.3, 0.3, n)}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                device="cpu", workers=2, progress=True)
    lines = [line for line in capfd.readouterr().err.splitlines() if line.startswith("warpfric")]
    assert len(lines) == 1 and lines[0].startswith(f"warpfric: {n} members in ") and lines[0].endswith(", 2 workers"), lines


def test_member_blocks_report_their_fraction_of_the_whole_chunk(monkeypatch):
    """What a worker's member blocks send its sink (the parent's line for the chunk): fractions of the
    whole chunk that never go back, members done counted over the blocks, and the final report once,
    at the end (each block's own fraction sent as the chunk's made it reach 100 % after its first)."""
    reports = []
    monkeypatch.setattr(progress, "SINK", lambda fraction, done, final: reports.append((fraction, done, final)))
    n = 70  # blocks of 32, 32 and 6 (simulate.CPU_MEMBER_BLOCK)
    wf.simulate({"eccentricity": np.linspace(-0.2, 0.2, n)}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                device="cpu", workers=1, progress=True)
    fractions = [fraction for fraction, _, _ in reports]
    assert all(b >= a for a, b in zip(fractions, fractions[1:])) and max(fractions) == 1.0
    assert [final for _, _, final in reports].count(True) == 1 and reports[-1] == (1.0, n, True)
    done = [members for _, members, _ in reports]
    assert all(b >= a for a, b in zip(done, done[1:])) and {32, 64, n} <= set(done)


def test_a_split_run_warns_of_late_recording_times_once_for_the_ensemble():
    """Each worker piece would name only its own recorded members: the parent warns once, with every
    recorded member whose run ended before some recording times, in the order recorded."""
    times = tuple(np.linspace(20.1, 20.4, 7))
    with pytest.warns(UserWarning) as caught:
        ds = wf.simulate({"eccentricity": [-0.3, -0.1, 0.1, 0.3]}, solver=wf.Solver(nodes=11), device="cpu",
                         workers=2, progress=False, record=wf.Record(members=(3, 0), times=times))
    late = [str(w.message) for w in caught if str(w.message).startswith("Record:")]
    assert len(late) == 1, late
    ends = ds.final_time.values
    named = [f"member {m}: ended at {ends[m]:.6g} s (the automatic end), {int((np.asarray(times) > ends[m]).sum())} "
             "of 7 times later"
             for m in (3, 0)]
    assert all(0 < int((np.asarray(times) > ends[m]).sum()) for m in (3, 0))
    assert late[0].index(named[0]) < late[0].index(named[1]), late[0]


def test_more_workers_than_cores_are_started_with_a_warning(monkeypatch):
    """--cpu-workers 3 on 2 cores started 3 processes without a word: allowed, since asked for, but
    said to buy nothing; as many as the cores, or fewer, say nothing."""
    import warnings

    monkeypatch.setattr(pool, "cpu_cores", lambda: 2)
    solver = wf.Solver(nodes=20)
    with pytest.warns(UserWarning, match=r"workers = 3 on 2 CPU cores: the processes share the cores and run no "
                                         r"faster than 2 would"):
        assert pool.plan(3, "cpu", 8, solver, None, None) == 3
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert pool.plan(2, "cpu", 8, solver, None, None) == 2
        assert pool.plan(3, "cpu", 2, solver, None, None) == 2  # no more workers than members


def test_member_blocks_on_the_cpu_equal_one_launch_bit_for_bit(monkeypatch, capsys):
    """On the CPU the thread kernel runs the members in blocks of CPU_MEMBER_BLOCK (32), one after the
    other: arrays laid out member fastest put a member's nodes a whole ensemble apart, and 2,048
    members at N = 41 took 20.6 s in one launch against 8.5 s in blocks (docs/performance.md, "CPU").
    70 members (blocks of 32, 32, 6): fronts, a recording of members in three blocks in an order of
    their own, a member offset and the grid check give one launch's outputs bit for bit, and one
    progress line for the ensemble."""
    simulate_module = sys.modules["warpfric.simulate"]  # (warpfric.simulate is also the function)
    n = 70
    members = {"eccentricity": np.linspace(-0.2, 0.2, n), "normal_force": np.geomspace(300.0, 3000.0, n)}
    kw = dict(solver=wf.Solver(nodes=21, rtol=1e-4), fronts=wf.Fronts(grid_check=True), device="cpu", workers=1,
              record=wf.Record.window(20.2, 20.26, 5, members=(69, 0, 40)), member_offset=7)
    assert simulate_module.CPU_MEMBER_BLOCK == 32
    blocked = wf.simulate(members, progress="blocks", **kw)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("warpfric blocks: 70 members"), err  # one line, not one a block
    monkeypatch.setattr(simulate_module, "CPU_MEMBER_BLOCK", 10**9)
    one = wf.simulate(members, progress=False, **kw)
    assert (one.status.values == 0).all() and list(blocked.recorded_member.values) == [76, 7, 47]
    assert_same(one, blocked)
