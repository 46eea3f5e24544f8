"""warpfric.front_outputs: the front outputs as Dataset variables (names, units, long names,
comments, flags) and which members' fronts are unknown; shared by :func:`warpfric.simulate`, which
makes them, and :func:`warpfric.fronts.resegment`, which makes them again from stored arrival times."""

from __future__ import annotations

import dataclasses

import numpy as np
import xarray as xr

from .parameters import Fronts


def detachment_not_over(ds: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
    """(capped, cut), (member,) bool each: the members ok whose run ended before their detachment was
    over, at max_end_time, the automatic end's cap (end_time None: its conditions never all held;
    :func:`warpfric.simulate.not_over_groups` tells which), or, with fronts, at an explicit end_time (detachment_end_time NaN and their
    front outputs NaN; detached_fraction is 0, not NaN, for a member that saw its detachment through
    without a front). Neither rule needs detachment_end_time of a file of an earlier version, which
    is unknown (NaN) for every member."""
    n = ds.sizes["member"]
    ok = ds.status.values == 0

    def per_member(name):
        return np.broadcast_to(np.asarray(ds[name].values, dtype=float), (n,))

    automatic = ~np.isfinite(per_member("end_time")) if "end_time" in ds else np.ones(n, bool)
    capped = ok & automatic & (per_member("final_time") >= per_member("max_end_time")) if "max_end_time" in ds \
        else np.zeros(n, bool)
    cut = np.zeros(n, bool)
    if "fronts_event" in ds.attrs and "detachment_end_time" in ds and "detached_fraction" in ds:
        cut = ok & ~capped & ~np.isfinite(per_member("detachment_end_time")) & np.isnan(per_member("detached_fraction"))
    return capped, cut


EVENT_WORDS = {
    "contact": "contact front (each node's first gate opening after the disc starts: its stick-to-slip transition)",
    "strength": "strength front (each node's peak of tau_f/sigma_n)",
    "velocity": "velocity front (the pad velocity against the disc reaches threshold times its event maximum)",
}
# each front output: (units, long_name, comment or None). The long_name is short (xarray labels plots
# with it); the comment says exactly what the value is. {front}: the event's name ("contact front"),
# {words}: its description (EVENT_WORDS)
FRONT_ATTRS = {
    "arrival_time": ("s", "arrival time t_a of the {front} at each node", "{words}; NaN: never reached"),
    "arrival_time_error": ("s", "interpolation error of t_a of the {front}", "the error of t_a inside its step: a "
                           "lower bound, the "
                           "trajectory's error at rtol and the grid's move t_a further"),
    "event_max_velocity": ("m s-1", "maximum of the detachment velocity w over the pad and the event window", None),
    "strength_peak": ("1", "peak of tau_f/sigma_n at each node", "each node's own static friction coefficient; NaN: "
                      "no confirmed peak in the run"),
    "nucleation_position": ("m", "position of the node that the {front} reaches first", "{words}"),
    "front_start_time": ("s", "first arrival time of the {front}", "{words}"),
    "front_end_time": ("s", "last arrival time of the {front}", "over the nodes it reached; {words}"),
    "detached_fraction": ("1", "fraction of the nodes the {front} reached", "{words}"),
    "front_count": ("1", "separate fronts of the {front}", "local minima of t_a(x) over the run of nodes it reached "
                    "(a flat run of equal times once), each a nucleation (2: a second front, e.g. from the other "
                    "edge, meets the first); 0: it reached no node; NaN: unknown (the member did not end ok or "
                    "ended before its detachment was over); {words}"),
    "collision_position": ("m", "where the first front of the {front} meets another", "the maximum of t_a(x) at an "
                           "end of the first front, the middle of a flat top; the earlier end where both are "
                           "meetings; NaN: the first front meets none; {words}"),
    "collision_time": ("s", "when the first front of the {front} meets another", "NaN: it meets none; {words}"),
    "second_nucleation_position": ("m", "position where the second front of the {front} starts", "the earliest "
                                   "arrival outside the nodes the first front reaches first; NaN: one front; {words}"),
    "second_front_start_time": ("s", "time the second front of the {front} starts", "NaN: one front; {words}"),
}
# each segment and whole front: (short words, its definition)
SEGMENT_WORDS = {"left": ("the first front's left segment", "the segment at smaller x"),
                  "middle": ("the first front's middle segment", "between its left and right segments"),
                  "right": ("the first front's right segment", "the segment at larger x"),
                  "precursor": ("the first front's precursor", "its slow segment at the nucleation edge"),
                  "main": ("the first front's main segment", "its middle segment"),
                  "far": ("the first front's far segment", "its slow segment at the end opposite the nucleation "
                          "edge"),
                  "first": ("the first front", "whole: the nodes it reaches before any other front"),
                  "second": ("the second front", "whole: from where it starts to where it meets another front")}
for _seg, (_short, _definition) in SEGMENT_WORDS.items():
    # a position, not where the front starts (nucleation_position): the name's start/end is smaller/larger x
    FRONT_ATTRS[f"{_seg}_front_start"] = ("m", f"smaller x of {_short} of the {{front}}",
                                           f"the name's start: its smaller x, not where it starts; {_short[4:]}: "
                                           f"{_definition}; {{words}}")
    FRONT_ATTRS[f"{_seg}_front_end"] = ("m", f"larger x of {_short} of the {{front}}",
                                         f"the name's end: its larger x; {_short[4:]}: {_definition}; {{words}}")
    FRONT_ATTRS[f"{_seg}_front_length"] = ("m", f"length of {_short} of the {{front}}",
                                            f"{_short[4:]}: {_definition}; {{words}}")
    FRONT_ATTRS[f"v_{_seg}"] = ("m s-1", f"speed of {_short} of the {{front}}",
                                 f"mean speed, 1/|slope| of t_a(x); {_short[4:]}: {_definition}; inf: its nodes "
                                 f"arrived at one time (not resolved, v_{_seg}_error inf); {{words}}")
    FRONT_ATTRS[f"v_{_seg}_error"] = ("m s-1", f"interpolation error of v_{_seg} of the {{front}}",
                                       "from the arrival_time_error of "
                                       "its end (and nucleation) nodes: a lower bound, not the speed's error "
                                       "(v_*_grid_error from Fronts(grid_check=True) is usually far larger); inf: "
                                       "not resolved")


def fronts_attrs(fronts: Fronts) -> dict:
    """The Fronts settings as Dataset attributes (fronts_*)."""
    attrs = {}
    for f in dataclasses.fields(fronts):
        value = getattr(fronts, f.name)
        if f.name == "event":
            value = " ".join(fronts.events)  # netCDF: one string, the primary event first
        attrs[f"fronts_{f.name}"] = int(value) if isinstance(value, bool) else value  # netCDF has no bool
    return attrs


def fronts_from_attrs(ds) -> Fronts:
    """The Fronts settings an ensemble ran with, from its fronts_* attributes (:func:`fronts_attrs`
    read back; ValueError where it has none)."""
    if "fronts_event" not in ds.attrs:
        has = "arrival_time" in ds
        raise ValueError("the ensemble has arrival_time but not the fronts_* attributes that say how it ran (were its "
                         "attributes dropped? ds.attrs of the file that holds it has them)" if has else
                         "the ensemble has no front outputs (it ran with fronts=None, or fronts = false): nothing "
                         "to segment")
    given = {}
    for f in dataclasses.fields(Fronts):
        if f"fronts_{f.name}" in ds.attrs:
            value = ds.attrs[f"fronts_{f.name}"]
            value = tuple(str(value).split()) if f.name == "event" else value
            given[f.name] = bool(value) if f.name == "grid_check" else value.item() if hasattr(value, "item") \
                else value
    return Fronts(**given)


def front_variables(front: dict, fronts: Fronts, failed: np.ndarray) -> dict:
    """The front outputs (_front_metrics) as Dataset variables, {name: (dims, values, attrs)}, NaN
    for the failed members (member,) bool."""
    new = {}
    for name, arr in front.items():
        arr = np.where(failed[:, None] if arr.ndim == 2 else failed, np.nan, arr)
        event = next((e for e in fronts.events[1:] if name.startswith(e + "_")), fronts.events[0])
        base = name[len(event) + 1:] if event != fronts.events[0] else name
        words = EVENT_WORDS[event]
        if base == "nucleation_edge":
            # -3 where the front is not known (a member not ok, or cut off before its detachment was over),
            # -2 where the member saw its detachment through and no node was reached: "none" only there (a
            # failed member read as "none" made a category of its own in a groupby)
            edge = np.where(np.isfinite(arr), arr, np.where(failed, -3, -2)).astype(np.int8)
            new[name] = (("member",), edge, {
                "long_name": f"edge where the {event} front nucleates",
                "comment": f"{words}; unknown: the member did not end ok or ended before its detachment was over",
                "flag_values": np.array([-3, -2, -1, 0, 1], dtype=np.int8),
                "flag_meanings": "unknown none left interior right",
            })
            continue
        if base == "front_count":  # 0 where the member saw its detachment through and no node was reached
            # (NaN read as "unknown" left those members out of counts and means); NaN stays for the unknown
            arr = np.where(np.isnan(arr) & ~failed, 0.0, arr)
        units, long_name, comment = FRONT_ATTRS[base]
        dims = ("member", "x") if arr.ndim == 2 else ("member",)
        attrs = {"units": units, "long_name": long_name.format(front=f"{event} front")}
        if comment:
            attrs["comment"] = comment.format(words=words)
        new[name] = (dims, arr, attrs)
    return new
