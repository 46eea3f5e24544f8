"""warpfric.plots: quick-look figures of an ensemble (matplotlib, no display needed).

Against each swept parameter: mu_s, and the front speeds in one panel per segment; a second swept
parameter is the colour (a legend where it takes at most MAX_LEGEND values, each value's members
joined along the x axis, else a colour bar; a line breaks at a member that is not ok). An axis is
logarithmic where its positive values span a decade or more (its ticks powers of ten where they
span more than three or leave [1e-3, 1e5)), symmetric-logarithmic where values of both signs span
two decades or more. Arrival-time curves of up to MAX_CURVES members spread over the ensemble, each
labelled with its swept values; the space-time map of every recorded member, with its arrival-time
curve of each front event in the Dataset and, for the velocity event, the threshold contour, and its
friction coefficient mu(t) over the recorded times.
"""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np

from .progress import plural, status_name

MAX_LEGEND = 8  # values of a colour parameter shown in a legend; more: a colour bar
MAX_CURVES = 8  # arrival-time curves in one figure
OUTLIER_SPAN = 10.0  # an arrival-time curve spanning more than this x the median curve's time runs off the axis
ROUND_OFF_VELOCITY = 1e-9  # a recorded field whose largest |v| stays below this fraction of the disc's
# velocity (1e-13 m/s at the default 0.1 mm/s: 1e-12 m in 10 s) is round-off: the space-time map says so
# instead of stretching its colours over it
# symbols of the parameters most often swept (legend entries "F = 1000 N"; axis labels)
_SYMBOLS = {"normal_force": "F", "eccentricity": "2e/L", "disc_velocity": "v", "shear_strength": "tau_c",
            "length": "L", "height": "h", "stop_time": "t_stop"}
_UNITS = {"1": "", "m s-1": "m/s", "s-1": "1/s", "m2": "m^2"}
# each front event's arrival-time curve on a space-time map: (colour, line style); the velocity
# event's lies on its black threshold contour
_ARRIVAL_STYLES = {"contact": ("k", "--"), "strength": ("tab:green", "-."), "velocity": ("w", ":")}
_OTHER_ARRIVAL = ("k", ":")  # an event the table lacks


def _span_colour(event) -> str:
    """A front event's time span in mu(t): the colour of its curve on the space-time map (a white
    curve's span blue, which white cannot be on white)."""
    colour = _ARRIVAL_STYLES.get(event, _OTHER_ARRIVAL)[0]
    return "tab:blue" if colour == "w" else colour


def _subplots(*args, **kwargs):
    """(figure, axes) as pyplot.subplots gives them, on a Figure of matplotlib's object interface
    with an Agg canvas of its own: no pyplot figure manager and no backend chosen, so that a
    notebook's inline display stays as it was (pyplot's Agg, chosen here before, switched it off for
    the session) and nothing needs closing."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=kwargs.pop("figsize", None))
    FigureCanvasAgg(fig)  # its own canvas (text extents, savefig), the global backend untouched
    return fig, fig.subplots(*args, **kwargs)


def _axis_scale(values) -> str:
    """'log' where the positive finite values span a decade or more, else 'linear'."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return "log" if v.size and v.min() > 0 and v.max() / v.min() >= 10 else "linear"


def _units(ds, name: str) -> str:
    units = ds[name].attrs.get("units", "")
    return _UNITS.get(units, units)


def _label(ds, name: str) -> str:
    """Axis label: 'normal force F (N)'."""
    words = name.replace("_", " ")
    symbol = _SYMBOLS.get(name)
    units = _units(ds, name)
    return f"{words}{' ' + symbol if symbol else ''}{f' ({units})' if units else ''}"


def _number(value: float) -> str:
    """10000 as '10000' (not '1e+04'), 1698.3 as '1698', 0.02901 as '0.029', 3e-7 as '3e-07'."""
    value = float(value)
    if abs(value) < 1e7 and (value.is_integer() or abs(value) >= 100):
        return f"{value:.0f}"
    return f"{value:.2g}" if abs(value) < 1 else f"{value:.3g}"


PLAIN_TICKS_BELOW = 1e5  # a log axis whose values all lie in [1e-3, this) has plain-number ticks (_log_ticks)
MAX_LOG_TICKS = 7  # labelled ticks of a log axis of powers of ten


def _log_ticks(axis, values) -> None:
    """Ticks on a log axis (ax.xaxis, ax.yaxis, a colour bar's). Within [1e-3, 1e5) and up to three
    decades plain numbers: 1, 2 and 5 x 10^k over up to 1.5 decades, 1 and 3 x 10^k up to 3.
    Beyond, powers of ten written as such (10^4, not 10000 beside 1e+07, which ran together on a
    narrow panel), at most MAX_LOG_TICKS of them (every second or third decade where more). No
    minor labels (they overlap)."""
    from matplotlib import ticker

    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v) & (v > 0)]
    decades = np.log10(v.max() / v.min()) if v.size else 0.0
    plain = v.size and v.min() >= 1e-3 and v.max() < PLAIN_TICKS_BELOW and decades <= 3.0
    if plain:
        subs = (1.0, 2.0, 5.0) if decades <= 1.5 else (1.0, 3.0)
        axis.set_major_locator(ticker.LogLocator(base=10, subs=subs))
        axis.set_major_formatter(ticker.FuncFormatter(lambda tick, _: _number(tick)))
    else:
        axis.set_major_locator(ticker.LogLocator(base=10, subs=(1.0,), numticks=MAX_LOG_TICKS))
        axis.set_major_formatter(ticker.LogFormatterMathtext())
    axis.set_minor_formatter(ticker.NullFormatter())


