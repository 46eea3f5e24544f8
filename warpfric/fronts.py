"""warpfric.fronts: detachment-front metrics from arrival times (docs/model.md, "Fronts").

simulate() computes the arrival times in the integrator and segments them here; the functions are
public so that a stored ensemble can be re-segmented with other settings without re-simulating
(:func:`resegment`: ``new = resegment(ds, speed_ratio=2)``, then ``ds.update(new)`` and
``ds.attrs.update(new.attrs)``; :func:`segment` for bare arrays) and so that the rule can be checked
on sampled velocity fields (:func:`arrival_times_from_history`).
"""

from __future__ import annotations

import math

import numpy as np

from .device import check_device, init_warp
from .parameters import Fronts

FRONT_METRIC_NAMES = (
    "nucleation_position", "nucleation_edge", "front_start_time", "front_end_time", "detached_fraction",
    "left_front_start", "left_front_end", "left_front_length", "v_left",
    "middle_front_start", "middle_front_end", "middle_front_length", "v_middle",
    "right_front_start", "right_front_end", "right_front_length", "v_right",
    "first_front_start", "first_front_end", "first_front_length", "v_first",
    "second_front_start", "second_front_end", "second_front_length", "v_second",
    "front_count", "collision_position", "collision_time", "second_nucleation_position", "second_front_start_time",
)
# the first front's segments by position; the first and the second front are also reported whole
POSITION_SEGMENTS = ("left", "middle", "right")
WHOLE_FRONTS = ("first", "second")
# the segments named from where the front starts (nucleation_edge -1: left, +1: right)
START_SEGMENTS = ("precursor", "main", "far")
SEGMENT_NAMES = POSITION_SEGMENTS + START_SEGMENTS + WHOLE_FRONTS


def _segment_fields(seg: str) -> tuple:
    return (f"{seg}_front_start", f"{seg}_front_end", f"{seg}_front_length", f"v_{seg}")


def name_from_start(metrics: dict) -> dict:
    """The segments named from where the front starts, from the positional ones: the precursor is
    the slow segment at the nucleation edge, the main front the middle one, the far segment the slow
    one at the other edge (left/right swap with the nucleation edge). A front that nucleates inside
    the pad has no precursor and no far segment (NaN); its main front is the middle one.
    Returns {name: (members,) array} for the start/end/length/speed of each (positions in m)."""
    edge = np.asarray(metrics["nucleation_edge"], dtype=np.float64)
    out = {}
    for name, at_left, at_right in (("precursor", "left", "right"), ("far", "right", "left")):
        for field_new, field_left, field_right in zip(_segment_fields(name), _segment_fields(at_left),
                                                      _segment_fields(at_right)):
            out[field_new] = np.where(edge == -1, metrics[field_left], np.where(edge == 1, metrics[field_right], np.nan))
    for field_new, field_mid in zip(_segment_fields("main"), _segment_fields("middle")):
        out[field_new] = np.asarray(metrics[field_mid], dtype=np.float64).copy()
    return out


def min_segment_intervals(fronts: Fronts, nodes: int) -> int:
    """Fewest node intervals of a front segment: min_segment_fraction of the pad, at least 3."""
    return max(3, int(math.ceil(fronts.min_segment_fraction * (nodes - 1) - 1e-9)))


def segment(arrival_time, length, fronts: Fronts = Fronts(), device: str | None = "cpu") -> dict:
    """Front metrics from arrival times.

    arrival_time: (members, nodes) s, NaN where the front never arrived; nodes evenly spaced over
                  the pad from -L/2 to +L/2.
    length:       pad length L in m, scalar or (members,).
    Returns {name: (members,) float64 array} for FRONT_METRIC_NAMES and the segments named from the
    start (:func:`name_from_start`; positions and lengths in m, times in s, speeds in m/s;
    nucleation_edge -1 left, 0 interior, +1 right, NaN none). An xarray DataArray with the
    dimension ``x`` is checked to be on that grid (its x in m, or in units of L where "1"): the union
    of other files' grids (xarray.open_mfdataset of runs with other node counts), or a selection of
    nodes, gave speeds and fractions of a pad that is not the member's, without a word.
    """
    if hasattr(arrival_time, "dims") and "x" in arrival_time.dims:
        arrival_time = arrival_time.transpose(..., "x")
        if "x" in arrival_time.coords:  # (a dimension without positions is taken as the grid, as an array is)
            _check_pad_grid(arrival_time.x, length)
    ta = np.atleast_2d(np.asarray(arrival_time, dtype=np.float64))
    return segment_nodes_first(np.ascontiguousarray(ta.T), length, fronts, device)


# the Fronts settings that decide the arrival times (stored in an ensemble), and those that segment them
ARRIVAL_SETTINGS = ("event", "threshold", "direction", "min_event_fraction")
SEGMENT_SETTINGS = ("min_segment_fraction", "fast_fraction", "speed_ratio", "edge_zone_fraction")


