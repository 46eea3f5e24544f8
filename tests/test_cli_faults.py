"""Every fault before or during a run ends in one line, its own exit code and nothing half written
(issue 22, part 1): a folder that cannot be written (exit 2, checked before anything runs), a full
disk (exit 3; no temporary file stays, a sweep's finished chunks do), a second run on the same
output (exit 4, OUT.nc.lock), an unreachable scheduler (exit 2, no parts folder), Ctrl-C (130),
and the temporary files of a killed run (removed by the next run on that output)."""

import errno
import importlib
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import DEVICE, TINY_SWEEP, run, run_cli

from warpfric.io import open_ensemble

SIMULATE_MODULE = importlib.import_module("warpfric.simulate")
IO_MODULE = importlib.import_module("warpfric.io")


def _error_line(err, *words):
    """The last stderr line is the one error line, and the only line starting 'warpfric: error:'."""
    errors = [line for line in err if line.startswith("warpfric: error:")]
    assert len(errors) == 1 and err[-1] == errors[0], err
    for word in words:
        assert word in errors[0], (word, errors[0])


def _files(folder: Path) -> list:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.fixture
def sweep(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(TINY_SWEEP)
    return path


@pytest.fixture
def no_simulation(monkeypatch):
    """The faults checked before a run: any simulation (the kernels' warm-up included) fails the test."""
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate() ran although the output cannot be written")

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", forbidden)


def _deny_writes_in(monkeypatch, folder: Path, error=errno.EACCES):
    """os.open of a new file in ``folder`` fails as it does in a folder without write permission
    (we run as root here, which chmod does not stop); other paths open as usual."""
    real = os.open
    folder = folder.resolve()

    def guarded(path, flags, *args, **kwargs):
        if flags & os.O_CREAT and Path(path).resolve().parent == folder:
            raise OSError(error, os.strerror(error), str(path))
        return real(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", guarded)


@pytest.mark.parametrize("kind", ["default scene", "sweep"])
def test_an_unwritable_folder_exits_2_before_anything_runs(tmp_path, sweep, capsys, monkeypatch, no_simulation, kind):
    folder = tmp_path / "ro"
    folder.mkdir()
    _deny_writes_in(monkeypatch, folder)
    out = folder / "out.nc"
    args = (["run", "--nodes", 11] if kind == "default scene" else ["run", sweep]) + ["-o", out, "--device", DEVICE]
    code, stdout, err = run_cli(capsys, *args)
    assert code == 2 and stdout == []
    assert err == [f"warpfric: error: output '{out}': cannot write in folder '{folder}' (permission denied); "
                   "choose another -o or make the folder writable"]
    assert _files(folder) == []  # no parts folder, no lock, no temporary file


def _mount_tmpfs(folder: Path, options: str) -> bool:
    """A small tmpfs at ``folder`` where this process may mount one (root with CAP_SYS_ADMIN)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    folder.mkdir()
    return subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                          capture_output=True).returncode == 0


def test_a_really_unwritable_folder_exits_2(tmp_path, sweep, capsys, no_simulation):
    """The same with a folder the file system refuses: read-only tmpfs as root, chmod 555 otherwise."""
    folder = tmp_path / "ro"
    if os.geteuid() == 0:
        if not _mount_tmpfs(folder, "size=64k,ro"):
            pytest.skip("root without mount: no real read-only folder here (the os.open test covers it)")
        reason = "read-only file system"
    else:
        folder.mkdir()
        folder.chmod(0o555)
        reason = "permission denied"
    try:
        code, _, err = run_cli(capsys, "run", sweep, "-o", folder / "s.nc", "--device", DEVICE)
        assert code == 2
        _error_line(err, f"cannot write in folder '{folder}' ({reason})")
        assert _files(folder) == []
    finally:
        if os.geteuid() == 0:
            subprocess.run(["umount", "-l", str(folder)], check=False)  # -l: a handle the failed HDF5 write left
        else:
            folder.chmod(0o755)


def test_a_folder_without_write_permission_as_a_normal_user():
    """The issue's case (mkdir ro && chmod 555 ro && warpfric run -o ro/out.nc) as a normal user: as
    root, the command runs as user nobody (setpriv); exit 2, one line, nothing written."""
    import tempfile

    command = [sys.executable, "-m", "warpfric", "run", "--nodes", "11", "--device", "cpu"]
    if os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("root without setpriv: no normal user to run as")
        command = ["setpriv", "--reuid", "65534", "--regid", "65534", "--clear-groups", *command]
    home = Path(tempfile.mkdtemp(prefix="warpfric-ro-"))  # not pytest's tmp_path: nobody cannot enter it
    try:
        home.chmod(0o755)
        folder = home / "ro"
        folder.mkdir()
        folder.chmod(0o555)
        if os.geteuid() == 0 and subprocess.run(["setpriv", "--reuid", "65534", "--regid", "65534", "--clear-groups",
                                                 sys.executable, "-c", "import warpfric"], capture_output=True,
                                                cwd=home).returncode != 0:
            pytest.skip("user nobody cannot import warpfric from this environment")
        env = {**os.environ, "HOME": str(home), "PYTHONWARNINGS": "ignore"}
        res = subprocess.run([*command, "-o", str(folder / "out.nc")], capture_output=True, text=True, timeout=120,
                             env=env, cwd=home)
        errors = [line for line in res.stderr.splitlines() if line.startswith("warpfric:")]
        assert res.returncode == 2 and errors == [
            f"warpfric: error: output '{folder / 'out.nc'}': cannot write in folder '{folder}' (permission denied); "
            "choose another -o or make the folder writable"], res.stderr
        assert res.stdout == "" and _files(folder) == []
    finally:
        shutil.rmtree(home, ignore_errors=True)


def _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, interrupt_at=2, *options):
    """Run the sweep in chunks of one member, Ctrl-C in chunk ``interrupt_at`` (1-based); ``options``
    are further command-line options."""
    real = SIMULATE_MODULE.simulate
    calls = []

    def interrupted(*args, **kwargs):
        if "member_offset" in kwargs:
            calls.append(kwargs["member_offset"])
            if len(calls) == interrupt_at:
                raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", interrupted)
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, "--quiet", *options)
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", real)
    return code, err


def test_an_unwritable_parts_folder_stops_resume_before_it_runs(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    code, err = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out)
    assert code == 130
    parts = tmp_path / "s.nc.parts"
    before = _files(parts)
    _deny_writes_in(monkeypatch, parts)
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", lambda *a, **k: pytest.fail("ran"))
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 2
    _error_line(err, f"cannot write in folder '{parts}' (permission denied)")
    assert _files(parts) == before and not (tmp_path / "s.nc.lock").exists()


def _full_disk(monkeypatch, fail_on):
    """Dataset.to_netcdf fails as on a full disk (HDF5's ENOSPC is netCDF's 'NetCDF: HDF error') for
    the files whose name starts with ``fail_on``, after writing part of the file."""
    real, real_free = xr.Dataset.to_netcdf, IO_MODULE.free_bytes
    full = []

    def to_netcdf(self, path=None, *args, **kwargs):
        if path is not None and Path(path).name.startswith(fail_on):
            Path(path).write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(1000))  # the part written before the disk filled
            full.append(path)
            raise RuntimeError("NetCDF: HDF error")
        return real(self, path, *args, **kwargs)

    monkeypatch.setattr(xr.Dataset, "to_netcdf", to_netcdf)
    monkeypatch.setattr(IO_MODULE, "free_bytes", lambda folder: 0 if full else real_free(folder))


def test_a_full_disk_in_a_chunk_exits_3_and_keeps_the_finished_chunks(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    _full_disk(monkeypatch, "chunk-000001.nc")
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, "--quiet")
    assert code == 3
    _error_line(err, "disk full while writing", "chunk-000001.nc", "0 bytes free", "its partial file removed",
                "the 1 finished chunk is kept", "free some space, then", "--resume")
    assert _files(tmp_path) == ["s.nc.parts", "s.nc.parts/chunk-000000.nc", "s.nc.parts/manifest.json",
                                "s.nc.parts/sweep.toml", "s.toml"]
    monkeypatch.undo()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert open_ensemble(out).member.values.tolist() == [0, 1, 2]
    assert _files(tmp_path) == ["s.nc", "s.toml"]


def test_ctrl_c_in_a_sweep_of_one_chunk_says_how_chunks_keep_results(tmp_path, sweep, capsys, monkeypatch):
    """Without --chunk a sweep is one chunk, and a Ctrl-C near its end kept nothing: the line says how a
    run keeps what finishes (its members were not named: 3 here)."""
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", interrupted)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--device", DEVICE, "--quiet")
    assert code == 130 and err[-1] == ("warpfric: interrupted; nothing was kept (the sweep ran as one chunk of 3 "
                                       "members: with --chunk N, or [run] chunk = N, each N members are kept once "
                                       "they finish, and --resume goes on from them)"), err
    assert _files(tmp_path) == ["s.toml"]


def test_a_full_disk_in_the_first_chunk_leaves_nothing(tmp_path, sweep, capsys, monkeypatch):
    _full_disk(monkeypatch, "chunk-000000.nc")
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--device", DEVICE, "--quiet")
    assert code == 3
    _error_line(err, "disk full", "nothing was kept")
    assert _files(tmp_path) == ["s.toml"]  # no parts folder blocks the next plain run


def test_a_full_disk_while_combining_keeps_every_chunk_for_resume(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    _full_disk(monkeypatch, "s.nc.")
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 2, "--device", DEVICE, "--quiet")
    assert code == 3
    _error_line(err, f"disk full while writing '{out}'", "the 2 finished chunks are kept")
    assert not list(tmp_path.rglob("*.tmp")) and not out.exists()
    monkeypatch.undo()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 0 and "0 of them to run" in err[-3] and "combining the 2 chunk files" in err[-2], err  # resume only combines
    assert _files(tmp_path) == ["s.nc", "s.toml"]


def test_a_full_disk_writing_the_default_scene_exits_3(tmp_path, capsys, monkeypatch):
    _full_disk(monkeypatch, "d.nc")
    code, stdout, err = run_cli(capsys, "run", "--nodes", 11, "-o", tmp_path / "d.nc", "--device", DEVICE, "--quiet")
    assert code == 3 and stdout[0].startswith("scene:")  # the run itself was printed
    assert err == [f"warpfric: error: disk full while writing '{tmp_path / 'd.nc'}' (0 bytes free; its partial "
                   "file removed)"]
    assert _files(tmp_path) == []


def test_an_io_error_that_is_not_a_full_disk_says_what_it_was(tmp_path, capsys, monkeypatch):
    _full_disk(monkeypatch, "d.nc")
    monkeypatch.setattr(IO_MODULE, "free_bytes", lambda folder: 10**12)  # plenty: another I/O error
    code, _, err = run_cli(capsys, "run", "--nodes", 11, "-o", tmp_path / "d.nc", "--device", DEVICE, "--quiet")
    assert code == 3
    _error_line(err, "could not write", "RuntimeError: NetCDF: HDF error", "its partial file removed")
    assert _files(tmp_path) == []


def test_a_file_system_without_a_size_is_not_a_full_disk(tmp_path, monkeypatch):
    """A pseudo file system (/proc, /sys) reports 0 bytes of 0 in all; a write that fails there is
    the write's own error, not "disk full" (it was, before free_bytes read the total); a real disk
    with 0 bytes free still is one."""
    from warpfric.io import free_bytes, write_failure

    monkeypatch.setattr(shutil, "disk_usage", lambda folder: shutil._ntuple_diskusage(0, 0, 0))
    assert free_bytes(tmp_path) is None
    err = write_failure(tmp_path / "x.nc", PermissionError(13, "Permission denied"), free_bytes(tmp_path))
    assert not err.disk_full and "could not write" in str(err) and "Permission denied" in str(err)
    monkeypatch.setattr(shutil, "disk_usage", lambda folder: shutil._ntuple_diskusage(10**9, 10**9, 0))
    assert free_bytes(tmp_path) == 0
    assert write_failure(tmp_path / "x.nc", RuntimeError("NetCDF: HDF error"), free_bytes(tmp_path)).disk_full


def test_too_little_free_space_is_refused_before_the_run(tmp_path, sweep, capsys, monkeypatch, no_simulation):
    monkeypatch.setattr(shutil, "disk_usage", lambda folder: shutil._ntuple_diskusage(10**9, 10**9 - 1000, 1000))
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--device", DEVICE)
    assert code == 3
    _error_line(err, "disk full: 1000 bytes free", "this run (3 members of 11 nodes", "needs about")
    assert _files(tmp_path) == ["s.toml"]


@pytest.mark.parametrize("body, words", [
    # the product was built as a Python list before any check: minutes of silence, then MemoryError
    ("[grid]\neccentricity = {start = -0.5, stop = 0.5, num = 100000}\n"
     "normal_force = {start = 500, stop = 5000, num = 100000}\n",
     ["the sweep has 10,000,000,000 members (100,000 (eccentricity) x 100,000 (normal_force))", "at most 2,130,706,432"]),
    ("[grid]\neccentricity = {start = -0.5, stop = 0.5, num = 40000}\n"
     "normal_force = {start = 500, stop = 5000, num = 40000}\n",
     ["the sweep's 1,600,000,000 members need about 51.5 GB to build and check their parameter values alone", "more than this machine's"]),
    ("[sample]\nn = 3000000000\neccentricity = {low = -0.2, high = 0.2}\n",
     ["[sample] n = 3000000000: expected an integer in [1, 2130706432]"]),
    # a range or a sample was built before the check (16 GB for 2e9 values: a numpy MemoryError)
    ("[sample]\nn = 2000000000\neccentricity = {low = -0.2, high = 0.2}\n",
     ["the sweep's 2,000,000,000 members need about 64.3 GB", "more than this machine's 25.0 GB"]),
    ("[grid]\nnormal_force = {start = 500, stop = 5000, num = 2000000000}\n",
     ["the sweep's 2,000,000,000 members need about 64.3 GB", "more than this machine's 25.0 GB"]),
    ("[grid]\neccentricity = [0.0]\n[record]\ntimes = {start = 20, stop = 21, num = 20000000000}\n",
     ["[record] times has 20,000,000,000 times; valid: at most 1,000,000"]),
    ("[grid]\neccentricity = [0.0]\n[record]\nstart = 20\nstop = 21\ncount = 100000000\n",
     ["record setting 'count' = 100000000 is invalid; valid: an integer in [2, 1,000,000]"]),
    # 53 GB for one member: the system killed the run and left its lock and parts folder
    ("[solver]\nnodes = 100000000\n[grid]\neccentricity = [0.0]\n",
     ["a chunk (1 member x 100000000 nodes at once) needs about 53.0 GB of memory", "more than this machine's"]),
])
def test_a_sweep_too_large_for_the_machine_is_refused_before_anything(tmp_path, capsys, monkeypatch, no_simulation,
                                                                      body, words):
    """Sizes beyond the member numbers or this machine's memory are one line, exit 2, nothing
    written (the machine's memory held at 25 GB so that the test does not depend on the host)."""
    from warpfric import progress

    monkeypatch.setattr(progress, "machine_memory_bytes", lambda: 25 * 10**9)
    monkeypatch.setattr("warpfric.sweep_file.machine_memory_bytes", lambda: 25 * 10**9)
    sweep = tmp_path / "big.toml"
    sweep.write_text(body)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "big.nc", "--device", "cpu")
    assert code == 2
    _error_line(err, *words)
    assert _files(tmp_path) == ["big.toml"]


@pytest.mark.parametrize("size, words", [
    ("300k", ["disk full: 29", "free in", "needs about 1.6 MiB"]),  # refused before the run
    ("1000k", ["disk full while writing", "finished chunk", "--resume"]),  # the run fills it
])
def test_a_really_full_disk(tmp_path, capsys, size, words):
    """A small tmpfs (where this process may mount one): too small for the estimate, the run is
    refused; big enough for the estimate (refused below half of it, 0.8 MiB) but not for the chunks
    and the combined file (1.27 MB: 3 x 274 + 445 kB, ~190 kB of netCDF headers a file), the write
    that does not fit ends the run; exit 3 either way, and no temporary file or lock stays."""
    folder = tmp_path / "small"
    if not _mount_tmpfs(folder, f"size={size}"):
        pytest.skip("no tmpfs can be mounted here (the injected ENOSPC tests cover it)")
    try:
        sweep = tmp_path / "big.toml"  # ~120 KB per chunk of 20 members
        sweep.write_text(TINY_SWEEP.replace("nodes = 11", "nodes = 101\nrtol = 1e-3").replace(
            "[-0.2, 0.0, 0.2]", "{start = -0.2, stop = 0.2, num = 60}"))
        code, _, err = run_cli(capsys, "run", sweep, "-o", folder / "big.nc", "--chunk", 20, "--device", DEVICE,
                             "--quiet")
        assert code == 3
        _error_line(err, *words)
        assert not list(folder.rglob("*.tmp")) and not (folder / "big.nc").exists()
        assert not (folder / "big.nc.lock").exists()
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)  # -l: a handle the failed HDF5 write left


def _hold_lock(out: Path, pid: int) -> Path:
    lock = out.with_name(out.name + ".lock")
    lock.write_text(json.dumps({"pid": pid, "host": socket.gethostname(), "started": "2026-01-01T00:00:00Z"}))
    return lock


def test_a_second_run_on_the_same_output_is_refused_with_exit_4(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = _hold_lock(out, other.pid)
        for args in (["run", sweep, "-o", out], ["run", "--nodes", 11, "-o", out]):
            monkeypatch.setattr(SIMULATE_MODULE, "simulate", lambda *a, **k: pytest.fail("ran"))
            code, _, err = run_cli(capsys, *args, "--device", DEVICE)
            assert code == 4
            assert err == [f"warpfric: error: output '{out}' is being written by another warpfric run (pid {other.pid} "
                           f"on {socket.gethostname()}, since 2026-01-01T00:00:00Z); wait for it to end, or remove "
                           f"'{lock}' if that run is gone"]
            assert _files(tmp_path) == ["s.nc.lock", "s.toml"]
    finally:
        other.kill()
        other.wait()
    monkeypatch.undo()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--device", DEVICE, "--quiet")  # its run is gone: stale
    assert code == 0, err
    assert _files(tmp_path) == ["s.nc", "s.toml"]  # the lock is removed at the end


def test_write_ensemble_into_a_missing_folder_says_so(tmp_path):
    """The folder is named as missing (HDF5 would report 'Permission denied', and no partial file
    existed), and nothing is created."""
    ds = run({"eccentricity": [0.0]}, nodes=11, fronts=None)
    with pytest.raises(IO_MODULE.OutputWriteError, match="folder '.*newdir.*' does not exist"):
        IO_MODULE.write_ensemble(ds, tmp_path / "newdir" / "sub" / "py.nc")
    assert _files(tmp_path) == []


def test_write_ensemble_from_python_respects_a_running_output(tmp_path):
    """write_ensemble beside a living run on the same output raises OutputBusy and writes nothing;
    this process's own lock and a dead run's lock do not stop it."""
    ds = run({"eccentricity": [0.0]}, nodes=11, fronts=None)
    out = tmp_path / "py.nc"
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = _hold_lock(out, other.pid)
        with pytest.raises(IO_MODULE.OutputBusy, match=f"being written by another warpfric run \\(pid {other.pid} "):
            IO_MODULE.write_ensemble(ds, out)
        assert _files(tmp_path) == ["py.nc.lock"]
    finally:
        other.kill()
        other.wait()
    IO_MODULE.write_ensemble(ds, out)  # its run is gone: stale
    assert open_ensemble(out).sizes["member"] == 1
    lock.unlink()
    with IO_MODULE.output_lock(out):
        IO_MODULE.write_ensemble(ds, out)  # this process's own lock


def test_two_runs_started_at_once_one_is_refused(tmp_path, sweep):
    """Two processes on one output: one writes it, the other exits 4 with one line."""
    slow = tmp_path / "slow.toml"
    slow.write_text(TINY_SWEEP.replace("[-0.2, 0.0, 0.2]", "[-0.3, -0.2, -0.1, 0.0, 0.1, 0.2]"))
    out = tmp_path / "slow.nc"
    cmd = [sys.executable, "-m", "warpfric", "run", str(slow), "-o", str(out), "--chunk", "1", "--device", DEVICE,
           "--quiet"]
    first = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True)
    lock = out.with_name("slow.nc.lock")
    while not lock.exists() and first.poll() is None:
        pass
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert first.wait(timeout=120) == 0
    errors = [line for line in second.stderr.splitlines() if line.startswith("warpfric: error:")]
    assert second.returncode == 4 and len(errors) == 1 and "being written by another warpfric run" in errors[0]
    assert open_ensemble(out).sizes["member"] == 6 and not lock.exists()


@pytest.mark.parametrize("sigint_ignored", [False, True])
def test_sigterm_keeps_the_finished_chunks_and_removes_the_lock(tmp_path, sigint_ignored):
    """`timeout`, `kill` or a batch system's time limit (SIGTERM) ended a sweep without a word and
    left its lock, which another host could not take over: now it ends as Ctrl-C does (exit 130,
    the finished chunks kept, the --resume command said, the lock removed), and --resume finishes;
    also where SIGINT is ignored (a job started with & from a script), where SIGTERM was ignored too."""
    import signal

    slow = tmp_path / "slow.toml"
    slow.write_text(TINY_SWEEP.replace("[-0.2, 0.0, 0.2]", "{start = -0.3, stop = 0.3, num = 40}"))
    out = tmp_path / "slow.nc"
    cmd = [sys.executable, "-m", "warpfric", "run", str(slow), "-o", str(out), "--chunk", "1", "--device", "cpu",
           "--quiet"]
    ignore = (lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint_ignored else None
    run = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, preexec_fn=ignore)
    first_chunk = tmp_path / "slow.nc.parts" / "chunk-000000.nc"
    deadline = time.monotonic() + 120
    while not first_chunk.exists() and run.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    run.send_signal(signal.SIGTERM)
    _, err = run.communicate(timeout=120)
    last = err.strip().splitlines()[-1]
    assert run.returncode == 130, err
    assert last.startswith("warpfric: interrupted; the ") and last.endswith("--resume --device cpu` goes on from them"), err
    assert not (tmp_path / "slow.nc.lock").exists() and first_chunk.exists() and not out.exists()
    assert subprocess.run(cmd[:-1] + ["--resume"], capture_output=True, timeout=300).returncode == 0
    assert open_ensemble(out).sizes["member"] == 40


@pytest.mark.parametrize("extra, run_table, words", [
    (["--workers", "2"], "", ["--workers = 2", "new local Dask cluster", "--cpu-workers"]),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "", ["--workers = 2", "does not start"]),
    ([], "[run]\nworkers = 2\n", ["[run] workers = 2", "new local Dask cluster", "scheduler = \"local\""]),
])
def test_workers_without_a_new_local_cluster_are_refused(tmp_path, capsys, no_simulation, extra, run_table, words):
    """--workers (or [run] workers) sizes a new local Dask cluster only: without one it was ignored
    without a word, and looks like --cpu-workers."""
    path = tmp_path / "w.toml"
    path.write_text(TINY_SWEEP + run_table)
    code, _out, err = run_cli(capsys, "run", path, "-o", tmp_path / "w.nc", "--device", "cpu", *extra)
    assert code == 2
    _error_line(err, *words)
    assert _files(tmp_path) == ["w.toml"]


