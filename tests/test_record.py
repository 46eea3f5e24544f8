"""Recorded fields of one member as a user meets them: mu(t) of the recorded fields is the engine's
own mu(t) (its value at the run's end is mu_final, its maximum over a dense window mu_s within the
sampling), recording changes no output, `warpfric run -o OUT.nc --record` records the default
scene's detachment (found by a first run) and `warpfric plot` draws mu(t) beside the space-time
map."""

import warnings

import numpy as np
import pytest
from conftest import DEVICE, one_line_error, run, run_cli

import warpfric as wf
from warpfric import plots
from warpfric.io import open_ensemble

OUTPUTS = ("mu_s", "mu_s_time", "mu_final", "final_time", "steps_accepted", "steps_rejected", "front_start_time")


@pytest.fixture(scope="module")
def unrecorded():
    """The default scene and its mirror image (disc the other way), N = 41, rtol 1e-6, no record."""
    return run({"disc_velocity": [1e-4, -1e-4]}, nodes=41, fronts=wf.Fronts())


@pytest.fixture(scope="module")
def recorded(unrecorded):
    """The same two members recorded before the load (t = 0: no normal force), densely around the
    mu_s peak, and at the first member's own final_time."""
    peak, end = float(unrecorded.mu_s_time[0]), float(unrecorded.final_time[0])
    times = (0.0, *np.linspace(peak - 2e-3, peak + 2e-3, 401), end)
    with warnings.catch_warnings():  # the mirror image may end an ulp before the last time
        warnings.filterwarnings("ignore", "Record: recording times after a member's end")
        return run({"disc_velocity": [1e-4, -1e-4]}, nodes=41, fronts=wf.Fronts(),
                   record=wf.Record(members=(0, 1), times=times))


def test_recording_changes_no_output(unrecorded, recorded):
    for name in OUTPUTS:
        np.testing.assert_array_equal(recorded[name].values, unrecorded[name].values, err_msg=name)


def test_the_recorded_friction_coefficient_is_the_engines_mu(unrecorded, recorded):
    mu = recorded.friction_coefficient_history
    assert mu.dims == ("recorded", "time") and mu.attrs["units"] == "1"
    # at the run's last accepted step the fields are the final state: the engine's mu_final, from its
    # own sums of tau_f and sigma_n+ in the kernel
    assert abs(float(mu[0, -1]) / float(unrecorded.mu_final[0]) - 1.0) < 1e-12
    # before the load there is no normal force: mu is undefined, not 0
    assert np.isnan(mu.values[:, 0]).all()
    # between accepted steps the fields are interpolated linearly, and under the constant normal force
    # mu with them, so the recorded maximum is that of the accepted steps; the engine refines its
    # peak between steps by a parabola: never below, and above by far less than the 1e-5 that mu_s
    # is converged to at these settings
    mu_s = float(unrecorded.mu_s[0])
    peak = np.nanmax(mu.values[0, 1:-1])
    assert mu_s - 1e-5 < peak <= mu_s
    # the mirror image (disc the other way): the same mu(t), by the sign of v_d
    np.testing.assert_allclose(mu.values[1, 1:-1], mu.values[0, 1:-1], rtol=1e-9)


def test_the_friction_figure_draws_mu_t_with_mu_s_and_the_front(recorded, tmp_path):
    fig = plots.friction_history_figure(recorded, 0)
    ax = fig.axes[0]
    curve = ax.get_lines()[0]
    np.testing.assert_array_equal(curve.get_xdata(), recorded.time.values)
    np.testing.assert_array_equal(curve.get_ydata(), recorded.friction_coefficient_history.values[0])
    mu_s = float(recorded.mu_s[0])
    marks = {line.get_label(): (line.get_xdata()[0], line.get_ydata()[0]) for line in ax.get_lines()[1:]
             if len(line.get_xdata())}
    assert marks[f"mu_s = {mu_s:.6f} (the peak)"] == (float(recorded.mu_s_time[0]), mu_s)
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    start, end = float(recorded.front_start_time[0]), float(recorded.front_end_time[0])
    assert f"contact front: t = {start:.5f} .. {end:.5f} s" in texts
    # a file written without friction_coefficient_history: the figure computes the same curve
    older = recorded.drop_vars("friction_coefficient_history")
    np.testing.assert_array_equal(plots.friction_history_figure(older, 1).axes[0].get_lines()[0].get_ydata(),
                                  recorded.friction_coefficient_history.values[1])
    with pytest.raises(ValueError, match="recorded_index = 2; valid: 0..1"):
        plots.friction_history_figure(recorded, 2)
    with pytest.raises(ValueError, match="no recorded fields .*--record"):
        plots.friction_history_figure(recorded.drop_vars([v for v in recorded.data_vars if v.endswith("_history")]), 0)
    names = {p.name for p in plots.quick_look(recorded, tmp_path)}
    assert {"friction_member0.png", "friction_member1.png", "space_time_member0.png"} <= names