def resegment(ds, *, device: str | None = "cpu", **settings):
    """The front outputs of an ensemble (from :func:`warpfric.simulate` or a file) segmented again
    from its stored arrival times with other segmentation ``settings``, without re-simulating: an
    xarray.Dataset of the variables, dtypes and attributes that ``simulate`` gives them, for every
    front event of ``ds``. Put them in place with ``ds.update(new)`` and ``ds.attrs.update(new.attrs)``
    (the fronts_* settings used).

    settings: min_segment_fraction, fast_fraction, speed_ratio, edge_zone_fraction (docs/model.md,
              "Fronts"); those not given are the ensemble's own, so that ``resegment(ds)`` gives its
              outputs back. The event, threshold, direction and min_event_fraction decided the
              stored arrival times: a run with other values is a new run.
    Returns a Dataset along ``member`` (the ensemble's member coordinate): nucleation_edge int8,
    -3 (unknown) and front_count NaN for the members not ok or ended before their detachment was
    over, as in ``simulate``; positions in m, times in s, speeds in m/s. The segment speeds' grid
    errors of a run with ``Fronts(grid_check=True)`` (v_*_grid_error) need a second run: with other
    settings they are NaN here (unknown), so that ``update`` does not leave the old segments' values.
    """
    import dataclasses

    import xarray as xr

    from .front_outputs import detachment_not_over, front_variables, fronts_attrs, fronts_from_attrs

    unknown = sorted(set(settings) - set(SEGMENT_SETTINGS))
    if unknown:
        from .parameters import did_you_mean

        which = unknown[0]
        why = (": it decided the stored arrival times, so another value needs a new run (warpfric.simulate)"
               if which in ARRIVAL_SETTINGS else did_you_mean(which, SEGMENT_SETTINGS))
        raise TypeError(f"resegment: {which} = {settings[which]!r} cannot be set{why}; valid: "
                        f"{', '.join(SEGMENT_SETTINGS)}")
    if not isinstance(ds, xr.Dataset) or "member" not in ds.dims:
        got = type(ds).__name__ if not isinstance(ds, xr.Dataset) else f"a Dataset with dimensions {tuple(ds.dims)}"
        raise ValueError(f"resegment: expects an ensemble along the dimension member, got {got} (ds.isel(member=0) "
                         "drops the dimension, ds.isel(member=[0]) keeps it; a by_parameters view: the Dataset it "
                         "was made from)")
    own = fronts_from_attrs(ds)
    fronts = dataclasses.replace(own, **settings)  # (checks the values, naming the setting and its range)
    prefixes = ["" if k == 0 else f"{event}_" for k, event in enumerate(own.events)]  # as simulate names them
    missing = [prefix + name for prefix in prefixes for name in ("arrival_time", "arrival_time_error")
               if prefix + name not in ds]
    if missing:
        raise ValueError(f"resegment: the ensemble lacks {', '.join(missing)} (dropped with the dimension x, as "
                         "ds.drop_dims(['x', ...]) does?): the stored arrival times are what it segments")
    n = ds.sizes["member"]
    capped, cut = detachment_not_over(ds)
    failed = (np.broadcast_to(np.asarray(ds.status.values), (n,)) != 0) | capped | cut
    length = np.broadcast_to(np.asarray(ds.length.values, dtype=np.float64), (n,))
    variables = {}
    for prefix in prefixes:
        arrival_time = ds[prefix + "arrival_time"].transpose("member", "x")
        metrics = segment(arrival_time, length, fronts, device)
        errors = speed_errors(metrics, arrival_time.values, ds[prefix + "arrival_time_error"].transpose(
            "member", "x").values, length)
        metrics.update({name: value for name, value in errors.items() if name != "arrival_time_error"})
        variables.update({prefix + name: value for name, value in metrics.items()})
    out = xr.Dataset({name: xr.Variable(*spec) for name, spec in front_variables(variables, fronts, failed).items()},
                     coords={name: coord for name, coord in ds.member.coords.items() if coord.dims == ("member",)})
    if fronts != own:  # the grid check's speed changes were the old segments': unknown for these
        for name in [f"v_{seg}_grid_error" for seg in SEGMENT_NAMES if f"v_{seg}_grid_error" in ds]:
            attrs = {**ds[name].attrs, "comment": "NaN: not known for the segment settings of "
                     "warpfric.fronts.resegment (a run with Fronts(grid_check=True) and these settings gives it)"}
            out[name] = xr.Variable(("member",), np.full(n, np.nan), attrs)
    out.attrs.update(fronts_attrs(fronts))
    return out