def _scale(ax, which: str, values) -> str:
    """Axis ``which`` ('x' or 'y') of ``ax``: log where ``values`` span a decade or more (with
    _log_ticks), symlog where they take both signs and their magnitudes span two decades or more
    (linear within the smallest magnitude), else linear, its small or large numbers as a common power of ten beside the axis
    (a disc velocity of +-1e-4 m/s as -1, 0, 1 and x 10^-4: written out, its ticks overlapped).
    Returns the scale."""
    from matplotlib import ticker

    scale = _axis_scale(values)
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    largest = float(np.abs(v).max()) if v.size else 0.0
    v = v[np.abs(v) > 1e-9 * largest]  # a round-off zero (np.arange(-0.3, 0.31, 0.1) has 5.6e-17) is zero
    magnitude = np.abs(v)
    if scale == "linear" and (v < 0).any() and (v > 0).any() and magnitude.max() >= 100 * magnitude.min():
        scale = "symlog"  # both signs over two decades or more: +-1e-5 and +-1e-4 lay on top of each other at 0
        getattr(ax, f"set_{which}scale")(scale, linthresh=float(magnitude.min()), linscale=0.5)
        getattr(ax, f"{which}axis").set_minor_formatter(ticker.NullFormatter())
        return scale
    getattr(ax, f"set_{which}scale")(scale)
    axis = getattr(ax, f"{which}axis")
    if scale == "log":
        _log_ticks(axis, values)
    else:
        formatter = ticker.ScalarFormatter(useMathText=True)
        formatter.set_powerlimits((-3, 4))
        axis.set_major_formatter(formatter)
    return scale


def _value(ds, name: str, value: float) -> str:
    """Legend entry: 'F = 1000 N', 't_stop = 20.15 s' (the value to 6 digits: a member's value, not a
    tick, which _number rounds to 3)."""
    units = _units(ds, name)
    value = float(value)
    text = f"{value:.0f}" if value.is_integer() and abs(value) < 1e7 else f"{value:.6g}"
    return f"{_SYMBOLS.get(name, name)} = {text}{' ' + units if units else ''}"


def _meeting_point(ds, prefix: str, m: int, metres: bool):
    """(x, t) where member m's first front of the event ``prefix`` meets another, x in mm (metres) or
    in units of L, t in s; None where it meets none (or x / L cannot be had without ``length``)."""
    name = f"{prefix}collision_position"
    meet = float(ds[name].values[m]) if name in ds else np.nan
    if not np.isfinite(meet) or not (metres or "length" in ds):
        return None
    where = meet * 1e3 if metres else meet / float(_per_member(ds, "length")[m])
    return where, float(ds[f"{prefix}collision_time"].values[m])


def front_events(ds) -> list:
    """(event, prefix) of each front event whose arrival times ``ds`` holds, the primary event (its
    outputs unprefixed: ``arrival_time``) first, each other one's outputs prefixed ``event_``
    (``strength_arrival_time``). The events are the attribute ``fronts_event`` (every run with fronts
    writes it, the primary first); without it, the event that arrival_time's long_name names, else
    'velocity' where event_max_velocity exists, else None (not known)."""
    events = ds.attrs.get("fronts_event", "").split()
    if not events and "arrival_time" in ds:
        named = re.search(r"of the (\w+) front", ds.arrival_time.attrs.get("long_name", ""))
        events = [named.group(1) if named else "velocity" if "event_max_velocity" in ds else None]
    prefixes = ["" if k == 0 else f"{event}_" for k, event in enumerate(events)]
    return [(event, prefix) for event, prefix in zip(events, prefixes) if f"{prefix}arrival_time" in ds]


def _front_name(ds) -> str:
    """The primary front event's outputs (arrival_time, v_*) in a title: 'contact front', or
    'detachment front' where the event is not known."""
    events = front_events(ds)
    return f"{events[0][0]} front" if events and events[0][0] else "detachment front"


def _per_member(ds, name: str) -> np.ndarray:
    return np.broadcast_to(np.asarray(ds[name].values, dtype=float), (ds.sizes["member"],))


def _file_layout(ds) -> bool:
    """Whether ``ds`` is a warpfric file opened with xarray itself (``xr.open_dataset``): members
    labelled by strings beside their numbers (``member_number``), recorded fields left in the file's
    group ``recorded``."""
    from .io import MEMBER_NUMBER

    return "member" in ds.dims and MEMBER_NUMBER in ds.coords and ds.member.dtype.kind in "OSU"


def _recorded_group_left_out(ds) -> bool:
    """Whether the file that ``ds`` (opened with xarray.open_dataset) was read from has recorded
    fields (its group 'recorded', which ``ds`` then lacks): the file named in its encoding, where
    that still exists."""
    from .io import RECORDED_GROUP, _has_group

    source = ds.encoding.get("source")
    try:
        return bool(source) and _has_group(source, RECORDED_GROUP)
    except OSError:
        return False


def _require_ensemble(ds, what: str):
    """The ensemble Dataset (simulate's, open_ensemble's layout) of ``ds``: ``ds`` itself, or a file
    opened with xarray itself in that layout (its member numbers as the member coordinate; its
    recorded fields, in the file's group ``recorded``, are not there); a ValueError unless ``ds`` is
    a Dataset with the dimension member and the status of each member."""
    import xarray as xr

    if not isinstance(ds, xr.Dataset):
        raise ValueError(f"{what}: expects the ensemble's xarray Dataset (from simulate or open_ensemble), got "
                         f"{type(ds).__name__}")
    if "member" not in ds.dims or "status" not in ds:
        view = "member" not in ds.dims and "member_number" in ds
        found = ("a by_parameters view (its members are dimensions)" if view else
                 f"dimensions {tuple(ds.dims)}" + ("" if "status" in ds else " without the variable status"))
        raise ValueError(f"{what}: expects an ensemble along the dimension member with each member's status, got "
                         f"{found}; pass the ensemble itself (select members with ds.sel(member=...))")
    if _file_layout(ds):
        from .io import _from_file_layout

        return _from_file_layout(ds)
    return ds


