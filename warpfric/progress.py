"""warpfric.progress: the progress line of a run, the launch size that keeps it moving on the CPU,
and the warning before a run far beyond the usual size.

The line (stderr; drawn by tqdm in a terminal or a Jupyter notebook) shows a percentage, members
done, members per second and the time left; it is redrawn at most every ``Line.interval`` s and at
least after every launch, which on the CPU lasts ~0.1 s (``launch_steps``). The time left comes
from the fraction's growth over the last ``Line.rate_window`` s (at least; a fifth of the run's
time where that is longer); where the fraction has not grown in that window (members that need more
steps than expected, held at ``RUNNING_CAP``) the time left is unknown and shown as "?". Where
stderr is neither (a log, a pipe), a run with progress on writes one plain line every
``Line.log_interval`` s while it goes, and one summary line at its end; a run shorter than that
interval writes the summary only.

The percentage: a member that is done counts 1; a running member counts its attempted steps over
the steps a member is expected to need (``expected_attempts``; in the second pass of the front
metrics: the member's own steps of the first pass), at most ``RUNNING_CAP``, so that a member
needing more than expected holds the line below 100 % instead of taking it past; each pass is an
equal share. The shown percentage never goes back.
"""

from __future__ import annotations

import io
import math
import os
import sys
import time
import warnings
import weakref
from pathlib import Path

import numpy as np

# --- cost model: one member of the default scene through one pass, on one core of this project's
# CPU (rtol 1e-5, the stress gate, the contact front, Solver.error_filter_nodes 800, at 38f2938: median
# 283 attempts at N = 41 over 200 members of eccentricity in [-0.2, 0.2] and F in [500, 5000] N
# (studies/bench_engine.py's members, seed 0), 297 at N = 100 and 384 at N = 200 (200 members), 573 at
# N = 400 (100), 900 at N = 800 (50); 1550 and 2990 at N = 1600 and 3200, measured before the filter,
# which changes nothing at N >= 800; 4.7x more attempts at rtol 1e-7: _rtol_factor). Per node and attempt, with the contact front
# (one pass): 0.27 us for 200 members at N = 40 (0.72 s), 0.26 us for 64 at N = 100 (0.54 s), 0.24 us
# for 16 at N = 200 (0.30 s), one process, best of two. The front events cost FRONT_PASSES passes
# of that (200 members at N = 40: none 0.716 s, contact 0.713, strength 0.765, velocity 1.831: its
# first pass takes ~30 % more steps, then a second) ---
CPU_SECONDS_PER_NODE_ATTEMPT = 0.26e-6
# (nodes, median attempts of a member) at rtol 1e-5: the measurements above
# (studies/results/attempt_medians_cpu_38f2938.txt, with its script)
ATTEMPTS_BY_NODES = ((41, 283.0), (100, 297.0), (200, 384.0), (400, 573.0), (800, 900.0), (1600, 1550.0),
                     (3200, 2990.0))
FRONT_PASSES = {"contact": 1.0, "strength": 1.1, "velocity": 2.6}


def front_passes(fronts) -> float:
    """Passes' worth of work of a run with ``fronts`` (None: 1): its costliest event's, 1.5x with
    the grid check (the same members on a coarser grid)."""
    if fronts is None:
        return 1.0
    return max(FRONT_PASSES[event] for event in fronts.events) * (1.5 if fronts.grid_check else 1.0)


def expected_attempts(nodes: int, rtol: float = 1e-5, method: str = "tr_bdf2", extra: float = 0.0) -> float:
    """Attempted steps one member is expected to need for one pass of the protocol: with the
    automatic end the measured medians of ATTEMPTS_BY_NODES, linear in log N between them (below 41
    nodes the value at 41, above 3,200 in proportion to N: ~0.93 N); ``extra`` more for an explicit
    end_time past the detachment (:func:`end_time_attempts`); all times _rtol_factor(rtol, method)."""
    grid, attempts = zip(*ATTEMPTS_BY_NODES)
    if nodes >= grid[-1]:
        base = attempts[-1] * nodes / grid[-1]
    else:
        base = float(np.interp(math.log(max(nodes, grid[0])), np.log(grid), attempts))
    return (base + extra) * _rtol_factor(rtol, method)