def test_run_record_alone_records_the_default_scenes_detachment(tmp_path, capsys):
    out = tmp_path / "one.nc"
    code, lines, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", out, "--record")
    assert code == 0, err
    ds = open_ensemble(out)
    alone = run(nodes=21, rtol=1e-5, fronts=wf.Fronts())
    for name in OUTPUTS:  # the file's outputs are those of a run without recording
        np.testing.assert_array_equal(ds[name].values, alone[name].values, err_msg=name)
    t = ds.time.values
    start, peak, end = (float(alone[name][0]) for name in ("front_start_time", "mu_s_time", "final_time"))
    # the window: from the front's start less half the time from there to the end, to the end
    assert t.size == 1001 and t[-1] == end
    assert t[0] == pytest.approx(start - 0.5 * (end - start), abs=1e-12) and t[0] < start < peak < end
    assert np.isfinite(ds.velocity_history.values).all()  # no time after the member's end
    assert abs(float(ds.friction_coefficient_history[0, -1]) / float(ds.mu_final[0]) - 1) < 1e-12
    assert any(line.startswith("recording the fields at 1001 times from") and "the detachment found by a first run" in line
               for line in lines)
    assert lines[-1] == f"wrote {out} (with the recorded fields: warpfric plot {out} draws them)"
    code, lines, err = run_cli(capsys, "plot", out)
    assert code == 0 and f"wrote {tmp_path / 'one' / 'friction_member0.png'}" in lines
    assert not any("--record" in line for line in lines)
    # without --record the plot says how to get these figures
    code, _, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", tmp_path / "bare.nc")
    code, lines, err = run_cli(capsys, "plot", tmp_path / "bare.nc")
    assert code == 0 and [line for line in lines if not line.startswith("wrote")] == [
        "(one member without recorded fields: warpfric run -o OUT.nc --record records them, and plot then draws its "
        "space-time map and mu(t))"]


@pytest.mark.parametrize("front_event", ["contact", "off"])
def test_run_record_alone_ends_where_the_recording_run_ends(tmp_path, capsys, front_event):
    """The first run locates the detachment with detachment_fronts' event, the strength front under
    the gate-less law; the automatic end waits for the fronts a run reads, so the recording run, with
    the contact front (NaN there) or none, ended before the window did (20.287 against 20.299 s at
    N = 40): its last 13 % of times were NaN. The window ends where a run with the recording run's
    fronts ends, and its outputs are those of a run without recording."""
    out = tmp_path / f"gate_less_{front_event}.nc"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "fronts event 'contact' with relaxation_gate='none'")
        code, lines, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", out, "--record",
                                   "--relaxation-gate", "none", "--front-event", front_event)
        assert code == 0, err
        model = wf.Model(relaxation_gate="none")
        alone = run(nodes=21, rtol=1e-5, model=model, fronts=None if front_event == "off" else wf.Fronts())
        strength = run(nodes=21, rtol=1e-5, model=model, fronts=wf.Fronts(event="strength"))
    ds = open_ensemble(out)
    for name in ("mu_s", "mu_s_time", "mu_final", "final_time", "steps_accepted", "steps_rejected"):
        np.testing.assert_array_equal(ds[name].values, alone[name].values, err_msg=name)
    end, start = float(alone.final_time[0]), float(strength.front_start_time[0])
    assert end < float(strength.final_time[0])  # the case: the strength front's run ends later
    t = ds.time.values
    assert t[-1] == end and t[0] == pytest.approx(start - 0.5 * (end - start), abs=1e-12)
    assert np.isfinite(ds.velocity_history.values).all()  # no time after the member's end
    assert not any("recording times after a member's end" in line for line in err), err


