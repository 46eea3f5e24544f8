"""Outputs a user can trust (issue 11, items 5 and 6): files that pass a CF checker, member numbers
that survive combining runs (--member-offset, [run] member_offset, chunks), recorded fields that
combine with xr.open_mfdataset, and the command line's answers to an interrupted run, a bad
--chunk, a file that is not netCDF and an empty sweep file."""

import importlib
import json
import shlex

import netCDF4
import numpy as np
import pytest
import xarray as xr
from conftest import DEVICE, one_line_error, run, run_cli

import warpfric as wf
from warpfric.io import COMBINE_KWARGS, open_ensemble, open_ensembles, write_ensemble

SIMULATE_MODULE = importlib.import_module("warpfric.simulate")  # (warpfric.simulate is also the function)

SWEEP = """
title = "files test"
fronts = false
[solver]
nodes = 11
[grid]
eccentricity = [-0.2, 0.0, 0.2]
[record]
members = [1, 2]
start = 20.2
stop = 20.3
count = 5
"""




def _cf_failures(path, tmp_path) -> list:
    """Failed checks (all priorities) of the IOOS compliance checker's CF-1.8 suite on ``path``."""
    runner = pytest.importorskip("compliance_checker.runner",
                                 reason="compliance-checker (the CF checker of the test extra) is not installed")
    runner.CheckSuite.load_all_available_checkers()
    report = tmp_path / f"{path.stem}_cf.json"
    runner.ComplianceChecker.run_checker(str(path), ["cf:1.8"], 0, "normal", output_filename=str(report),
                                         output_format="json_new")
    result = json.loads(report.read_text())[str(path)]["cf:1.8"]
    assert result["possible_points"] > 100, result.get("errors")  # the suite did run
    return [(level, item["name"], item["msgs"]) for level in ("high_priorities", "medium_priorities", "low_priorities")
            for item in result[level] if item["value"][0] < item["value"][1]]


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # compliance-checker's own (its ioos_sos plugin)
def test_written_files_pass_the_cf_checker(tmp_path, capsys):
    ds = run({"eccentricity": [-0.1, 0.1]}, nodes=11, fronts=wf.Fronts(),
             record=wf.Record.window(20.2, 20.3, 5, members=(1,)))
    plain = tmp_path / "plain.nc"
    # control: what xarray writes by itself is flagged, so the checker is live (one variable with its
    # float coordinate x: the checker's time grows with the variables, 16 s for all ~110 here)
    ds[["displacement"]].to_netcdf(plain)
    assert any("_FillValue" in " ".join(msgs) for _, _, msgs in _cf_failures(plain, tmp_path))
    path = write_ensemble(ds, tmp_path / "api.nc")
    assert _cf_failures(path, tmp_path) == []
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "cli.nc", "--chunk", 2, "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert _cf_failures(tmp_path / "cli.nc", tmp_path) == []
    for name in ("api.nc", "cli.nc"):
        with netCDF4.Dataset(tmp_path / name) as nc:
            assert nc.Conventions == "CF-1.8"
            assert "warpfric" in nc.history and nc.history[:4].isdigit()
            recorded = nc.groups["recorded"]  # the recorded fields: a group of their own
            for vname, var in [*nc.variables.items(), *recorded.variables.items()]:
                assert var.dtype not in (np.int64, np.uint64), (name, vname)
                assert "long_name" in var.ncattrs(), (name, vname)
                # short enough for a plot's axis label (xarray's long_name [units]); the rest in comment
                assert len(var.long_name) <= 85, (name, vname, var.long_name)
                assert "units" in var.ncattrs() or "flag_values" in var.ncattrs(), (name, vname)
                if "flag_values" in var.ncattrs():
                    assert np.asarray(var.flag_values).dtype == var.dtype, (name, vname)
                    assert len(var.flag_values) == len(var.flag_meanings.split()), (name, vname)
            for group, coord in ((nc, "member"), (nc, "x"), (recorded, "record_time"), (recorded, "recorded_member"),
                                 (recorded, "x")):
                assert "_FillValue" not in group.variables[coord].ncattrs(), (name, coord)
    with netCDF4.Dataset(tmp_path / "cli.nc") as nc:
        assert nc.history.split(": ", 1)[1].startswith(f"warpfric run {sweep} -o ")


