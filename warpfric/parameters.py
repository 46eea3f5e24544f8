"""Parameter types: the physical scene, the model switches and the solver settings.

All values are SI. ``Parameters`` holds every public name of SPEC section 8 with the paper's
defaults (Table 1, PMMA). Any numeric field can vary between the members of an ensemble: pass
per-member arrays through ``simulate(members=...)``; ``Parameters`` itself holds the scalar
defaults that every member starts from (the "scene").

Every field carries its unit, a long name and its valid range in ``dataclasses.field`` metadata;
:func:`validate_value` checks a value (scalar or array) against that range and raises a
``ValueError`` that names the parameter, the offending value and the valid range.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .progress import first_few, plural

INF = math.inf


def _p(default, units, long_name, low, high, low_open=False, high_open=False, none_means=None):
    """Field with its metadata: unit, CF long name and valid range [low, high] (or open ends). An
    infinite end is open (inf is no value) unless ``none_means`` is that end (stop_time and end_time
    take inf: no stop, the automatic end)."""
    low_open = low_open or (math.isinf(low) and none_means != low)
    high_open = high_open or (math.isinf(high) and none_means != high)
    return field(
        default=default,
        metadata=dict(
            units=units,
            long_name=long_name,
            low=low,
            high=high,
            low_open=low_open,
            high_open=high_open,
            none_means=none_means,
        ),
    )


@dataclass(frozen=True, kw_only=True)  # Parameters(1000) set the first field, the shear modulus, without a word
class Parameters:
    """The scene: material, friction law, geometry and load protocol of one pad (SI units).
    Keyword arguments only: ``Parameters(normal_force=1000.0)``.

    Defaults are the paper's (Papangelo et al. 2014, Table 1, PMMA) and the protocol of its Fig. 2:
    the normal force ramps 0 -> ``normal_force`` over ``force_ramp_time``, rests until
    ``rest_until``, then the disc velocity ramps 0 -> ``disc_velocity`` over
    ``velocity_ramp_time``; optional sudden disc stop at ``stop_time``; the run ends at
    ``end_time``, or with ``end_time=None`` (default) when the detachment is over (docs/model.md,
    "End of a run"), at ``max_end_time`` at the latest.
    """

    # --- pad material -------------------------------------------------------------------------
    shear_modulus: float = _p(3.1e9, "Pa", "shear modulus G of the pad", 0.0, INF, low_open=True)
    poisson_ratio: float = _p(0.35, "1", "Poisson ratio nu of the pad", -1.0, 0.5, True, True)
    density: float = _p(1200.0, "kg m-3", "density rho of the pad", 0.0, INF, low_open=True)
    # --- friction law (Bouchbinder / Bar-Sinai) ---------------------------------------------------
    memory_length: float = _p(5e-7, "m", "memory length D (mean contact size)", 0.0, INF, True)
    shear_strength: float = _p(
        1.3e8, "Pa", "shear strength tau_c: yield threshold of the asperity-level stress |tau_f|/A", 0.0, INF,
        True, True
    )
    hardness: float = _p(5.4e8, "Pa", "hardness sigma_H", 0.0, INF, low_open=True)
    viscous_coefficient: float = _p(2.7e13, "Pa s m-1", "viscous friction coefficient eta", 0.0, INF)
    reference_velocity: float = _p(1e-7, "m s-1", "reference velocity v_star", 0.0, INF, True)
    aging_coefficient: float = _p(0.075, "1", "aging coefficient b", 0.0, INF)
    aging_time: float = _p(3.33e-4, "s", "aging time scale phi0", 0.0, INF, low_open=True)
    interface_stiffness: float = _p(3e14, "Pa m-1", "interface stiffness mu0/h", 0.0, INF, True)
    gate_velocity: float = _p(
        1e-9, "m s-1", "v0 of the smooth velocity gate sqrt(s^2 + v0^2) (relaxation_gate='velocity')",
        0.0, INF, True, True
    )
    # --- geometry -------------------------------------------------------------------------------
    height: float = _p(0.015, "m", "pad height H", 0.0, INF, low_open=True)
    length: float = _p(0.2, "m", "pad length L", 0.0, INF, low_open=True)
    depth: float = _p(0.12, "m", "pad depth p", 0.0, INF, low_open=True)
    damping: float = _p(0.0, "Pa s m-1", "numerical damping c of the pad", 0.0, INF)
    # --- load protocol --------------------------------------------------------------------------
    normal_force: float = _p(1000.0, "N", "maximum normal force F_max", 0.0, INF, low_open=True)
    # beyond |2e/L| = 0.6 most of the pad lifts off; its undamped free vibration then holds the step
    # size at ~5e-7 s (docs/model.md, "Open choices [10] and how to change them": lift-off): such scenes stall and are refused
    eccentricity: float = _p(0.0, "1", "normalised eccentricity 2e/L of the normal force", -0.6, 0.6)
    disc_velocity: float = _p(1e-4, "m s-1", "maximum disc velocity v_max", -INF, INF, True, True)
    force_ramp_time: float = _p(10.0, "s", "duration of the normal-force ramp", 0.0, INF)
    rest_until: float = _p(20.0, "s", "time at which the disc starts to move", 0.0, INF)
    velocity_ramp_time: float = _p(2.0, "s", "duration of the disc-velocity ramp", 0.0, INF)
    stop_time: float | None = _p(
        None, "s", "time of a sudden disc stop, after rest_until (None or inf: no stop)", 0.0, INF, True, False,
        none_means=INF
    )
    end_time: float | None = _p(
        None, "s", "end of the simulated time (None or inf: when the detachment is over, at most max_end_time)",
        0.0, INF, True, False, none_means=INF
    )
    max_end_time: float = _p(
        80.0, "s", "latest end of a run whose end_time is None (the detachment may not end)", 0.0, INF, True
    )
    # --- open model choices (SPEC [choice]) ------------------------------------------------------
    interface_velocity_factor: float = _p(
        1.0, "1", "k_if: interface velocity = k_if * pad velocity", 0.0, INF, low_open=True, high_open=True
    )
    torque_arm: float | None = _p(
        None, "m", "height h_arm of the friction torque arm (None: the pad height; < 0: reversed torque, "
        "a counterfactual, see docs/model.md)", -INF, INF, True, True
    )
    initial_age: float = _p(3.33e-4, "s", "initial contact age phi_init", 0.0, INF, high_open=True)

    def __post_init__(self):
        # each value against its range now, where the user wrote it (simulate checks them again per
        # member, with the protocol's cross-parameter rules)
        for f in dataclasses.fields(self):
            value = resolve_value(f.name, getattr(self, f.name))
            if value is not None:
                if value.ndim != 0:  # a scene is one pad: values per member go in simulate's members
                    raise ValueError(
                        f"parameter {f.name!r}: value {getattr(self, f.name)!r} is not a single number; a scene "
                        f"(Parameters) holds one value a parameter: give values per member in simulate's members, "
                        f"e.g. simulate({{{f.name!r}: [...]}}, scene=...)")
                validate_value(f.name, value)
                raw = getattr(self, f.name)
                if isinstance(raw, (np.ndarray, np.generic)):  # array(1000.) as 1000.0: the value, not its box
                    object.__setattr__(self, f.name, float(value))


PARAMETER_NAMES: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(Parameters))
_FIELDS = {f.name: f for f in dataclasses.fields(Parameters)}


def parameter_units(name: str) -> str:
    """SI unit string (UDUNITS form) of a parameter."""
    return _FIELDS[name].metadata["units"]


def parameter_long_name(name: str) -> str:
    return _FIELDS[name].metadata["long_name"]


def units_text(units: str) -> str:
    """A unit as a reader should see it: '' for the dimensionless '1' of the files (CF/UDUNITS),
    which reads like an index in a message, else the unit."""
    return "" if units in ("1", "") else units


def _range_text(meta) -> str:
    """Valid range, e.g. '(0, inf)': an infinite end is open (inf itself is never a value), except
    where inf is what None means (stop_time = inf: no stop; end_time = inf: the automatic end)."""
    lo = "(" if meta["low_open"] or math.isinf(meta["low"]) else "["
    inf_allowed = meta["none_means"] is not None and math.isinf(meta["none_means"])
    hi = ")" if (meta["high_open"] or math.isinf(meta["high"])) and not inf_allowed else "]"
    return f"{lo}{meta['low']:g}, {meta['high']:g}{hi}"


def _valid_range(name: str) -> str:
    """'valid range (0, inf) N', or '... (dimensionless)': parameter ``name``'s range and unit, as the
    messages of a bad value end."""
    units = units_text(parameter_units(name))
    return f"valid range {_range_text(_FIELDS[name].metadata)}{' ' + units if units else ' (dimensionless)'}"


def parameter_range_text(name: str) -> str:
    """The valid range of parameter ``name`` as the error messages write it, e.g. '(0, inf)' (N)."""
    return _range_text(_FIELDS[name].metadata)


def _fields_text() -> str:
    """Every parameter with its unit, valid range, default and meaning, for help(Parameters): the
    field metadata that the checks and the files' attributes use."""
    rows = []
    for f in dataclasses.fields(Parameters):
        meta = f.metadata
        default = f"{f.default:g}" if isinstance(f.default, (int, float)) else str(f.default)
        rows.append(f"    {f.name:<26} {units_text(meta.get('units', '')) or '-':<9} {_range_text(meta):<17} "
                    f"{default:<9} {meta.get('long_name', '')}")
    head = f"    {'name':<26} {'unit':<9} {'valid range':<17} {'default':<9} meaning"
    return "\n\n    Parameters (SI; unit '-': dimensionless):\n\n" + "\n".join([head, *rows]) + "\n"