def _require_parameters(ds, what: str, *names) -> None:
    """ValueError naming the first of ``names`` (None: none asked for) that ``ds`` lacks."""
    for name in names:
        if name is not None and name not in ds:
            swept = ds.attrs.get("varying_parameters", "").split()
            raise ValueError(f"{what}: {name!r} is not a parameter of the ensemble; valid: a parameter, e.g. the "
                             f"swept {', '.join(swept) or 'none'}")


def _require_fronts(ds, what: str) -> None:
    if "v_middle" not in ds or "arrival_time" not in ds:
        raise ValueError(f"{what}: the ensemble has no front outputs (run with fronts=None, or written without "
                         "them); run with fronts=warpfric.Fronts()")


def _status_text(ds, ok: np.ndarray) -> str:
    """The members that are not ok, by status, for a title: '; 3 max_steps_reached', or ''."""
    if ok.all():
        return ""
    codes, counts = np.unique(ds.status.values[~ok], return_counts=True)
    return "; " + ", ".join(f"{k} {status_name(ds, int(c))}" for c, k in zip(codes, counts))


def _nothing_to_plot(ax, reason: str) -> None:
    """An empty panel that says why, without the made-up axes of an empty plot."""
    ax.text(0.5, 0.5, reason, transform=ax.transAxes, ha="center", va="center", fontsize=9, wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])


def _no_front_reason(ds, ok: np.ndarray) -> tuple[str, bool]:
    """Why a front panel of ``ds`` is empty, and whether some ok member's front is unknown: its run
    ended before its detachment was over (an explicit end_time, or max_end_time;
    simulate.not_over_groups), where the others saw theirs through and have none."""
    from .simulate import not_over_groups

    groups = list(not_over_groups(ds).values()) if "mu_final" in ds and "mu_s" in ds else []  # (a reduced Dataset)
    unknown = int((ok & np.any(groups, axis=0)).sum()) if groups else 0
    front, n_ok = _front_name(ds), int(ok.sum())
    if not unknown:
        return f"no ok member has a {front}", False
    if unknown == n_ok:
        return (f"no ok member's {front} is known: {plural(unknown, 'run')} ended before the detachment was over",
                True)
    return (f"no ok member has a known {front}: {unknown} of {n_ok} ended before the detachment was over, the "
            "others have none", True)


def _axis_values(ds, name: str, sel: np.ndarray):
    """(x, label, note) of parameter ``name`` as an axis: its values, or their magnitude where all of
    ``sel``'s are negative and span a decade (a log axis of |v|; a linear one put -1e-4 and -1e-5
    on top of each other); ``note`` counts the members at an infinite value, which no axis shows."""
    x = _per_member(ds, name)
    label = _label(ds, name)
    finite = x[sel & np.isfinite(x)]
    if finite.size and (finite < 0).all() and _axis_scale(-finite) == "log":
        x, label = -x, f"|{label.split(' (')[0]}|" + (f" ({_units(ds, name)}), all negative" if _units(ds, name)
                                                        else ", all negative")
    infinite = int((sel & np.isinf(x)).sum())
    note = f"; {plural(infinite, 'member')} at {name} = inf not on the axis" if infinite else ""
    return x, label, note


class _Colours:
    """A second swept parameter as colour: per member ``colour``; ``discrete`` (at most MAX_LEGEND
    values): one colour per value for a legend, else a colour map for a colour bar; viridis, log
    scaled where the values span a decade or more."""

    def __init__(self, ds, name: str, sel: np.ndarray):
        import matplotlib
        from matplotlib import cm, colors

        self.ds, self.name = ds, name
        self.values = _per_member(ds, name)
        # inf (no stop, the automatic end) is a value of its own in a legend; a colour bar has no place
        # for it, so it is left out there (the figure's own count says so)
        self.levels = np.unique(self.values[sel & ~np.isnan(self.values)])
        self.discrete = self.levels.size <= MAX_LEGEND
        self.note = ""  # the members a colour bar leaves out, for the title
        if not self.discrete:
            self.levels = self.levels[np.isfinite(self.levels)]
            left_out = int((sel & np.isinf(self.values)).sum())
            if left_out:
                self.note = f"; {plural(left_out, 'member')} at {name} = inf not shown (no colour for inf)"
        finite = self.levels[np.isfinite(self.levels)]
        lo, hi = (finite.min(), finite.max()) if finite.size else (0.0, 1.0)
        if hi == lo:
            lo, hi = lo - 1.0, hi + 1.0
        self.norm = colors.LogNorm(lo, hi) if _axis_scale(finite) == "log" else colors.Normalize(lo, hi)
        self.cmap = matplotlib.colormaps["viridis"]
        self.mappable = cm.ScalarMappable(norm=self.norm, cmap=self.cmap)

    def colour(self, value: float):
        if self.discrete:  # evenly spaced by rank (0 .. 0.9 of viridis: the last yellow is hard to see)
            rank = int(np.searchsorted(self.levels, value))
            return self.cmap(0.9 * rank / max(self.levels.size - 1, 1))
        return self.cmap(self.norm(value))

    def groups(self, sel: np.ndarray):
        """(value, members) for each value (discrete)."""
        for value in self.levels:
            yield value, sel & (self.values == value)

    def explain(self, fig, axes, extra=()) -> None:
        """The legend (discrete; on the last axes, outside on the right) or the colour bar; ``extra``:
        more legend handles (with a colour bar, a legend of their own on the last axes)."""
        from matplotlib import colors
        from matplotlib.lines import Line2D

        if self.discrete:  # every value, also one that the last panel lacks
            handles = [Line2D([], [], color=self.colour(value), marker="o", ms=4, lw=1.2,
                              label=_value(self.ds, self.name, value)) for value in self.levels]
            axes[-1].legend(handles=handles + list(extra), title=_label(self.ds, self.name), fontsize=8,
                            title_fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                            frameon=False)
        else:
            bar = fig.colorbar(self.mappable, ax=list(axes), label=_label(self.ds, self.name), pad=0.02)
            if isinstance(self.norm, colors.LogNorm):
                _log_ticks(bar.ax.yaxis, self.levels)
            if extra:
                axes[-1].legend(handles=list(extra), fontsize=8)


