"""netCDF round trip, combining files, and the command line end to end (run, info, plot, resume
after a kill, bad input)."""

import os
import re
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from conftest import DEVICE, run

import warpfric as wf
from warpfric.cli import main, summary
from warpfric.io import by_parameters, open_ensemble, write_ensemble

TINY = """
title = "test sweep"
[solver]
nodes = 21
rtol = 1e-5
[grid]
eccentricity = [-0.2, 0.0, 0.2]
normal_force = [500.0, 2000.0]
"""


def _cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "warpfric", *args], capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, "PYTHONWARNINGS": "ignore"})


def test_netcdf_round_trip(tmp_path):
    members = {"eccentricity": [-0.1, 0.1], "normal_force": 800.0}
    ds = run(members, nodes=21, fronts=wf.Fronts(), record=wf.Record.window(20.2, 20.3, 11, members=(1,)))
    path = write_ensemble(ds, tmp_path / "ens.nc")
    back = open_ensemble(path)
    assert back.normal_force.dims == () and float(back.normal_force) == 800.0  # constant: a scalar
    assert back.eccentricity.dims == ("member",)
    for name, var in ds.variables.items():
        got = back[name]
        expected = var if name != "normal_force" else var.isel(member=0)
        np.testing.assert_array_equal(got.values, expected.values, err_msg=name)
        assert got.dtype == (np.int32 if expected.dtype == np.int64 else expected.dtype), name  # CF-1.8: no int64
        for key in ("units", "long_name", "flag_meanings"):
            if key in var.attrs and name != "recorded_member":  # in files: member numbers, said so
                assert got.attrs[key] == var.attrs[key], (name, key)
    for key in ("model_tilt", "solver_rtol", "solver_dtype", "warpfric_version", "warp_version", "device",
                "fronts_threshold", "Conventions"):
        assert back.attrs[key] == ds.attrs[key], key
    assert back.attrs["warpfric_complete"] == 1
    with xr.open_dataset(path) as raw:
        assert raw.mu_s.encoding["zlib"] and raw.arrival_time.encoding["zlib"]


def test_by_parameters_puts_every_member_at_its_swept_values(tmp_path):
    """A 2 x 3 grid sweep as a (normal_force, eccentricity) array, from simulate and from its file:
    each member's mu_s and arrival times sit at its own parameters, its number in member_number;
    a combination not run is NaN; names that cannot tell members apart are refused, naming them."""
    ds = run({"eccentricity": [-0.2, 0.0, 0.2], "normal_force": [[500.0], [2000.0]]}, nodes=11, rtol=1e-5,
             fronts=wf.Fronts())
    for source in (ds, open_ensemble(write_ensemble(ds, tmp_path / "grid.nc"))):
        grid = by_parameters(source)
        assert grid.mu_s.dims == ("normal_force", "eccentricity") and grid.arrival_time.dims[:2] == grid.mu_s.dims
        assert grid.member_number.dtype == np.int32  # in memory as from the file (int64 there before)
        for m in range(6):
            at = dict(normal_force=float(ds.normal_force[m]), eccentricity=float(ds.eccentricity[m]))
            assert float(grid.mu_s.sel(at)) == float(ds.mu_s[m]) and int(grid.member_number.sel(at)) == m
            np.testing.assert_array_equal(grid.arrival_time.sel(at).values, ds.arrival_time[m].values)
    partial = by_parameters(ds.isel(member=[0, 1, 2, 3, 4]))
    assert np.isnan(float(partial.mu_s.sel(normal_force=2000.0, eccentricity=0.2)))
    # one row of the grid: the swept parameter that no longer varies is left out; one name works
    row = by_parameters(ds.isel(member=[3, 4, 5]))
    assert row.mu_s.dims == ("eccentricity",) and list(row.member_number.values) == [3, 4, 5]
    np.testing.assert_array_equal(row.mu_s.values, ds.mu_s.values[3:])
    assert by_parameters(ds.isel(member=[0, 3]), "normal_force").mu_s.dims == ("normal_force",)
    with pytest.raises(ValueError, match="2 combinations of normal_force occur in more than one member"):
        by_parameters(ds, "normal_force")
    with pytest.raises(ValueError, match="'density' is 1200 kg m-3 in every member"):
        by_parameters(ds, ["density", "eccentricity"])
    with pytest.raises(ValueError, match="no parameter varies among this member"):
        by_parameters(run(None, nodes=11))
    holed = ds.assign(eccentricity=ds.eccentricity.where(ds.member != 3))
    with pytest.raises(ValueError, match=r"'eccentricity' is not finite in 1 member\(s\) \(numbers 3\)"):
        by_parameters(holed)
    with pytest.raises(ValueError, match=r"expects the ensemble along the dimension member, got a Dataset with "
                                         r"dimensions \('x',\) \(ds.isel\(member=0\) drops the dimension"):
        by_parameters(ds.isel(member=0))  # a KeyError 'member' before
    # random samples are no grid: 6 members would fill 6 of 36 combinations
    sampled = ds.assign(eccentricity=ds.eccentricity + 0.01 * ds.member, normal_force=ds.normal_force + ds.member)
    with pytest.raises(ValueError, match=r"not a grid of normal_force, eccentricity: .* fill 6 of 36 combinations.*select them with ds.sel\(member=ds.member\[...\]\)"):
        by_parameters(sampled)