def test_a_sweeps_detachment_window_ends_where_its_own_runs_end(tmp_path, capsys):
    """The sweep's first run, like --record's, read the strength front under the gate-less law while
    the chunks read the contact front (NaN there) and ended earlier: its line named member 0 as
    ending before the window while member 1's last 208 of 1001 times were NaN as well, unsaid. The
    window ends with the latest of the members' own runs, and the line names exactly the members
    with NaN times."""
    sweep = tmp_path / "g.toml"
    sweep.write_text('[model]\nrelaxation_gate = "none"\n[solver]\nnodes = 21\n[grid]\neccentricity = [0.0, 0.2]\n'
                     '[record]\nmembers = [0, 1]\nwindow = "detachment"\ncount = 101\n')
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "fronts event 'contact' with relaxation_gate='none'")
        code, _, err = run_cli(capsys, "run", sweep, "-o", tmp_path / "g.nc", "--device", DEVICE)
        assert code == 0, err
        alone = run({"eccentricity": [0.0, 0.2]}, nodes=21, rtol=1e-5, model=wf.Model(relaxation_gate="none"),
                    fronts=wf.Fronts())
    ds = open_ensemble(tmp_path / "g.nc")
    ends = alone.final_time.values
    assert ds.time.values[-1] == ends.max() and ends[0] < ends[1]
    nan_times = np.isnan(ds.velocity_history.values).any(axis=-1).sum(axis=-1)
    assert nan_times[1] == 0 and nan_times[0] == (ds.time.values > ends[0]).sum() > 0
    assert any(line.endswith("the detachment found by the first run; member 0 ends before the window does: NaN after "
                             "its end") for line in err), err


def test_record_detachment_spans_every_chosen_members_detachment(tmp_path):
    # the last two: no_peak, their discs stopped early; the last runs on to 25 s
    members = {"eccentricity": [0.0, 0.3, 0.0, 0.0], "stop_time": [np.inf, np.inf, 20.03, 20.03],
               "end_time": [np.inf, np.inf, np.inf, 25.0]}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "members that did not end ok")
        ds = run(members, nodes=21, rtol=1e-5, fronts=wf.Fronts())
    assert list(ds.status.values != 0) == [False, False, True, True] and float(ds.final_time[3]) == 25.0
    record = wf.Record.detachment(ds, members=(0, 1), count=11)
    starts = [float(ds.front_start_time[m]) for m in (0, 1)]
    ends = [float(ds.final_time[m]) for m in (0, 1)]
    peaks = [float(ds.mu_s_time[m]) for m in (0, 1)]
    first = [min(s, p) - 0.5 * (e - min(s, p)) for s, p, e in zip(starts, peaks, ends)]
    assert record.members == (0, 1) and len(record.times) == 11
    assert record.times[0] == pytest.approx(min(first), abs=1e-12) and record.times[-1] == max(ends)
    # members without a detachment (their discs stopped early) widen the window neither to t = 0 nor
    # to 25 s
    assert wf.Record.detachment(ds, count=11).times == record.times
    assert wf.Record.detachment(ds, count=11).members == (0, 1, 2, 3)
    # alone, it is recorded from the disc's start to its end
    alone = wf.Record.detachment(ds, members=(2,), count=11)
    assert alone.times[0] == wf.Parameters().rest_until and alone.times[-1] == float(ds.final_time[2])
    # members are numbers: on a selection of the run, and with the run's member offset
    assert wf.Record.detachment(ds.sel(member=[1]), count=11).members == (1,)
    shifted = ds.assign_coords(member=ds.member + 7)  # the run of member_offset=7
    assert wf.Record.detachment(shifted, members=(8,), member_offset=7, count=11).members == (1,)
    with pytest.raises(ValueError, match=r"members = \(4,\) is invalid; valid: member numbers of ds \(0, 1, 2, 3\)"):
        wf.Record.detachment(ds, members=(4,))
    with pytest.raises(ValueError, match="member 8 lies before member_offset = 9"):
        wf.Record.detachment(shifted, members=(8,), member_offset=9)
    # the ends of the run to repeat, where ds read other fronts: one per member of ds, in its order
    later = ds.final_time.values + [0.01, 0.02, 0.0, 0.0]
    assert wf.Record.detachment(ds, members=(0, 1), count=11, final_time=later).times[-1] == later[:2].max()
    with pytest.raises(ValueError, match=r"final_time has 1 values; valid: one per member of ds \(4\)"):
        wf.Record.detachment(ds, members=(1,), final_time=[20.3])