def _check_pad_grid(x, length) -> None:
    """ValueError where the positions ``x`` (an xarray coordinate: m, or units "1" for x/L) are not
    evenly spaced nodes from -L/2 to +L/2 of every length in ``length`` (m)."""
    pos = np.asarray(x.values, dtype=np.float64)
    scaled = x.attrs.get("units") == "1"
    halves = [0.5] if scaled else 0.5 * np.unique(np.asarray(length, dtype=np.float64))
    n = pos.size
    even = n >= 2 and np.allclose(np.diff(pos), (pos[-1] - pos[0]) / (n - 1), rtol=1e-9, atol=0.0)
    # one length where x is in m (a swept length puts x in units of L)
    ends = n >= 2 and len(halves) == 1 and np.allclose([pos[0], pos[-1]], [-halves[0], halves[0]], rtol=1e-9, atol=0.0)
    if not (even and ends):
        unit = "L" if scaled else "m"
        raise ValueError(f"segment: arrival_time's x ({n} positions from {pos[0]:.6g} to {pos[-1]:.6g} {unit}) is not "
                         "the pad's own grid of evenly spaced nodes from -L/2 to +L/2; the union of the grids of files "
                         "of other node counts (xarray.open_mfdataset) or a selection of nodes gives the front metrics "
                         "of another pad: segment each file's own arrival_time")


def segment_nodes_first(arrival_nodes_first, length, fronts: Fronts = Fronts(), device: str | None = "cpu") -> dict:
    """:func:`segment` of arrival times given as (nodes, members) s, the layout of the segmentation
    kernel and of the engine's read-back (warpfric.simulate passes them so, without transposing)."""
    wp = init_warp()
    from warpfric.kernels.reductions import N_FRONT_METRICS, SegmentSettings, segment_fronts

    nodes_first = np.ascontiguousarray(arrival_nodes_first, dtype=np.float64)
    n, n_members = nodes_first.shape
    if n < 2:
        raise ValueError(f"arrival_time: {n} nodes; valid: at least 2")
    length = np.broadcast_to(np.asarray(length, dtype=np.float64), (n_members,)).copy()
    if not (np.isfinite(length).all() and (length > 0).all()):
        raise ValueError(f"length: {length!r}; valid: finite lengths > 0 (m)")
    seg = SegmentSettings()
    seg.min_nodes = min_segment_intervals(fronts, n)
    seg.fast_fraction = fronts.fast_fraction
    seg.speed_ratio = fronts.speed_ratio
    seg.edge_zone_fraction = float(fronts.edge_zone_fraction)  # the kernel takes each member's own L
    with wp.ScopedDevice(check_device(device)):
        arrival = wp.array(nodes_first, dtype=wp.float64)
        sums = wp.zeros((5, n, n_members), dtype=wp.float64)
        out = wp.zeros((N_FRONT_METRICS, n_members), dtype=wp.float64)
        wp.launch(segment_fronts, dim=n_members, inputs=[wp.array(length, dtype=wp.float64), arrival, seg, sums, out])
        rows = out.numpy()
    metrics = {name: rows[i] for i, name in enumerate(FRONT_METRIC_NAMES)}
    metrics.update(name_from_start(metrics))
    return metrics


def arrival_times_from_history(times, velocity, disc_velocity=1.0, fronts: Fronts = Fronts(),
                               device: str | None = "cpu"):
    """Arrival times by the integrator's rule from a sampled pad-velocity history.

    times:         (T,) s, increasing.
    velocity:      (members, T, nodes) or (T, nodes) pad velocity u_t in m/s.
    disc_velocity: sign source for the detachment velocity (scalar or (members,), m/s).
    Returns (arrival_time (members, nodes) s, event_max_velocity (members,) m/s).
    """
    wp = init_warp()
    from warpfric.kernels.types import FRONT_DIRECTIONS
    from warpfric.kernels.reductions import arrival_from_history

    v = np.asarray(velocity, dtype=np.float64)
    if v.ndim == 2:
        v = v[None]
    n_members, n_t, n = v.shape
    times = np.asarray(times, dtype=np.float64)
    if times.shape != (n_t,) or (np.diff(times) <= 0).any():
        raise ValueError(f"times: shape {times.shape}; valid: ({n_t},) increasing (s)")
    sign = np.where(np.broadcast_to(np.asarray(disc_velocity, dtype=np.float64), (n_members,)) < 0, -1.0, 1.0)
    with wp.ScopedDevice(check_device(device)):
        vel = wp.array(np.ascontiguousarray(np.transpose(v, (1, 2, 0))), dtype=wp.float64)
        arrival = wp.zeros((n, n_members), dtype=wp.float64)
        event_max = wp.zeros(n_members, dtype=wp.float64)
        wp.launch(arrival_from_history, dim=n_members,
                  inputs=[wp.array(times, dtype=wp.float64), vel, wp.array(sign, dtype=wp.float64),
                          FRONT_DIRECTIONS.index(fronts.direction), fronts.threshold, arrival, event_max])
        return arrival.numpy().T.copy(), event_max.numpy()