def test_a_files_local_cluster_workers_stay_unused_on_another_scheduler(tmp_path, capsys, monkeypatch, no_simulation):
    """[run] scheduler = "local" with workers = 2, run on another scheduler (--scheduler): the
    file's workers belong to its own local cluster and are not refused; the run gets as far as
    connecting (nothing listens at the address here)."""
    distributed = pytest.importorskip("distributed")

    def unreachable(address, timeout=None, **kwargs):
        raise OSError(f"Timed out trying to connect to {address} after {timeout}")

    monkeypatch.setattr(distributed, "Client", unreachable)
    path = tmp_path / "w.toml"
    path.write_text(TINY_SWEEP + '[run]\nscheduler = "local"\nworkers = 2\n')
    code, _out, err = run_cli(capsys, "run", path, "-o", tmp_path / "w.nc", "--device", "cpu",
                              "--scheduler", "tcp://127.0.0.1:1")
    assert code == 2
    _error_line(err, "scheduler 'tcp://127.0.0.1:1': cannot connect")


def test_the_size_warning_of_a_chunked_sweep_is_the_whole_runs_and_said_once(tmp_path, sweep, capsys, monkeypatch):
    """Each chunk warned of its own size (a sweep too large as a whole but cut into usual chunks was
    not warned of at all); now the run warns once, with its own numbers. The usual size is made
    small here so that the tiny sweep (3 members x 11 nodes, chunks of 1) is beyond it."""
    from warpfric import progress

    monkeypatch.setattr(progress, "USUAL_NODES", 5)
    code, _out, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--chunk", 1, "--device", DEVICE,
                              "--quiet")
    assert code == 0, err
    warned = [line for line in err if "far beyond the usual size" in line]
    assert len(warned) == 1 and "3 members x 11 nodes" in warned[0], err