def _two_runs(tmp_path, capsys, second_offset_in_file: bool):
    """The sweep run twice, chunked: numbers 0..2, then 3..5 (--member-offset or [run] member_offset)."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", a, "--chunk", 2, "--device", DEVICE, "--quiet")
    assert code == 0, err
    if second_offset_in_file:
        sweep_b = tmp_path / "s_b.toml"
        sweep_b.write_text(SWEEP + "[run]\nmember_offset = 3\n")
        code, _, err = run_cli(capsys, "run", sweep_b, "-o", b, "--chunk", 2, "--device", DEVICE, "--quiet")
    else:
        code, _, err = run_cli(capsys, "run", sweep, "-o", b, "--chunk", 2, "--member-offset", 3, "--device", DEVICE,
                             "--quiet")
    assert code == 0, err
    assert "numbers 3..5" in err[0]
    return a, b


def test_chunk_lines_name_the_member_numbers_of_an_offset_run(tmp_path, capsys):
    """Each chunk's line and the summary give the members' numbers (offset included), not their
    positions in the sweep."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "b.nc", "--chunk", 2, "--member-offset", 3,
                           "--device", DEVICE)
    assert code == 0, err
    chunk_lines = [line for line in err if line.startswith("warpfric chunk")]
    assert [line.split(":")[0] for line in chunk_lines] == ["warpfric chunk 1/2 (members 3..4)",
                                                            "warpfric chunk 2/2 (member 5)"], err


@pytest.mark.parametrize("new_defaults", [False, True])
@pytest.mark.parametrize("offset_in_file", [False, True])
def test_runs_with_member_offsets_combine_with_open_mfdataset(tmp_path, capsys, offset_in_file, new_defaults):
    pytest.importorskip("dask")
    a, b = _two_runs(tmp_path, capsys, offset_in_file)
    first, second = open_ensemble(a), open_ensemble(b)
    np.testing.assert_array_equal(first.member.values, [0, 1, 2])
    np.testing.assert_array_equal(second.member.values, [3, 4, 5])
    assert first.member.dtype == np.int32 and list(second.recorded_member.values) == [4, 5]
    assert second.velocity_history.dims == ("recorded", "time", "x")  # simulate()'s layout, back from the file
    # the call docs/sweeps.md gives, spelled out (= COMBINE_KWARGS), under both xarray combine defaults
    kwargs = dict(combine="nested", concat_dim="member", data_vars="minimal", coords="minimal",
                  compat="no_conflicts", join="outer")
    assert kwargs == COMBINE_KWARGS
    with xr.set_options(use_new_combine_kwarg_defaults=new_defaults), xr.open_mfdataset([a, b], **kwargs) as both:
        np.testing.assert_array_equal(both.member_number.values, [0, 1, 2, 3, 4, 5])  # member: their labels
        np.testing.assert_array_equal(both.eccentricity.values, [-0.2, 0.0, 0.2] * 2)
        np.testing.assert_array_equal(both.mu_s.values, np.concatenate([first.mu_s.values, second.mu_s.values]))
        assert "velocity_history" not in both  # the recorded fields are a group of their own
    # the recorded fields (netCDF4 group "recorded"), at xarray's defaults
    with xr.set_options(use_new_combine_kwarg_defaults=new_defaults), \
            xr.open_mfdataset([a, b], group="recorded") as recorded:
        np.testing.assert_array_equal(recorded.recorded_member_number.values, [1, 2, 4, 5])
        assert recorded.velocity_history.dims == ("recorded_member", "record_time", "x")
        np.testing.assert_array_equal(recorded.velocity_history.values, np.concatenate(
            [first.velocity_history.values, second.velocity_history.values]))
    combined = open_ensembles([a, b])  # the helper: the same ensemble, in simulate()'s layout
    np.testing.assert_array_equal(combined.member.values, [0, 1, 2, 3, 4, 5])
    np.testing.assert_array_equal(combined.recorded_member.values, [1, 2, 4, 5])
    np.testing.assert_array_equal(combined.velocity_history.values,
                                  np.concatenate([first.velocity_history.values, second.velocity_history.values]))


def test_repeated_member_numbers_are_kept_or_refused_never_dropped(tmp_path, capsys):
    pytest.importorskip("dask")
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP.split("[record]")[0])  # no recorded fields
    other = tmp_path / "o.toml"
    other.write_text(sweep.read_text().replace("[-0.2, 0.0, 0.2]", "[0.1, 0.3, 0.4]"))
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    for s, out in ((sweep, a), (other, b)):  # both numbered 0..2: the user forgot --member-offset
        code, _, err = run_cli(capsys, "run", s, "-o", out, "--device", DEVICE, "--quiet")
        assert code == 0, err
    with xr.open_mfdataset([a, b], **COMBINE_KWARGS) as both:  # xarray keeps all six, apart by their labels
        np.testing.assert_array_equal(both.member_number.values, [0, 1, 2, 0, 1, 2])
        assert np.unique(both.member.values).size == 6
        np.testing.assert_array_equal(both.eccentricity.values, [-0.2, 0.0, 0.2, 0.1, 0.3, 0.4])
    with pytest.raises(ValueError, match="member numbers 0, 1, 2 occur more than once.*--member-offset"):
        open_ensembles([a, b])
    code, out, err = run_cli(capsys, "info", a, b)
    one_line_error(err, "more than once", str(a), str(b), "--member-offset")
    assert code == 2 and out == []