def test_run_record_alone_without_a_detachment_records_the_whole_run(tmp_path, capsys):
    out = tmp_path / "early.nc"
    code, lines, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", out, "--record",
                               "--end-time", "20.05")
    assert code == 1  # no_peak: the run ended before mu peaked
    t = open_ensemble(out).time.values
    assert (t[0], t[-1], t.size) == (20.0, 20.05, 1001)  # from the disc's start (rest_until)
    assert "recording the fields at 1001 times from 20 to 20.05 s, the disc's start to the end: a first run found " \
           "no detachment (status no_peak) (the last run records; its outputs are those of a run without recording)" in lines


def test_the_detachment_window_of_a_run_that_ended_at_its_start_is_its_start():
    """A member whose state became non-finite at t = 0 (no rest, no ramp, F = 1e300 N) has no
    detachment, and its run ended where the disc starts: the window is that instant, count equal
    times (Record takes non-decreasing times), not a refusal of a window the user never wrote."""
    with pytest.warns(UserWarning, match="non_finite_state"):
        ds = run({"normal_force": [1e300]}, scene=wf.Parameters(rest_until=0.0, force_ramp_time=0.0), nodes=11)
    assert float(ds.final_time.values[0]) == 0.0
    record = wf.Record.detachment(ds, count=5)
    assert record.times == (0.0,) * 5 and record.members == (0,)


def test_run_record_with_a_window(tmp_path, capsys):
    out = tmp_path / "w.nc"
    code, _, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", out,
                           "--record", "20.1", "20.2", "11")
    assert code == 0, err
    np.testing.assert_allclose(open_ensemble(out).time.values, np.linspace(20.1, 20.2, 11), rtol=0, atol=1e-12)


@pytest.mark.parametrize("args, words", [
    (["--record"], ["--record", "-o OUT.nc"]),  # nothing to write into
    (["-o", "x.nc", "--record", "20"], ["--record 20", "START STOP [COUNT]"]),
    (["-o", "x.nc", "--record", "20", "21", "many"], ["--record 20 21 many", "COUNT an integer"]),
    (["-o", "x.nc", "--record", "21", "20"], ["--record 21 20", "0 <= START < STOP"]),
    (["-o", "x.nc", "--record", "20", "20"], ["--record 20 20", "0 <= START < STOP"]),
    (["--record", "one.toml", "-o", "x.nc"], ["'one.toml' is a sweep file, not a time", "[record] table"]),
    (["-o", "x.nc", "--record", "20", "21", "1"], ["--record 20 21 1", "count", "[2, 1,000,000]"]),
])
def test_bad_record_options_are_one_line(tmp_path, capsys, monkeypatch, args, words):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(capsys, "run", "--device", DEVICE, *args)
    assert code == 2
    one_line_error(err, *words)
    assert not (tmp_path / "x.nc").exists()


def test_record_with_a_sweep_file_points_to_its_record_table(tmp_path, capsys):
    sweep = tmp_path / "s.toml"
    sweep.write_text("fronts = false\n[solver]\nnodes = 11\n[grid]\neccentricity = [0.0]\n")
    code, _, err = run_cli(capsys, "run", str(sweep), "--record")
    assert code == 2
    one_line_error(err, "--record", "[record] table", str(sweep))
    # beside other default-scene options, all in one line (--record alone was said, and the user
    # refused again for the next)
    code, _, err = run_cli(capsys, "run", str(sweep), "--nodes", "21", "--record")
    assert code == 2
    one_line_error(err, "--nodes, --record:", "[solver] nodes = 21, a [record] table of members and times", str(sweep))
    # plot of a one-member sweep's file without recorded fields points to the same table
    code, _, err = run_cli(capsys, "run", str(sweep), "--quiet", "--device", DEVICE)
    assert code == 0, err
    code, lines, _ = run_cli(capsys, "plot", tmp_path / "s.nc")
    assert lines[-1] == ("(one member without recorded fields: a [record] table in its sweep file records them "
                         "(docs/sweeps.md), and plot then draws its space-time map and mu(t))")