def test_an_address_that_is_no_dask_scheduler_is_one_line(tmp_path, sweep, capsys, monkeypatch):
    """A server that accepts and never answers as a scheduler (a dashboard's port, a web server) hung
    `warpfric run --scheduler` for good, past distributed's own 20 s timeout; one that answers with
    other bytes ended in a MemoryError traceback. One line, exit 2, nothing written."""
    import socket
    import threading

    import warpfric.runner as runner

    pytest.importorskip("distributed")
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    accepted = []
    threading.Thread(target=lambda: accepted.append(server.accept()), daemon=True).start()  # and silence
    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 2.0)
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    try:
        t0 = time.monotonic()
        code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--scheduler", address, "--chunk", 1)
        assert code == 2 and time.monotonic() - t0 < 30
        _error_line(err, f"scheduler '{address}': no Dask scheduler answered within 2 s")
        assert _files(tmp_path) == ["s.toml"]
    finally:
        server.close()
    import distributed

    def garbled(address, timeout=None, **kwargs):
        raise MemoryError("Unable to allocate 3.07 EiB")

    monkeypatch.setattr(distributed, "Client", garbled)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--scheduler", address, "--chunk", 1)
    assert code == 2
    _error_line(err, f"scheduler '{address}': not a Dask scheduler (MemoryError: Unable to allocate 3.07 EiB)")