def _series(ax, x: np.ndarray, y: np.ndarray, sel: np.ndarray, marker: str = "o", failed=None, **kw) -> None:
    """Members ``sel`` as markers, joined by a line where their x values are distinct (a grid); the
    line breaks where a member of ``failed`` (the same series' members that are not ok) lies between
    two neighbours, so that it draws no trend across a member without a value."""
    sel = sel & np.isfinite(x) & np.isfinite(y)
    xs, ys = x[sel], y[sel]
    order = np.argsort(xs, kind="stable")
    xs, ys = xs[order], ys[order]
    joined = xs.size > 1 and np.unique(xs).size == xs.size
    if joined and failed is not None:
        cut = np.sort(x[failed & np.isfinite(x)])
        # a failed member strictly between neighbours k and k + 1: a NaN after k (a gap in the line)
        between = np.searchsorted(cut, xs[:-1], side="right") < np.searchsorted(cut, xs[1:], side="left")
        at = np.flatnonzero(between) + 1
        xs, ys = np.insert(xs, at, np.nan), np.insert(ys, at, np.nan)
    ax.plot(xs, ys, marker=marker, ms=4, lw=1.2 if joined else 0, ls="-" if joined else "none", **kw)


def _plot_by(ax, x, y, sel, colours: _Colours | None, ds, marker="o", label=None, colour=None, failed=None) -> None:
    """y against x for the members ``sel``: one series per colour value, or a coloured scatter;
    ``failed``: the members not ok, where a series' line breaks (_series)."""
    if colours is None:
        _series(ax, x, y, sel, marker, failed, color=colour, label=label)
    elif colours.discrete:
        for value, members in colours.groups(sel):
            _series(ax, x, y, members, marker, None if failed is None else failed & (colours.values == value),
                    color=colours.colour(value), label=_value(ds, colours.name, value))
    else:
        use = sel & np.isfinite(x) & np.isfinite(y) & np.isfinite(colours.values)
        ax.scatter(x[use], y[use], c=colours.values[use], cmap=colours.cmap, norm=colours.norm, s=14, marker=marker)


def _finish(fig, path, written: list) -> None:
    fig.savefig(path, dpi=130, bbox_inches="tight")
    written.append(Path(path))


def _mixed_note(ds, names, ok: np.ndarray) -> str:
    """The swept parameters a figure neither plots nor colours, for its title: their members lie on
    the same axes, not told apart."""
    counts = [(name, np.unique(_per_member(ds, name)[ok]).size) for name in names]
    mixed = [f"{_SYMBOLS.get(name, name)} ({n} values)" for name, n in counts if n > 1]
    return f"\nalso varying, not told apart: {', '.join(mixed)}" if mixed else ""


def mu_s_figure(ds, pname: str, colour_by: str | None = None, mixed=()):
    """mu_s against ``pname`` (ok members), coloured by ``colour_by``; the title names the other
    swept parameters ``mixed`` (their members share the axes)."""
    ds = _require_ensemble(ds, "mu_s_figure")
    _require_parameters(ds, "mu_s_figure", pname, colour_by)
    ok = ds.status.values == 0
    x, xlabel, off_axis = _axis_values(ds, pname, ok)
    mu = np.asarray(ds.mu_s.values, dtype=float)
    colours = _Colours(ds, colour_by, ok) if colour_by else None
    fig, ax = _subplots(figsize=(5.6, 3.8))
    ax.set_title(f"mu_s against {pname.replace('_', ' ')} ({ok.sum()} of {plural(ok.size, 'member')} ok"
                 f"{_status_text(ds, ok)}{off_axis}{colours.note if colours else ''})" + _mixed_note(ds, mixed, ok),
                 fontsize=10)
    shown = ok & np.isfinite(x) & np.isfinite(mu)
    if not shown.any():
        _nothing_to_plot(ax, "no member has a mu_s to show")
        return fig
    _plot_by(ax, x, mu, ok, colours, ds, label=plural(int(ok.sum()), "ok member"), colour="C0", failed=~ok)
    # the members not ok have no mu_s: marked on the axis at their x, so that their values are seen
    # (an axis of the ok members' values alone hid them; the title only counted them)
    failed = ~ok & np.isfinite(x)
    scale = _scale(ax, "x", x[shown | failed] if _axis_scale(x[shown | failed]) == _axis_scale(x[shown]) else x[shown])
    marks = []
    if failed.any():
        on_axis = failed & (x > 0) if scale == "log" else failed
        off = int(failed.sum() - on_axis.sum())
        label = (f"{plural(int(on_axis.sum()), 'member')} not ok (no mu_s), on the axis"
                 + (f"; {off} more at x <= 0, off the log axis" if off else ""))
        marks = ax.plot(x[on_axis], np.zeros(int(on_axis.sum())), "x", color="0.45", ls="none", label=label,
                        transform=ax.get_xaxis_transform(), clip_on=False)
    _scale(ax, "y", mu[shown])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("static friction coefficient mu_s")
    ax.grid(alpha=0.3, which="both" if ax.get_xscale() == "log" else "major")
    if colours is not None:
        colours.explain(fig, [ax], extra=marks)
    else:
        ax.legend(fontsize=8)
    return fig