def test_recorded_fields_with_repeated_numbers_do_not_merge_silently(tmp_path, capsys):
    """Same member numbers in two runs: their recorded fields stay apart under their members' labels."""
    pytest.importorskip("dask")
    sweep, other = tmp_path / "s.toml", tmp_path / "o.toml"
    sweep.write_text(SWEEP)
    other.write_text(SWEEP.replace("[-0.2, 0.0, 0.2]", "[0.1, 0.3, 0.4]"))
    for s, out in ((sweep, "a.nc"), (other, "b.nc")):
        assert run_cli(capsys, "run", s, "-o", tmp_path / out, "--device", DEVICE, "--quiet")[0] == 0
    paths = [tmp_path / "a.nc", tmp_path / "b.nc"]
    with xr.open_mfdataset(paths, group="recorded") as recorded:
        np.testing.assert_array_equal(recorded.recorded_member_number.values, [1, 2, 1, 2])
        np.testing.assert_array_equal(recorded.velocity_history.values, np.concatenate(
            [open_ensemble(p).velocity_history.values for p in paths]))
        with xr.open_mfdataset(paths) as both:
            assert set(recorded.recorded_member.values) <= set(both.member.values)  # labels of members


def test_combining_runs_of_different_constant_parameters_makes_them_vary(tmp_path):
    a = run({"eccentricity": [0.0, 0.1]}, scene=wf.Parameters(normal_force=500.0), nodes=11)
    b = wf.simulate({"eccentricity": [0.0, 0.1]}, scene=wf.Parameters(normal_force=900.0),
                    solver=wf.Solver(nodes=11, rtol=1e-6), fronts=None, device=DEVICE, progress=False, member_offset=2)
    write_ensemble(a, tmp_path / "a.nc")
    write_ensemble(b, tmp_path / "b.nc")
    assert open_ensemble(tmp_path / "a.nc").normal_force.dims == ()  # constant within each file
    both = open_ensembles([tmp_path / "a.nc", tmp_path / "b.nc"])
    np.testing.assert_array_equal(both.normal_force.values, [500.0, 500.0, 900.0, 900.0])
    assert both.attrs["varying_parameters"].split() == ["normal_force", "eccentricity"]
    c = run({"eccentricity": [0.0, 0.1]}, nodes=11, rtol=1e-5)
    c = c.assign_coords(member=c.member + 4)
    write_ensemble(c, tmp_path / "c.nc")
    with pytest.raises(ValueError, match="solver_rtol"):
        open_ensembles([tmp_path / "a.nc", tmp_path / "c.nc"])


def test_member_offset_of_the_default_run_and_a_scene_only_sweep(tmp_path, capsys):
    out = tmp_path / "d.nc"
    code, _, err = run_cli(capsys, "run", "-o", out, "--nodes", 11, "--member-offset", 7, "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert open_ensemble(out).member.values.tolist() == [7]
    scene = tmp_path / "scene.toml"
    scene.write_text("fronts = false\n[scene]\nnormal_force = 800.0\n[solver]\nnodes = 11\n[run]\nmember_offset = 5\n")
    code, _, err = run_cli(capsys, "run", scene, "-o", tmp_path / "scene.nc", "--device", DEVICE, "--quiet")
    assert code == 0, err
    ds = open_ensemble(tmp_path / "scene.nc")
    assert ds.member.values.tolist() == [5] and float(ds.normal_force) == 800.0


@pytest.mark.parametrize("args, words", [
    (["--member-offset", "-1"], ["--member-offset = -1", "[0, "]),
    (["--member-offset", str(2**31)], ["--member-offset", str(2**31), "int32"]),
    (["--chunk", "0"], ["--chunk 0", "integer >= 1"]),
    (["--chunk", "-3"], ["--chunk -3", "integer >= 1"]),
])
def test_bad_chunk_and_offset_options_exit_2(tmp_path, capsys, args, words):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    out = tmp_path / "s.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--device", DEVICE, *args)
    assert code == 2
    one_line_error(err, *words)
    assert not out.exists() and not (tmp_path / "s.nc.parts").exists()