def test_an_unreachable_scheduler_leaves_no_parts_folder(tmp_path, sweep, capsys, monkeypatch):
    distributed = pytest.importorskip("distributed")

    def unreachable(address, timeout=None, **kwargs):
        raise OSError(f"Timed out trying to connect to {address} after {timeout}")

    monkeypatch.setattr(distributed, "Client", unreachable)
    out = tmp_path / "s.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--scheduler", "tcp://127.0.0.1:1", "--chunk", 1)
    assert code == 2
    _error_line(err, "scheduler 'tcp://127.0.0.1:1': cannot connect")
    assert _files(tmp_path) == ["s.toml"]
    monkeypatch.undo()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--device", DEVICE, "--quiet")  # the next plain run
    assert code == 0, err


def test_resume_removes_what_a_killed_run_left(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    assert _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out)[0] == 130
    # a combine killed by SIGKILL, and a chunk's writer killed mid-file
    (tmp_path / "s.nc.12345.0badf00d.tmp").write_bytes(b"half a file")
    (tmp_path / "s.nc.parts" / "chunk-000001.nc.12345.deadbeef.tmp").write_bytes(b"half a chunk")
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 0, err
    assert "removed 2 temporary files that an interrupted run left" in "\n".join(err)
    assert _files(tmp_path) == ["s.nc", "s.toml"]


def test_ctrl_c_in_one_scene_says_nothing_of_chunks(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", interrupted)
    code, _, err = run_cli(capsys, "run", "--nodes", 11, "-o", tmp_path / "d.nc", "--device", DEVICE)
    assert code == 130 and err == ["warpfric: interrupted; nothing was written"]
    code, _, err = run_cli(capsys, "run", "--nodes", 11, "--device", DEVICE)
    assert code == 130 and err == ["warpfric: interrupted"]
    assert _files(tmp_path) == []


def test_ctrl_c_in_a_sweep_says_what_was_kept(tmp_path, sweep, capsys, monkeypatch):
    out = tmp_path / "s.nc"
    code, err = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, interrupt_at=1)
    assert code == 130 and err[-1] == "warpfric: interrupted; nothing was kept"
    assert _files(tmp_path) == ["s.toml"]
    code, err = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, interrupt_at=3)
    assert code == 130
    assert err[-1] == (f"warpfric: interrupted; the 2 finished chunks are kept in '{tmp_path / 's.nc.parts'}'; "
                       f"`warpfric run {sweep} -o {out} --resume --device {DEVICE}` goes on from them")
    assert not list(tmp_path.rglob("*.tmp")) and not (tmp_path / "s.nc.lock").exists()


def test_the_printed_resume_command_is_quoted_for_the_shell(tmp_path, capsys, monkeypatch):
    """Paths with a space printed `warpfric run my sweep.toml -o my results.nc --resume`, which a
    shell splits into other words; the words of the printed command, split as a shell does, finish
    the run into the file an uninterrupted run writes."""
    import shlex

    folder = tmp_path / "my study"
    folder.mkdir()
    sweep = folder / "my sweep.toml"
    sweep.write_text(TINY_SWEEP)
    out = folder / "my results.nc"
    code, err = _interrupted_run(folder, sweep, capsys, monkeypatch, out, interrupt_at=3)
    printed = err[-1].split("`")[1]
    assert code == 130 and printed == (f"warpfric run '{sweep}' -o '{out}' --resume --device {DEVICE}"), err
    words = shlex.split(printed)
    assert words[:2] == ["warpfric", "run"] and words[2] == str(sweep) and words[4] == str(out)
    code, _, err = run_cli(capsys, *words[1:], "--quiet")
    assert code == 0, err
    whole = tmp_path / "whole.nc"
    assert run_cli(capsys, "run", sweep, "-o", whole, "--device", DEVICE, "--quiet")[0] == 0
    with open_ensemble(out) as resumed, open_ensemble(whole) as uninterrupted:
        np.testing.assert_array_equal(resumed.mu_s.values, uninterrupted.mu_s.values)


def test_a_killed_cpu_worker_exits_5_keeping_the_finished_chunks(tmp_path, sweep, capsys, monkeypatch):
    """A CPU worker killed in a chunk (the out-of-memory killer) ended `warpfric run` with a
    BrokenProcessPool traceback and exit 1, the code of failed members, and no --resume command."""
    from warpfric.pool import WorkerDied

    real = SIMULATE_MODULE.simulate
    calls = []

    def killed(*args, **kwargs):
        if "member_offset" in kwargs:  # a chunk (not the kernels' warm-up)
            calls.append(1)
        if len(calls) == 2:
            raise WorkerDied("a CPU worker process ended abruptly (pid 123, killed by SIGKILL) while ...")
        return real(*args, **kwargs)

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", killed)
    out = tmp_path / "s.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, "--quiet")
    assert code == 5, err
    assert err[-1].startswith("warpfric: error: a CPU worker process ended abruptly (pid 123, killed by SIGKILL)")
    assert err[-1].endswith(f"the 1 finished chunk is kept in '{tmp_path / 's.nc.parts'}'; "
                            f"`warpfric run {sweep} -o {out} --resume --device {DEVICE}` goes on from them"), err
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", real)
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE, "--quiet")
    assert code == 0 and _files(tmp_path) == ["s.nc", "s.toml"], err


def test_resume_with_nothing_to_resume_says_so_and_runs_the_sweep(tmp_path, sweep, capsys):
    """A mistyped -o with --resume ran the whole sweep without a word (20 s where 2 chunks were left)."""
    out = tmp_path / "typo.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE, "--quiet")
    assert code == 0 and out.exists(), err
    assert f"warpfric: no interrupted run to resume: '{tmp_path / 'typo.nc.parts'}' does not exist, so the whole " \
           "sweep runs now" in err, err


def test_resume_with_other_settings_names_the_one_that_differs(tmp_path, sweep, capsys, monkeypatch):
    """It said 'a different sweep, chunk size (1) or member offset (0)' whichever differed."""
    out = tmp_path / "s.nc"
    code, _ = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, 3)
    assert code == 130
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--chunk", 2, "--device", DEVICE)
    assert code == 2
    _error_line(err, "belongs to a run with another chunk size (1, now 2); resume with the interrupted run's settings")
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--member-offset", 5, "--device", DEVICE)
    _error_line(err, "another member offset (0, now 5)")
    original = sweep.read_text()
    sweep.write_text(original.replace("nodes = 11", "nodes = 13"))
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    # a comment edited was enough, and the user was left with --overwrite (the finished chunks lost):
    # the run's text is kept in the parts folder, and the message says how to put it back
    kept = tmp_path / "s.nc.parts" / "sweep.toml"
    _error_line(err, f"another sweep file (its text changed); resume with the interrupted run's settings (the "
                     f"interrupted run's sweep file is kept as '{kept}': `cp {kept} {sweep}` puts it back)")
    assert kept.read_text() == original
    # info's command to finish the run puts the run's own text back first (it printed one that was refused)
    code, lines, _ = run_cli(capsys, "info", out)
    assert code == 1 and lines[0].split("`")[1].startswith(f"cp {kept} {sweep} && warpfric run {sweep} -o {out} "
                                                         "--resume")
    sweep.write_text(kept.read_text())
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 0 and out.exists() and not kept.exists(), err