_SEGMENTS = (("left", "v"), ("middle", "o"), ("right", "^"))
_SECOND = ("second", "s")


def front_speeds_figure(ds, pname: str, colour_by: str | None = None, mixed=()):
    """The first front's v_left, v_middle, v_right, and v_second where some member has a second front,
    against ``pname``: one panel, the segments as markers; with ``colour_by``, one panel per segment,
    coloured by it; the title names the other swept parameters ``mixed``."""
    ds = _require_ensemble(ds, "front_speeds_figure")
    _require_fronts(ds, "front_speeds_figure")
    _require_parameters(ds, "front_speeds_figure", pname, colour_by)
    ok = ds.status.values == 0
    x, xlabel, off_axis = _axis_values(ds, pname, ok)
    segments = _SEGMENTS
    if "v_second" in ds and np.isfinite(np.asarray(ds.v_second.values, dtype=float)[ok]).any():
        segments = _SEGMENTS + (_SECOND,)
    speeds = {seg: np.asarray(ds[f"v_{seg}"].values, dtype=float) for seg, _ in segments}
    shown = {seg: ok & np.isfinite(x) & np.isfinite(v) for seg, v in speeds.items()}
    every = np.concatenate([speeds[seg][shown[seg]] for seg in speeds])
    colours = _Colours(ds, colour_by, ok) if colour_by else None
    title = (f"{_front_name(ds)} speeds ({plural(int(ok.sum()), 'ok member')}{_status_text(ds, ok)}{off_axis}"
             f"{colours.note if colours else ''})")
    if not every.size:
        fig, ax = _subplots(figsize=(5.6, 3.8))
        ax.set_title(title, fontsize=10)
        _nothing_to_plot(ax, _no_front_reason(ds, ok)[0])
        return fig
    if colours is None:
        fig, ax = _subplots(figsize=(5.6, 3.8))
        for k, (seg, marker) in enumerate(segments):
            _plot_by(ax, x, speeds[seg], shown[seg], None, ds, marker,
                     label=f"v_{seg} ({plural(int(shown[seg].sum()), 'member')})", colour=f"C{k}", failed=~ok)
        axes = [ax]
        ax.legend(fontsize=8)
        ax.set_ylabel("front speed (m/s)")
        ax.set_title(title, fontsize=10)
    else:
        fig, axes = _subplots(1, len(segments), figsize=(3.85 * len(segments), 3.6), sharex=True, sharey=True)
        for ax, (seg, marker) in zip(axes, segments):
            _plot_by(ax, x, speeds[seg], shown[seg], colours, ds, marker, failed=~ok)
            # short panel titles (the first front's segments: the figure's title says so), which
            # did not fit beside each other with a colour bar
            ax.set_title(f"{'second front' if seg == 'second' else seg + ' segment'}, "
                         f"{plural(int(shown[seg].sum()), 'member')}", fontsize=9)
        axes[0].set_ylabel("front speed (m/s)")
        colours.explain(fig, axes)
        # its foot at the figure's top (the saved figure grows to hold it): a second line (the
        # parameters not told apart) ran over the panels' titles
        fig.suptitle(title.replace(" speeds (", " speeds, first front's segments (", 1) + _mixed_note(ds, mixed, ok),
                     fontsize=10, y=1.0, va="bottom")
    for ax in axes:
        _scale(ax, "x", x[np.any(list(shown.values()), axis=0)])
        _scale(ax, "y", every)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3, which="both")
    return fig


def _curve_colour(k: int, n: int):
    """Curve k of n its own colour: matplotlib's ten cycle colours, tab20's twenty, else viridis."""
    import matplotlib

    if n <= 10:
        return f"C{k}"
    return matplotlib.colormaps["tab20"](k) if n <= 20 else matplotlib.colormaps["viridis"](k / (n - 1))


