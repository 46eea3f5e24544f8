"""Resolve the members of an ensemble: the scene's scalars, overridden per member by broadcastable
arrays, validated before any kernel runs."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import numpy as np

from .parameters import PARAMETER_NAMES, Parameters, did_you_mean, resolve_value, unknown_parameter, validate_value


# coordinates along member that are no parameter: the member index and the labels of a file
MEMBER_COORDS = ("member", "member_id", "member_number")


def _stacked(ds):
    """A by_parameters view (warpfric/io.py: the swept parameters as dimensions, the member numbers in
    ``member_number``) back along ``member``, its members in the order of their numbers, the
    combinations that no member ran (NaN numbers) left out; any other Dataset as it is."""
    grid = [str(d) for d in ds.dims if str(d) in PARAMETER_NAMES]
    if "member" in ds.dims or "member_number" not in ds.variables:  # (a file's view holds it as a coordinate)
        return ds
    if not grid:  # one cell of a view, selected: a member, unless no member ran it
        if ds.member_number.ndim == 0 and not np.isfinite(float(ds.member_number)):
            raise ValueError("members: this cell of a by_parameters view was run by no member (its member_number is "
                             "NaN: a combination missing from the grid); select a combination that a member ran")
        return ds
    ds = ds.drop_vars([name for name in ("member", "member_id") if name in ds.coords])  # one swept name: along it
    ds = ds.stack(member=grid)
    numbers = np.asarray(ds.member_number.values, dtype=np.float64)
    ran = np.flatnonzero(np.isfinite(numbers))
    return ds.isel(member=ran[np.argsort(numbers[ran], kind="stable")])


def _member_arrays(members: Any) -> dict[str, np.ndarray]:
    """Mapping name -> array from a mapping or an xarray Dataset with dimension 'member'."""
    if members is None:
        return {}
    try:
        import xarray as xr
    except ImportError:  # pragma: no cover - xarray is a dependency
        xr = None
    if xr is not None and isinstance(members, xr.Dataset):
        members = _stacked(members)
        if "warpfric_version" in members.attrs:  # a run's outputs (simulate's Dataset, or its file): its members'
            # parameters (variables along member, scalars where its file holds one value for all, or coordinates
            # after set_coords; a by_parameters view is stacked back above); its outputs and recorded fields are no
            # input
            members = members.drop_vars([name for name in members.data_vars if name not in PARAMETER_NAMES])
        out = {}
        # the parameters among its coordinates too (a grid built with .stack(member=[...]) holds them
        # there): they were ignored, and the default scene ran
        coords = {name: var for name, var in members.coords.items() if str(name) in PARAMETER_NAMES}
        for name, var in members.coords.items():  # a misspelt parameter as a coordinate: as a variable, refused
            if var.dims == ("member",) and str(name) not in PARAMETER_NAMES and str(name) not in MEMBER_COORDS:
                raise ValueError(f"members: coordinate {str(name)!r} along member is no parameter"
                                 f"{did_you_mean(str(name), PARAMETER_NAMES)}; coordinates along member other than "
                                 f"{', '.join(MEMBER_COORDS)} are taken as parameters")
        for name, var in {**coords, **members.data_vars}.items():
            if var.dims not in ((), ("member",)):
                raise ValueError(
                    f"members: variable {name!r} has dims {var.dims}; expected () or ('member',)"
                )
            out[str(name)] = var.values
        n = members.sizes.get("member", 1)
        if n > 1 and not any(np.ndim(v) == 1 for v in out.values()):
            raise ValueError(f"members: the Dataset has {n} members along 'member' but no parameter along it (its "
                             f"variables or coordinates named as parameters: {', '.join(PARAMETER_NAMES[:4])}, ...)")
        return out
    if isinstance(members, Mapping):
        return {str(k): v for k, v in members.items()}
    raise ValueError(
        f"members: expected None, a mapping of parameter name -> array, or an xarray Dataset with "
        f"dim 'member'; got {type(members).__name__}"
    )


def resolve_members(members: Any, scene: Parameters, first_member: int = 0,
                    before_building=None) -> tuple[dict[str, np.ndarray], tuple[str, ...]]:
    """Return (values, varying): every parameter as a float64 array of shape (M,), and the names
    of the parameters given per member. Raises ValueError naming the parameter, value and range;
    ``first_member``: the number of the first member in such messages (a slice of a larger
    ensemble validated slice by slice); ``before_building(M, shape)``: called with the member count
    and the arrays' broadcast shape once it is known, before any (M,) array is built (a memory check: a
    broadcasting slip of 1e8 members raised numpy's MemoryError, or met the system's killer)."""
    if not isinstance(scene, Parameters):
        raise ValueError(f"scene: expected a warpfric.Parameters, got {type(scene).__name__}")
    given = _member_arrays(members)
    for name in given:
        if name not in PARAMETER_NAMES:
            raise ValueError(unknown_parameter(name))
    arrays: dict[str, np.ndarray] = {}
    for name in given:
        arr = resolve_value(name, given[name])
        if arr is None:
            arr = np.asarray(np.nan)  # torque_arm None: the pad height, resolved below
        arrays[name] = arr
    try:
        shape = np.broadcast_shapes(*(a.shape for a in arrays.values())) if arrays else ()
    except ValueError:
        shapes = ", ".join(f"{k}{tuple(v.shape)}" for k, v in arrays.items())
        raise ValueError(f"members: the per-member arrays do not broadcast together: {shapes}") from None
    n_members = int(np.prod(shape)) if shape else 1
    if n_members == 0:
        raise ValueError("members: the ensemble is empty (a per-member array has length 0)")
    if before_building is not None:
        before_building(n_members, shape)
    values: dict[str, np.ndarray] = {}
    for f in dataclasses.fields(Parameters):
        name = f.name
        if name in arrays:
            v = np.broadcast_to(arrays[name], shape).reshape(n_members).copy()
        else:
            scalar = resolve_value(name, getattr(scene, name))
            v = np.full(n_members, np.nan if scalar is None else float(scalar))
        values[name] = v
    # torque_arm None (the scene's, or given for every member) means "the pad height"; a NaN in a
    # per-member array is no value (validate_value refuses it, as in Parameters)
    if given.get("torque_arm", 0.0) is None or ("torque_arm" not in arrays and scene.torque_arm is None):
        values["torque_arm"] = values["height"].copy()
    for name in PARAMETER_NAMES:
        validate_value(name, values[name], first_member)
    _check_protocol(values, first_member)
    return values, tuple(name for name in PARAMETER_NAMES if name in given)


def _check_protocol(values: dict[str, np.ndarray], first_member: int = 0) -> None:
    """Cross-parameter rules of the load protocol (member numbers in messages from ``first_member``)."""
    rest = values["rest_until"]
    # each a time after the disc starts to move: what one before it does, the range's closing
    # bracket (inf: none for an end, no stop for stop_time), a note
    ends = ("ends before the disc starts to move", ")", "")
    rules = {"end_time": ends,
             "max_end_time": ("ends before the disc starts to move", ")", "; the automatic end's cap, used where "
                              "end_time is inf: a later max_end_time, or an explicit end_time"),
             "stop_time": ("stops the disc before it starts to move", "]", ", inf: no stop")}
    for name, (what, bracket, note) in rules.items():
        bad = ~(values[name] > rest)
        if name == "max_end_time":  # the automatic end's cap: unused where an explicit end_time ends the run
            bad &= np.isposinf(values["end_time"])
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"parameter {name!r} = {float(values[name][i])!r} (s) {what}; "
                f"valid range (rest_until, inf{bracket} = ({float(rest[i])!r}, inf{bracket} s{note} (member {first_member + i})"
            )