def test_run_record_alone_with_a_member_offset(tmp_path, capsys):
    out = tmp_path / "five.nc"
    code, _, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "-o", out, "--record",
                           "--member-offset", "5")
    assert code == 0, err
    ds = open_ensemble(out)
    assert list(ds.recorded_member.values) == [5] and list(ds.member.values) == [5]
    assert abs(float(ds.friction_coefficient_history[0, -1]) / float(ds.mu_final[0]) - 1) < 1e-12


def test_files_of_an_earlier_version_get_mu_t_on_reading(recorded, tmp_path):
    """A recorded file written before friction_coefficient_history: open_ensemble computes it (the
    same values), so it combines with a new file and a selection of it plots."""
    from warpfric.io import open_ensembles, write_ensemble

    old = write_ensemble(recorded.drop_vars("friction_coefficient_history"), tmp_path / "old.nc")
    back = open_ensemble(old)
    np.testing.assert_array_equal(back.friction_coefficient_history.values,
                                  recorded.friction_coefficient_history.values)
    def later_run(record):  # members 2 and 3: numbers of their own beside the first run's
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "Record: recording times after a member's end")
            return wf.simulate({"disc_velocity": [1e-4, -1e-4]}, solver=wf.Solver(nodes=41, rtol=1e-6),
                               fronts=wf.Fronts(), device=DEVICE, progress=False, member_offset=2, record=record)

    new = write_ensemble(later_run(wf.Record(members=(0,), times=tuple(recorded.time.values[1:-1]))), tmp_path / "new.nc")
    for files in ((old, new), (new, old)):  # the recording times differ: refused in one line, either order
        with pytest.raises(ValueError, match="recorded their fields at different times.*recorded=False"):
            open_ensembles(list(files))
        # without the recorded fields they combine (two sweeps' own detachment windows were refused whole)
        rest = open_ensembles(list(files), recorded=False)
        assert rest.sizes["member"] == 4 and "recorded" not in rest.dims and "time" not in rest.dims
        np.testing.assert_array_equal(rest.mu_s.sel(member=[2, 3]).values, open_ensemble(new).mu_s.values)
    same_times = write_ensemble(later_run(wf.Record(members=(1,), times=tuple(recorded.time.values))),
                                tmp_path / "same.nc")
    for files in ((old, same_times), (same_times, old)):
        both = open_ensembles(list(files))
        assert both.friction_coefficient_history.shape == (3, recorded.time.size)
    names = {p.name for p in plots.quick_look(back.sel(member=[1]), tmp_path / "sel")}
    assert names >= {"friction_member1.png", "space_time_member1.png"} and "friction_member0.png" not in names


def test_a_sweep_file_s_record_window_counts_as_the_command_line_does(tmp_path):
    """[record] start and stop without count was refused ("missing key 'count'") where --record START
    STOP takes its default; both take RECORD_COUNT, and a count or the times given are kept."""
    from warpfric.parameters import RECORD_COUNT
    from warpfric.sweep_file import SweepError, load_sweep

    sweep = tmp_path / "s.toml"
    sweep.write_text("[record]\nmembers = [0]\nstart = 20.1\nstop = 20.3\n[grid]\neccentricity = [0.0, 0.1]\n")
    times = np.asarray(load_sweep(sweep).record.times)
    assert RECORD_COUNT == 1001 and times.size == RECORD_COUNT and (times[0], times[-1]) == (20.1, 20.3)
    sweep.write_text("[record]\nstart = 20.1\nstop = 20.3\ncount = 5\n[grid]\neccentricity = [0.0, 0.1]\n")
    assert len(load_sweep(sweep).record.times) == 5
    sweep.write_text("[record]\nstart = 20.1\n[grid]\neccentricity = [0.0, 0.1]\n")
    with pytest.raises(SweepError, match="missing key 'stop'.*default 1001"):
        load_sweep(sweep)