def arrival_times_figure(ds, max_curves: int = MAX_CURVES):
    """Arrival time minus the first arrival against x for up to ``max_curves`` ok members spread
    over the ensemble, coloured by the first swept parameter, dashed or dotted by the second (where
    it takes at most 4 values among them) and labelled with every swept value."""
    ds = _require_ensemble(ds, "arrival_times_figure")
    _require_fronts(ds, "arrival_times_figure")
    swept = ds.attrs.get("varying_parameters", "").split()
    ok = ds.status.values == 0
    arrived = np.isfinite(ds.arrival_time.values).any(axis=1)
    candidates = np.flatnonzero(ok & arrived)
    if candidates.size > max_curves:
        candidates = candidates[np.unique(np.linspace(0, candidates.size - 1, max_curves).round().astype(int))]
    colours = _Colours(ds, swept[0], np.isin(np.arange(ok.size), candidates)) if swept else None
    styles = {}
    if len(swept) > 1:
        second = _per_member(ds, swept[1])
        levels = np.unique(second[candidates])
        styles = {value: style for value, style in zip(levels, ("-", "--", ":", "-."))} if levels.size <= 4 else {}
    looks = [(colours.colour(colours.values[m]) if colours is not None else _curve_colour(k, len(candidates)),
              styles.get(second[m], "-") if styles else "-") for k, m in enumerate(candidates)]
    if len(set(looks)) < len(looks):  # curves alike (a second parameter of many values, a third): one colour each
        looks = [(_curve_colour(k, len(candidates)), "-") for k in range(len(candidates))]
    metres = ds.x.attrs.get("units") == "m"
    x = ds.x.values * (1e3 if metres else 1.0)
    fig, ax = _subplots(figsize=(7.4, 3.8))
    # a curve spanning more than OUTLIER_SPAN x the median curve's time (a member far from the others)
    # runs off the axis, which keeps the others' shapes: it squashed them flat at 0
    spans = np.array([np.nanmax(ds.arrival_time.values[m]) - np.nanmin(ds.arrival_time.values[m]) for m in candidates])
    median = float(np.median(spans)) if spans.size >= 3 else 0.0
    outlier = spans > OUTLIER_SPAN * median if median > 0 else np.zeros(spans.size, bool)
    meetings = 0
    for k, m in enumerate(candidates):
        ta = ds.arrival_time.values[m]
        label = ", ".join(_value(ds, name, _per_member(ds, name)[m]) for name in swept) or f"member {int(ds.member[m])}"
        if outlier[k]:
            label += f" (to {spans[k] * 1e3:.3g} ms, off the axis)"
        colour, style = looks[k]
        ax.plot(x, (ta - np.nanmin(ta)) * 1e3, lw=1.4, color=colour, ls=style, label=label)
        meet = _meeting_point(ds, "", m, metres)  # where the first front meets another (its segments end there)
        if meet is not None:
            ax.plot(meet[0], (meet[1] - np.nanmin(ta)) * 1e3, "v", color=colour, ms=7, mfc="none", label="_meeting")
            meetings += 1
    if outlier.any():
        ax.set_ylim(0.0, 1.1 * spans[~outlier].max() * 1e3)
    ax.set_xlabel("x (mm)" if metres else "x / L")
    ax.set_ylabel("t_a - first arrival (ms)")
    with_front = int((ok & arrived).sum())
    reason, unknown = _no_front_reason(ds, ok) if not candidates.size else ("", False)
    shown = (f"{candidates.size} of the {plural(with_front, 'ok member')} with a front" if candidates.size
             else "no ok member with a known front" if unknown else "no ok member with a front")
    met = f"; \u25bd where two fronts meet: {meetings}" if meetings else ""
    ax.set_title(f"{_front_name(ds)} arrival times ({shown}{_status_text(ds, ok)}{met})", fontsize=10)
    ax.grid(alpha=0.3)
    if not candidates.size:
        _nothing_to_plot(ax, reason)
    else:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, frameon=False)
    return fig


def mu_s_histogram_figure(ds):
    """The histogram of the ok members' mu_s (quick_look's figure of an ensemble without a swept
    parameter); the title counts the members by status."""
    ds = _require_ensemble(ds, "mu_s_histogram_figure")
    ok = ds.status.values == 0
    mu = np.asarray(ds.mu_s.values, dtype=float)[ok & np.isfinite(ds.mu_s.values)]
    fig, ax = _subplots(figsize=(5.6, 3.8))
    ax.set_title(f"mu_s of {plural(ok.size, 'member')} ({ok.sum()} ok{_status_text(ds, ok)})", fontsize=10)
    if not mu.size:
        _nothing_to_plot(ax, "no member has a mu_s to show")
        return fig
    if mu.min() == mu.max():  # one value: numpy's bins were value +- 0.5, a bar from 0.01 to 1.01
        width = max(abs(mu[0]) * 1e-3, 1e-12)
        ax.hist(mu, bins=[mu[0] - width, mu[0] + width], label=f"{plural(mu.size, 'ok member')}, all at {mu[0]:.6g}")
    else:
        edges = np.histogram_bin_edges(mu, bins="auto")
        ax.hist(mu, bins=edges if np.size(edges) <= 41 else 40, label=plural(mu.size, "ok member"))
    ax.set_xlabel("static friction coefficient mu_s")
    ax.set_ylabel("members")
    ax.legend(fontsize=8)
    return fig


def quick_look(ds, outdir, max_curves: int = MAX_CURVES) -> list:
    """Write PNGs into ``outdir``: mu_s and front speeds against each swept parameter (coloured by
    another swept parameter), arrival-time curves, and the space-time map and mu(t) of every recorded
    member. ``ds``: simulate's or open_ensemble's Dataset (a file opened with xarray.open_dataset has
    no recorded fields: they are in its group 'recorded').
    Returns the paths written."""
    ensemble = _require_ensemble(ds, "quick_look")
    if ensemble is not ds and ("velocity_history" in ds or _recorded_group_left_out(ds)):  # a file opened with xarray
        warnings.warn("quick_look: a file opened with xarray itself: its recorded fields are not drawn (they are in "
                      "the file's group 'recorded', which xarray.open_dataset does not read); open the file with "
                      "warpfric.io.open_ensemble(path) to draw them too", stacklevel=2)
    ds = ensemble
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    written = []
    swept = ds.attrs.get("varying_parameters", "").split()
    for pname in swept:
        others = [name for name in swept if name != pname]
        colour_by = others[0] if others else None
        _finish(mu_s_figure(ds, pname, colour_by, others[1:]), outdir / f"mu_s_vs_{pname}.png", written)
        if "v_middle" in ds:
            _finish(front_speeds_figure(ds, pname, colour_by, others[1:]), outdir / f"front_speeds_vs_{pname}.png",
                    written)
    if not swept and ds.sizes["member"] > 1:
        _finish(mu_s_histogram_figure(ds), outdir / "mu_s_histogram.png", written)
    if "arrival_time" in ds:
        _finish(arrival_times_figure(ds, max_curves), outdir / "arrival_times.png", written)
    if "velocity_history" in ds:
        for r, member in enumerate(ds.recorded_member.values):
            if member in ds.member.values:  # a selection of members may leave recorded ones out
                written.append(space_time_map(ds, r, outdir / f"space_time_member{int(member)}.png"))
                _finish(friction_history_figure(ds, r), outdir / f"friction_member{int(member)}.png", written)
    return written


