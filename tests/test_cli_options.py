"""The command line does what it is told or says why not (issue 22, part 2): scene options with a
sweep file are refused (as --grid-check is) naming the sweep-file key, options that do not apply
without a sweep file are refused, negative numbers follow their option, --cpu-workers reaches
simulate(workers=...), and every option and argument has help text."""

import importlib

import pytest
from conftest import DEVICE, one_line_error, run_cli, TINY_SWEEP

from warpfric.cli import build_parser, join_negative_values, main
from warpfric.io import open_ensemble

SIMULATE_MODULE = importlib.import_module("warpfric.simulate")



@pytest.fixture
def no_simulation(monkeypatch):
    monkeypatch.setattr(SIMULATE_MODULE, "simulate", lambda *a, **k: pytest.fail("simulate() ran"))


@pytest.mark.parametrize("args, words", [
    (["--nodes", "21"], ["--nodes", "[solver] nodes = 21"]),
    (["--rtol", "1e-3"], ["--rtol", "[solver] rtol = 0.001"]),
    (["--eccentricity", "0.3"], ["--eccentricity", "[scene] eccentricity = 0.3"]),
    (["--disc-velocity", "-1e-4"], ["--disc-velocity", "[scene] disc_velocity = -0.0001"]),
    (["--normal-force", "500"], ["--normal-force", "[scene] normal_force = 500"]),
    (["--end-time", "25"], ["--end-time", "[scene] end_time = 25"]),
    (["--dtype", "float32"], ["--dtype", "[solver] dtype = 'float32'"]),
    (["--relaxation-gate", "none"], ["--relaxation-gate", "[model] relaxation_gate = 'none'"]),
    (["--grid-check"], ["--grid-check", "[fronts] grid_check = true"]),
    (["--nodes", "21", "--rtol", "1e-3", "--eccentricity", "0.3"],  # the case: all three named
     ["--eccentricity, --nodes, --rtol", "[scene] eccentricity = 0.3, [solver] nodes = 21, [solver] rtol = 0.001"]),
])
def test_scene_options_with_a_sweep_file_are_refused(tmp_path, capsys, no_simulation, args, words):
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY_SWEEP)
    code, out, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", *args)
    assert code == 2 and out == []
    one_line_error(err, *words, "default scene only", str(sweep))
    assert [p.name for p in tmp_path.iterdir()] == ["s.toml"]


@pytest.mark.parametrize("args, words", [
    (["--resume"], ["--resume", "sweep file"]),
    (["--chunk", "3"], ["--chunk", "sweep file"]),
    (["--resume", "--chunk", "3"], ["sweep file"]),
    (["--overwrite"], ["--overwrite", "-o OUT.nc"]),
    (["--cpu-workers", "0"], ["--cpu-workers 0", "integer >= 1"]),
])
def test_options_that_do_not_apply_without_a_sweep_file_are_refused(tmp_path, capsys, no_simulation, args, words):
    out = [] if "--overwrite" in args else ["-o", tmp_path / "x.nc"]
    code, stdout, err = run_cli(capsys, "run", *out, *args)
    assert code == 2 and stdout == []
    one_line_error(err, *words)
    assert list(tmp_path.iterdir()) == []


def test_cpu_workers_is_refused_on_a_dask_cluster(tmp_path, capsys, no_simulation):
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY_SWEEP)
    code, _, err = run_cli(capsys, "run", sweep, "--cpu-workers", 2, "--local-cluster")
    assert code == 2
    one_line_error(err, "--cpu-workers", "Dask")


@pytest.mark.parametrize("words, expected", [
    (["run", "--disc-velocity", "-1e-4"], ["run", "--disc-velocity=-1e-4"]),
    (["run", "--eccentricity", "-.2", "--quiet"], ["run", "--eccentricity=-.2", "--quiet"]),
    (["run", "--disc-velocity", "-1E+2"], ["run", "--disc-velocity=-1E+2"]),
    (["run", "--end-time", "-inf"], ["run", "--end-time=-inf"]),
    (["run", "--quiet", "-1e-4"], ["run", "--quiet", "-1e-4"]),  # a flag takes no value: left alone
    (["run", "-o", "-x.nc"], ["run", "-o", "-x.nc"]),  # not a number
])
def test_negative_numbers_are_joined_to_their_option(words, expected):
    _, value_options = build_parser()
    assert join_negative_values(words, value_options) == expected


def test_a_negative_disc_velocity_runs(tmp_path, capsys):
    code, out, err = run_cli(capsys, "run", "--disc-velocity", "-1e-4", "--eccentricity", "-0.2", "--nodes", 11,
                           "-o", tmp_path / "neg.nc", "--device", DEVICE, "--quiet")
    assert code == 0, err
    assert out[0].startswith("scene: F = 1000 N, 2e/L = -0.2, v_d = -0.0001 m/s")
    ds = open_ensemble(tmp_path / "neg.nc")
    assert float(ds.disc_velocity) == -1e-4 and float(ds.eccentricity) == -0.2
    assert "--disc-velocity -1e-4" in ds.attrs["history"]  # the command as typed


def test_cpu_workers_reach_simulate(tmp_path, capsys):
    """--cpu-workers 2 splits a sweep's members over two worker processes (the file says so), and
    the default scene passes it on to simulate(workers=...)."""
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY_SWEEP)
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--cpu-workers", 2, "--device", "cpu",
                         "--quiet")
    assert code == 0, err
    assert int(open_ensemble(tmp_path / "s.nc").attrs["workers"]) == 2
    code, _, err = run_cli(capsys, "run", "--nodes", 11, "--cpu-workers", 1, "--device", "cpu", "--quiet")
    assert code == 0, err


def _actions(parser):
    for action in parser._actions:  # noqa: SLF001 - argparse lists its arguments only here
        if action.choices and isinstance(action.choices, dict):  # the subcommands
            for sub in action.choices.values():
                yield from _actions(sub)
        else:
            yield parser.prog, action


def test_every_option_and_argument_has_help():
    parser, _ = build_parser()
    seen = [(prog, action.dest, action.help) for prog, action in _actions(parser)]
    assert len(seen) > 30
    missing = [(prog, dest) for prog, dest, text in seen if not text or not text.strip()]
    assert missing == []
    dests = {(prog.split()[-1], dest) for prog, dest, _ in seen}
    assert {("run", "dtype"), ("info", "file"), ("plot", "file"), ("run", "cpu_workers"), ("run", "sweep")} <= dests


def test_help_shows_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for code in ("0 ", "1 ", "2 ", "3 ", "4 ", "130"):
        assert f"\n  {code}" in text, code