def test_a_parts_folder_without_a_manifest(tmp_path, sweep, capsys):
    """A run killed between creating OUT.nc.parts/ and writing its manifest left an empty folder: the
    next run was told to --resume, and --resume failed on 'unreadable chunk manifest
    (FileNotFoundError(2, ...))'. An empty folder is removed (nothing to lose); a folder with chunks
    but no readable manifest says that --overwrite starts again."""
    out = tmp_path / "s.nc"
    (tmp_path / "s.nc.parts").mkdir()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert _files(tmp_path) == ["s.nc", "s.toml"]
    (tmp_path / "s.nc.parts").mkdir()  # beside a complete file: info reads the file, exit 0 (it was 2)
    code, lines, _ = run_cli(capsys, "info", out)
    assert code == 0 and "complete" in lines[0] and not any("replace" in line for line in lines)
    # nor does it make --resume replace the file (the folder was removed after the check that let it)
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 2 and not (tmp_path / "s.nc.parts").exists()
    _error_line(err, "exists; pass --overwrite to replace it (it is complete: nothing to resume)")
    other = tmp_path / "t.nc"
    (tmp_path / "t.nc.parts").mkdir()
    (tmp_path / "t.nc.parts" / "chunk-000000.nc").write_bytes(b"a chunk")
    code, _, err = run_cli(capsys, "run", sweep, "-o", other, "--resume", "--device", DEVICE)
    assert code == 2
    _error_line(err, "unreadable chunk manifest (no such file or directory); nothing can be resumed from it: "
                     "--overwrite starts the run again; its chunk file is a whole ensemble, which "
                     "warpfric.io.open_ensembles reads (copy it elsewhere first: --overwrite removes it)")


def test_info_on_a_run_still_going_says_so(tmp_path, sweep, capsys, monkeypatch):
    """info on a sweep whose lock a living run holds called it INCOMPLETE and offered --resume (which
    that run's lock then refused): it says RUNNING and who writes it, without a resume command."""
    out = tmp_path / "s.nc"
    code, _ = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, 3)
    assert code == 130
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        _hold_lock(out, other.pid)
        code, lines, _ = run_cli(capsys, "info", out)
        assert code == 1 and lines[0].startswith(f"{out}: RUNNING: being written by warpfric run (pid {other.pid} on ")
        assert "2/3 chunks" in lines[0] and "--resume" not in lines[0]
    finally:
        other.kill()
        other.wait()
    code, lines, _ = run_cli(capsys, "info", out)  # its process gone: interrupted
    assert code == 1 and "INCOMPLETE" in lines[0] and "--resume" in lines[0]
    # beside a complete file: the same line and exit 1 (it was exit 2 and "run the same command
    # again with --resume", which info does not take)
    whole = tmp_path / "whole.nc"
    assert run_cli(capsys, "run", sweep, "-o", whole, "--device", DEVICE, "--quiet")[0] == 0
    code, lines, _ = run_cli(capsys, "info", whole, out)
    assert code == 1 and lines == [line for line in lines if line.startswith(f"{out}: INCOMPLETE run: 2/3 chunks")]


def test_a_chunk_of_another_run_is_not_counted_as_done(tmp_path, sweep, capsys, monkeypatch):
    """A cluster's worker can finish a chunk of an interrupted run after that run has exited; its file
    must not count as a chunk of the next run on the same output (an --overwrite of an edited sweep
    would have combined it): a chunk is done only with this run's id in its member labels."""
    import shutil

    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    assert _interrupted_run(tmp_path, sweep, capsys, monkeypatch, a, 3)[0] == 130  # chunks 0 and 1
    assert _interrupted_run(tmp_path, sweep, capsys, monkeypatch, b, 2)[0] == 130  # chunk 0
    shutil.copy(tmp_path / "a.nc.parts" / "chunk-000001.nc", tmp_path / "b.nc.parts" / "chunk-000001.nc")
    store = IO_MODULE.ChunkStore.load(tmp_path / "b.nc.parts")
    assert [store.is_done(i) for i in range(3)] == [True, False, False]


def test_chunks_that_all_raise_leave_no_parts_folder(tmp_path, sweep, capsys, monkeypatch):
    """On a Dask cluster a run whose every chunk raised (e.g. a device the workers lack) kept a parts
    folder with only its manifest and advised a --resume that could only fail again; the next plain
    run was then told to --resume. Nothing finished: nothing is kept."""
    import warpfric.runner as runner

    def all_raise(sweep_, sweep_file, store, *args):
        return [], [dict(index=i, start=store.members(i).start, stop=store.members(i).stop, error="RunError: no GPU")
                    for i in range(store.n_chunks)], 0.1

    monkeypatch.setattr(runner, "_run_chunks", all_raise)
    out = tmp_path / "s.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 2, "--device", DEVICE)
    assert code == 1 and err[-1].endswith("no chunk finished, nothing was kept"), err
    assert _files(tmp_path) == ["s.toml"]


def test_a_resumed_run_exits_1_for_failed_members_of_earlier_chunks(tmp_path, capsys, monkeypatch):
    """The exit code counted only the chunks run now: a resume whose own chunks were ok exited 0 although
    the file holds a member that is not ok (from the interrupted run's chunk). It is the file's now."""
    sweep = tmp_path / "s.toml"
    sweep.write_text("fronts = false\n[solver]\nnodes = 11\n[zip]\ndisc_velocity = [0.0, 1e-4, 1e-4]\n"
                     "eccentricity = [0.0, 0.0, 0.1]\n")  # member 0: a disc that never moves, no_peak
    out = tmp_path / "s.nc"
    code, _ = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, 2)
    assert code == 130
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 1, err
    assert err[-1].endswith("0 failed members in the chunks run now, 1 in the file)"), err


def test_an_interrupted_overwrite_is_resumed_with_the_command_it_printed(tmp_path, sweep, capsys, monkeypatch):
    """A run with --overwrite over a complete file, interrupted after a chunk, printed `... --resume`;
    that command answered 'exists; pass --overwrite (it is complete: nothing to resume)' and the
    finished chunk could only be thrown away. It finishes the replacement now."""
    out = tmp_path / "s.nc"
    code, _, _ = run_cli(capsys, "run", sweep, "-o", out, "--device", DEVICE, "--quiet")
    assert code == 0
    with xr.open_dataset(out) as ds:
        first = ds.attrs["history"]
    code, err = _interrupted_run(tmp_path, sweep, capsys, monkeypatch, out, 2, "--overwrite")
    assert code == 130 and err[-1].endswith(f"`warpfric run {sweep} -o {out} --resume --device {DEVICE}` goes on from them")
    code, stdout, _ = run_cli(capsys, "info", out)  # the old file, complete, and what is replacing it
    assert code == 0 and stdout[-1].startswith(f"  an interrupted run that replaces it: 1/3 chunks finished in {out}.parts")
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:  # still running: no resume command (the run's lock would refuse it)
        _hold_lock(out, other.pid)
        code, stdout, _ = run_cli(capsys, "info", out)
        assert code == 0 and stdout[-1].startswith(f"  being replaced by a running warpfric run (pid {other.pid} ")
        assert "--resume" not in stdout[-1]
    finally:
        other.kill()
        other.wait()
        (tmp_path / "s.nc.lock").unlink()
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 0, err
    assert any(f"'{out}' is replaced when the interrupted run it belongs to ends" in line for line in err), err
    assert _files(tmp_path) == ["s.nc", "s.toml"]
    with xr.open_dataset(out) as ds:
        assert ds.attrs["history"] != first and "--overwrite" in ds.attrs["history"] and ds.sizes["member"] == 3


def test_a_ctrl_c_during_a_write_waits_for_the_write_and_then_stops_it(tmp_path):
    """A SIGINT inside xarray's netCDF write left its file lock half taken and `warpfric run` hung
    while it wrote the combined file; now the write runs to its end, then KeyboardInterrupt is
    raised, the old file kept and no temporary file left."""
    import signal

    from warpfric.io import replace_atomically

    out = tmp_path / "out.nc"
    out.write_text("the old result")
    finished = []

    def write(tmp):
        Path(tmp).write_text("half")
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C in the middle of the write
        Path(tmp).write_text("the new result")
        finished.append(True)

    # Python's own Ctrl-C, also where the tests run with SIGINT ignored (started with & from a script)
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            replace_atomically(out, write)
        assert finished and out.read_text() == "the old result" and _files(tmp_path) == ["out.nc"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # Python's own handler again
        replace_atomically(out, lambda tmp: Path(tmp).write_text("written"))  # and a write without one
        assert out.read_text() == "written" and _files(tmp_path) == ["out.nc"]
    finally:
        signal.signal(signal.SIGINT, inherited)


def test_a_write_holds_the_command_lines_sigterm_and_leaves_a_users_own_handler_alone(tmp_path):
    """The command line's SIGTERM (as Ctrl-C) is held during a write like Ctrl-C; a SIGTERM handler of
    the user's own (a batch job's 'stop after this' flag) was swallowed too, its write thrown away
    with KeyboardInterrupt: it runs, and the write completes."""
    import signal

    from warpfric.io import replace_atomically, sigterm_as_ctrl_c

    out = tmp_path / "out.nc"

    def write(tmp):
        Path(tmp).write_text("half")
        os.kill(os.getpid(), signal.SIGTERM)
        Path(tmp).write_text("the new result")

    calls = []
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: calls.append(signum))
    try:
        replace_atomically(out, write)
        assert calls == [signal.SIGTERM] and out.read_text() == "the new result"
        signal.signal(signal.SIGTERM, sigterm_as_ctrl_c)
        with pytest.raises(KeyboardInterrupt):
            replace_atomically(out, write)
        assert out.read_text() == "the new result" and _files(tmp_path) == ["out.nc"]  # held, then stopped
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_write_ensemble_removes_its_temporary_file_on_ctrl_c(tmp_path, monkeypatch):
    from warpfric.io import write_ensemble

    ds = xr.Dataset({"mu_s": ("member", np.array([0.5]))}, coords={"member": np.array([0], dtype=np.int32)})

    def interrupted(self, path=None, *args, **kwargs):
        Path(path).write_bytes(b"partial")
        raise KeyboardInterrupt

    monkeypatch.setattr(xr.Dataset, "to_netcdf", interrupted)
    with pytest.raises(KeyboardInterrupt):
        write_ensemble(ds, tmp_path / "e.nc")
    assert _files(tmp_path) == []