def _recorded_member(ds, recorded_index: int, what: str) -> tuple[int, int]:
    """(member number, position along member) of the recorded member at ``recorded_index``; a
    ValueError naming ``what`` where there is none."""
    if _require_ensemble(ds, what) is not ds:  # a file's layout (even with its group merged in: string labels)
        raise ValueError(f"{what}: a file opened with xarray itself: xarray.open_dataset reads a file's root group "
                         "only, and a file keeps its recorded fields in the group 'recorded'; open the file with "
                         "warpfric.io.open_ensemble(path)")
    if "velocity_history" not in ds:
        raise ValueError(f"{what}: the ensemble has no recorded fields (run with record=warpfric.Record(...); the "
                         "command line: warpfric run -o OUT.nc --record, or [record] in a sweep file)")
    recorded = [int(m) for m in ds.recorded_member.values]
    if not (isinstance(recorded_index, (int, np.integer)) and 0 <= recorded_index < len(recorded)):
        raise ValueError(f"{what}: recorded_index = {recorded_index!r}; valid: 0..{len(recorded) - 1}, the "
                         f"position among the recorded members (numbers {', '.join(map(str, recorded))})")
    member = recorded[recorded_index]
    if member not in ds.member.values:
        raise ValueError(f"{what}: recorded member {member} is not among the ensemble's members (a selection left "
                         "it out)")
    return member, int(np.flatnonzero(ds.member.values == member)[0])  # member numbers may start past 0


def _member_title(ds, member: int, position: int, what: str) -> str:
    """'member 3: WHAT (2e/L = 0.1, F = 500 N)': one member's figure title with its first three swept
    values."""
    swept = [name for name in ds.attrs.get("varying_parameters", "").split() if name in ds]
    values = ", ".join(_value(ds, name, _per_member(ds, name)[position]) for name in swept[:3])
    return f"member {member}: {what}" + (f" ({values})" if values else "")


def friction_history_figure(ds, recorded_index: int):
    """The friction coefficient mu(t) of one recorded member over its recording times
    (``friction_coefficient_history``, or computed from the recorded fields of a file written
    without it), with the member's mu_s at mu_s_time, its mu_final at final_time and the time span
    of its first front of each front event the Dataset holds, where they lie in the recorded window."""
    from .simulate import friction_coefficient_history

    member, position = _recorded_member(ds, recorded_index, "friction_history_figure")
    mu_all = ds["friction_coefficient_history"] if "friction_coefficient_history" in ds else \
        friction_coefficient_history(ds)
    mu = np.asarray(mu_all.values[recorded_index], dtype=float)
    t = np.asarray(ds.time.values, dtype=float)
    fig, ax = _subplots(figsize=(6, 3.6))
    ax.plot(t, mu, color="k", lw=1.3, label="mu(t), recorded fields")
    window = (t.min(), t.max())
    status = int(ds.status.values[position])
    marks = (("mu_s", "mu_s_time", "o", "tab:red", "mu_s = {:.6f} (the peak)"),
             ("mu_final", "final_time", "s", "tab:blue", "mu_final = {:.6f} (the run's end)"))
    for name, when, marker, colour, text in marks:
        value, at = float(_per_member(ds, name)[position]), float(_per_member(ds, when)[position])
        if np.isfinite(value) and window[0] <= at <= window[1]:
            ax.plot([at], [value], marker, color=colour, mfc="none", ms=8, ls="none", label=text.format(value),
                    clip_on=False)  # the end's marker sits on the window's edge
        elif name == "mu_s" or np.isfinite(value):  # mu_final is NaN only where mu_s says why
            why = ("not given (status " + status_name(ds, status) + ")" if not np.isfinite(value) else
                   f"{value:.6f} at t = {at:.6g} s, outside the recorded times")
            ax.plot([], [], ls="none", label=f"{name}: {why}")
    for event, prefix in front_events(ds):
        start, end = (float(_per_member(ds, f"{prefix}front_{when}_time")[position]) for when in ("start", "end"))
        if np.isfinite(start) and np.isfinite(end) and end >= window[0] and start <= window[1]:
            front = f"{event} front" if event else "front"
            ax.axvspan(max(start, window[0]), min(end, window[1]), color=_span_colour(event),
                       alpha=0.2,
                       label=f"{front}: t = {start:.5f} .. {end:.5f} s")
    end = float(_per_member(ds, "final_time")[position]) if "final_time" in ds else np.nan
    if np.isfinite(end) and end < window[1]:  # grey after the member's end, as on its space-time map
        ax.axvspan(max(end, window[0]), window[1], color="0.8", alpha=0.6, lw=0, label="after the run's end")
    if np.isfinite(mu).sum() < 2:  # one point draws no curve (and its axis spans a round-off)
        _nothing_to_plot(ax, "no recorded time with a normal force before the member's end" if not np.isfinite(mu).any()
                         else "one recorded time before the member's end: no curve to draw")
    ax.set_xlim(window)
    ax.set_xlabel("t (s)")
    ax.set_ylabel("friction coefficient mu")
    ax.ticklabel_format(axis="x", useOffset=False)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best", framealpha=0.8)
    ax.set_title(_member_title(ds, member, position, "friction coefficient"), fontsize=10)
    fig.tight_layout()
    return fig


def space_time_map(ds, recorded_index: int, path) -> Path:
    """:func:`space_time_figure` of one recorded member, written to ``path``."""
    fig = space_time_figure(ds, recorded_index)
    fig.savefig(path, dpi=130)
    return Path(path)