Parameters.__doc__ = (Parameters.__doc__ or "").rstrip() + _fields_text()


def did_you_mean(name, names, spell=repr) -> str:
    """" (did you mean 'x'?)" with the closest of ``names`` to ``name``, or "" where none is close; a
    name that is one word of a single one of ``names`` is close to it ('gate': 'relaxation_gate').
    ``spell``: how the suggestion is written (a sweep file's value: as TOML spells it)."""
    import difflib

    names = list(names)
    by_lower = {str(n).lower(): n for n in reversed(names)}  # a name's case alone wrong (mu_S) is close too
    close = difflib.get_close_matches(str(name).lower(), list(by_lower), n=1)
    if close:
        return f" (did you mean {spell(by_lower[close[0]])}?)"
    holding = [n for n in names if str(name).lower() in str(n).lower().split("_")]
    return f" (did you mean {spell(holding[0])}?)" if len(holding) == 1 else ""


def unknown_parameter(name: str) -> str:
    """The message for a parameter name that is not one: the valid names and the closest match, or
    where the name is a Solver or Model setting, that setting's place."""
    for kind in (Solver, Model):
        if name in {f.name for f in dataclasses.fields(kind)}:
            return (f"unknown parameter {name!r}: {name} is a {kind.__name__} setting, the same for every member "
                    f"(wf.{kind.__name__}({name}=...); in a sweep file [{kind.__name__.lower()}] {name} = ...); "
                    f"valid parameter names: {', '.join(PARAMETER_NAMES)}")
    return f"unknown parameter {name!r}{did_you_mean(name, PARAMETER_NAMES)}; valid names: {', '.join(PARAMETER_NAMES)}"


def _holds_bool(value) -> bool:
    """Whether a (nested) list or tuple holds a boolean: numpy turns [True, 500.0] into [1.0, 500.0]."""
    if isinstance(value, (list, tuple)):
        return any(_holds_bool(v) for v in value)
    return isinstance(value, (bool, np.bool_))


def resolve_value(name: str, value: Any, scene: Parameters | None = None):
    """Return ``value`` as a float64 array, with None replaced by what None means for ``name``."""
    if value is None:
        if name == "torque_arm":
            return None  # resolved against height by the caller
        meta = _FIELDS[name].metadata
        if meta["none_means"] is None:
            raise ValueError(f"parameter {name!r}: value None is not allowed; {_valid_range(name)}")
        return np.asarray(meta["none_means"], dtype=np.float64)
    if np.ma.isMaskedArray(value):  # np.asarray drops the mask: the data under it would run as a value
        mask = np.ma.getmaskarray(value)
        if mask.any():
            where = f"[{int(np.flatnonzero(mask.ravel())[0])}]" if mask.ndim else ""
            more = f" ({int(mask.sum())} members masked)" if mask.sum() > 1 else ""
            raise ValueError(f"parameter {name}{where} is masked (no value: a missing or fill value, as netCDF4 "
                             f"returns it){more}; {_valid_range(name)}; give every member a value")
        value = np.ma.getdata(value)
    if isinstance(value, int) and not isinstance(value, bool):  # beyond int64 numpy makes an object array of it
        try:
            value = float(value)
        except OverflowError:  # 10**400
            raise ValueError(f"parameter {name!r}: value {_short_repr(value)} is out of range (beyond float64's "
                             f"1.8e308); {_valid_range(name)}") from None
    try:
        arr = np.asarray(value)
    except ValueError:  # nested lists of different lengths
        raise ValueError(f"parameter {name!r}: value {value!r} is not a rectangular array (nested lists of different "
                         "lengths); give a number, or a list or array of numbers per member") from None
    if arr.dtype.kind not in "iuf" or _holds_bool(value):  # booleans: True would pass as 1.0, False as 0.0
        meta = _FIELDS[name].metadata
        hint = ""
        if meta["none_means"] is not None and arr.ndim > 0:  # [None, 21.0]: None only stands for the whole
            hint = f" (per member, write {meta['none_means']:g} where you mean None)"
        elif name == "torque_arm" and arr.ndim > 0:  # None: the pad height, which may differ per member
            hint = " (per member, write the member's pad height where you mean None, e.g. 0.015 m)"
        raise ValueError(f"parameter {name!r}: value {_short_repr(value)} is not a real number; "
                         f"{_valid_range(name)}{hint}")
    return arr.astype(np.float64)