def test_a_full_disk_on_a_dask_worker_exits_3_and_keeps_the_finished_chunks(tmp_path, sweep, capsys, monkeypatch):
    """As on one host: the worker's error ends the run with exit 3 once the other chunks have ended,
    and the finished chunks are kept for --resume (an in-process cluster, so that the full disk
    patched here is the worker's too)."""
    distributed = pytest.importorskip("distributed")
    _full_disk(monkeypatch, "chunk-000001.nc")
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None)
    try:
        code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--chunk", 1, "--scheduler",
                               cluster.scheduler_address, "--device", DEVICE, "--quiet")
    finally:
        cluster.close()
    assert code == 3
    _error_line(err, "disk full while writing", "chunk-000001.nc", "the 2 finished chunks are kept",
                "free some space, then", "--resume")
    assert _files(tmp_path) == ["s.nc.parts", "s.nc.parts/chunk-000000.nc", "s.nc.parts/chunk-000002.nc",
                                "s.nc.parts/manifest.json", "s.nc.parts/sweep.toml", "s.toml"]
    monkeypatch.undo()
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--resume", "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert open_ensemble(tmp_path / "s.nc").member.values.tolist() == [0, 1, 2]


def test_a_write_error_keeps_its_disk_full_flag_across_processes():
    """A Dask worker's exception reaches the client pickled."""
    import pickle

    err = pickle.loads(pickle.dumps(IO_MODULE.OutputWriteError("disk full while writing 'x.nc'", True)))
    assert isinstance(err, IO_MODULE.OutputWriteError) and err.disk_full is True
    assert str(err) == "disk full while writing 'x.nc'"


def test_a_figure_folder_that_cannot_be_written_is_one_line(tmp_path, capsys, monkeypatch):
    """`warpfric plot` into a read-only or forbidden folder ended in matplotlib's or mkdir's
    traceback (exit 1): one line, exit 2, with the reason and --outdir."""
    import xarray as xr

    import warpfric.plots
    from warpfric.cli import RUN_OUTPUTS

    run_outputs = xr.Dataset({name: ("member", [0.0]) for name in RUN_OUTPUTS})  # what plot reads of every file
    monkeypatch.setattr(IO_MODULE, "open_ensemble", lambda path: run_outputs)
    for error, reason in ((errno.EROFS, "read-only file system"), (errno.EACCES, "permission denied")):
        def refused(ds, outdir, error=error):
            raise OSError(error, os.strerror(error), str(outdir / "mu_s.png"))

        monkeypatch.setattr(warpfric.plots, "quick_look", refused)
        code, _out, err = run_cli(capsys, "plot", tmp_path / "e.nc", "--outdir", tmp_path / "figures")
        assert code == 2
        _error_line(err, f"figure folder '{tmp_path / 'figures'}': cannot write in it ({reason})", "--outdir DIR")


def test_figures_are_not_written_into_a_sweeps_parts_folder(tmp_path, capsys, no_simulation):
    """`warpfric plot OUT.nc.parts/chunk-000000.nc` wrote its PNGs into the parts folder, which the
    sweep's end (or --resume) removes with them."""
    parts = tmp_path / "s.nc.parts"
    parts.mkdir()
    for argv in (["plot", parts / "chunk-000000.nc"], ["plot", tmp_path / "s.nc", "--outdir", parts / "figs"]):
        code, _out, err = run_cli(capsys, *argv)
        assert code == 2
        _error_line(err, f"lies in '{parts}', the chunks of a sweep, which is removed when the sweep ends", "--outdir")


def test_a_figure_folder_that_is_a_file_is_refused(tmp_path, capsys):
    """`warpfric plot OUT.nc --outdir FILE` (or an ensemble file without a suffix, whose default
    folder is its own name) ended in mkdir's traceback."""
    taken = tmp_path / "taken.png"
    taken.write_bytes(b"not a folder")
    code, _out, err = run_cli(capsys, "plot", tmp_path / "any.nc", "--outdir", taken)
    assert code == 2
    _error_line(err, "taken.png' is a file", "--outdir")
    bare = tmp_path / "ensemble"
    bare.write_bytes(b"an ensemble without a suffix")
    code, _out, err = run_cli(capsys, "plot", bare)
    assert code == 2
    _error_line(err, "ensemble' is a file")
    assert taken.read_bytes() == b"not a folder"


def test_a_figure_folder_in_a_missing_folder_is_refused(tmp_path, capsys):
    """`warpfric plot OUT.nc --outdir /mistyped/path/figs` created every missing folder of the path
    (mkdir parents=True), where `warpfric run -o` refuses a missing folder: refused the same way,
    nothing created."""
    code, _out, err = run_cli(capsys, "plot", tmp_path / "any.nc", "--outdir", tmp_path / "typo" / "figs")
    assert code == 2
    _error_line(err, f"folder '{tmp_path / 'typo'}' does not exist", "--outdir DIR")
    assert not (tmp_path / "typo").exists()


def test_the_interrupt_warning_reads_kept_chunks_with_a_parameter_missing(tmp_path):
    """An interrupted sweep warns of the members not ok in its kept chunks, read from the chunk files;
    a chunk without disc_velocity (an edited file) turned Ctrl-C into an AttributeError traceback:
    it reads as unknown, and the warning counts every chunk's members."""
    import warnings
    from types import SimpleNamespace

    import netCDF4

    from warpfric.kernels.types import STATUS_MEANINGS
    from warpfric.parameters import Solver
    from warpfric.runner import _warn_members_not_ok_kept

    meanings = " ".join(STATUS_MEANINGS)
    no_peak = STATUS_MEANINGS.index("no_peak")
    paths = []
    for i, (status, velocity) in enumerate((([0, no_peak], [1e-4, 0.0]), ([no_peak, no_peak], None))):
        path = tmp_path / f"chunk-{i}.nc"
        with netCDF4.Dataset(path, "w") as nc:
            nc.createDimension("member", 2)
            var = nc.createVariable("status", "i4", ("member",))
            var[:] = status
            var.flag_meanings = meanings
            if velocity is not None:
                nc.createVariable("disc_velocity", "f8", ("member",))[:] = velocity
            else:
                nc.createVariable("working_precision", "i1", ("member",))[:] = [32, 64]
        paths.append(path)
    from warpfric.io import _summary_columns

    def summary_columns(i):  # what ChunkStore.is_done reads of a finished chunk
        with netCDF4.Dataset(paths[i]) as nc:
            return _summary_columns(nc)

    store = SimpleNamespace(summary_columns=summary_columns)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_members_not_ok_kept(store, [0, 1], Solver(), tmp_path / "out.nc")
    assert len(caught) == 1
    text = str(caught[0].message)
    assert "3 of 4 members in the 2 finished chunks: 3 no_peak" in text, text
    assert "; 1 of them: disc_velocity = 0: the disc never moves" in text, text  # the one that is known
    # the precision each member ran in (the advice of float64 reads it), unknown where a file lacks it
    assert np.isnan(summary_columns(0)["working_precision"]).all()
    assert summary_columns(1)["working_precision"].tolist() == [32.0, 64.0]


