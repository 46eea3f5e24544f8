"""The progress line a person reads: it moves steadily and never back, shows members/s and the time
left, redraws at least every ~2 s in a terminal and stays quiet elsewhere; the warning before a run
far beyond the usual size; launches short enough on the CPU to keep the line moving."""

import io
import os
import re
import sys
import warnings

import numpy as np
import pytest

import warpfric as wf
from warpfric import progress
from warpfric.kernels.types import IntegratorState


class FakeTerminal(io.StringIO):
    def isatty(self):
        return True


class FakeClock:
    def __init__(self):
        self.now = 1000.0

    def __call__(self):
        return self.now


@pytest.fixture
def clock(monkeypatch):
    """One fake clock for the line's throttle and for tqdm's rate and time left."""
    import tqdm.std

    fake = FakeClock()
    monkeypatch.setattr(tqdm.std, "time", fake)
    return fake


def drawn(stream):
    """The redrawn states of a bar: (percentage, text) per carriage return."""
    frames = [f for f in stream.getvalue().split("\r") if f.strip()]
    return [(float(re.search(r"([\d.]+)%\|", f).group(1)), f) for f in frames]


def states(attempts, done):
    st = np.zeros(len(attempts), dtype=IntegratorState.numpy_dtype())
    st["steps_accepted"] = attempts
    st["done"] = done
    return st