@pytest.mark.parametrize("table, words", [
    ("[run]\nchunk = 0\n", ["[run] chunk = 0", "integer >= 1"]),
    ("[run]\nmember_offset = -4\n", ["[run] member_offset = -4", "[0, "]),
])
def test_bad_run_table_exits_2(tmp_path, capsys, table, words):
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP + table)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--device", DEVICE)
    assert code == 2
    one_line_error(err, *words)
    assert list(tmp_path.iterdir()) == [sweep]


@pytest.mark.parametrize("text", ["", "# nothing yet\n", 'title = "forgot the grid"\n[solver]\nnodes = 11\n'])
def test_empty_sweep_file_is_refused(tmp_path, capsys, text):
    sweep = tmp_path / "empty.toml"
    sweep.write_text(text)
    code, out, err = run_cli(capsys, "run", sweep, "--device", DEVICE)
    assert code == 2 and out == []
    one_line_error(err, "empty.toml", "nothing to run", "[grid]", "[sample]", "[design]", "[scene]")
    assert list(tmp_path.iterdir()) == [sweep]


@pytest.mark.parametrize("content", [b"this is not netCDF\n", b"", b"\x89HDF\r\n\x1a\n" + bytes(100)])
def test_info_on_a_file_that_is_not_netcdf(tmp_path, capsys, content):
    path = tmp_path / "junk.nc"
    path.write_bytes(content)
    code, out, err = run_cli(capsys, "info", path)
    assert code == 2 and out == []
    one_line_error(err, str(path), "not a readable netCDF file")


def test_info_on_netcdf_that_is_not_an_ensemble_and_on_a_folder(tmp_path, capsys):
    xr.Dataset({"a": ("x", [1.0, 2.0])}).to_netcdf(tmp_path / "other.nc")
    code, _, err = run_cli(capsys, "info", tmp_path / "other.nc")
    assert code == 2
    one_line_error(err, "not a warpfric ensemble", "another program")
    xr.Dataset({"a": ("member", [1.0, 2.0])}, attrs={"warpfric_version": "0"}).to_netcdf(tmp_path / "cut.nc")
    code, _, err = run_cli(capsys, "info", tmp_path / "cut.nc")
    assert code == 2
    one_line_error(err, "not a complete warpfric ensemble")
    (tmp_path / "dir.nc").mkdir()
    code, _, err = run_cli(capsys, "info", tmp_path / "dir.nc")
    assert code == 2
    one_line_error(err, "folder")


def test_info_prints_a_resume_command_that_works(tmp_path, capsys, monkeypatch):
    """Interrupt a chunked run (Ctrl-C in the second chunk), then run exactly what info prints:
    the chunk size and the member offset come from the manifest."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(SWEEP)
    out = tmp_path / "s.nc"
    real = SIMULATE_MODULE.simulate
    calls = []

    def interrupted(*args, **kwargs):
        if "member_offset" not in kwargs:  # the kernel warm-up before the chunks (runner.prepare_worker)
            return real(*args, **kwargs)
        calls.append(kwargs["member_offset"])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(SIMULATE_MODULE, "simulate", interrupted)
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 1, "--member-offset", 10, "--device", DEVICE,
                         "--quiet")
    assert code == 130 and "--resume" in err[-1] and calls == [10, 11]
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", real)
    code, lines, _ = run_cli(capsys, "info", out)
    assert code == 1 and "INCOMPLETE" in lines[0] and "1/3 chunks" in lines[0]
    command = shlex.split(lines[0].split("`")[1])
    assert command[:2] == ["warpfric", "run"] and "--resume" in command and "--chunk" not in command
    code, _, err = run_cli(capsys, *command[1:], "--chunk", 2)  # another chunk size: refused, names it
    assert code == 2
    one_line_error(err, "chunk size (1, now 2)", "--overwrite")
    code, _, err = run_cli(capsys, *command[1:], "--quiet")
    assert code == 0, err
    assert "(numbers 10..12) in 3 chunks of <= 1 member, 2 of them to run" in err[0]
    ds = open_ensemble(out)
    assert ds.member.values.tolist() == [10, 11, 12] and ds.recorded_member.values.tolist() == [11, 12]
    assert ds.attrs["chunks"] == 3 and "--resume" in ds.attrs["history"]
    whole = real({"eccentricity": [-0.2, 0.0, 0.2]}, solver=wf.Solver(nodes=11), fronts=None, device=DEVICE,
                 progress=False, record=wf.Record.window(20.2, 20.3, 5, members=(1, 2)))
    for name in ("mu_s", "eccentricity", "velocity_history", "friction_stress"):
        np.testing.assert_array_equal(ds[name].values, whole[name].values, err_msg=name)