def test_slips_a_new_user_makes_are_one_line_errors_that_name_them(tmp_path, capsys, monkeypatch):
    """-o "" (an unset shell variable) ran and wrote nothing without a word; an ensemble file given as
    the sweep file gave "'utf-8' codec can't decode byte 0x89"; [run] workers = 0 was reported as the
    flag --workers, which the user never gave. Each is one line naming what was given (exit 2)."""
    from conftest import one_line_error

    monkeypatch.chdir(tmp_path)
    code, out, err = run_cli(capsys, "run", "--nodes", "11", "-o", "")
    assert code == 2 and not out
    one_line_error(err, "-o ''", "empty file name", ".nc")
    (tmp_path / "tiny.toml").write_text(TINY_SWEEP)
    assert run_cli(capsys, "run", "tiny.toml", "-o", "tiny.nc", "--quiet")[0] == 0
    code, out, err = run_cli(capsys, "run", "tiny.nc")
    assert code == 2
    one_line_error(err, "'tiny.nc' is not text", "a netCDF file", "warpfric info")
    (tmp_path / "w.toml").write_text(TINY_SWEEP + "[run]\nworkers = 0\n")
    code, out, err = run_cli(capsys, "run", "w.toml", "-o", "w.nc")
    assert code == 2 and not (tmp_path / "w.nc").exists()
    one_line_error(err, "[run] workers = 0", "expected an integer >= 1")


def test_a_sweep_file_sets_the_team_size(tmp_path):
    """[solver] lanes had no value a sweep file could give (its default None made every value "expected a
    string", and "4" failed Solver's own check): an integer is taken; a string is refused by Solver's
    own check, which names the valid values (the sweep file's "expected an integer" did not)."""
    from warpfric.sweep_file import SweepError, parse_sweep

    assert parse_sweep(TINY_SWEEP.replace("nodes = 11", "nodes = 11\nlanes = 4")).solver.lanes == 4
    assert parse_sweep(TINY_SWEEP).solver.lanes is None
    for value in ('"4"', '"auto"'):  # (the files' solver_lanes attribute reads "auto"; TOML cannot write None)
        with pytest.raises(SweepError, match=rf"\[solver\] lanes = {value}: expected an integer; leave the key "
                                             "out for the default"):
            parse_sweep(TINY_SWEEP.replace("nodes = 11", f'nodes = 11\nlanes = {value}'))
    # [record] windows and times that Record refuses name their table, as the sweep file's other errors do
    with pytest.raises(SweepError, match=r"^\[record\] record window: start 21.0 s is after stop 20.0 s"):
        parse_sweep(TINY_SWEEP + "[record]\nstart = 21.0\nstop = 20.0\n")
    with pytest.raises(SweepError, match=r"^\[record\] record setting 'times' = \[20, 19\] s is invalid"):
        parse_sweep(TINY_SWEEP + "[record]\ntimes = [20.0, 19.0]\n")
    with pytest.raises(SweepError, match=r"\[solver\] solver setting 'nodes' = '30' is invalid; valid: an integer in "
                                         r"\[3, 2147483647\]"):
        parse_sweep(TINY_SWEEP.replace("nodes = 11", 'nodes = "30"'))


def test_the_command_line_says_why_a_cut_off_runs_front_is_not_given(capsys):
    """--end-time inside the front: the front line said "absent: no node reached the front's event",
    which a cut-off run's NaN fronts now are not; it says the run ended before the detachment was over."""
    code, out, err = run_cli(capsys, "run", "--nodes", "30", "--end-time", "20.245", "--quiet")
    assert code == 0
    front = [line for line in out if line.startswith("front")]
    assert front == ["front     : not given: the run ended at t = 20.245 s, before the detachment was over (a later "
                     "--end-time, or none: the automatic end), so its front outputs are NaN"], out


def test_chunks_that_do_not_combine_are_kept_and_said_so(tmp_path, capsys, monkeypatch):
    """A combine that refuses its chunks (parts written by another warpfric version for --resume)
    raised its ValueError as bad input (exit 2), with no word of the finished chunks it left behind:
    it is a failed write now (exit 3), naming the parts folder and the kept chunks."""
    import warpfric.io

    def refuse(datasets, names=None):
        raise ValueError(f"{names[0]} and {names[1]} differ in displacement: not one ensemble")

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(warpfric.io, "concat_members", refuse)
    (tmp_path / "tiny.toml").write_text(TINY_SWEEP)
    code, out, err = run_cli(capsys, "run", "tiny.toml", "-o", "out.nc", "--chunk", "1", "--quiet")
    assert code == 3 and not (tmp_path / "out.nc").exists()
    _error_line(err, "do not combine into one file", "differ in displacement", "remove the chunk files it names",
                "the 3 finished chunks are kept", "out.nc.parts")
    assert len(list((tmp_path / "out.nc.parts").glob("*.nc"))) == 3