def test_a_sweep_file_s_detachment_window(tmp_path):
    """[record] window = "detachment" takes the default count, keeps a count given, and is refused
    beside times or start/stop and with another window; the times come from the run (a chunk given
    none is refused, not run without them)."""
    import warpfric.runner as runner
    from warpfric.parameters import RECORD_COUNT
    from warpfric.sweep_file import RecordDetachment, SweepError, load_sweep

    sweep = tmp_path / "s.toml"
    grid = "[grid]\neccentricity = [0.0, 0.1]\n"
    sweep.write_text('[record]\nmembers = [1]\nwindow = "detachment"\n' + grid)
    assert load_sweep(sweep).record == RecordDetachment(members=(1,), count=RECORD_COUNT)
    sweep.write_text('[record]\nwindow = "detachment"\ncount = 7\n' + grid)
    assert load_sweep(sweep).record == RecordDetachment(members=(0,), count=7)
    for table, words in (('window = "peak"', 'window = "peak": expected "detachment"'),
                         ('window = "detachment"\nstart = 20.1\nstop = 20.3', "not two of them"),
                         ('window = "detachment"\ntimes = [20.1]', "not two of them"),
                         ('window = "detachment"\ncount = 1', "'count' = 1 is invalid"),
                         ('window = "detachment"\nmembers = [0, 0]', "repeated indices")):
        sweep.write_text(f"[record]\n{table}\n" + grid)
        with pytest.raises(SweepError, match=words.replace("(", r"\(").replace("'", "'")):
            load_sweep(sweep)
    sweep.write_text('[record]\nwindow = "detachment"\n' + grid)
    with pytest.raises(runner.RunError, match="found by the sweep's run"):
        runner.sweep_record(load_sweep(sweep), None)


@pytest.mark.filterwarnings("ignore:Record. recording times after a member's end")  # direct: member 4 ends first
def test_a_sweep_records_its_members_detachment_and_resumes_with_the_same_times(tmp_path, capsys, monkeypatch):
    """A sweep file could record only at times it gave (start and stop): finding the detachment took a
    run of its own. With window = "detachment" the run finds it by a first run of the recorded members
    alone; the window is Record.detachment's over those members run by themselves, the fields are
    those of a run recording at those times, and an interrupted run's --resume takes the times from
    its manifest (no first run again, the same times in every chunk)."""
    import importlib
    import json

    import warpfric.runner as runner

    simulate_module = importlib.import_module("warpfric.simulate")  # (warpfric.simulate is also the function)

    sweep = tmp_path / "s.toml"
    sweep.write_text("[solver]\nnodes = 21\n[grid]\neccentricity = [-0.2, 0.0, 0.2]\nnormal_force = [500.0, 2000.0]\n"
                     '[record]\nmembers = [1, 4]\nwindow = "detachment"\ncount = 11\n')
    solver = wf.Solver(nodes=21)
    alone = wf.simulate({"eccentricity": [-0.2, 0.2], "normal_force": [2000.0, 500.0]}, solver=solver,
                        device=DEVICE, progress=False)  # members 1 and 4 (grid order: force fastest)
    times = wf.Record.detachment(alone, count=11).times
    assert times[0] < min(float(alone.mu_s_time[0]), float(alone.mu_s_time[1])) and times[-1] == max(alone.final_time)
    real, chunks = simulate_module.simulate, []

    def interrupted(*args, **kwargs):  # Ctrl-C in the second chunk
        if "member_offset" in kwargs:
            chunks.append(kwargs["member_offset"])
            if len(chunks) == 2:
                raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(simulate_module, "simulate", interrupted)
    out = tmp_path / "s.nc"
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", 4, "--device", DEVICE)
    monkeypatch.setattr(simulate_module, "simulate", real)
    assert code == 130, err
    assert [line for line in err if line.startswith("warpfric: ") and ("recording the fields" in line or "first run" in line)] == [
        f"warpfric: finding the detachment of the recorded 2 members (1, 4): a first run of them alone on {DEVICE}",
        f"warpfric: recording the fields at 11 times from {times[0]:.6g} to {times[-1]:.6g} s, the detachment found "
        "by the first run; member 4 ends before the window does: NaN after its end"]
    assert not any("Record: recording times after a member's end" in line for line in err)  # said once, above
    manifest = json.loads((tmp_path / "s.nc.parts" / "manifest.json").read_text())
    assert manifest["record_times"] == list(times)
    monkeypatch.setattr(runner, "find_record_times", lambda *a, **k: pytest.fail("found the times again"))
    code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--resume", "--device", DEVICE)
    assert code == 0, err
    assert f"warpfric: recording the fields at 11 times from {times[0]:.6g} to {times[-1]:.6g} s, the interrupted " \
           "run's detachment window" in err
    # member 4 (ending before the window) runs in this chunk: its NaN tail was said by the first run
    assert not any("Record: recording times after a member's end" in line for line in err), err
    ds = open_ensemble(out)
    direct = wf.simulate({"eccentricity": [[-0.2], [0.0], [0.2]], "normal_force": [500.0, 2000.0]}, solver=solver,
                         record=wf.Record(members=(1, 4), times=times), device=DEVICE, progress=False)
    assert list(ds.recorded_member.values) == [1, 4] and tuple(ds.time.values) == times
    for name in ("mu_s", "velocity_history", "friction_coefficient_history"):
        np.testing.assert_array_equal(ds[name].values, direct[name].values, err_msg=name)