@pytest.mark.filterwarnings("ignore:In a future version of xarray the default value for data_vars:FutureWarning")
@pytest.mark.parametrize("new_defaults", [False, True])
def test_open_mfdataset_combines_two_runs(tmp_path, new_defaults):
    """Both xarray combine defaults (the current one and the announced one) give the same ensemble."""
    pytest.importorskip("dask")
    a = run({"eccentricity": [0.0, 0.1]}, nodes=21, fronts=wf.Fronts())
    b = run({"eccentricity": [0.2, 0.3]}, nodes=21, fronts=wf.Fronts())
    b = b.assign_coords(member=b.member + 2)
    write_ensemble(a, tmp_path / "a.nc")
    write_ensemble(b, tmp_path / "b.nc")
    with xr.set_options(use_new_combine_kwarg_defaults=new_defaults), \
            xr.open_mfdataset([tmp_path / "a.nc", tmp_path / "b.nc"], combine="nested", concat_dim="member") as both:
        np.testing.assert_array_equal(both.member_number.values, [0, 1, 2, 3])  # member: their labels
        np.testing.assert_array_equal(both.eccentricity.values, [0.0, 0.1, 0.2, 0.3])
        np.testing.assert_array_equal(both.mu_s.values, np.concatenate([a.mu_s.values, b.mu_s.values]))
        np.testing.assert_array_equal(both.arrival_time.values, np.concatenate([a.arrival_time.values, b.arrival_time.values]))
        assert np.all(both.normal_force.values == 1000.0)


def test_cli_run_info_plot_end_to_end(tmp_path):
    sweep = tmp_path / "tiny.toml"
    sweep.write_text(TINY + "[record]\nmembers = [1, 4]\nstart = 20.2\nstop = 20.3\ncount = 11\n")  # one per chunk
    out = tmp_path / "tiny.nc"
    res = _cli("run", str(sweep), "-o", str(out), "--chunk", "4", "--device", DEVICE)
    assert res.returncode == 0, res.stderr
    assert "chunk 2/2" in res.stderr and not (tmp_path / "tiny.nc.parts").exists()
    ds = open_ensemble(out)
    assert ds.sizes["member"] == 6 and list(ds.recorded_member.values) == [1, 4]
    direct = wf.simulate({"eccentricity": [[-0.2], [0.0], [0.2]], "normal_force": [500.0, 2000.0]},
                         solver=wf.Solver(nodes=21, rtol=1e-5), record=wf.Record.window(20.2, 20.3, 11, members=(1, 4)),
                         device=DEVICE, progress=False)
    for name in ("mu_s", "mu_s_time", "v_middle", "arrival_time", "eccentricity", "normal_force", "velocity_history"):
        np.testing.assert_array_equal(ds[name].values, direct[name].values, err_msg=name)
    assert ds.attrs["sweep_toml"].startswith("\ntitle")
    res = _cli("info", str(out))
    assert res.returncode == 0 and "6 members" in res.stdout and "status: ok 6" in res.stdout
    assert "eccentricity" in res.stdout and "mu_s: mean" in res.stdout
    res = _cli("plot", str(out), "--outdir", str(tmp_path / "png"))
    assert res.returncode == 0, res.stderr
    pngs = sorted(p.name for p in (tmp_path / "png").glob("*.png"))
    assert {"mu_s_vs_eccentricity.png", "front_speeds_vs_normal_force.png", "arrival_times.png",
            "space_time_member1.png", "space_time_member4.png"} <= set(pngs)
    assert all((tmp_path / "png" / p).stat().st_size > 10_000 for p in pngs)