def front_collisions(arrival_time, length, device: str | None = "cpu") -> dict:
    """How many fronts the arrival times (members, nodes) s hold and where the first front meets
    another (nodes evenly spaced over [-L/2, L/2], ``length`` L in m, scalar or (members,)): the
    ``front_count``, ``collision_position`` (m) and ``collision_time`` (s) of :func:`segment`,
    (members,) float64 each. Within the run of arrived nodes around the nucleation node, a front
    starts at each local minimum of t_a(x) (a flat run of equal times counts once; an end node when
    its neighbour does not arrive earlier) and two fronts meet at each interior local maximum; the
    collision is at an end of the first front (the middle of a flat top; the earlier end where both
    are meetings). NaN where the first front meets none, and every field NaN where no node was
    reached."""
    metrics = segment(arrival_time, length, device=device)
    return {name: metrics[name] for name in ("front_count", "collision_position", "collision_time")}


def speed_errors(metrics: dict, arrival_time, arrival_error, length) -> dict:
    """The interpolation error of the segment speeds (m/s), (members,) each: a lower bound of their
    error, which the trajectory's error at rtol and the grid's (Fronts.grid_check) exceed.

    ``arrival_error`` ((members, nodes) s) estimates each t_a's error: the distance between the
    crossings of the quadratic (through the step's ends and its second stage) and of the linear
    interpolant inside the accepted step that holds it (the whole step after a backward-Euler
    restart). A segment's speed is its length over the time spent T between its end nodes (the
    two branches from the nucleation node when it lies inside), so dv = v * dT / (T - dT) with dT
    the sum of the end (and twice the nucleation) nodes' errors; inf where dT >= T (the speed is
    not resolved). NaN where the segment is absent. Also returns arrival_time_error where t_a is
    finite.
    """
    ta = np.atleast_2d(np.asarray(arrival_time, dtype=np.float64))
    dt = np.where(np.isfinite(ta), np.atleast_2d(np.asarray(arrival_error, dtype=np.float64)), np.nan)
    n_members, n = ta.shape
    length = np.broadcast_to(np.asarray(length, dtype=np.float64), (n_members,))
    dx = length / (n - 1)
    out = {"arrival_time_error": dt}

    def node_of(position):  # the node at each member's position (m); NaN where the position is
        return np.rint((position + 0.5 * length) / dx)

    for seg in POSITION_SEGMENTS + (WHOLE_FRONTS if "v_second" in metrics else ()):
        error = np.full(n_members, np.nan)
        start, end, v = metrics[f"{seg}_front_start"], metrics[f"{seg}_front_end"], metrics[f"v_{seg}"]
        sel = np.flatnonzero(~np.isnan(v) & np.isfinite(start) & np.isfinite(end))  # v = inf: not resolved, error inf
        # the segment's end nodes a < b and its own front's nucleation node k (the second front's for
        # its segment), member by member (whole arrays)
        nuc = node_of(metrics["second_nucleation_position" if seg == "second" else "nucleation_position"])[sel]
        a = node_of(start)[sel].astype(np.int64)
        b = node_of(end)[sel].astype(np.int64)
        k = np.where(np.isfinite(nuc), nuc, -1.0).astype(np.int64)
        ta_a, ta_b, ta_k = (ta[sel, np.clip(j, 0, n - 1)] for j in (a, b, k))
        dt_a, dt_b, dt_k = (dt[sel, np.clip(j, 0, n - 1)] for j in (a, b, k))
        # an end that never arrived: the speed comes from the interval sums (inf)
        arrived = (0 <= a) & (a < b) & (b < n) & np.isfinite(ta_a) & np.isfinite(ta_b)
        inside = (a < k) & (k < b) & np.isfinite(ta_k)  # the two branches from an inner nucleation
        spent = np.where(inside, (ta_a - ta_k) + (ta_b - ta_k), np.abs(ta_b - ta_a))
        slack = np.where(inside, (dt_a + dt_b) + 2 * dt_k, dt_a + dt_b)
        with np.errstate(divide="ignore", invalid="ignore"):
            resolved = np.where(spent > slack, v[sel] * slack / (spent - slack), np.inf)
        error[sel] = np.where(arrived, resolved, np.inf)
        out[f"v_{seg}_error"] = error
    edge = np.asarray(metrics["nucleation_edge"], dtype=np.float64)
    out["v_precursor_error"] = np.where(edge == -1, out["v_left_error"], np.where(edge == 1, out["v_right_error"], np.nan))
    out["v_far_error"] = np.where(edge == -1, out["v_right_error"], np.where(edge == 1, out["v_left_error"], np.nan))
    out["v_main_error"] = out["v_middle_error"].copy()
    return out