def space_time_figure(ds, recorded_index: int):
    """Pad velocity over (x, t) of one recorded member (the paper's Fig. 3 style), with the member's
    arrival-time curve t_a(x) of each front event the Dataset holds (over the nodes the front
    reached; none where it reached none: 'no contact front' in the legend, or 'not given' with the
    status of a member that is not ok, whose front outputs are NaN); grey where nothing was recorded
    (after the member's end); and, for the velocity
    event, the contour of threshold x its event maximum on the recorded field (event_max_velocity
    exists only for that event), and a triangle where the first front meets another. The legend
    names the event of each curve; the axes keep the recorded window."""
    import matplotlib
    from matplotlib import patheffects
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    member, position = _recorded_member(ds, recorded_index, "space_time_figure")
    v = ds.velocity_history.values[recorded_index]
    t = ds.time.values
    metres = ds.x.attrs.get("units") == "m"
    x = ds.x.values * (1e3 if metres else 1.0)
    fig, ax = _subplots(figsize=(6, 4))
    recorded_values = np.isfinite(v)
    largest = float(np.abs(v[recorded_values]).max()) if recorded_values.any() else 0.0
    scale = largest or 1.0
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.8")  # NaN (after the member's end) grey, not
    # the white of zero velocity
    mesh = ax.pcolormesh(x, t, v * 1e9, cmap=cmap, vmin=-scale * 1e9, vmax=scale * 1e9, shading="nearest")
    if recorded_values.any():  # a colour bar of nothing recorded showed a made-up scale
        fig.colorbar(mesh, ax=ax, label="pad velocity (nm/s)")
        disc = abs(float(_per_member(ds, "disc_velocity")[position])) if "disc_velocity" in ds else 0.0
        if disc > 0 and largest < ROUND_OFF_VELOCITY * disc:  # (a member that failed before the disc moved,
            # a window before the disc starts) the colours stretch to whatever is there: +-2e-14 nm/s of
            # round-off read as structure
            size = f"|v| <= {largest:.2g} m/s, {largest / disc:.1g} x the disc's velocity" if largest else "v = 0"
            ax.text(0.5, 0.5, f"round-off only: {size}", transform=ax.transAxes, ha="center", va="center",
                    fontsize=9, bbox={"facecolor": "w", "alpha": 0.8, "lw": 0})
    else:
        ax.text(0.5, 0.5, "nothing recorded: the run ended before the recorded times", transform=ax.transAxes,
                ha="center", va="center", fontsize=9)
    window = ax.get_xlim(), ax.get_ylim()
    handles = []
    if not recorded_values.all():
        end = float(_per_member(ds, "final_time")[position]) if "final_time" in ds else np.nan
        handles.append(Patch(color="0.8", label="not recorded: after the run's end" +
                             (f" (t = {end:.6g} s)" if np.isfinite(end) else "")))
    for event, prefix in front_events(ds):
        front = f"{event} front" if event else "front"
        event_max = f"{prefix}event_max_velocity"  # the velocity event's: its threshold contour
        if event_max in ds and np.isfinite(float(ds[event_max][position])):
            sign = -np.sign(_per_member(ds, "disc_velocity")[position])
            threshold = float(ds.attrs.get("fronts_threshold", 0.4))
            level = threshold * float(ds[event_max][position])
            if ds.attrs.get("fronts_direction", "against_disc") == "against_disc" and np.nanmax(sign * v) >= level:
                ax.contour(x, t, sign * v, levels=[level], colors="k", linewidths=1)
                handles.append(Line2D([], [], color="k", lw=1,
                                      label=f"{front}: {threshold:g} x event maximum (recorded)"))
        ta = np.asarray(ds[f"{prefix}arrival_time"].values[position], dtype=float)
        reached = np.flatnonzero(np.isfinite(ta))
        if not reached.size:  # no curve; the legend says so
            status = int(ds.status.values[position])  # (_require_ensemble: every ensemble has one)
            # a member that is not ok has NaN front outputs whether or not a front ran (no_peak: the
            # map may show one): not "no front"
            text = f"no {front}" if status == 0 else f"{front}: not given (status {status_name(ds, status)})"
            from .simulate import not_over_groups

            # a run that ended before its detachment was over (cut off by end_time, or stopped by
            # max_end_time): its fronts are not known
            if any(which[position] for which in not_over_groups(ds).values()):
                text = f"{front}: not given (the run ended before the detachment was over)"
            handles.append(Line2D([], [], ls="none", label=text))
            continue
        gaps = np.flatnonzero(np.diff(reached) > 1) + 1  # no line across nodes the front did not reach
        colour, style = _ARRIVAL_STYLES.get(event, _OTHER_ARRIVAL)
        seen = (ta[reached] >= t.min()) & (ta[reached] <= t.max())
        # a white curve (the velocity event's, on its black contour) is outlined, so that its legend
        # entry shows on the legend's white
        outline = [patheffects.withStroke(linewidth=2.6, foreground="k")] if colour == "w" else None
        handles += ax.plot(np.insert(x[reached], gaps, np.nan), np.insert(ta[reached], gaps, np.nan), color=colour,
                           ls=style, lw=1.5, path_effects=outline, label=f"{front}: arrival time t_a"
                           + ("" if seen.any() else " (outside the recorded times)"))
        meet = _meeting_point(ds, prefix, position, metres)
        if meet is not None:
            handles += ax.plot(*meet, "v", color=colour, ms=8, mfc="none", ls="none",
                               label=f"{front}: where the first front meets another")
    ax.set_xlim(window[0])
    ax.set_ylim(window[1])
    if handles:
        # below the axes: inside, it covered the later fronts' curves (the strength and velocity
        # fronts cross near the window's top)
        ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.15), frameon=False)
    ax.set_xlabel("x (mm)" if metres else "x / L")
    ax.set_ylabel("t (s)")
    ax.set_title(_member_title(ds, member, position, "pad velocity"), fontsize=10)
    fig.tight_layout()
    return fig