def _short_repr(value, limit: int = 60) -> str:
    """repr(value), its middle left out beyond ``limit`` characters (10**400 printed 401 digits)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit // 2]}...{text[-10:]} ({len(text)} characters)"


def bound_outside_range(name: str, key: str, value: float, takes_high: bool = False) -> str | None:
    """What is wrong with a distribution's bound or mean ``key`` = ``value`` for parameter ``name``
    ("high = 0.7 is outside eccentricity's valid range [-0.6, 0.6] (dimensionless)"), or None where
    the values drawn from it lie inside the range. A ``high`` is checked just below itself, where the
    draws lie (it may be an open limit of the range: poisson_ratio's 0.5), unless ``takes_high``
    (Morris levels take the bound itself). A [sample] distribution and a [design] bound say it alike."""
    inside = float(np.nextafter(value, -np.inf)) if key == "high" and not takes_high else float(value)
    try:
        validate_value(name, np.float64(inside))
    except ValueError:
        units = units_text(parameter_units(name))
        return (f"{key} = {value!r} is outside {name}'s valid range "
                f"{parameter_range_text(name)}{' ' + units if units else ''}")
    return None


def validate_value(name: str, value: np.ndarray, first_member: int = 0) -> None:
    """Raise ValueError naming ``name``, the first bad value and the valid range (a per-member
    array's members numbered from ``first_member``)."""
    if name not in _FIELDS:
        raise ValueError(unknown_parameter(name))
    meta = _FIELDS[name].metadata
    arr = np.asarray(value, dtype=np.float64)
    lo, hi = meta["low"], meta["high"]
    bad = ~np.isfinite(arr)
    bad |= (arr <= lo) if meta["low_open"] else (arr < lo)
    bad |= (arr >= hi) if meta["high_open"] else (arr > hi)
    if name in ("stop_time", "end_time"):  # inf means "no stop" / "when the detachment is over"
        bad &= ~np.isposinf(arr)
    if np.any(bad):
        flat = bad.reshape(-1)
        index = int(np.flatnonzero(flat)[0])
        first = float(arr.reshape(-1)[index])
        units = units_text(parameter_units(name))
        # a per-member array: name the member, e.g. eccentricity[1234] = nan
        what = f"{name}[{first_member + index}]" if arr.size > 1 or first_member else repr(name)
        more = f" ({int(flat.sum())} members out of range)" if flat.sum() > 1 else ""
        raise ValueError(f"parameter {what} = {first!r}{' ' + units if units else ''} is out of range; "
                         f"{_valid_range(name)}{more}")


RELAXATION_GATES = ("stress", "none", "velocity")


def _zero_d_as_scalars(settings) -> None:
    """0-d numpy arrays among a settings dataclass's fields (np.array(1e-5)) as their values, before
    its checks: they were refused as 'array(1e-05)', where Parameters takes them."""
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if isinstance(value, np.ndarray) and value.ndim == 0:
            object.__setattr__(settings, f.name, value.item())


def _plain_settings(settings) -> None:
    """numpy scalars among a validated settings dataclass's fields (np.True_, np.int64(100)) as Python's
    bool, int and float: they reach the Dataset's attributes, where netCDF refuses np.bool_."""
    for f in dataclasses.fields(settings):
        value = getattr(settings, f.name)
        if isinstance(value, np.generic):
            object.__setattr__(settings, f.name, value.item())


@dataclass(frozen=True, kw_only=True)
class Model:
    """Model switches. Each combination compiles its own specialised kernel, so a term that is off
    costs nothing at run time.

    inertia:            pad inertia rho*H*u_tt (off: quasi-static pad, velocity is algebraic).
    tilt:               the backing plate may tilt (off: it only translates; no moment balance).
    poisson_coupling:   the -lambda*eps_xx term of the interface normal stress (SPEC section 4).
    viscous_friction:   the viscous (velocity-strengthening) friction stress tau_vis.
    relaxation_gate:    what gates the relaxation of tau_el and the rejuvenation of the contact age
                        (SPEC v2 section 5, docs/model.md "Equations"):
                        'stress' (default): Heaviside theta(|tau_f|/A - tau_c) of Bar-Sinai, Brener &
                        Bouchbinder, GRL 39 L03308 (2012), tau_c = ``shear_strength``;
                        'none': no gate, |s| always (the SPEC v1 law of earlier results);
                        'velocity': |s| -> sqrt(s^2 + v0^2), v0 = ``gate_velocity`` (Bar-Sinai et
                        al., PRE 88, 060403, 2013).

    A parameter that the switches leave without effect (eccentricity and torque_arm without tilt,
    viscous_coefficient without viscous friction, shear_strength without the stress gate,
    gate_velocity without the velocity gate, density without inertia) is named in one warning by
    ``simulate`` where a member sets it away from the default scene (``unused_parameters``).
    """

    inertia: bool = True
    tilt: bool = True
    poisson_coupling: bool = True
    viscous_friction: bool = True
    relaxation_gate: str = "stress"

    def __post_init__(self):
        _zero_d_as_scalars(self)
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.name == "relaxation_gate":
                if v not in RELAXATION_GATES:
                    raise ValueError(f"model switch 'relaxation_gate' = {v!r}: valid: {', '.join(map(repr, RELAXATION_GATES))}")
            elif not isinstance(v, (bool, np.bool_)):
                raise ValueError(f"model switch {f.name!r} = {v!r}: must be True or False")
        _plain_settings(self)

    def unused_parameters(self, values: dict) -> list:
        """The parameters that these switches leave without effect and that some member sets away from
        the default scene's value (``values``: resolved parameters, name -> (member,) float64; the
        torque arm's default is the member's height), as 'name (why)' texts."""
        unused = {
            "eccentricity": (not self.tilt, "tilt=False: no moment balance, the load is spread evenly"),
            "torque_arm": (not self.tilt, "tilt=False: no moment balance"),
            "viscous_coefficient": (not self.viscous_friction, "viscous_friction=False"),
            "shear_strength": (self.relaxation_gate != "stress", f"relaxation_gate={self.relaxation_gate!r}"),
            "gate_velocity": (self.relaxation_gate != "velocity", f"relaxation_gate={self.relaxation_gate!r}"),
            "density": (not self.inertia, "inertia=False: a quasi-static pad"),
        }
        texts = []
        for name, (without_effect, why) in unused.items():  # the default scene's values: the fields' defaults
            default = values["height"] if name == "torque_arm" else _FIELDS[name].default
            if without_effect and np.any(np.asarray(values[name]) != default):
                texts.append(f"{name} ({why})")
        return texts


def check_precision(model: "Model", solver: "Solver") -> None:
    """ValueError for float32 under the stress gate (docs/model.md, "Precision": the located switches
    need steps that float32 cannot integrate), before anything runs or is written."""
    if solver.dtype == "float32" and model.relaxation_gate == "stress":
        raise ValueError(
            "solver setting 'dtype' = 'float32' is invalid with relaxation_gate='stress'; valid: 'float64' "
            "(float32 stalls at the gate switches), or float32 with relaxation_gate='none' or 'velocity'"
        )


def check_fronts_method(fronts: "Fronts | None", solver: "Solver") -> None:
    """ValueError for the velocity front with a method other than TR-BDF2 (docs/model.md, "Time
    integration", ESDIRK4: its arrival times read TR-BDF2's second stage), before anything runs or
    is written."""
    if fronts is not None and "velocity" in fronts.events and solver.method != "tr_bdf2":
        raise ValueError(
            f"fronts setting 'event' = {fronts.event!r} is invalid with solver setting 'method' = {solver.method!r}; "
            "valid: the contact or strength front with that method, or method='tr_bdf2' for the velocity front "
            "(its arrival times read TR-BDF2's second stage)"
        )


_DTYPES = ("float32", "float64")
_METHODS = ("tr_bdf2", "esdirk4")
FLOAT32_MIN_RTOL = 1e-5  # docs/performance.md: float32 stalls below this
INT32_MAX = 2**31 - 1  # the kernels' step counters and node indices are int32
# member numbers are int32 (as a file holds them); below 2**31 with room for the member labels' run
MEMBER_NUMBER_LIMIT = 2**31 - 2**24
MAX_LANES = 256  # threads per block: the cooperative kernel takes 255 registers per thread on the H100, and a block has 65,536


@dataclass(frozen=True, kw_only=True)
class Solver:
    """Numerical settings.

    nodes:            N, grid nodes along the pad (>= 3), spacing L/(N-1).
    dtype:            'float64' or 'float32' for the state and the arithmetic (time is always float64).
                      float64 is the robust choice and, on a GPU, was the faster one at N = 200 (float32
                      runs the thread-per-member kernel there; docs/performance.md).
    method:           the time integrator (docs/model.md, "Time integration"): 'tr_bdf2' (default; order 2,
                      3 stages) or 'esdirk4' (ESDIRK4(3)6L[2]SA of Kennedy & Carpenter 2016: order 4,
                      6 stages, fewer Newton iterations at tight tolerances). 'esdirk4' runs
                      the contact and strength fronts, not the velocity front (use 'tr_bdf2').
    rtol:             relative local error tolerance of the adaptive step (1e-12 .. 1e-1).
                      The absolute tolerance of each variable kind is rtol times its natural scale
                      (docs/model.md, "Time integration").
    initial_step:     s, the first step and the backward-Euler restart step after a discontinuity.
    min_step:         s, a member whose step falls below this stops with status step_size_underflow.
    max_step:         s, largest step.
    max_steps:        attempted steps (accepted + rejected) per member before status max_steps_reached.
    newton_max_iter:  Newton iterations per stage before the step is rejected.
    newton_tol:       Newton convergence threshold in the error-weighted norm (units of rtol).
    switch_tol:       stress gate: tolerance of the located gate switches, in units of rtol (docs/model.md,
                      "Gate switches"); 1 holds the error of a switch to the step's local tolerance,
                      inf lets every switch happen at the end of the step in which it occurs (no location).
    predict_switches: stress gate: True ends a step just past the next gate switch that the nodes' yield
                      margins predict (their secant over the last step), so that most switches are taken
                      without the rejected step that locates them; False locates every switch by a
                      rejected step (docs/model.md, "Gate switches").
    sliding_width:    stress gate: a node held on the yield surface (Filippov sliding) has the gate
                      theta_w(x) = (1 + tanh x)/2, x = (|tau_f|/A - tau_c)/(sliding_width*tau_c), solved
                      implicitly; its limit 0 is the sharp equivalent gate (docs/model.md, "Gate switches").
                      The steps of nodes sliding there grow about as 1/sliding_width: loaded pads with a
                      soft interface (mu0/h 1e13-1e14 Pa/m) took 10x the median's steps at 1e-3, 2-3.5x
                      more at 1e-4, and 5-10x fewer at 1e-2, mu_s moving about as much as the width
                      (1e-2: 1.0e-2 in the median member against 1e-3; docs/performance.md, "Known limits").
                      At the default interface stiffness the width matters little: 1e-3 moved mu_s by
                      1.8e-5 at most against 1e-4 in 60 loaded members (30-300 kN), and 58 of the
                      engine benchmark's first 60 members not at all.
    error_filter_nodes: the pad velocity's error estimate is filtered by the diagonal of (I - gamma h J)^-1
                      (docs/model.md, "Time integration"), whose elastic part 2 M H / dx^2 grows as N^2:
                      a coarse grid's filter hides less of the pad's lowest modes' ringing (kicked by
                      every gate opening, hardly damped without viscous friction), and its steps
                      follow that ringing. A grid coarser than error_filter_nodes nodes is filtered
                      with the elastic diagonal of a grid of error_filter_nodes nodes (spacing
                      L/(error_filter_nodes - 1)); finer grids with their own. 0: every grid its
                      own (the ringing resolved where the filter is weak: N = 25 took 57,177
                      attempts a member for inviscid scenes at rtol 1e-5, against 747 with 200;
                      docs/performance.md, "Known limits"). Default 800: at rtol 1e-6 such members
                      take ~1,200-1,500 attempts at N = 25-200 with 800 against 30,000-270,000
                      with 200, and at rtol 1e-5 the reference scenes take 10-24 % fewer (the
                      viscous ones 0-2 %), at the same largest mu_s errors (docs/performance.md,
                      "Work-precision"); grids of 800 nodes and more keep their own filter, bit for
                      bit. A very large value takes the velocity out of the error control altogether
                      (the other components still hold the steps).
    viscous_velocity_cap: float64 with viscous friction (Model(viscous_friction=True), the default; float32
                      and the law without it keep the member's scale): the pad velocity's error scale
                      (in the error estimate at nodes in contact, and in the Newton test) is at most
                      this many times hardness/viscous_coefficient (2e-5 m/s with the defaults: 2e-4
                      m/s at the default 10), but not below the scale of the disc's velocity now,
                      u_scale*max(|v_d(t)|, v*)/D (docs/model.md, "Time integration"). A velocity
                      error dV moves a sticking node's viscous stress by ~eta*(sigma_n/hardness)*dV,
                      and the member's scale (u_scale*|v_max|/D) let errors of
                      tens to hundreds of kPa through in loaded pads with fast discs (F = 91 kN, v = 0.107
                      m/s: a scale 1e4 times the default cap), whose edge nodes then opened microseconds
                      after the disc started. Members whose scale is below the cap (F*|v| below ~10 times
                      the default scene's, the benchmark's members among them) run bit for bit as without
                      it. 1: the stress's own tolerance (largest mu_s error of 300 wide members 1.4e-5
                      against 7.6e-5 at rtol 1e-5; 10.7 % more Newton iterations on the benchmark's
                      members, their mu_s unchanged); inf: off.
    steps_per_launch: attempted steps per kernel launch (progress granularity; no effect on results).
    stall_factor:     once half of an ensemble has ended ok, a member still running after more than
                      max(stall_min_steps, stall_factor * the lower median of the ok and running
                      members' attempted steps, running ones counted so far) attempted steps stops
                      with status 'stalled' (NaN outputs), so that one straggler cannot hold a
                      launch; inf: never.
    stall_min_steps:  see stall_factor.
    step_safety, step_min_factor, step_max_factor:
                      step-size controller (kernels/controller.py): after a step with error norm err
                      the next step is h*clamp(step_safety*err^(-1/3), step_min_factor,
                      step_max_factor); a rejected step shrinks by at least step_safety.
    failure_factor:   a step whose Newton solve fails is retried with failure_factor*h.
    float32_fallback: dtype='float32' only: members that end max_steps_reached, non_finite_state,
                      step_size_underflow or stalled are run again in float64 (after the float32
                      launch, on the same device) and their outputs replaced; the output
                      ``working_precision`` says which precision produced each member
                      (docs/model.md, "Precision"). False keeps the float32 failure statuses.
    lanes:            threads per member. 1: one thread integrates a member (the thread-per-member
                      kernel); 2 .. min(256, nodes // 2): a team of that many threads (one Warp tile
                      block) shares each member's nodes, its tridiagonal Newton solve and its
                      reductions (the cooperative kernel; float64 only). None (default): chosen per
                      run, see warpfric.engine.choose_lanes and docs/model.md, "Time
                      integration" (the cooperative kernel). Results of the two kernels agree within the error control, not bit
                      for bit (sums are taken in another order).
    """

    nodes: int = 100
    dtype: str = "float64"
    method: str = "tr_bdf2"
    rtol: float = 1e-5
    initial_step: float = 1e-6
    min_step: float = 1e-14
    max_step: float = 1.0
    max_steps: int = 100_000
    newton_max_iter: int = 8
    newton_tol: float = 0.03
    switch_tol: float = 1.0
    predict_switches: bool = True
    sliding_width: float = 1e-3
    error_filter_nodes: int = 800
    viscous_velocity_cap: float = 10.0
    steps_per_launch: int = 500
    stall_factor: float = 10.0
    stall_min_steps: int = 2000
    step_safety: float = 0.9
    step_min_factor: float = 0.2
    step_max_factor: float = 5.0
    failure_factor: float = 0.25
    float32_fallback: bool = True
    lanes: int | None = None

    def __post_init__(self):
        _zero_d_as_scalars(self)

        def need(cond, name, value, valid):
            if not cond:
                raise ValueError(f"solver setting {name!r} = {value!r} is invalid; valid: {valid}")

        def is_int(v):
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        def is_real(v):
            return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)

        need(is_int(self.nodes) and 3 <= self.nodes <= INT32_MAX, "nodes", self.nodes, f"an integer in [3, {INT32_MAX}]")
        need(self.dtype in _DTYPES, "dtype", self.dtype, " or ".join(_DTYPES))
        need(isinstance(self.method, str) and self.method in _METHODS, "method", self.method,
             " or ".join(repr(m) for m in _METHODS))
        need(is_real(self.rtol) and 1e-12 <= self.rtol <= 0.1, "rtol", self.rtol, "a number in [1e-12, 0.1]")
        need(self.dtype == "float64" or self.rtol >= FLOAT32_MIN_RTOL, "rtol", self.rtol,
             f"a number in [{FLOAT32_MIN_RTOL:g}, 0.1] with dtype='float32' (float32 round-off stalls "
             "the error control below that; use dtype='float64')")
        for name in ("initial_step", "min_step", "max_step"):
            v = getattr(self, name)
            need(is_real(v) and v > 0, name, v, "a number > 0 (s)")
        if not self.min_step <= self.max_step:  # either may be the one set: both named
            raise ValueError(f"solver settings 'min_step' = {self.min_step!r} and 'max_step' = {self.max_step!r} (s) "
                             "are invalid; valid: min_step <= max_step (the step size lies in [min_step, max_step])")
        need(self.min_step <= self.initial_step <= self.max_step, "initial_step", self.initial_step,
             f"min_step ({self.min_step:g}) <= initial_step <= max_step ({self.max_step:g})")
        need(is_int(self.max_steps) and 1 <= self.max_steps <= INT32_MAX, "max_steps", self.max_steps,
             f"an integer in [1, {INT32_MAX}] (the kernels count in int32)")
        need(is_int(self.newton_max_iter) and 1 <= self.newton_max_iter <= 100, "newton_max_iter",
             self.newton_max_iter, "an integer in [1, 100]")
        need(is_real(self.newton_tol) and 0 < self.newton_tol <= 1, "newton_tol", self.newton_tol, "a number in (0, 1]")
        need(isinstance(self.switch_tol, (int, float, np.integer, np.floating)) and not isinstance(self.switch_tol, bool)
             and self.switch_tol > 0 and not math.isnan(self.switch_tol), "switch_tol", self.switch_tol,
             "a number > 0 (inf allowed)")
        need(isinstance(self.predict_switches, (bool, np.bool_)), "predict_switches", self.predict_switches,
             "True or False")
        need(is_real(self.sliding_width) and 0 < self.sliding_width <= 0.1, "sliding_width", self.sliding_width,
             "a number in (0, 0.1]")
        need(is_int(self.error_filter_nodes) and (self.error_filter_nodes == 0 or 3 <= self.error_filter_nodes
                                                  <= INT32_MAX), "error_filter_nodes", self.error_filter_nodes,
             f"0 (every grid its own filter) or an integer in [3, {INT32_MAX}] (the grid whose elastic diagonal "
             "filters the velocity's error estimate on coarser grids)")
        need((is_real(self.viscous_velocity_cap) or self.viscous_velocity_cap == math.inf)
             and self.viscous_velocity_cap > 0, "viscous_velocity_cap", self.viscous_velocity_cap,
             "a number > 0, in units of hardness/viscous_coefficient (inf: off)")
        need(is_int(self.steps_per_launch) and 1 <= self.steps_per_launch <= INT32_MAX, "steps_per_launch",
             self.steps_per_launch, f"an integer in [1, {INT32_MAX}]")
        need(is_real(self.step_safety) and 0 < self.step_safety < 1, "step_safety", self.step_safety, "a number in (0, 1)")
        need(is_real(self.step_min_factor) and 0 < self.step_min_factor < 1, "step_min_factor", self.step_min_factor,
             "a number in (0, 1)")
        need(is_real(self.step_max_factor) and self.step_max_factor > 1, "step_max_factor", self.step_max_factor,
             "a number > 1")
        need(is_real(self.failure_factor) and 0 < self.failure_factor < 1, "failure_factor", self.failure_factor,
             "a number in (0, 1)")
        need((is_real(self.stall_factor) or self.stall_factor == math.inf) and self.stall_factor >= 1, "stall_factor",
             self.stall_factor, "a number >= 1 (inf: never)")
        need(is_int(self.stall_min_steps) and 1 <= self.stall_min_steps <= INT32_MAX, "stall_min_steps",
             self.stall_min_steps, f"an integer in [1, {INT32_MAX}]")
        need(isinstance(self.float32_fallback, (bool, np.bool_)), "float32_fallback", self.float32_fallback,
             "True or False")
        max_lanes = min(MAX_LANES, self.nodes // 2)
        need(self.lanes is None or (is_int(self.lanes) and (self.lanes == 1 or 2 <= self.lanes <= max_lanes)), "lanes",
             self.lanes, f"None, 1, or an integer in [2, {max_lanes}] (at most nodes // 2 and {MAX_LANES}: a block of 255-register threads)")
        need(self.lanes in (None, 1) or self.dtype == "float64", "lanes", self.lanes,
             "None or 1 with dtype='float32' (the cooperative kernel is float64 only)")
        _plain_settings(self)


_FRONT_DIRECTIONS = ("against_disc", "with_disc", "absolute")
# front events, in the order of the kernels' arrival array (kernels/types.py FRONT_EVENTS)
FRONT_EVENTS = ("contact", "strength", "velocity")


@dataclass(frozen=True, kw_only=True)
class Fronts:
    """Which detachment front is read, and how it is segmented (docs/model.md, "Fronts").

    event:                 the event that marks a node as detached; a name or a tuple of names (the
                           first gives the unprefixed outputs ``arrival_time``, ``v_main``, ...; each
                           other one the same outputs prefixed with its name, e.g.
                           ``strength_arrival_time``), from:
                           'contact' (default): each node's stick-to-slip transition, its first gate
                           opening after the disc starts, when its real contact area starts to fall
                           (relaxation_gate='stress' only: the other laws have no yield threshold, and
                           this event's outputs say none there, speeds and positions NaN,
                           nucleation_edge -2, detached_fraction 0, with a warning);
                           'strength': each node's peak of tau_f/sigma_n (its own static friction),
                           under every law;
                           'velocity': the pad velocity against the disc reaches threshold * its event
                           maximum (the paper's 40 % rule); it follows the pad springing back after
                           the mu_s peak, and costs a second integration pass.
                           'contact' and 'strength' are located inside the step, in one pass.
    threshold:             velocity event: a node has detached once its detachment velocity w
                           reaches threshold * (the event maximum of w over nodes and time); 0.4 in
                           the paper.
    direction:             velocity event: w = -sign(v_max)*u_t ('against_disc', default: the pad
                           springs back as the interface lets go), sign(v_max)*u_t ('with_disc') or
                           |u_t| ('absolute').
    min_segment_fraction:  shortest segment, as a fraction of the pad length (at least 3 node
                           intervals).
    fast_fraction:         v_fast, the front's fast reference speed, is the plateau (the most
                           populated 10 % band) of the local speeds dx/|dt_a| among this fastest
                           fraction of the node intervals: the sustained speed of the fast front,
                           not the unbounded local speed next to an interior nucleation point.
    speed_ratio:           slow: a local speed below v_fast / speed_ratio. The left (right) front
                           is the run of slow intervals from the left (right) end; it counts when
                           it is at least min_segment_fraction long and v_middle >= speed_ratio *
                           its mean speed; else it is merged into the middle.
    edge_zone_fraction:    nucleation within this fraction of L of an edge is nucleation at that edge.
    min_event_fraction:    velocity event: a detachment event needs a maximum detachment velocity of
                           at least this fraction of |disc_velocity|; below it there is no front (all
                           front outputs NaN). Measured events: 1e-4 .. 3e-3 of |v_max| for 1e-6 ..
                           1e-2 m/s. (threshold, direction and min_event_fraction changed without the
                           velocity event asked for change nothing; simulate warns once.)
    grid_check:            also run the ensemble on a grid of about half the nodes ((N+1)//2) and
                           report the change as ``v_*_grid_error`` and ``mu_s_grid_error``, the
                           speeds' spatial error, which ``v_*_error`` (time only) does not see.
                           Costs a run on the coarse grid (about +50 %); off by default.

    Fronts and segments: the arrival times may hold several fronts (``front_count``: the minima of
    t_a(x)) that meet at maxima. The segments are the first front's, over the nodes it reaches
    before any other: ``left``, ``middle``, ``right`` by position, and the same segments named from
    where it starts: ``precursor`` (the slow segment at the nucleation edge), ``main`` (the middle
    one) and ``far`` (the slow segment at its other end); precursor and far are NaN when the front
    nucleates inside the pad. The first and the second front are also reported whole (``v_first``,
    ``v_second``, ...), and where the first front meets another (``collision_position``,
    ``collision_time``). No segment or front spans a node that no front reached
    (docs/model.md, "Fronts that meet").
    """

    event: str | tuple = "contact"
    threshold: float = 0.4
    direction: str = "against_disc"
    min_segment_fraction: float = 0.05
    fast_fraction: float = 0.3
    speed_ratio: float = 1.5
    edge_zone_fraction: float = 0.1
    min_event_fraction: float = 1e-6
    grid_check: bool = False

    def __post_init__(self):
        _zero_d_as_scalars(self)

        def need(cond, name, value, valid):
            if not cond:
                raise ValueError(f"fronts setting {name!r} = {value!r} is invalid; valid: {valid}")

        def real(v):
            return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool) and math.isfinite(v)

        if isinstance(self.event, list):
            object.__setattr__(self, "event", tuple(self.event))  # hashable, like every other setting
        events = (self.event,) if isinstance(self.event, str) else self.event
        need(isinstance(events, tuple) and len(events) >= 1 and all(isinstance(e, str) and e in FRONT_EVENTS for e in events)
             and len(set(events)) == len(events), "event", self.event,
             f"one of {', '.join(map(repr, FRONT_EVENTS))}, or a tuple of distinct ones (no fronts: "
             "simulate(..., fronts=None))")
        need(real(self.threshold) and 0 < self.threshold < 1, "threshold", self.threshold, "a number in (0, 1)")
        need(self.direction in _FRONT_DIRECTIONS, "direction", self.direction, " or ".join(_FRONT_DIRECTIONS))
        need(isinstance(self.grid_check, (bool, np.bool_)), "grid_check", self.grid_check, "True or False")
        need(real(self.min_segment_fraction) and 0 < self.min_segment_fraction <= 1 / 3, "min_segment_fraction",
             self.min_segment_fraction, "a number in (0, 1/3]")
        need(real(self.fast_fraction) and 0 < self.fast_fraction <= 1, "fast_fraction",
             self.fast_fraction, "a number in (0, 1]")
        need(real(self.speed_ratio) and self.speed_ratio >= 1, "speed_ratio", self.speed_ratio, "a number >= 1")
        need(real(self.edge_zone_fraction) and 0 <= self.edge_zone_fraction <= 0.5, "edge_zone_fraction",
             self.edge_zone_fraction, "a number in [0, 0.5]")
        need(real(self.min_event_fraction) and 0 <= self.min_event_fraction < 1, "min_event_fraction",
             self.min_event_fraction, "a number in [0, 1)")
        _plain_settings(self)

    def unused_settings(self) -> list:
        """The velocity event's settings (threshold, direction, min_event_fraction) changed from
        their defaults where no requested event reads them, as 'name = value' texts."""
        if "velocity" in self.events:
            return []
        defaults = {f.name: f.default for f in dataclasses.fields(self)}
        return [f"{name} = {getattr(self, name)!r}" for name in ("threshold", "direction", "min_event_fraction")
                if getattr(self, name) != defaults[name]]

    @property
    def events(self) -> tuple:
        """The requested front events as a tuple, the primary (unprefixed outputs) first."""
        return (self.event,) if isinstance(self.event, str) else tuple(self.event)


MAX_RECORD_TIMES = 1_000_000
RECORD_COUNT = 1001  # recording times of Record.detachment and --record: 0.2 ms apart over the default scene's detachment
_RECORD_TIMES_WHY = ("(each time holds 4 fields at every node of each recorded member: the largest count, 3.2 GB a "
                     "member at 100 nodes)")


@dataclass(frozen=True, kw_only=True)
class Record:
    """Field recording for chosen members (off unless given): pad velocity (m/s), slip rate (m/s),
    contact pressure (Pa) and friction stress (Pa) at every node, sampled at ``times`` (s) by linear
    interpolation between accepted steps. Memory: 4 * len(times) * nodes * len(members) values.

    members:  member indices (0-based, in the order of simulate's output) to record.
    times:    sampling times in s, non-decreasing. ``Record.window(start, stop, count)`` builds an
              evenly spaced grid. Times after a member's end (its ``final_time``) are NaN, and
              ``simulate`` warns which: with the automatic end (``Parameters(end_time=None)``) a run
              stops once the detachment is over (~20.3 s for the default scene); give ``end_time``
              to record later.
    """

    members: tuple = (0,)
    times: tuple = ()

    def __repr__(self) -> str:  # 1,001 times are no reading: their count and range
        times = self.times
        shown = f"<{len(times)} times from {times[0]:g} to {times[-1]:g} s>" if len(times) > 3 else repr(times)
        return f"Record(members={self.members!r}, times={shown})"

    @staticmethod
    def window(start: float, stop: float, count: int, members=(0,)) -> "Record":
        """``count`` evenly spaced times from ``start`` to ``stop`` (s), both included."""
        if not (isinstance(count, (int, np.integer)) and 2 <= count <= MAX_RECORD_TIMES):
            raise ValueError(f"record setting 'count' = {count!r} is invalid; valid: an integer in [2, "
                             f"{MAX_RECORD_TIMES:,}] {_RECORD_TIMES_WHY}")
        try:
            start, stop = float(start), float(stop)
        except (TypeError, ValueError):
            raise ValueError(f"record window: start {start!r} and stop {stop!r} are invalid; valid: numbers of "
                             "seconds, start <= stop") from None
        if start > stop:  # NaN: Record's own check names the times; start = stop: count equal times, as Record
            # takes non-decreasing times (Record.detachment's window of a run that ended at its start is one)
            raise ValueError(f"record window: start {start!r} s is after stop {stop!r} s; valid: start <= stop")
        return Record(members=tuple(members), times=tuple(np.linspace(float(start), float(stop), int(count))))

    @staticmethod
    def detachment(ds, members=None, count: int = RECORD_COUNT, member_offset: int = 0,
                   final_time=None) -> "Record":
        """``count`` evenly spaced times over the detachment of ``members`` in ``ds``, the outputs of a
        run without recording, for running the same members again (recording changes no output).

        members:       member numbers (``ds.member``, as simulate numbers them) to record; default
                       every member of ``ds``.
        member_offset: that of the run to repeat (simulate's ``member_offset``): a member's index
                       there (``Record.members``) is its number less the offset.
        final_time:    the final times (s, along ``ds.member``) of the run to repeat, where ``ds``
                       was run with other fronts (the automatic end waits for the front events a
                       run reads, so it can come earlier or later: the window ends there); default
                       ``ds.final_time``.

        The window: for each member with a detachment (its first front's start or its mu_s peak
        before its end), from the earlier of the two, less half the time from there to its end
        (final_time), to that end; the window spans those members'. Members without one (not ok, or
        ended before it) are recorded over that window too (times after their end are NaN); where
        none has one, from the disc's start (rest_until) to the latest end."""
        needed = ["member"] + (["final_time"] if final_time is None else [])
        variables = getattr(ds, "variables", None)  # (an xarray Dataset; this module imports no xarray)
        if variables is None or "member" not in getattr(ds, "dims", ()) or any(n not in variables for n in needed):
            missing = [n for n in needed if n not in variables] if variables is not None else []
            found = (type(ds).__name__ if variables is None else
                     "a Dataset without " + ", ".join(missing) if missing else
                     "a Dataset whose member is no dimension (one member selected with isel(member=0)? "
                     "isel(member=[0]) keeps it)")
            raise ValueError(f"Record.detachment: ds is invalid; valid: the outputs of a run (simulate's or "
                             f"open_ensemble's Dataset, along member), got {found}")
        numbers_there = np.asarray(ds.member.values).reshape(-1)
        numbers = numbers_there if members is None else np.asarray(members).reshape(-1)
        if isinstance(member_offset, bool) or not isinstance(member_offset, (int, np.integer)) or member_offset < 0:
            raise ValueError(f"Record.detachment: member_offset = {member_offset!r} is invalid; valid: an integer >= 0, "
                             "that of the run to repeat")
        shown = first_few(numbers_there)
        if numbers.size == 0 or numbers.dtype.kind not in "iu" or not np.isin(numbers, numbers_there).all():
            raise ValueError(f"Record.detachment: members = {members!r} is invalid; valid: member numbers of ds "
                             f"({shown})")
        if (numbers < member_offset).any():
            raise ValueError(f"Record.detachment: member {int(numbers.min())} lies before member_offset = "
                             f"{member_offset}; valid: the offset of the run to repeat, at most its first member's number")
        positions = [int(np.flatnonzero(numbers_there == m)[0]) for m in numbers]
        n = ds.sizes["member"]
        final = np.asarray(ds.final_time.values if final_time is None else final_time, dtype=float).reshape(-1)
        if final.shape != (n,):
            raise ValueError(f"Record.detachment: final_time has {final.size} values; valid: one per member of ds "
                             f"({n}), in its order")
        rest_until = np.broadcast_to(np.asarray(ds["rest_until"].values, dtype=float), (n,)) if "rest_until" in ds \
            else np.zeros(n)
        starts, ends, all_ends = [], [], []
        for m in positions:
            end = float(final[m])
            start = detachment_start(ds, m, end)
            if start is not None:
                starts.append(max(0.0, start - 0.5 * (end - start)))
                ends.append(end)
            all_ends.append(end)
        end = max(ends) if ends else max(all_ends)  # a member without a detachment widens neither end
        if not starts:  # no detachment: from the disc's start (or 0 where a run ended before it)
            starts = [t if t < end else 0.0 for t in rest_until[positions]]
        return Record.window(min(starts), end, count, members=tuple(int(m) - member_offset for m in numbers))

    def __post_init__(self):
        members = np.asarray(self.members).reshape(-1)
        if members.size == 0 or members.dtype.kind not in "iu" or (members < 0).any():
            raise ValueError(f"record setting 'members' = {self.members!r} is invalid; valid: non-empty list of member indices >= 0")
        if len(set(members.tolist())) != members.size:
            raise ValueError(f"record setting 'members' = {self.members!r} has repeated indices")
        try:
            times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            raise ValueError(f"record setting 'times' = {self.times!r} is invalid; valid: non-empty, finite, "
                             "non-decreasing times >= 0 (s)") from None
        if times.size > MAX_RECORD_TIMES:
            raise ValueError(f"record setting 'times' has {times.size:,} times; valid: at most {MAX_RECORD_TIMES:,} "
                             f"{_RECORD_TIMES_WHY}")
        if times.size == 0 or not np.isfinite(times).all() or (times < 0).any() or (np.diff(times) < 0).any():
            shown = ", ".join(f"{t:g}" for t in times[:6]) + (f", ... ({times.size} times)" if times.size > 6 else "")
            raise ValueError(f"record setting 'times' = [{shown}] s is invalid; valid: non-empty, finite, "
                             "non-decreasing times >= 0 (s)")
        object.__setattr__(self, "members", tuple(int(i) for i in members))
        object.__setattr__(self, "times", tuple(float(t) for t in times))


def recording_text(times) -> str:
    """'recording the fields at N times from A to B s': what a run records, as the command line says
    it before the run (warpfric run --record, a sweep's [record] window = "detachment")."""
    return f"recording the fields at {len(times)} times from {times[0]:.6g} to {times[-1]:.6g} s"


def detachment_fronts(model: Model) -> Fronts:
    """The front event a first run finds a detachment window with (``Record.detachment``, ``warpfric
    run --record``, a sweep's ``[record] window = "detachment"``), whatever fronts the run itself
    reports: the contact front under the stress gate, the strength front under the other laws (they
    have no gate to open). Both are located in one pass, and both start before the mu_s peak, where
    the velocity front starts after it and a run without fronts has the peak alone."""
    return Fronts(event="contact" if model.relaxation_gate == "stress" else "strength")


def detachment_start(ds, position: int, end: float | None = None) -> float | None:
    """The detachment's start of the member at ``position`` (an index along ``ds.member``) in the
    outputs ``ds`` of a run: the earlier of its first front's start and its mu_s peak (s), where
    either lies before its end (``end``, s; default its final_time); None where neither does (not
    ok, or ended before it). Record.detachment's window and `warpfric run --record` read a
    detachment by this one rule."""
    end = float(ds.final_time.values[position]) if end is None else float(end)
    marks = [float(ds[name].values[position]) for name in ("front_start_time", "mu_s_time") if name in ds]
    marks = [t for t in marks if np.isfinite(t) and t < end]
    return min(marks) if marks else None


# how simulate's warning of recording times after a member's end begins (warpfric/pool.py drops the
# workers' own, and the parent warns once for the whole ensemble)
RECORD_PAST_END = "Record: recording times after a member's end are NaN"
# how simulate's warning of members that did not end ok begins (the same: once per ensemble)
MEMBERS_NOT_OK = "members that did not end ok have NaN mu_s and fronts"
# how that warning ends: where to find their numbers, in the Python API (the command line shows its own)
MEMBERS_NOT_OK_HINT = 'their numbers: ds.member[ds.status != 0] (docs/model.md, "Statuses")'
# how simulate's warning of velocity-front settings that no requested event reads begins
FRONTS_SETTINGS_UNUSED = "fronts settings of the velocity event only, unused without it"
# how simulate's warning of parameters that the model switches leave without effect begins
PARAMETERS_UNUSED = "parameters without effect under these model switches"
# how simulate's warning of the contact front under a law without the yield gate begins
CONTACT_WITHOUT_GATE = "fronts event 'contact' with relaxation_gate="
# the warnings simulate raises once for the whole ensemble: the runs inside it (worker processes'
# chunks, the float32 fallback, the grid check) drop their own
# simulate's warning where a disc starts to move before the normal force is fully applied (said by the
# outer call only: the runs inside it, worker processes, the grid check, drop it)
DISC_BEFORE_FULL_LOAD = ("the disc starts to move (rest_until) before the normal force is fully applied "
                         "(force_ramp_time) in some members: their mu_s is measured under a normal force still "
                         "rising, below normal_force (docs/model.md, \"Equations\": protocol)")
# how simulate's warning of members whose run ended before their detachment was over begins (the same)
DETACHMENT_NOT_OVER = "runs ended before the detachment was over"
# how simulate's warning of members whose mean normal stress reaches the hardness begins (the same)
LOAD_ABOVE_HARDNESS = "normal_force / (length * depth) reaches the hardness"
# how simulate's warning of ok members whose pad lifted off with no damping begins (the same)
LIFT_OFF_UNDAMPED = "members whose pad lifted off with no damping"
ENSEMBLE_WARNINGS = (RECORD_PAST_END, MEMBERS_NOT_OK, DETACHMENT_NOT_OVER, DISC_BEFORE_FULL_LOAD, FRONTS_SETTINGS_UNUSED,
                     PARAMETERS_UNUSED, CONTACT_WITHOUT_GATE, LOAD_ABOVE_HARDNESS, LIFT_OFF_UNDAMPED)


def _with_named_keywords(cls):
    """Wrap a dataclass's __init__ so that an unknown keyword raises a TypeError that names the
    valid ones and the closest match (the default message names neither)."""
    init = cls.__init__
    names = [f.name for f in dataclasses.fields(cls)]
    keywords_only = all(f.kw_only for f in dataclasses.fields(cls))

    def __init__(self, *args, **kwargs):
        if args and keywords_only:
            raise TypeError(f"{cls.__name__} takes keyword arguments only, as {cls.__name__}({names[0]}=...); "
                            f"got {plural(len(args), 'positional value')}: {', '.join(map(repr, args))}")
        unknown = [k for k in kwargs if k not in names]
        if unknown:
            raise TypeError(f"{cls.__name__}: unknown parameter {unknown[0]!r}{did_you_mean(unknown[0], names)}; "
                            f"valid names: {', '.join(names)}")
        init(self, *args, **kwargs)

    __init__.__doc__ = init.__doc__
    __init__.__signature__ = __import__("inspect").signature(init)
    cls.__init__ = __init__
    return cls


for _cls in (Parameters, Model, Solver, Fronts, Record):
    _with_named_keywords(_cls)