def test_the_detachment_window_is_found_with_a_front_that_starts_before_the_peak(tmp_path, capsys):
    """Without fronts (`fronts = false`, --front-event off) the first run had the mu_s peak alone, and
    the window (from half the time from there to the end before it) missed the contact front, which
    crosses ~0.1 s earlier: the first run looks for the contact front under the stress gate and for
    the strength front under the other laws, whatever the run reports. Members not ok are named, the
    recorded members are in ascending order whatever --chunk, and the member numbers carry the offset."""
    from warpfric.parameters import detachment_fronts

    assert detachment_fronts(wf.Model()).events == ("contact",)
    assert detachment_fronts(wf.Model(relaxation_gate="none")).events == ("strength",)
    # the command line's --record alone: its first run too (it had the run's fronts: none here)
    for law in ("stress", "none"):
        out = tmp_path / f"one_{law}.nc"
        code, _, err = run_cli(capsys, "run", "--device", DEVICE, "--nodes", "21", "--quiet", "--front-event", "off",
                               "--relaxation-gate", law, "-o", out, "--record")
        assert code == 0, err
        found = run(nodes=21, rtol=1e-5, fronts=detachment_fronts(wf.Model(relaxation_gate=law)),
                    model=wf.Model(relaxation_gate=law))
        own = run(nodes=21, rtol=1e-5, fronts=None, model=wf.Model(relaxation_gate=law))  # where the run ends
        start, end = float(found.front_start_time[0]), float(own.final_time[0])
        assert start < float(found.mu_s_time[0]) - 0.01, law  # the front starts well before the peak
        t = open_ensemble(out).time.values
        assert t[0] == pytest.approx(start - 0.5 * (end - start), abs=1e-9) and t[-1] == end, law
    sweep = tmp_path / "s.toml"
    sweep.write_text("fronts = false\n[solver]\nnodes = 21\n[zip]\neccentricity = [0.0, 0.1, 0.0]\n"
                     "disc_velocity = [1e-4, 1e-4, 0.0]\n"  # member 2: a disc that never moves, no detachment
                     '[record]\nmembers = [2, 0]\nwindow = "detachment"\ncount = 5\n')
    alone = run({"eccentricity": [0.0]}, nodes=21, rtol=1e-5, fronts=wf.Fronts())
    front = float(alone.front_start_time[0])
    assert front < float(alone.mu_s_time[0]) - 0.05  # the contact front runs well before the peak
    for chunk in (1, 3):
        out = tmp_path / f"c{chunk}.nc"
        code, _, err = run_cli(capsys, "run", sweep, "-o", out, "--chunk", chunk, "--device", DEVICE,
                               "--member-offset", 100)
        assert code == 1, err  # member 102 ends no_peak
        line = next(line for line in err if "recording the fields" in line)
        assert line.endswith("the detachment found by the first run; not ok there, so not in the window: member "
                             "102 (no_peak)"), line
        ds = open_ensemble(out)
        assert list(ds.recorded_member.values) == [100, 102]
        t = ds.time.values
        assert t[0] == pytest.approx(front - 0.5 * (float(alone.final_time[0]) - front), abs=1e-9) and t[0] < front