def test_combined_parts_report_their_worker_processes():
    """A combined file kept the first part's workers, worker_chunks and worker_start_time_s."""
    from warpfric.io import concat_members

    kw = dict(solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None, device="cpu", progress=False, workers=1)
    split = wf.simulate({"eccentricity": [0.0]}, **kw).assign_attrs(workers=2, worker_chunks=4, worker_start_time_s=0.5)
    alone = wf.simulate({"eccentricity": [0.1]}, member_offset=1, **kw)
    alone.attrs.pop("workers", None)
    for parts in ((split, alone), (alone, split)):
        both = concat_members(list(parts))
        assert (both.attrs["workers"], both.attrs["worker_chunks"], both.attrs["worker_start_time_s"]) == (2, 5, 0.5)


def test_resume_after_kill_gives_the_uninterrupted_result(tmp_path):
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY.replace("[-0.2, 0.0, 0.2]", "[-0.3, -0.2, -0.1, 0.0, 0.1, 0.2]"))  # 12 members
    out = tmp_path / "s.nc"
    parts = tmp_path / "s.nc.parts"
    proc = subprocess.Popen([sys.executable, "-m", "warpfric", "run", str(sweep), "-o", str(out), "--chunk", "1",
                             "--device", DEVICE, "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 240
    while time.time() < deadline and not (parts / "chunk-000001.nc").exists():
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = sorted(parts.glob("chunk-*.nc"))
    assert 2 <= len(finished) < 12 and not out.exists()
    res = _cli("info", str(out))
    assert res.returncode == 1 and "INCOMPLETE" in res.stdout and "--resume" in res.stdout
    # plot, info of several files and open_ensemble said "run the same command again with --resume",
    # which plot and info do not take: the command itself
    with pytest.raises(ValueError, match=f"incomplete run, .* finished in .*; `warpfric run {sweep} -o {out} --resume "
                                         f"--device {DEVICE}` finishes it"):
        open_ensemble(out)
    # while a run holds the output's lock (it is still going), --resume would be refused (exit 4):
    # open_ensemble says to wait instead
    from warpfric.io import lock_output, unlock_output

    lock = lock_output(out, "warpfric run (a run still going)")
    try:
        with pytest.raises(ValueError, match=r"incomplete run, .*; its run is still going \(pid \d+ on .*\): open it "
                                             "when that ends"):
            open_ensemble(out)
    finally:
        unlock_output(lock)
    res = _cli("run", str(sweep), "-o", str(out), "--device", DEVICE)  # no --resume: refuses, exit 2
    assert res.returncode == 2 and "--resume" in res.stderr
    res = _cli("run", str(sweep), "-o", str(out), "--chunk", "1", "--device", DEVICE, "--resume")
    assert res.returncode == 0, res.stderr
    assert f"{12 - len(finished)} of them to run" in res.stderr or f"{13 - len(finished)} of them to run" in res.stderr
    resumed = open_ensemble(out)
    # its history names the interrupted command and the --resume (it named the --resume alone), each
    # once: the --resume's chunks and the file it combined share its line (it was there twice)
    history = resumed.attrs["history"].splitlines()
    assert len(history) == 2 and history[1].endswith(f"--chunk 1 --device {DEVICE} --quiet (warpfric {wf.__version__})")
    assert history[0].endswith(f"--resume (warpfric {wf.__version__})"), history
    whole = tmp_path / "whole.nc"
    assert _cli("run", str(sweep), "-o", str(whole), "--chunk", "5", "--device", DEVICE).returncode == 0
    reference = open_ensemble(whole)
    for name, var in reference.data_vars.items():
        np.testing.assert_array_equal(resumed[name].values, var.values, err_msg=name)


BAD = [
    ("[grid]\neccentricity = [0.0]\nfoo = [1.0]\n", ["foo", "accepted", "normal_force"]),  # unknown parameter
    ("[solver]\nnodez = 30\n", ["nodez", "(did you mean 'nodes'?); accepted"]),  # unknown key
    ("[grid]\neccentricty = [0.0]\n", ["eccentricty", "(did you mean 'eccentricity'?); accepted"]),
    ("[record]\nmember = [0]\n", ["member", "(did you mean 'members'?)"]),
    ("[grid]\neccentricity = [0.0]\n[run]\nchunks = 2\n", ["chunks", "(did you mean 'chunk'?)"]),
    ("colour = 'red'\n", ["colour", "accepted"]),  # unknown top-level key
    ("[solver]\nnodes = 'many'\n", ["nodes", "integer"]),  # wrong type
    ("[grid]\nnormal_force = ['a']\n", ["normal_force", "number"]),  # wrong type in a list
    ("[grid]\neccentricity = []\n", ["eccentricity", "empty"]),  # empty sweep
    ("[sample]\nn = 0\nnormal_force = {distribution = 'uniform', low = 1, high = 2}\n", ["n = 0", "an integer in [1, 2130706432]"]),
    ("[grid]\neccentricity = [0.0, 1.5]\n", ["eccentricity", "1.5", "valid range"]),  # out of range
    ("[sample]\nn = 4\nnormal_force = {distribution = 'gamma', low = 1, high = 2}\n", ["gamma", "uniform"]),
    ("[sample]\nn = 4\neccentricity = {distribution = 'uniform', low = 0.0, high = 0.9}\n",
     ["[sample] eccentricity.high = 0.9 is outside eccentricity's valid range"]),  # named, not a drawn value
    ("[sample]\nn = 4\neccentricity = {distribution = 'unifrom', low = 0.0, high = 0.1}\n",
     ['"unifrom" (did you mean "uniform"?)']),
    ("[sample]\nn = 4\neccentricity = {distribution = 'uniform', lo = 0.0, high = 0.1}\n",
     ["eccentricity.lo for uniform (did you mean 'low'?)"]),
    ("[zip]\neccentricity = [0.0, 0.1]\nnormal_force = [500.0]\n", ["zip", "length"]),
    ("[grid]\neccentricity = [0.0]\n[zip]\neccentricity = [0.1]\n", ["eccentricity", "twice"]),
    ("[scene]\nnormal_force = -5.0\n", ["normal_force", "-5.0", "valid range"]),
    ("[fronts]\nthreshold = 2.0\n", ["threshold", "(0, 1)"]),
    ("[fronts]\nthreshold = \"0.4\"\n", [': [fronts] threshold = "0.4": expected a number']),  # the table once
    ("[run]\nchunk = 1979-05-27\n[grid]\neccentricity = [0.0]\n", ["[run] chunk = 1979-05-27: expected an integer"]),  # a TOML date as written
    ("[fronts]\nevent = ['contact', 3]\n", ['[fronts] event = ["contact", 3]: expected an event name or a list']),
    # refused at load, not after the run's first line (inside its first chunk)
    ("[solver]\ndtype = 'float32'\n[grid]\neccentricity = [0.0]\n", ["'float32' is invalid with relaxation_gate='stress'"]),
    ("[fronts]\nevent = ['contact', 'strenght']\n", ["strenght"]),
    # the velocity front reads TR-BDF2's second stage: a traceback inside the first chunk (exit 1) before
    ("[solver]\nmethod = 'esdirk4'\n[fronts]\nevent = ['contact', 'velocity']\n[grid]\neccentricity = [0.0]\n",
     ["'event' = ('contact', 'velocity') is invalid with solver setting 'method' = 'esdirk4'", "method='tr_bdf2'"]),
]


@pytest.mark.parametrize("body, words", [
    ("[grid]\neccentricity = [0.0, 0.0, 0.1]\n", "[grid] eccentricity repeats a value (eccentricity = 0: 2 times)"),
    ("[zip]\neccentricity = [0.0, 0.0]\nnormal_force = [500.0, 500.0]\n",
     "[zip] repeats a row (eccentricity = 0, normal_force = 500: 2 times)"),
])
def test_a_sweep_file_that_repeats_members_is_warned(tmp_path, body, words):
    """Repeated members ran without a word, and by_parameters then refused the file."""
    from warpfric.sweep_file import load_sweep

    path = tmp_path / "s.toml"
    path.write_text(body)
    with pytest.warns(UserWarning, match=re.escape(words)):
        load_sweep(path)
    path.write_text("[grid]\neccentricity = [0.0, 0.1]\nnormal_force = [500.0, 600.0]\n[zip]\n"
                    "aging_coefficient = [0.05, 0.05]\nmemory_length = [5e-7, 6e-7]\n")  # distinct members
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert load_sweep(path).n_members == 8


def test_a_long_blocks_repeats_are_found_without_sorting_its_rows(tmp_path, monkeypatch):
    """Above REPEAT_CHECK_ROWS rows (ranges: a list that long is not typed) np.unique's copies and sort
    took several times the values' memory after the memory check had passed them: such a block
    repeats where all its columns are constant (a range's start equals its stop), said without it."""
    import warpfric.sweep_file as sweep_file

    monkeypatch.setattr(sweep_file, "REPEAT_CHECK_ROWS", 4)
    monkeypatch.setattr(sweep_file.np, "unique", lambda *a, **k: pytest.fail("sorted a long block's rows"))
    path = tmp_path / "s.toml"
    path.write_text("[zip]\neccentricity = {start = 0.1, stop = 0.1, num = 5}\n"
                    "normal_force = {start = 500, stop = 500, num = 5}\n")
    with pytest.warns(UserWarning, match=re.escape("[zip] repeats a row (eccentricity = 0.1, normal_force = 500: 5 "
                                                   "times)")):
        sweep_file.load_sweep(path)
    path.write_text("[zip]\neccentricity = {start = 0.1, stop = 0.1, num = 5}\n"
                    "normal_force = {start = 500, stop = 900, num = 5}\n")  # distinct rows
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert sweep_file.load_sweep(path).n_members == 5


def test_a_sweep_file_may_ask_for_several_front_events(tmp_path):
    """[fronts] event = ["contact", "strength"] was refused ("expected a string"), although docs/sweeps.md
    speaks of every front event in the file and Fronts takes several."""
    from warpfric.sweep_file import load_sweep

    path = tmp_path / "s.toml"
    path.write_text("[fronts]\nevent = ['contact', 'strength']\n[grid]\neccentricity = [0.0]\n")
    assert load_sweep(path).fronts.events == ("contact", "strength")


def test_a_sample_may_reach_an_open_upper_limit():
    """Uniform draws lie below high, so high may be the open upper limit of a parameter's range
    (poisson_ratio < 0.5); low may not, nor a high beyond it."""
    from warpfric.sweep_file import SweepError

    draws = load_sweep_text("[sample]\nn = 64\npoisson_ratio = {distribution = 'uniform', low = 0.3, high = 0.5}\n")
    assert ((draws >= 0.3) & (draws < 0.5)).all() and draws.size == 64
    with pytest.raises(SweepError, match="poisson_ratio.low = 0.5 is outside"):
        load_sweep_text("[sample]\nn = 4\npoisson_ratio = {distribution = 'uniform', low = 0.5, high = 0.6}\n")


def load_sweep_text(text):
    """The poisson_ratio values a sweep file's text draws."""
    import tempfile

    from warpfric.members import resolve_members
    from warpfric.sweep_file import load_sweep

    path = Path(tempfile.mkdtemp()) / "s.toml"
    path.write_text(text)
    sweep = load_sweep(path)
    values, _ = resolve_members(sweep.members, sweep.scene)
    return values["poisson_ratio"]


@pytest.mark.parametrize("text, words", BAD)
def test_bad_sweep_files_exit_2_with_one_line_and_no_output(tmp_path, capsys, text, words):
    sweep = tmp_path / "bad.toml"
    sweep.write_text(text)
    out = tmp_path / "bad.nc"
    code = main(["run", str(sweep), "-o", str(out), "--device", "cpu"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("warpfric: error:"), err
    for word in words:
        assert word in err[0], (word, err[0])
    assert not out.exists() and not (tmp_path / "bad.nc.parts").exists()


def test_existing_output_is_not_overwritten(tmp_path, capsys):
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY)
    out = tmp_path / "s.nc"
    out.write_text("precious")
    assert main(["run", str(sweep), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "exists" in err and "--overwrite" in err and out.read_text() == "precious"
    assert main(["info", str(tmp_path / "missing.nc")]) == 2
    assert "no such file" in capsys.readouterr().err


def test_example_sweeps_parse():
    """Every example sweep file parses; a [design] file needs SALib (the test extra), and without
    it (a host with the core packages only) refuses with the install hint instead."""
    import importlib.util

    from warpfric.sensitivity import DesignError
    from warpfric.sweep import load_sweep

    files = sorted(Path(__file__).resolve().parents[1].glob("studies/sweeps/*.toml"))
    assert len(files) >= 6
    have_salib = importlib.util.find_spec("SALib") is not None
    sizes = {}
    for f in files:
        if not have_salib and "[design]" in f.read_text():
            with pytest.raises(DesignError, match=r'pip install "warpfric\[sensitivity\]"'):
                load_sweep(f)
            continue
        sizes[f.stem] = load_sweep(f).n_members
    assert sizes["map_gpu"] >= 10_000 and sizes["tiny"] == 6 and sizes["fig4_eccentricity"] == 29


def test_progress_on_a_terminal_of_zero_size(tmp_path):
    """A chunked run under a pseudo-terminal nobody sized (`script -qc "warpfric run ..."`: stty size
    0 0): every chunk draws its bar, 80 columns wide, instead of an empty line, its counts whole."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY)
    master, slave = os.openpty()
    if tuple(os.get_terminal_size(slave)) != (0, 0):
        pytest.skip("this system sizes a new pseudo-terminal")
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen([sys.executable, "-m", "warpfric", "run", str(sweep), "-o", str(tmp_path / "s.nc"),
                             "--chunk", "3", "--device", DEVICE], stdin=slave, stdout=slave, stderr=slave,
                            env={**env, "PYTHONWARNINGS": "ignore"})
    os.close(slave)
    data = b""
    while True:
        try:
            block = os.read(master, 65536)
        except OSError:  # the child closed the terminal (Linux: EIO)
            break
        if not block:
            break
        data += block
    os.close(master)
    assert proc.wait(timeout=300) == 0, data
    lines = data.decode().replace("\r\n", "\n").split("\n")
    bars = [line.split("\r")[-1] for line in lines if "chunk 1/2" in line or "chunk 2/2" in line]
    # at 80 columns the label gives way to the counts (the tool's name, then the member range: the
    # chunk's number stays): each ends whole
    assert [bar[:9] for bar in bars] == ["chunk 1/2", "chunk 2/2"], lines
    assert all("100.0%|" in bar and len(bar) == 80 and bar.endswith("3/3 done]") for bar in bars), bars
    assert "" not in [line.strip() for line in lines[:-1]], lines


def test_info_and_run_speak_plainly(tmp_path, capsys):
    """One member and one chunk in the singular, the swept parameters in the sweep file's order
    (its [grid] lists eccentricity first), no trailing blanks, and a short run's wall time in two
    significant digits."""
    sweep = tmp_path / "s.toml"
    sweep.write_text("[model]\nrelaxation_gate = 'none'\n[solver]\nnodes = 11\n[grid]\neccentricity = [0.0, 0.1]\n"
                     "normal_force = [500.0, 600.0]\n")  # the gate-less law: no contact front, 0 of 4 present
    assert main(["run", str(sweep), "-o", str(tmp_path / "s.nc"), "--device", DEVICE, "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "4 members (numbers 0..3) in 1 chunk of <= 4 members," in err and "swept: eccentricity, normal_force" in err
    assert main(["info", str(tmp_path / "s.nc")]) == 0
    lines = capsys.readouterr().out.splitlines()
    swept = lines.index("  swept parameters:")
    assert [line.split()[0] for line in lines[swept + 1:swept + 3]] == ["eccentricity", "normal_force"]
    assert "  first front's middle segment present in 0/4 members" in lines
    assert "  second front present in 0/4 members" in lines and not [line for line in lines if line != line.rstrip()]
    one = tmp_path / "one.toml"
    one.write_text("fronts = false\n[scene]\n[solver]\nnodes = 11\n")
    assert main(["run", str(one), "-o", str(tmp_path / "one.nc"), "--member-offset", "7", "--device", DEVICE,
                 "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "1 member (number 7) in 1 chunk of <= 1 member," in err and "(1 member, " in err, err
    ds = open_ensemble(tmp_path / "one.nc")
    ds.attrs["wall_time_s"] = 0.0432
    text = summary(ds, "one.nc")
    assert text.startswith("one.nc: 1 member (number 7), 11 nodes, complete") and "wall 0.043 s" in text, text


def test_a_chunked_sweep_warns_once_of_its_members_not_ok(tmp_path, capsys):
    """Each chunk warned of its own failed members (92 of 100, then 46 of 100, ...: a run of many
    chunks, many warnings): one warning for the sweep, with its totals, once the file is written."""
    sweep = tmp_path / "fail.toml"
    sweep.write_text("[solver]\nnodes = 11\nmax_steps = 50\n[grid]\neccentricity = [-0.2, -0.1, 0.0, 0.1, 0.2, 0.15]\n")
    code = main(["run", str(sweep), "-o", str(tmp_path / "fail.nc"), "--chunk", "2", "--device", "cpu", "--quiet"])
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "members that did not end ok" in line]
    assert code == 1 and len(warned) == 1, err
    assert "6 of 6 members: 6 max_steps_reached" in warned[0] and "warpfric info" in warned[0]


def test_a_chunked_sweep_says_it_combines_and_counts_the_combine_in_its_time(tmp_path, capsys):
    """The combine of the chunk files ran without a word (22 s for 100 chunks, after the last chunk's
    line) and the final line's time left it out: a line says it starts, and the final line gives the
    chunks' time and the combine's apart, each a number of seconds. A sweep of one chunk has no
    combine to tell (--quiet leaves out the line that it starts, as it does the chunks' lines)."""
    import re

    sweep = tmp_path / "s.toml"
    sweep.write_text("[solver]\nnodes = 11\n[grid]\neccentricity = [-0.1, 0.0, 0.1]\n")
    assert main(["run", str(sweep), "-o", str(tmp_path / "s.nc"), "--chunk", "1", "--device", "cpu"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert f"warpfric: combining the 3 chunk files into {tmp_path / 's.nc'}" in err, err
    wrote = [line for line in err if line.startswith("warpfric: wrote")]
    assert len(wrote) == 1 and re.search(r"\(3 members, [0-9.e+-]+ s running chunks now and [0-9.e+-]+ s combining 3 "
                                         r"chunk files, 0 failed members", wrote[0]), wrote
    assert main(["run", str(sweep), "-o", str(tmp_path / "one.nc"), "--device", "cpu", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "combining" not in err and "s running chunks now, 0 failed" in err, err


def test_a_worker_names_the_gpus_it_has_when_a_pinned_one_is_missing(monkeypatch):
    """A pinned cuda:3 on a worker that sees one GPU (dask-cuda shows each worker its own, as cuda:0)
    raised check_device's ValueError inside simulate, logged by distributed with its traceback for
    every chunk; it is warpfric's one-line fault, naming the worker's GPUs (a GPU-less worker's too)."""
    import warp as wp

    from warpfric.runner import RunError, _worker_device_for

    monkeypatch.setattr(wp, "init", lambda: None)
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 1)
    monkeypatch.setattr(wp, "get_cuda_devices", lambda: ["cuda:0"])
    assert _worker_device_for("cuda:0", "chunk 1/2") == "cuda:0" and _worker_device_for("cuda", "chunk 1/2") == "cuda"
    with pytest.raises(RunError, match=r"chunk 1/2 \(members 0..1\): device cuda:3 asked for, but this worker "
                                       r"\(pid \d+\) has cuda:0 only"):
        _worker_device_for("cuda:3", "chunk 1/2 (members 0..1)")
    monkeypatch.setattr(wp, "get_cuda_device_count", lambda: 0)
    with pytest.raises(RunError, match="has no CUDA device"):
        _worker_device_for("cuda:0", "loading the kernels")