def test_terminal_line_redraws_every_half_second_with_rate_and_time_left(clock):
    out = FakeTerminal()
    line = progress.Line(200, "sweep", stream=out, clock=clock)
    times = []
    for k in range(1, 101):  # updates every 0.1 s of (fake) time for 10 s
        clock.now += 0.1
        if line.show(k / 100, 2 * k):
            times.append(clock.now)
    line.close()
    assert np.diff(times).max() <= 2.0 and len(times) >= 15  # at least every 2 s; throttled to ~0.5 s
    frames = drawn(out)
    percentages = [p for p, _ in frames]
    assert percentages == sorted(percentages) and percentages[-1] == 100
    middle = frames[len(frames) // 2][1]
    # 2 members per 0.1 s: 20 members/s; half done after 5 s: ~5 s left
    assert "warpfric sweep" in middle and re.search(r" (19|20|21)(\.\d+)? members/s", middle), middle
    assert re.search(r"<00:0[4-6]", middle) and "done" in middle, middle
    assert out.getvalue().endswith("\n")


def test_line_never_goes_back(clock):
    out = FakeTerminal()
    line = progress.Line(10, stream=out, clock=clock)
    for fraction in (0.2, 0.5, 0.3, 0.6, 0.1):
        clock.now += 1.0
        line.show(fraction, 0)
    percentages = [p for p, _ in drawn(out)]
    assert percentages == sorted(percentages) and max(percentages) == 60


def test_quiet_where_stderr_is_no_terminal(clock):
    out = io.StringIO()
    line = progress.Line(50, "chunk 2/2", stream=out, clock=clock)
    for k in range(100):
        clock.now += 0.5
        line.show(k / 100, k // 2)
    assert out.getvalue() == ""
    line.close()
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and "\r" not in out.getvalue()
    assert lines[0].startswith("warpfric chunk 2/2: 50 members in 50.0 s (1 members/s)")


def test_the_time_left_is_unknown_while_the_fraction_stands_still(clock):
    """Members past their expected steps (held at RUNNING_CAP) stopped the fraction at 93 %, and the
    line said 00:00 left for the 40 s the run still took (tqdm's rate never saw the pause). The time
    left reads the fraction's growth over the last rate_window s: '?' where it has not grown."""
    out = FakeTerminal()
    line = progress.Line(50, "slow", stream=out, clock=clock)
    shown = []
    for k in range(1, 121):  # 0.1 s apart: 0.93 at 4 s, then nothing until 11 s, then 0.95 at 12 s
        clock.now += 0.1
        fraction = min(0.93, 0.2325 * k / 10) if k <= 110 else 0.93 + 0.02 * (k - 110) / 10
        line.show(fraction, 0)
        shown.append((round(k / 10, 1), line.left_text()))
    left = dict(shown)
    assert left[2.0] == "00:02" and left[4.0] == "00:00"  # 0.465 at 2 s: 2.3 s left at its rate
    assert left[9.5] == "?" and left[11.0] == "?", shown  # stood still for over 5 s
    # growing again, 0.02 in the last 1 s of the window read (the redraw 5.0-5.5 s ago, the redraws
    # being 0.5 s apart): 0.05 left at 0.02 per 5.0-5.5 s, 12.5-13.75 s
    assert left[12.0] in ("00:12", "00:13", "00:14"), shown
    line.close()
    assert any("<?, " in text for _, text in drawn(out))


def test_a_log_gets_a_plain_line_a_minute_and_the_summary(clock):
    """A batch job's log showed nothing for hours until the run ended: now one line every
    log_interval s (60), with the percentage, the counts and the time left."""
    out = io.StringIO()
    line = progress.Line(100, "chunk 1/1", stream=out, clock=clock)
    for k in range(1, 301):  # 0.5 s apart for 150 s, steadily to 75 %
        clock.now += 0.5
        line.show(k / 400, k // 4)
    line.close()
    lines = out.getvalue().splitlines()
    assert len(lines) == 3 and "\r" not in out.getvalue(), lines
    assert lines[0] == "warpfric chunk 1/1: 30.0 % after 60 s, 0.5 members/s, 30/100 done, time left 02:20", lines
    assert lines[1].startswith("warpfric chunk 1/1: 60.0 % after 2 min, ") and lines[1].endswith("time left 01:20")
    assert lines[2].startswith("warpfric chunk 1/1: 100 members in 150.0 s")


def test_a_notebooks_output_is_watched_as_a_terminal(monkeypatch):
    """In Jupyter stderr is ipykernel's OutStream, no tty: the default showed no progress at all. A
    notebook shows a redrawn line as one line, so it gets the bar."""
    OutStream = type("OutStream", (io.StringIO,), {"__module__": "ipykernel.iostream"})
    notebook = OutStream()
    assert progress.interactive(notebook) and not progress.interactive(io.StringIO())
    monkeypatch.setattr(sys, "stderr", notebook)
    assert progress.shown(None) and not progress.shown(False) and progress.shown("label")
    line = progress.Line(10, "nb", stream=notebook)
    line.close()
    assert drawn(notebook)[-1][0] == 100 and "10/10 done" in drawn(notebook)[-1][1]


def test_a_long_kernel_load_is_said_before_the_line_starts(monkeypatch):
    """A first run compiled its kernels for ~8 s (CPU) or ~15 s (GPU) without a word before the line
    started at 0 %. A load longer than its threshold is now said, once; a quick one (from Warp's
    cache), a run without progress and a pool worker (whose parent draws the line) say nothing."""
    import time

    out = io.StringIO()
    with progress.building_note(True, stream=out, after=0.05) as note:
        time.sleep(0.3)  # a compilation
    assert note.written and out.getvalue().startswith("warpfric: compiling the kernels") and out.getvalue().count("\n") == 1
    for show, sink in ((True, None), (False, None), (True, lambda *a: None)):
        quiet = io.StringIO()
        monkeypatch.setattr(progress, "SINK", sink)
        with progress.building_note(show, stream=quiet, after=0.05 if show and sink is None else 0.0) as note:
            time.sleep(0.01 if sink is None and show else 0.2)  # quick, or long but not to be said
        assert quiet.getvalue() == "" and not note.written


@pytest.mark.parametrize("members", [10, 40])
def test_the_compilation_note_comes_also_where_the_members_run_in_blocks(monkeypatch, members):
    """Above 32 members a CPU run goes in member blocks, whose progress sink made the note think
    another process drew the line: it never came. Both sizes say it (the load made slow here)."""
    import time

    import warp as wp

    real = wp.load_module

    def slow_load(*args, **kwargs):
        time.sleep(0.1)
        return real(*args, **kwargs)

    monkeypatch.setattr(wp, "load_module", slow_load)
    monkeypatch.setattr(progress, "BUILD_NOTE_AFTER_S", 0.02)
    terminal = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    wf.simulate({"eccentricity": np.linspace(-0.1, 0.1, members)}, solver=wf.Solver(nodes=11, rtol=1e-4), fronts=None,
                device="cpu", progress=True, workers=1)
    text = terminal.getvalue()
    assert progress.COMPILING_NOTE in text and text.count(progress.COMPILING_NOTE) == (1 if members <= 32 else 2)


def test_percentage_moves_steadily_through_both_passes():
    """Members in lockstep (each launch advances every running member by the same attempts) with a
    spread of needed attempts: the fraction rises in small steps through pass 1 (to 1/2) and pass 2
    (each member expects its attempts of pass 1) and reaches 1 only at the end."""
    needed = np.random.default_rng(0).integers(250, 620, 200)
    bar = progress.Progress(True, 200, n_passes=2, solver=wf.Solver(nodes=100))
    seen = []
    bar.sink = lambda fraction, done, final: seen.append((fraction, done, final))
    for pass_index, scale in ((0, 1.0), (1, 0.9)):
        bar.start_pass(pass_index)
        total = np.round(needed * scale)
        for level in range(0, int(total.max()) + 25, 25):
            bar.update(states(np.minimum(level, total), level >= total))
        bar.end_pass(states(needed, np.ones(200)))
    fractions = np.array([f for f, _, _ in seen])
    assert np.all(np.diff(fractions) >= 0) and np.diff(fractions).max() < 0.05
    assert all(fraction < 1.0 for fraction, done, _ in seen if done < 200) and seen[-1] == (1.0, 200, True)
    assert all(done == 0 for fraction, done, _ in seen if fraction <= 0.5)  # done: after the last pass


def test_simulate_draws_the_line_in_a_terminal_and_one_summary_elsewhere(monkeypatch):
    members = {"eccentricity": [0.0, 0.1]}
    solver = wf.Solver(nodes=21, rtol=1e-4)
    terminal = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    wf.simulate(members, solver=solver, fronts=None, device="cpu", progress="tiny")
    frames = drawn(terminal)
    assert frames[-1][0] == 100 and "warpfric tiny" in frames[-1][1] and "2/2 done" in frames[-1][1]
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    wf.simulate(members, solver=solver, fronts=None, device="cpu", progress="tiny")
    assert re.fullmatch(r"warpfric tiny: 2 members in [\d.]+ s \([\d.e+]+ members/s\)\n", log.getvalue())
    log = io.StringIO()
    monkeypatch.setattr(sys, "stderr", log)
    wf.simulate(members, solver=solver, fronts=None, device="cpu")  # progress None: only in a terminal
    assert log.getvalue() == ""


def test_cpu_launches_last_about_a_tenth_of_a_second():
    solver = wf.Solver(nodes=100)
    assert progress.launch_steps(solver, 1000, "cuda:0") == 500  # a GPU: Solver.steps_per_launch
    assert progress.launch_steps(solver, 2, "cpu") == 500
    assert progress.launch_steps(solver, 1000, "cpu") == 3  # 3e5 node-attempts: ~0.1 s of a core
    assert progress.launch_steps(wf.Solver(nodes=100_000), 1, "cpu") == 3
    assert progress.launch_steps(wf.Solver(nodes=100_000), 100, "cpu") == 1


def test_a_run_far_beyond_the_usual_size_warns_with_time_and_memory():
    with pytest.warns(progress.SizeWarning, match=r"1 member x 100000 nodes .* roughly 8\d min on 1 CPU core .* "
                                                  r"MB of memory"):
        progress.size_warning(1, wf.Solver(nodes=100_000), 2, "cpu")
    with pytest.warns(progress.SizeWarning, match=r"roughly 4\d min on 2 CPU cores"):  # 1e7 node-members
        progress.size_warning(20_000, wf.Solver(nodes=1000), 1, "cpu", workers=2)
    with pytest.warns(progress.SizeWarning, match=r"200000 members x 100 nodes .* GB of device memory"):
        progress.size_warning(200_000, wf.Solver(nodes=100), 1, "cuda:0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert progress.size_warning(10_000, wf.Solver(nodes=200), 2, "cpu") is None  # usual: no warning


def test_a_slow_single_member_shows_its_pace_and_tenths_of_a_percent(clock):
    out = FakeTerminal()
    line = progress.Line(1, stream=out, clock=clock)
    clock.now += 10.0
    line.show(0.001, 0)
    percentage, text = drawn(out)[-1]
    assert percentage == 0.1 and "2.8 h per member" in text and "0/1 done" in text, text


class UnsizedTerminal(FakeTerminal):
    """A pseudo-terminal nobody gave a size (`script -qc ...`, some CI runners): stty size says 0 0."""

    def fileno(self):
        return 2


def test_a_terminal_of_zero_size_draws_80_columns(clock, monkeypatch):
    """tqdm read 0 x 0 as -1 rows and drew nothing: every line came out empty. A line fits its
    width with its counts whole."""
    terminal = UnsizedTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)  # where tqdm measures the terminal itself
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=None: os.terminal_size((0, 0)))
    monkeypatch.delenv("COLUMNS", raising=False)
    monkeypatch.delenv("LINES", raising=False)
    line = progress.Line(1200, "chunk 1/4 (members 0..1199)", clock=clock)
    clock.now += 1.0
    line.show(0.5, 600)
    line.close()
    frames = drawn(terminal)
    assert len(frames) >= 3 and all(len(text.rstrip("\n")) == 80 for _, text in frames), frames
    # the counts are whole (tqdm cut a long line's end: "..., 100/1"); the label gives way instead
    assert all(text.rstrip("\n").endswith(" done]") for _, text in frames), frames
    # the label keeps one length over the run (reckoned for the widest counts), so it does not jump
    assert len({text.split(": ")[0] for _, text in frames}) == 1, frames
    assert frames[-1][0] == 100 and frames[-1][1].startswith("chunk 1/4: 100.0%|")
    assert frames[-1][1].rstrip("\n").endswith("1200/1200 done]")
    monkeypatch.setenv("COLUMNS", "60")  # a size the environment gives
    assert progress._terminal_size(terminal) == (60, 24)
    monkeypatch.setenv("COLUMNS", "120")  # room for all of it
    wide = UnsizedTerminal()
    monkeypatch.setattr(sys, "stderr", wide)
    line = progress.Line(1200, "chunk 1/4 (members 0..1199)", clock=clock)
    clock.now += 1.0
    line.close()
    text = drawn(wide)[-1][1].rstrip("\n")
    assert len(text) == 120 and text.startswith("warpfric chunk 1/4 (members 0..1199): 100.0%|"), text


def test_a_label_too_long_for_the_line_is_left_out_not_cut_to_a_stub(clock, monkeypatch):
    """The plain label, beside counts and a note at 80 columns, came out as 'warpfr…'."""
    terminal = UnsizedTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.setenv("COLUMNS", "80")
    line = progress.Line(300, "", clock=clock)
    clock.now += 1.0
    line.close("2 workers")
    text = drawn(terminal)[-1][1].rstrip("\n")
    assert len(text) == 80 and text.startswith("100.0%|") and text.endswith("300/300 done, 2 workers]"), text
    assert "…" not in text


def test_the_chunk_number_stays_beside_a_note_at_80_columns(clock, monkeypatch):
    """With worker processes ('2 workers') the chunk's label was left out at 80 columns: nothing said
    which chunk ran. Its head ('chunk 1/4') stays, the bar narrower."""
    terminal = UnsizedTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.setenv("COLUMNS", "80")
    line = progress.Line(500, "chunk 1/4 (members 0..499)", clock=clock)
    clock.now += 1.0
    line.show(0.5, 250, "2 workers")
    line.close("2 workers")
    text = drawn(terminal)[-1][1].rstrip("\n")
    assert len(text) == 80 and text.startswith("chunk 1/4: 100.0%|") and text.endswith("500/500 done, 2 workers]"), text


def test_an_interrupted_run_ends_its_line_before_the_message(clock, monkeypatch):
    """Ctrl-C inside the engine left the bar open: the message followed it on its line, and Python
    redrew the bar below the message when it cleaned up. simulate ends every open line first."""
    import warpfric as wf
    from warpfric import engine

    terminal = UnsizedTerminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    opened = []

    def interrupted(*args, **kwargs):
        opened.append(progress.Line(10, "", stream=terminal, clock=clock))
        raise KeyboardInterrupt

    monkeypatch.setattr(engine, "run", interrupted)
    with pytest.raises(KeyboardInterrupt):
        wf.simulate({"eccentricity": [0.0]}, solver=wf.Solver(nodes=11), device="cpu", progress=True, workers=1)
    assert opened[0].closed and terminal.getvalue().endswith("\n") and not progress._OPEN_LINES


def test_durations_and_counts_read_as_words():
    assert [progress.seconds_text(t) for t in (0.0432, 0.00561, 0.999, 1.0, 12.34)] == ["0.043", "0.0056", "1.0", "1.0",
                                                                                         "12.3"]
    assert progress.plural(1, "chunk") == "1 chunk" and progress.plural(3, "chunk") == "3 chunks"
    assert progress.member_range(1, 7, 7) == "1 member (number 7)"
    assert progress.member_range(3, 0, 2) == "3 members (numbers 0..2)"


def test_the_summary_of_a_short_run_shows_its_time(clock):
    out = io.StringIO()
    line = progress.Line(1, "tiny", stream=out, clock=clock)
    clock.now += 0.04
    line.close()
    assert out.getvalue().startswith("warpfric tiny: 1 member in 0.04 s (25 members/s)")


def test_the_expected_attempts_follow_an_explicit_end_time():
    """The cost model behind the progress line, workers=None and the size warning counted the
    automatic end only: a run to 80 s took 1.7x the attempts it expected. With end_time_attempts the
    default scene's member at N = 40 is within 10 % of its attempts, at the automatic end and at 25
    and 80 s (280, 446 and 501 on this project's CPU)."""
    from warpfric.progress import end_time_attempts, expected_attempts

    for end in (None, 25.0, 80.0):
        ds = wf.simulate({"eccentricity": [0.0]}, scene=wf.Parameters(end_time=end), solver=wf.Solver(nodes=40),
                         device="cpu", progress=False, fronts=None, workers=1)
        attempts = int(ds.steps_accepted[0] + ds.steps_rejected[0])
        expected = expected_attempts(40, extra=end_time_attempts(ds.end_time.values, ds.rest_until.values))
        assert abs(expected / attempts - 1) < 0.1, (end, attempts, expected)
    assert end_time_attempts([np.inf, np.inf], [20.0, 20.0]) == 0.0
    assert end_time_attempts([20.1], [20.0]) == 0.0  # before the detachment: no more than the automatic end


def test_the_runs_of_a_recording_say_which_they_are(tmp_path, capsys):
    """`warpfric run --record` with the velocity front runs three times (the detachment, its end, the
    recording): its first two lines both said "first run"; each run's line names it."""
    from conftest import run_cli

    code, _, err = run_cli(capsys, "run", "--record", "--front-event", "velocity", "--nodes", 30, "--device", "cpu",
                           "-o", tmp_path / "v.nc")
    assert code == 0, err
    labels = [line.split(":")[0] for line in err if line.startswith("warpfric ") and " member in " in line]
    assert labels == ["warpfric first run", "warpfric second run (its end)", "warpfric recording"], err