def _rtol_factor(rtol: float, method: str) -> float:
    """How many more attempts than at rtol 1e-5: (1e-5/rtol)^(1/(order+1)), the steps of an error
    estimate O(h^(order+1)) under local error control: TR-BDF2 (1e-5/rtol)^(1/3), ESDIRK4 ^(1/5).
    Measured at 38f2938 (CPU, N = 100 and 40, the default scene: studies/results/gate_convergence_cpu.log,
    esdirk4_work_cpu.json): TR-BDF2 under the stress gate 0.64x / 2.07x / 4.66x the attempts of rtol
    1e-5 at rtol 1e-4 / 1e-6 / 1e-7 (this factor 0.46 / 2.15 / 4.64), gate-less 1.74x / 3.47x at
    1e-6 / 1e-7; ESDIRK4 1.3x / 1.7-1.9x at 1e-6 / 1e-7 (1.58 / 2.51)."""
    return (1e-5 / rtol) ** (1.0 / (5 if method == "esdirk4" else 3))


# an explicit end_time past the detachment: the pad's transient after it (~165 attempts within
# ~4.7 s), then ~1 attempt per second of steady sliding (default scene, two members, CPU, rtol 1e-5,
# automatic end -> end_time 25 / 40 / 80 s: N = 40 334 -> 500 / 515 / 555 attempts, N = 100 327 ->
# 493 / 508 / 548, N = 200 336 -> 502 / 517 / 557; without it the estimate was 1.7x low at 80 s)
AFTER_DETACHMENT_ATTEMPTS = 165.0
AFTER_DETACHMENT_SECONDS = 4.7
SLIDING_ATTEMPTS_PER_SECOND = 1.0
DETACHMENT_AFTER_START_S = 0.3  # the default scene's detachment is over ~0.27 s after the disc starts


def end_time_attempts(end_time, rest_until) -> float:
    """Extra attempts a member is expected to need, on average over the members, for its explicit
    end_time (s; inf or NaN: the automatic end, none) past its detachment (rest_until + ~0.3 s)."""
    end = np.asarray(end_time, dtype=float)
    after = end - (np.asarray(rest_until, dtype=float) + DETACHMENT_AFTER_START_S)
    with np.errstate(invalid="ignore"):
        extra = np.where(np.isfinite(end) & (after > 0),
                         AFTER_DETACHMENT_ATTEMPTS * np.minimum(1.0, after / AFTER_DETACHMENT_SECONDS)
                         + SLIDING_ATTEMPTS_PER_SECOND * np.maximum(0.0, after - AFTER_DETACHMENT_SECONDS), 0.0)
    return float(np.mean(extra)) if extra.size else 0.0


# attempts of a law without the yield gate against the stress gate's: it takes no steps at the gate
# switches (studies/bench_engine.py's first 20 members, N = 100, rtol 1e-5, fronts off, CPU, 38f2938:
# medians 129.5 against 305.5; 131 against 295.5 with the velocity error filter of 200)
LAW_ATTEMPTS = {"stress": 1.0, "none": 0.42, "velocity": 0.42}


def cpu_seconds(n_members: int, solver, passes: float = 1.0, model=None, extra: float = 0.0) -> float:
    """Rough time of an ensemble on one CPU core (s): members x passes x expected attempts x nodes x
    CPU_SECONDS_PER_NODE_ATTEMPT (passes: front_passes; ``model``: its law's LAW_ATTEMPTS, else the
    stress gate's; ``extra``: end_time_attempts)."""
    attempts = expected_attempts(solver.nodes, solver.rtol, solver.method)
    if model is not None:
        attempts *= LAW_ATTEMPTS.get(model.relaxation_gate, 1.0)
    # the extra once: a second pass (the velocity front's) ends at its front, before the explicit end
    after = extra * _rtol_factor(solver.rtol, solver.method)
    return n_members * (passes * attempts + after) * solver.nodes * CPU_SECONDS_PER_NODE_ATTEMPT


# member-node-attempts per launch on the CPU: ~0.1 s of one core. A launch there costs next to
# nothing beyond its steps (400 members, N = 100: 12.0 s with 500 attempts per launch, 12.2 s with
# 1), so short launches keep the line and Ctrl-C responsive at no measurable cost
CPU_LAUNCH_WORK = 3e5