def test_info_names_the_members_cut_off_before_their_detachment_was_over(tmp_path, capsys, monkeypatch):
    """The warning names at most 8 members and a file keeps no trace of it but NaN: `warpfric info`
    said only 'present in 0/2 members'. It lists the ok members whose run ended before the detachment
    was over, and why."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "cut.toml").write_text("[solver]\nnodes = 20\n[scene]\nend_time = 20.245\n[grid]\n"
                                       "eccentricity = [0.0, 0.1]\n")
    assert run_cli(capsys, "run", "cut.toml", "-o", "cut.nc", "--quiet")[0] == 0
    code, out, _ = run_cli(capsys, "info", "cut.nc")
    assert code == 0
    assert "    ok, but ended before the detachment was over at end_time (their fronts are NaN): members 0, 1" in out, out
    # the front lines count over the members whose fronts were read ("present in 0/2" read as absent)
    assert "  first front's middle segment: no member's front was read (2 not ok or cut off)" in out, out


def test_info_and_plot_name_what_a_partial_file_lacks(tmp_path, capsys, monkeypatch):
    """A file written from a selection of a run's Dataset (write_ensemble takes any) made `info` and
    `plot` end in an AttributeError or KeyError traceback: one line, exit 2, naming what it lacks;
    the whole file passes, and so does one without an output they do not read."""
    from warpfric.io import open_ensemble, write_ensemble

    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(TINY_SWEEP.replace("fronts = false", ""))  # with the contact front
    assert run_cli(capsys, "run", "tiny.toml", "-o", "tiny.nc", "--quiet")[0] == 0
    whole = open_ensemble("tiny.nc")
    write_ensemble(whole[["mu_s", "status", "eccentricity", "normal_force"]], "few.nc")
    write_ensemble(whole.drop_vars("v_left"), "no_left.nc")
    for command in ("info", "plot"):
        code, _, err = run_cli(capsys, command, "few.nc")
        assert code == 2
        _error_line(err, f"few.nc lacks mu_s_time, mu_final, final_time, which `warpfric {command}` reads")
        code, _, err = run_cli(capsys, command, "no_left.nc")
        assert code == 2
        _error_line(err, "no_left.nc lacks v_left, which")
    assert run_cli(capsys, "info", "tiny.nc")[0] == 0
    write_ensemble(whole.drop_vars("second_front_length"), "older.nc")  # e.g. a file of another version
    assert run_cli(capsys, "info", "older.nc")[0] == 0


def test_a_finished_chunk_is_read_once_while_it_is_unchanged(tmp_path, capsys, monkeypatch):
    """An interrupted or failed sweep opened every finished chunk twice or three times (counted, kept,
    then read for its warning: 1.6 + 1.7 s at 400 chunks): is_done keeps what it read while the file
    is unchanged (inode, size, mtime), and a chunk written again is read again."""
    import netCDF4

    from warpfric.io import ChunkStore, parts_dir

    monkeypatch.chdir(tmp_path)
    (tmp_path / "tiny.toml").write_text(TINY_SWEEP)
    monkeypatch.setattr(ChunkStore, "combine", lambda self, *a, **k: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert run_cli(capsys, "run", "tiny.toml", "-o", "out.nc", "--chunk", "1", "--quiet")[0] == 130
    store = ChunkStore.load(parts_dir(tmp_path / "out.nc"))
    opened = []
    real = netCDF4.Dataset
    monkeypatch.setattr(netCDF4, "Dataset", lambda path, *a, **k: (opened.append(str(path)), real(path, *a, **k))[1])
    assert [store.is_done(i) for i in range(3)] == [True, True, True] and len(opened) == 3
    assert store.summary_columns(1)["status"].tolist() == [0] and [store.is_done(i) for i in range(3)] == [True] * 3
    assert len(opened) == 3  # nothing opened again
    path = store.chunk_path(2)
    data = path.read_bytes()
    path.unlink()
    path.write_bytes(data)  # the same content in a new file: read again
    assert store.is_done(2) and len(opened) == 4
    path.unlink()
    assert not store.is_done(2) and len(opened) == 4


def test_info_counts_members_stopped_by_max_end_time_as_not_read(capsys, tmp_path):
    """Members stopped by max_end_time have NaN fronts too (nucleation_edge -3): info counted them
    among the members whose fronts were read ('present in 1/3')."""
    import warpfric as wf
    from warpfric.io import write_ensemble

    with pytest.warns(UserWarning, match="detachment was over"):
        ds = run({"aging_coefficient": [5e-3, 0.075]}, nodes=20, rtol=1e-5, fronts=wf.Fronts(),
                 scene=wf.Parameters(max_end_time=24.0))
    write_ensemble(ds, tmp_path / "cap.nc")
    code, out, _ = run_cli(capsys, "info", tmp_path / "cap.nc")
    assert code == 0 and int(ds.nucleation_edge.values[0]) == -3
    line = next(line for line in out if line.startswith("  first front's middle segment"))
    assert "present in 1/1 member" in line and "(1 more not read: not ok or cut off)" in line, out


ECCENTRICITY_BEYOND = np.linspace(-0.5, 0.9285, 2000) > 0.6  # eccentricity's range is [-0.6, 0.6]
END_BEFORE_REST = np.linspace(30, 19.9, 2000) <= 20.0


@pytest.mark.parametrize("body, words", [
    # members out of range from the sixth slice of 300 on
    ("[zip]\neccentricity = {start = -0.5, stop = 0.9285, num = 2000}\nnormal_force = {start = 500, stop = 600, "
     "num = 2000}\n", [f"eccentricity[{np.argmax(ECCENTRICITY_BEYOND)}]",
                       f"({ECCENTRICITY_BEYOND.sum()} members out of range)"]),
    # a protocol broken in the seventh slice: runs that end before the disc starts to move
    ("[scene]\nrest_until = 20.0\n[zip]\nend_time = {start = 30, stop = 19.9, num = 2000}\n"
     "eccentricity = {start = -0.5, stop = 0.5, num = 2000}\n", [f"(member {np.argmax(END_BEFORE_REST)})"]),
    # two parameters out of range, the file's first after the other in PARAMETER_NAMES: the same one is named
    ("[zip]\neccentricity = {start = -0.5, stop = 0.9285, num = 2000}\nnormal_force = {start = 500, stop = -100, "
     "num = 2000}\n", ["normal_force["]),
])
def test_a_large_sweep_is_validated_slice_by_slice_with_the_same_message(monkeypatch, body, words):
    """Beyond VALIDATE_ROWS members the sweep's members are validated slice by slice (resolve_members
    holds ~272 bytes a member: 272 GB for 1e9 members, while the sweep's own check counted ~24): the
    message must name the same member, value and count as validating them all at once."""
    from warpfric import sweep_file
    from warpfric.sweep_file import SweepError, parse_sweep

    with pytest.raises(SweepError) as whole:
        parse_sweep(body, "s.toml")
    monkeypatch.setattr(sweep_file, "VALIDATE_ROWS", 300)
    with pytest.raises(SweepError) as sliced:
        parse_sweep(body, "s.toml")
    assert str(sliced.value) == str(whole.value)
    assert all(word in str(whole.value) for word in words), (str(whole.value), words)


def test_building_a_large_sweep_stays_within_its_memory_check(monkeypatch):
    """The sweep's memory check must not be a gross underestimate: tracemalloc's peak while a
    1,000,000-member grid of two parameters is built and validated (in slices of 10,000) stays
    within 1.25x the check's 8 * (columns + 2) bytes a member plus its blocks (it was ~11x, 272
    bytes a member against 24, while every member was validated at once)."""
    import tracemalloc

    from warpfric import sweep_file

    monkeypatch.setattr(sweep_file, "VALIDATE_ROWS", 10_000)
    body = ("[grid]\neccentricity = {start = -0.5, stop = 0.5, num = 1000}\n"
            "normal_force = {start = 500, stop = 5000, num = 1000}\n")
    tracemalloc.start()
    try:
        sweep = sweep_file.parse_sweep(body, "s.toml")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(sweep.members["eccentricity"]) == 1_000_000
    checked = 8 * (1_000_000 * (2 + 2) + 2 * 1000) + sweep_file.VALIDATE_BYTES_PER_MEMBER * 10_000
    assert peak < 1.25 * checked, (peak, checked)


def test_a_reader_that_goes_away_loses_no_file_and_prints_no_traceback(tmp_path):
    """`warpfric run -o OUT.nc | head -1`, `warpfric info OUT.nc | head -1`: the reader of stdout
    closes the pipe. The run still writes its file (it printed before writing, and a
    BrokenPipeError ended it with a traceback and no file), exits with its own code, and neither
    command prints a traceback. Here the pipe's read end is closed before the command starts, so
    every write to stdout fails."""
    out = tmp_path / "bp.nc"
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    for args in (["run", "--nodes", "11", "--device", DEVICE, "-o", str(out)], ["info", str(out)]):
        read_end, write_end = os.pipe()
        os.close(read_end)
        try:
            res = subprocess.run([sys.executable, "-m", "warpfric", *args], stdout=write_end, stderr=subprocess.PIPE,
                                 text=True, timeout=300, env=env)
        finally:
            os.close(write_end)
        assert res.returncode == 0, res.stderr
        assert "Traceback" not in res.stderr and "BrokenPipeError" not in res.stderr, res.stderr
        assert out.exists()
    assert int(open_ensemble(out).status.values[0]) == 0
    # an error line to a reader gone as well: the exit code stays the fault's (it became 1)
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        res = subprocess.run([sys.executable, "-m", "warpfric", "info", str(tmp_path / "none.nc")], stdout=write_end,
                             stderr=write_end, timeout=300, env=env)
    finally:
        os.close(write_end)
    assert res.returncode == 2


def test_a_parts_name_that_holds_no_run_is_said_as_such(tmp_path, sweep, capsys, no_simulation):
    """A file named OUT.nc.parts sent a user round in circles: `run` said it held an interrupted run
    (pass --resume or --overwrite), --resume said "not a directory" and --overwrite failed to write
    with exit 3. A parts folder whose manifest cannot be read was to be resumed by `run`, and could
    not be by --resume. Both are now one line, exit 2, that says what to do, whatever the option."""
    out = tmp_path / "s.nc"
    Path(f"{out}.parts").write_text("")
    for option in ([], ["--resume"], ["--overwrite"]):
        code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, *option)
        assert code == 2, (option, err)
        _error_line(err, f"'{out}.parts' is a file, where a chunked run keeps its finished chunks", "remove or rename it")
    Path(f"{out}.parts").unlink()
    Path(f"{out}.parts").mkdir()
    Path(f"{out}.parts", "manifest.json").write_text("{not json")
    for option in ([], ["--resume"]):
        code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, *option)
        assert code == 2, (option, err)
        _error_line(err, "unreadable chunk manifest", "nothing can be resumed from it: --overwrite starts the run again")


def test_a_ctrl_c_during_a_chunks_write_keeps_that_chunk(tmp_path, sweep, capsys, monkeypatch):
    """A Ctrl-C while a chunk's file was written waited for the write, then removed the file: its
    members (for a GPU chunk, minutes of work) ran again on --resume. The whole chunk is kept now,
    counted in the line, and --resume runs only the chunk after it; the combined file's write still
    leaves the output as it was (its chunks are still there)."""
    import signal

    real = xr.Dataset.to_netcdf

    def to_netcdf(self, path=None, *args, **kwargs):
        done = real(self, path, *args, **kwargs)
        if path is not None and Path(path).name.startswith("chunk-000001.nc") and kwargs.get("mode", "w") == "w":
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C in the middle of the chunk's write (its group follows)
        return done

    out = tmp_path / "s.nc"
    monkeypatch.setattr(xr.Dataset, "to_netcdf", to_netcdf)
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's own Ctrl-C, as in a terminal
    try:
        code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--device", DEVICE, "--quiet")
    finally:
        signal.signal(signal.SIGINT, inherited)
    monkeypatch.undo()
    assert code == 130 and "the 2 finished chunks are kept" in err[-1], err
    assert _files(tmp_path) == ["s.nc.parts", "s.nc.parts/chunk-000000.nc", "s.nc.parts/chunk-000001.nc",
                                "s.nc.parts/manifest.json", "s.nc.parts/sweep.toml", "s.toml"]
    ran = []
    real_simulate = SIMULATE_MODULE.simulate
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", lambda *a, **k: ran.append(k.get("member_offset"))
                        or real_simulate(*a, **k))
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE, "--quiet")
    assert code == 0 and [offset for offset in ran if offset is not None] == [2], (err, ran)  # (None: the warm-up)
    assert open_ensemble(out).member.values.tolist() == [0, 1, 2]
