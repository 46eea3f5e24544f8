"""The command line does what it is told or says why not (issue 22, part 2): scene options with a
sweep file are refused (as --grid-check is) naming the sweep-file key, options that do not apply
without a sweep file are refused, negative numbers follow their option, --cpu-workers reaches
simulate(workers=...), --front-event picks the front, warnings are one line each and said once, and
every option and argument has help text."""

import importlib
import warnings

import pytest
from conftest import DEVICE, one_line_error, run_cli, TINY_SWEEP

from warpfric.cli import build_parser, join_negative_values, main
from warpfric.io import open_ensemble
from warpfric.parameters import Model, Solver

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
    (["--front-event", "strength"], ["--front-event", "[fronts] event = 'strength'"]),
    (["--front-event", "off"], ["--front-event", "fronts = false"]),
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
    (["--front-event", "off", "--grid-check"], ["--grid-check", "--front-event off"]),
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
    # the sweep file's own cluster: it started, and each chunk failed on its worker ("daemonic processes are not
    # allowed to have children"; --cpu-workers 1 was taken without a word); refused before anything runs
    sweep.write_text(TINY_SWEEP + '[run]\nscheduler = "local"\n')
    for n in (1, 2):
        code, _, err = run_cli(capsys, "run", sweep, "--cpu-workers", n)
        assert code == 2
        one_line_error(err, f"--cpu-workers {n}", "the sweep file's [run] scheduler = 'local'", "leave it out")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


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