def launch_steps(solver, n_members: int, device) -> int:
    """Attempted steps per launch: Solver.steps_per_launch on a GPU; on the CPU at most that, and
    fewer for a big ensemble or grid, so that a launch lasts ~0.1 s. Outputs do not depend on it
    (the kernel resumes each member where the last launch left it); only the straggler rule is
    applied between launches, so it can catch a straggler earlier."""
    if not str(device).startswith("cpu"):
        return solver.steps_per_launch
    return int(max(1, min(solver.steps_per_launch, CPU_LAUNCH_WORK // (n_members * solver.nodes))))


# --- size warning ---
USUAL_NODES = 5000
USUAL_NODE_MEMBERS = 1e7
# bytes per node and member: the device arrays (device_bytes_per_member / N: 272 .. 324 in float64,
# by friction law and fronts) and the outputs on the host (the read-back and the Dataset's
# per-node variables)
DEVICE_BYTES_PER_NODE = 330.0
HOST_BYTES_PER_NODE = 200.0


class SizeWarning(UserWarning):
    """A run far beyond the usual size (it says how long and how much memory it will roughly take)."""


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{seconds:.0f} s"
    if seconds < 5400:
        return f"{seconds / 60:.0f} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def plural(n: int, word: str) -> str:
    """'1 member', '3 members'."""
    return f"{n} {word}{'' if n == 1 else 's'}"


def member_range(n: int, first, last) -> str:
    """'3 members (numbers 0..2)', '1 member (number 5)'."""
    return f"{n} members (numbers {first}..{last})" if n != 1 else f"1 member (number {first})"


def first_few(items, limit: int = 8) -> str:
    """Member numbers (or any items) as a person reads them: '0, 3, 7', at most ``limit``, then '...'."""
    items = list(items)
    return ", ".join(map(str, items[:limit])) + (", ..." if len(items) > limit else "")


def status_name(ds, code: int) -> str:
    """Status ``code``'s meaning in ``ds`` ('max_steps_reached', from the status variable's
    flag_meanings), or 'status <code>' where the file gives none."""
    meanings = ds.status.attrs.get("flag_meanings", "").split()
    code = int(code)
    return meanings[code] if 0 <= code < len(meanings) else f"status {code}"


def seconds_text(value) -> str:
    """A duration in s without its unit: 2 significant digits below 1 s (0.043), else one decimal (12.3)."""
    v = float(value)
    return f"{v:.2g}" if math.isfinite(v) and abs(v) < 0.995 else f"{v:.1f}"  # 0.999: "1.0", not "1"


def _size(n_bytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n_bytes >= scale:
            return f"{n_bytes / scale:.1f} {unit}"
    return f"{n_bytes / 1e3:.0f} kB"


def machine_memory_bytes() -> int | None:
    """This machine's physical memory in bytes (a cgroup limit where one is lower), or None where
    it cannot be read."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        if limit.isdigit():
            total = min(total, int(limit))
    except OSError:
        pass
    return total


def memory_bytes(n_members: int, solver) -> tuple[float, float]:
    """(device, host) bytes a run of ``n_members`` holds at once, roughly (DEVICE_BYTES_PER_NODE and
    HOST_BYTES_PER_NODE a node and member; half in float32). On the CPU the device is the host."""
    scale = 1.0 if solver.dtype == "float64" else 0.5
    node_members = n_members * solver.nodes * scale
    return node_members * DEVICE_BYTES_PER_NODE, node_members * HOST_BYTES_PER_NODE


def check_memory(n_members: int, solver, device, what: str = "this run") -> None:
    """ValueError where the members held at once need more memory than this machine has (the
    estimate of size_warning: host and, on the CPU, the kernels' arrays): such a run would only be
    killed by the system, leaving its files behind."""
    device_bytes, host_bytes = memory_bytes(n_members, solver)
    need = host_bytes + (device_bytes if str(device).startswith("cpu") else 0.0)
    have = machine_memory_bytes()
    if have is not None and need > have:
        raise ValueError(f"{what} ({plural(n_members, 'member')} x {solver.nodes} nodes at once) needs about "
                         f"{_size(need)} of memory, more than this machine's {_size(have)}; fewer nodes, or fewer "
                         "members at once (a sweep's chunk, --chunk)")


def size_warning(n_members: int, solver, passes: float, device, workers: int = 1, extra: float = 0.0) -> str | None:
    """Warn (SizeWarning) before a run of more than USUAL_NODES nodes or USUAL_NODE_MEMBERS
    node-members, with its rough time (on the CPU; ``extra``: end_time_attempts) and memory; return
    the message, or None."""
    nodes = solver.nodes
    if nodes <= USUAL_NODES and n_members * nodes <= USUAL_NODE_MEMBERS:
        return None
    device_bytes, host_bytes = memory_bytes(n_members, solver)
    what = f"{n_members} member{'s' if n_members != 1 else ''} x {nodes} nodes"
    usual = f"usual: up to {USUAL_NODES} nodes and {USUAL_NODE_MEMBERS:.0e} node-members"
    if str(device).startswith("cpu"):
        seconds = cpu_seconds(n_members, solver, passes, extra=extra) / max(1, workers)
        cores = f"{workers} CPU core{'s' if workers != 1 else ''}"
        when = (f"roughly {_duration(seconds)} on {cores} (~{expected_attempts(nodes, solver.rtol, solver.method, extra):.0f} "
                f"steps per member and pass, {CPU_SECONDS_PER_NODE_ATTEMPT * 1e6:.2f} us per node and step on this "
                f"project's CPU) and {_size(device_bytes + host_bytes)} of memory")
    else:
        when = f"{_size(device_bytes)} of device memory and {_size(host_bytes)} on the host (GPU time not estimated)"
    message = (f"{what} is far beyond the usual size ({usual}): expect {when}. Fewer nodes or members give a "
               "quick first look; the fronts' grid check (Fronts(grid_check=True), on the command line --grid-check) "
               "says whether a finer grid changes the result")
    warnings.warn(message, SizeWarning, stacklevel=4)
    return message


# --- the line ---
def _isatty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


def interactive(stream) -> bool:
    """Whether a person watches ``stream`` as it is written: a terminal, or a Jupyter kernel's output
    (ipykernel's OutStream, which is no tty but shows a redrawn line as one line)."""
    kind = type(stream)
    return _isatty(stream) or (kind.__name__ == "OutStream" and kind.__module__.startswith("ipykernel"))


def shown(progress) -> bool:
    """Whether a run shows progress: ``progress`` as simulate takes it (None: where stderr is
    ``interactive``; a string: on, with that label)."""
    return interactive(sys.stderr) if progress is None else bool(progress)


FALLBACK_COLUMNS, FALLBACK_ROWS = 80, 24


def _terminal_size(stream) -> tuple[int, int]:
    """(columns, rows) of the terminal of ``stream``, columns at most 120. A size that reads as 0 (a
    pseudo-terminal nobody sized: `script`, some CI runners and containers) or cannot be read: the
    environment's COLUMNS and LINES, else 80 x 24."""
    try:
        columns, rows = os.get_terminal_size(stream.fileno())
    except (AttributeError, ValueError, OSError, io.UnsupportedOperation):
        columns, rows = 0, 0

    def fallback(name: str, default: int) -> int:
        try:
            value = int(os.environ.get(name, ""))
        except ValueError:
            return default
        return value if value > 0 else default

    columns = columns if columns > 0 else fallback("COLUMNS", FALLBACK_COLUMNS)
    rows = rows if rows > 0 else fallback("LINES", FALLBACK_ROWS)
    return min(columns, 120), rows


LINE_MIN_BAR = 5  # characters of the bar itself that a line keeps (Line._fitted_label)
LINE_MIN_LABEL = 8  # a label cut shorter than this (with its ellipsis) is left out instead
_OPEN_LINES = weakref.WeakSet()  # lines drawn in a terminal and not yet closed (stop_open_lines)


def stop_open_lines() -> None:
    """End every open progress line where it stands: a run interrupted inside the engine (Ctrl-C,
    SIGTERM) left its bar open, and Python redrew it below the interruption's message."""
    for line in list(_OPEN_LINES):
        line.stop()


class Line:
    """One progress line for n members on ``stream`` (default stderr). In a terminal or a notebook:
    a tqdm bar (percentage, members done, members/s, time left), redrawn by ``show`` at most every
    ``interval`` s. Elsewhere a plain line every ``log_interval`` s and one summary line at
    ``close``. The fraction shown never decreases. ``clock``: seconds (tests pass a fake one)."""

    interval = 0.5  # s between redraws of the bar
    log_interval = 60.0  # s between the plain lines of a log
    rate_window = 5.0  # s (at least) over which the time left reads the fraction's growth

    def __init__(self, n_members: int, label: str = "", stream=None, clock=time.monotonic):
        self.stream = stream if stream is not None else sys.stderr
        self.n = int(n_members)
        self.label = f"warpfric {label}".strip()
        self.clock = clock
        self.t0 = clock()
        self.last = self.t0  # drawn below: the next redraw after ``interval`` (a rate needs a span of time)
        self.fraction = 0.0
        self.done = 0
        self.note = ""
        self.closed = False
        self.bar = None
        self.samples = [(self.t0, 0.0)]  # (time, fraction) at each redraw, for the time left
        self.logged = self.t0  # the last plain line of a log
        if interactive(self.stream):
            from tqdm import tqdm

            line = weakref.ref(self)  # no cycle: a line left open goes, and its bar with it, as before

            class _Bar(tqdm):
                monitor_interval = 0  # no monitor thread: this class throttles the redraws itself

                @property
                def format_dict(self):  # the time left as this line reckons it ("{left}")
                    owner = line()
                    return {**super().format_dict, "left": owner.left_text() if owner is not None else "?"}

            # both given: tqdm does not read the size itself (a terminal of 0 x 0 gave it -1 rows, and then
            # it drew nothing)
            columns, rows = _terminal_size(self.stream)
            self.columns = columns
            postfix = self._postfix()
            self.bar = _Bar(total=self.n, desc=self._fitted_label(postfix), postfix=postfix, unit=" members",
                            file=self.stream, mininterval=0, miniters=0, smoothing=0.1, ncols=columns, nrows=rows,
                            leave=True, bar_format="{desc}{percentage:5.1f}%|{bar}| [{elapsed}<{left}{postfix}]")
            _OPEN_LINES.add(self)

    def _set_postfix(self) -> None:
        """The bar's counts and its label, fitted to the terminal (drawn at the next update)."""
        postfix = self._postfix()
        self.bar.set_description_str(self._fitted_label(postfix), refresh=False)
        self.bar.set_postfix_str(postfix, refresh=False)

    def _fitted_label(self, postfix: str) -> str:
        """The line's start, ``label: ``, fitted to the terminal's width beside the counts (tqdm cuts
        a line that is too long at its end, which holds them): the label whole, else without the
        tool's name, else cut (an ellipsis) where at least LINE_MIN_LABEL characters stay, else none.
        The room is reckoned for the widest counts of the run (a rate of up to 8 characters, all
        members done), so that the label keeps its length from one redraw to the next."""
        elapsed = self.clock() - self.t0
        remaining = self.time_left()
        remaining = elapsed * (1.0 - self.fraction) / self.fraction if remaining is None and self.fraction > 0 else (
            remaining or 0.0)
        # the rest of the line: "100.0%|", a bar of LINE_MIN_BAR, "| [", elapsed "<" remaining as
        # tqdm writes them (MM:SS, or H:MM:SS from an hour on; "?" within MM:SS's width), ", " and "]"
        clock_width = sum(5 if t < 3600 else len(f"{int(t // 3600)}:00:00") for t in (elapsed, remaining))
        widest = len(f"1.23e+03 members/s, {self.n}/{self.n} done") + (len(f", {self.note}") if self.note else 0)
        short = self.label.removeprefix("warpfric ")
        head = short.split(" (")[0]  # "chunk 1/4 (members 0..49)" -> "chunk 1/4": which chunk, at least

        def room(bar: int) -> int:
            return self.columns - max(len(postfix), widest) - (7 + bar + 3 + clock_width + 1 + 2 + 1) - 2

        own = [(head, LINE_MIN_BAR), (head, 1)] if short != "warpfric" else []  # a label of the run's own
        for label, bar in [(self.label, LINE_MIN_BAR), (short, LINE_MIN_BAR), *own]:
            if len(label) <= room(bar):
                return f"{label}: "
        return f"{short[:room(LINE_MIN_BAR) - 1]}…: " if room(LINE_MIN_BAR) >= LINE_MIN_LABEL else ""

    def _postfix(self) -> str:
        rate = self.fraction * self.n / max(self.clock() - self.t0, 1e-9)  # members (or their fractions) per second
        pace = ("? members/s" if rate == 0 else f"{rate:.3g} members/s" if rate >= 0.1 else
                f"{_duration(1 / rate)} per member")
        return f"{pace}, {self.done}/{self.n} done" + (f", {self.note}" if self.note else "")

    def _window(self, now: float) -> float:
        """The span (s) whose growth the time left reads: ``rate_window``, or a fifth of the time so far
        where longer."""
        return max(self.rate_window, 0.2 * (now - self.t0))

    def time_left(self) -> float | None:
        """Seconds left at the fraction's growth over the last ``_window`` s, from the redraws'
        samples; None where it has not grown there."""
        now = self.clock()
        window = self._window(now)
        # the latest sample at least a window old (the start where none is)
        then, before = next(((t, f) for t, f in reversed(self.samples) if now - t >= window), self.samples[0])
        if self.fraction >= 1.0:
            return 0.0
        if self.fraction <= before or now <= then:
            return None
        return (1.0 - self.fraction) * (now - then) / (self.fraction - before)

    def left_text(self) -> str:
        """The time left as tqdm writes a time (MM:SS, H:MM:SS), or "?" where it is unknown."""
        from tqdm import tqdm

        left = self.time_left()
        return "?" if left is None else tqdm.format_interval(round(left))

    def _sample(self, now: float) -> None:
        """Keep (now, fraction) for the time left, and only the samples its window can still read."""
        self.samples.append((now, self.fraction))
        window = self._window(now)
        while len(self.samples) > 2 and now - self.samples[1][0] >= window:
            self.samples.pop(0)

    def show(self, fraction: float, done: int, note: str | None = None, force: bool = False) -> bool:
        """Take the latest fraction (0..1) and members done; redraw when ``interval`` s have passed
        since the last redraw (or ``force``); in a log, a plain line every ``log_interval`` s. Returns
        whether it drew."""
        self.fraction = max(self.fraction, min(float(fraction), 1.0))
        self.done = max(self.done, int(done))
        if note is not None:
            self.note = note
        now = self.clock()
        if self.closed or (not force and now - self.last < self.interval):
            return False
        self.last = now
        self._sample(now)
        if self.bar is None:
            if now - self.logged < self.log_interval:
                return False
            self.logged = now
            self.stream.write(f"{self.label}: {100 * self.fraction:.1f} % after {_duration(now - self.t0)}, "
                              f"{self._postfix()}, time left {self.left_text()}\n")
            self.stream.flush()
            return True
        self._set_postfix()
        self.bar.update(self.fraction * self.n - self.bar.n)
        return True

    def stop(self) -> None:
        """An interrupted run: end the bar's line where it stands (nothing elsewhere)."""
        _OPEN_LINES.discard(self)
        if self.bar is not None and not self.closed:
            self.closed = True
            self.bar.close()

    def close(self, summary: str = "") -> None:
        """The final state: the full bar in a terminal, else one summary line (members, seconds,
        members/s and ``summary``)."""
        _OPEN_LINES.discard(self)
        if self.closed:
            return
        self.closed = True
        self.fraction, self.done = 1.0, self.n
        if self.bar is not None:
            self.note = summary or self.note
            self._set_postfix()
            self.bar.update(self.n - self.bar.n)
            self.bar.close()
            return
        elapsed = max(self.clock() - self.t0, 1e-9)
        self.stream.write(f"{self.label}: {plural(self.n, 'member')} in {seconds_text(elapsed)} s "
                          f"({self.n / elapsed:.3g} members/s){', ' + summary if summary else ''}\n")
        self.stream.flush()


BUILD_NOTE_AFTER_S = 1.0  # a kernel load that takes longer than this is a compilation: say so


COMPILING_NOTE = "warpfric: compiling the kernels for these settings (once: Warp keeps them in its cache) ..."


def write_note(text: str, stream=None) -> None:
    """One line on ``stream`` (default stderr) above any progress bar drawn there (tqdm clears and
    redraws it)."""
    from tqdm import tqdm

    tqdm.write(text, file=stream if stream is not None else sys.stderr)


class building_note:
    """Around the kernels' compile or load: where progress is shown and this process draws the
    line (no SINK, or a SINK of this process's own line: ``draws_here``), COMPILING_NOTE on
    ``stream`` (default stderr) once the load has taken BUILD_NOTE_AFTER_S, since a first
    compilation takes seconds (~15 s on a GPU) before the progress line can move. Loading a kernel
    from Warp's cache says nothing."""

    def __init__(self, show: bool, stream=None, after: float | None = None):
        self.show = bool(show) and (SINK is None or getattr(SINK, "draws_here", False))
        self.stream = stream
        self.after = BUILD_NOTE_AFTER_S if after is None else after
        self.timer = None
        self.written = False

    def _write(self) -> None:
        write_note(COMPILING_NOTE, self.stream)
        self.written = True

    def __enter__(self):
        if self.show:
            import threading

            self.timer = threading.Timer(self.after, self._write)
            self.timer.daemon = True
            self.timer.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.timer is not None:
            self.timer.cancel()
            self.timer.join()


RUNNING_CAP = 0.8  # the most a running member counts (see the module's docstring)


def pass_fraction(states: np.ndarray, expected) -> tuple[float, int]:
    """(fraction of the pass, members done) from a snapshot of the member states: a member that is
    done counts 1, a running one min(attempts / expected, RUNNING_CAP); ``expected``: a number or
    one per member."""
    done = states["done"] != 0
    attempts = states["steps_accepted"].astype(np.float64) + states["steps_rejected"]
    running = np.minimum(attempts / np.maximum(expected, 1.0), RUNNING_CAP)
    return float(np.mean(np.where(done, 1.0, running))), int(done.sum())


# in a worker process of warpfric.pool: where a run's progress goes instead of a line,
# sink(fraction, done, final)
SINK = None


class Progress:
    """The progress of one engine run (all its passes), as warpfric.engine reports it: ``start_pass``
    before each pass, ``update`` with a snapshot of the member states after each launch,
    ``end_pass`` with the final states. Draws a Line, or reports to SINK where one is set (a pool
    worker: the parent draws one line for all)."""

    def __init__(self, enabled: bool, n_members: int, label: str = "", n_passes: int = 1, solver=None,
                 stream=None, clock=time.monotonic, extra: float = 0.0):
        self.enabled = bool(enabled)
        self.n = n_members
        self.label = label
        self.n_passes = n_passes
        self.prior = (expected_attempts(solver.nodes, solver.rtol, solver.method, extra) if solver is not None
                      else expected_attempts(100, extra=extra))
        self.expected = self.prior
        self.pass_index = 0
        self.sink = SINK if self.enabled else None
        self.stream, self.clock = stream, clock
        self.line = None

    def start_pass(self, index: int) -> None:
        self.pass_index = index
        if self.enabled and self.sink is None and self.line is None:  # shown before the first launch
            self.line = Line(self.n, self.label, self.stream, self.clock)

    def _report(self, states, final: bool = False) -> None:
        if not self.enabled:
            return
        fraction, done = pass_fraction(states, self.expected)
        if final:
            fraction = 1.0
        overall = (self.pass_index + fraction) / self.n_passes
        last = self.pass_index == self.n_passes - 1
        members_done = done if last else 0
        if self.sink is not None:
            self.sink(overall, members_done, final and last)
            return
        if self.line is None:
            self.line = Line(self.n, self.label, self.stream, self.clock)
        note = f"pass {self.pass_index + 1}/{self.n_passes}" if self.n_passes > 1 else ""
        self.line.show(overall, members_done, note, force=final)
        if final and last:
            self.line.close()

    def update(self, states: np.ndarray) -> None:
        self._report(states)

    def end_pass(self, states: np.ndarray) -> None:
        """The pass is over: the next one (the front metrics' second pass, which repeats each member's
        trajectory up to its event) expects each member's attempts of this one."""
        self._report(states, final=True)
        self.expected = np.maximum(states["steps_accepted"].astype(np.float64) + states["steps_rejected"], 1.0)