def test_every_option_a_help_names_exists():
    """A --option named in a help text or description is an option of the same command (the
    --device help named --lanes, which only a Solver or a sweep file's [solver] table has)."""
    import re

    parser, _ = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")  # noqa: SLF001
    checked = 0
    for command, cmd_parser in sub.choices.items():
        options = {name for action in cmd_parser._actions for name in action.option_strings}  # noqa: SLF001
        texts = [cmd_parser.description or ""] + [action.help or "" for action in cmd_parser._actions]  # noqa: SLF001
        named = {name for text in texts for name in re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", text)}
        assert named <= options, (command, sorted(named - options))
        checked += len(named)
    assert checked >= 5  # the run command's helps name several of its options
    # the top level's description and epilog: an option of some command
    every = {name for cmd_parser in sub.choices.values() for action in cmd_parser._actions  # noqa: SLF001
             for name in action.option_strings}
    top = " ".join([parser.description or "", parser.epilog or ""])
    named = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", top))
    assert named <= every, sorted(named - every)


def test_help_shows_the_exit_codes(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for code in ("0 ", "1 ", "2 ", "3 ", "4 ", "130"):
        assert f"\n  {code}" in text, code


def test_front_event_picks_the_front(tmp_path, capsys):
    """--front-event strength reads a front under the gate-less law (the contact front has none
    there), without a warning; off computes none; the default is simulate's, the contact front."""
    out = tmp_path / "strength.nc"
    code, stdout, err = run_cli(capsys, "run", "--relaxation-gate", "none", "--front-event", "strength", "--nodes", 11,
                                "-o", out, "--device", DEVICE, "--quiet")
    assert code == 0 and not _warnings(err), err
    ds = open_ensemble(out)
    assert ds.attrs["fronts_event"] == "strength" and ds.attrs["model_relaxation_gate"] == "none"
    assert ds.front_start_time.values[0] > 20 and "strength front nucleates" in "\n".join(stdout)
    code, stdout, _ = run_cli(capsys, "run", "--front-event", "off", "--nodes", 11, "-o", tmp_path / "off.nc",
                              "--device", DEVICE, "--quiet")
    assert code == 0 and "front     : not computed (--front-event off)" in stdout
    off = open_ensemble(tmp_path / "off.nc")
    assert "v_middle" not in off and "arrival_time" not in off and "fronts_event" not in off.attrs
    code, stdout, _ = run_cli(capsys, "run", "--nodes", 11, "-o", tmp_path / "default.nc", "--device", DEVICE,
                              "--quiet")
    assert code == 0 and open_ensemble(tmp_path / "default.nc").attrs["fronts_event"] == "contact"
    assert any(line.startswith("front     : contact front nucleates") for line in stdout), stdout


def _warnings(err):
    """The warning lines of stderr: warpfric's, and Python's own ('...: UserWarning: ...')."""
    return [line for line in err if line.startswith("warpfric: warning:") or "Warning:" in line]


def test_a_warning_is_one_line_said_once(tmp_path, capsys):
    """The gate-less law's contact front (no such front): one line 'warpfric: warning: ...', no source
    line, and the front line says which option reads a front; a sweep file of three chunks (each warns,
    and so did the kernels' warm-up) says it once too."""
    code, stdout, err = run_cli(capsys, "run", "--relaxation-gate", "none", "--nodes", 11, "--device", DEVICE,
                                "--quiet")
    assert code == 0
    warned = _warnings(err)
    assert len(warned) == 1 and warned[0].startswith("warpfric: warning: fronts event 'contact' with "
                                                     "relaxation_gate='none': this law has no yield threshold"), err
    assert not any("cli.py" in line or "simulate(" in line or "UserWarning" in line for line in err), err
    assert any(line.startswith("front     : absent") and "--front-event strength" in line for line in stdout), stdout
    sweep = tmp_path / "s.toml"
    sweep.write_text(TINY_SWEEP.replace("fronts = false", "[model]\nrelaxation_gate = 'none'"))
    code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "s.nc", "--chunk", 1, "--device", DEVICE, "--quiet")
    warned = _warnings(err)
    assert code == 0 and len(warned) == 1 and warned[0].startswith("warpfric: warning: fronts event 'contact'"), err
    assert not any("runner.py" in line for line in err), err


def test_the_size_warning_is_one_line(capsys):
    code, _, err = run_cli(capsys, "run", "--nodes", 8000, "--end-time", 20.0001, "--device", "cpu", "--quiet")
    assert code == 1  # no peak in 0.1 ms of sliding: status no_peak
    warned = _warnings(err)
    assert len(warned) == 2 and warned[0].startswith("warpfric: warning: 1 member x 8000 nodes is far beyond the "
                                                     "usual size"), err
    assert "--grid-check" in warned[0]
    # and what the status means, with what to change
    assert warned[1].startswith("warpfric: warning: members that did not end ok have NaN mu_s and fronts: 1 of 1 "
                                "member: 1 no_peak (mu was still rising at the run's end"), err
    assert "a later end_time" in warned[1]
    assert "their numbers" not in warned[1] and warned[1].endswith("a later end_time or stop_time)"), err  # no file


def test_the_warning_of_members_not_ok_points_to_info_on_the_file(capsys, tmp_path):
    out = tmp_path / "one scene.nc"
    code, _, err = run_cli(capsys, "run", "--nodes", 11, "--end-time", 20.0001, "--device", "cpu", "--quiet",
                           "-o", out)
    warned = _warnings(err)
    assert code == 1 and len(warned) == 1, err
    assert warned[0].endswith(f"their numbers: warpfric info '{out}' (docs/model.md, \"Statuses\")"), err
    code, stdout, _ = run_cli(capsys, "info", out)
    assert code == 0 and "    no_peak: member 0" in stdout, stdout


def test_the_python_api_keeps_python_warnings(capsys):
    """Only the command line formats warnings: afterwards simulate() warns as Python does."""
    shown = warnings.showwarning
    run_cli(capsys, "run", "--relaxation-gate", "none", "--nodes", 11, "--device", DEVICE, "--quiet")
    assert warnings.showwarning is shown
    with pytest.warns(UserWarning, match="fronts event 'contact' with relaxation_gate='none'"):
        SIMULATE_MODULE.simulate(model=Model(relaxation_gate="none"), solver=Solver(nodes=11), device=DEVICE,
                                 progress=False)


def test_the_relaxation_gate_help_says_what_each_law_is(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "SPEC" not in text
    assert "none: the friction law without the yield gate, relaxation and rejuvenation at every stress" in text
    assert "--front-event {contact,strength,velocity,off}" in text


@pytest.mark.parametrize("argv, words", [
    (["run", "--eccentricty", "0.1"], ["unrecognized arguments: --eccentricty", "did you mean --eccentricity?"]),
    (["run", "--nodes", "10.5"], ["argument --nodes: invalid int value: '10.5'", "`warpfric run --help`"]),
    (["run", "--front-event", "contct"], ["argument --front-event: invalid choice: 'contct'"]),
    (["rn"], ["invalid choice: 'rn'", "`warpfric COMMAND --help`"]),
    # no abbreviations: a prefix of one option is no option (it would break when another starts alike)
    (["run", "--overw"], ["unrecognized arguments: --overw", "did you mean --overwrite?"]),
    (["sensitivity", "x.nc", "--overwr"], ["unrecognized arguments: --overwr", "did you mean --overwrite?"]),
    (["info", "x.nc", "--nodes", "20"], ["unrecognized arguments: --nodes 20", "`warpfric info --help`"]),
])
def test_a_command_line_mistake_is_one_line(capsys, argv, words):
    """argparse's faults end like every other fault: one line 'warpfric: error: ...', exit code 2, an
    unknown option answered with the closest known one (not a usage block)."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    one_line_error(err, *words)


def test_unknown_options_are_matched_within_their_subcommand(capsys):
    """info has no --eccentricity: no suggestion from run's options."""
    with pytest.raises(SystemExit):
        main(["info", "x.nc", "--eccentricty", "0.1"])
    err = capsys.readouterr().err
    assert "did you mean" not in err and "`warpfric info --help`" in err, err


def test_a_failed_member_says_its_front_outputs_are_nan(capsys):
    """The run ends before mu peaks (no_peak), after the front: its front outputs are NaN, and the
    CLI says why instead of 'absent'."""
    code, out, _ = run_cli(capsys, "run", "--nodes", 20, "--end-time", 20.2, "--device", DEVICE, "--quiet")
    assert code == 1
    front = [line for line in out if line.startswith("front")]
    assert front == ["front     : not given: the member did not end ok (no_peak), so its front outputs are NaN"], out


def test_the_front_lines_give_the_front_whole_then_its_segments(capsys, tmp_path):
    """One front (2e/L = 0.3, an interior nucleation) printed its segments only, so a front of two slow
    ends and a fast middle read as if v_middle were the front; both one front and two (the default
    scene) now give the first front whole, its extent and the file's v_first, before the segments."""
    for eccentricity, first in ((0.3, "  the front x = "), (0.0, "  first front x = ")):
        path = tmp_path / f"e{eccentricity}.nc"
        code, out, _ = run_cli(capsys, "run", "--nodes", 60, "--eccentricity", eccentricity, "--device", DEVICE,
                               "--quiet", "-o", path)
        assert code == 0
        lines = [line for line in out if line.startswith(first)]
        assert len(lines) == 1 and lines[0].endswith("; its segments:"), out
        assert f"v_first = {float(open_ensemble(path).v_first[0]):.3g} m/s" in lines[0]
        assert out[out.index(lines[0]) + 1].startswith("  v_left ")


def test_a_grid_too_coarse_for_the_grid_check_says_so(tmp_path, capsys):
    """At N = 3 the run's front lines do not send the reader to --grid-check but say that it needs
    N >= 5; --grid-check refuses N = 4 in one line naming the limit and runs at N = 5, where the
    speeds get their error estimate."""
    code, out, err = run_cli(capsys, "run", "--nodes", "3", "--device", DEVICE, "-o", tmp_path / "n3.nc")
    assert code == 0, err
    hint = [line for line in out if "no error estimate" in line]
    assert len(hint) == 1 and "N = 3 is too coarse for --grid-check" in hint[0] and "--nodes >= 5" in hint[0], out
    code, out, err = run_cli(capsys, "run", "--nodes", "4", "--grid-check", "--device", DEVICE,
                             "-o", tmp_path / "g4.nc")
    assert code == 2 and not (tmp_path / "g4.nc").exists()
    one_line_error(err, "'grid_check'", "'nodes' >= 5", "got 4")
    code, out, err = run_cli(capsys, "run", "--nodes", "5", "--grid-check", "--device", DEVICE,
                             "-o", tmp_path / "g5.nc")
    assert code == 0, err
    assert not [line for line in out if "no error estimate" in line], out
    assert any(line.strip().startswith("(+- : the change on a grid of half the nodes") for line in out), out
