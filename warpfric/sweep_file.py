"""Sweep files (TOML) -> the members and settings of an ensemble run (public as warpfric.sweep).

A sweep file (examples in studies/sweeps/, reference in docs/sweeps.md)::

    title = "mu_s against eccentricity and force"      # optional
    [scene]   normal_force = 1000.0 ...                 # Parameters defaults for every member (SI)
    [model]   tilt = true ...                           # Model switches
    [solver]  nodes = 100, rtol = 1e-5 ...              # Solver settings
    [fronts]  threshold = 0.4 ...                       # Fronts settings; `fronts = false` skips them
    [record]  members = [0], start = 20.0, stop = 20.6, count = 121   # or times = [...], or
              window = "detachment"                 # the recorded members' detachment (a first run)
    [grid]    eccentricity = [-0.2, 0.0, 0.2]           # full grid; or {start, stop, num, spacing}
    [zip]     a = [...], b = [...]                      # zipped lists of one length
    [sample]  n = 1000, seed = 1, viscous_coefficient = {distribution = "uniform", low = 0, high = 2.7e13}
    [design]  method = "saltelli", n = 1024, ...          # SALib designs (warpfric.sensitivity)
    [run]     chunk = 1000, device = "cpu"              # defaults of the command-line options;
              final_fields = false                      # leave out the final-state fields (member, x)
              member_offset = 0                         # number of the first member (combining runs)
              scheduler = "local"                       # or "tcp://host:8786": chunks as Dask tasks

Members are every combination of one grid point, one zip row and one sample row, in C order over
the blocks: grid keys in file order, then the zip rows, then the sample rows (fastest). Each sampled parameter draws from its own random stream, seeded by (seed, name), so
adding a parameter does not change the others' draws.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import math
import tomllib
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .members import resolve_members
from .parameters import (_RECORD_TIMES_WHY, MAX_RECORD_TIMES, MEMBER_NUMBER_LIMIT, PARAMETER_NAMES, RECORD_COUNT,
                         Fronts, Model, Parameters, Record, Solver, bound_outside_range, check_fronts_method,
                         check_precision, did_you_mean, parameter_range_text, parameter_units, units_text,
                         validate_value)
from .progress import machine_memory_bytes, plural

TOP_KEYS = ("title", "description", "scene", "model", "solver", "fronts", "record", "grid", "zip", "sample", "design",
            "run")
RUN_KEYS = {"chunk": int, "device": str, "final_fields": bool, "member_offset": int, "scheduler": str,
            "workers": int}
MEMBERS_NEEDED = ("a sweep file needs members: a [grid], [zip], [sample] or [design] table, or a [scene] table "
                  "(even an empty one) to run that scene as one member")
DISTRIBUTIONS = {"uniform": ("low", "high"), "normal": ("mean", "std"), "loguniform": ("low", "high")}
RANGE_KEYS = ("start", "stop", "num", "spacing")
# a [grid] or [zip] block of more rows is checked for repeated rows by its constant columns only: the
# copies and sort of np.unique took several times the memory of the values (a range's rows repeat
# only where its start equals its stop)
REPEAT_CHECK_ROWS = 1_000_000
# members validated at once, and what resolve_members holds a member while it validates them
# (tracemalloc: 272 bytes, ~33 float64 parameters and their temporaries)
VALIDATE_ROWS = 1_000_000
VALIDATE_BYTES_PER_MEMBER = 272


class SweepError(ValueError):
    """A sweep file that cannot be run; the message names the key and the accepted values."""


@dataclass(frozen=True)
class RecordDetachment:
    """``[record] window = "detachment"``: record ``members`` (indices in the sweep) at ``count``
    evenly spaced times over their detachment. The times are not in the file: a sweep run finds them
    by a first run of these members (``Record.detachment``, as ``warpfric run --record`` alone does),
    keeps them in its chunks' manifest for ``--resume`` and gives every chunk the same
    (warpfric.runner)."""

    members: tuple
    count: int

    def with_times(self, times) -> Record:
        """The Record of these members at ``times`` (s)."""
        return Record(members=self.members, times=tuple(times))


@dataclass(frozen=True)
class Sweep:
    text: str  # the file's text (stored in the output's attributes)
    title: str
    scene: Parameters
    model: Model
    solver: Solver
    fronts: Fronts | None
    record: Record | RecordDetachment | None  # RecordDetachment: times found by the run (warpfric.runner)
    members: dict  # name -> (M,) float64, only the swept parameters
    varying: tuple
    run: dict
    design: dict | None = None  # a sensitivity design (warpfric.sensitivity), JSON-serialisable

    @property
    def n_members(self) -> int:
        return next(iter(self.members.values())).shape[0] if self.members else 1

    def member_slice(self, sl: slice) -> dict:
        return {k: v[sl] for k, v in self.members.items()}


def _where(table: str, key: str | None = None) -> str:
    return f"[{table}] {key}" if key else f"[{table}]"


def _accepted(key: str, names, value: bool = False) -> str:
    """'(did you mean 'x'?); accepted: a, b, ...' for a key that is not one of ``names``; ``value``:
    for a string value, the suggestion as TOML spells it ("x")."""
    return f"{did_you_mean(key, names, spell=_toml if value else repr)}; accepted: {', '.join(names)}"


def _toml(value) -> str:
    """``value`` as a sweep file spells it (true, "text", [1, 2]), for messages that quote it."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, (datetime.date, datetime.time)):  # (datetime is a date)
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + "}"
    return repr(value)


def _number(value, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        key, _, part = where.split("] ")[-1].partition(".")  # '[grid] normal_force.start' -> normal_force, start
        value_of_parameter = key in PARAMETER_NAMES and part in ("", "start", "stop", "mean", "low", "high")
        valid = (f" in {parameter_range_text(key)} {units_text(parameter_units(key))}".rstrip()
                 if value_of_parameter else "")  # a spread (std, ...) is no value of the parameter
        raise SweepError(f"{where} = {_toml(value)}: expected a number{valid}")
    return float(value)


def _refused_by(cls, key: str, value) -> bool:
    """Whether ``cls(key=value)`` (its other fields at their defaults) raises ValueError: its own check
    of ``key``, whose message names the valid range."""
    try:
        cls(**{key: value})
    except ValueError:
        return True
    except TypeError:  # a class with required fields
        return False
    return False


def _dataclass_kwargs(table: dict, cls, where: str, parameters: bool = False) -> dict:
    names = {f.name: f for f in dataclasses.fields(cls)}
    out = {}
    for key, value in table.items():
        if key not in names:
            raise SweepError(f"unknown key {_where(where, key)}{_accepted(key, names)}")
        default = names[key].default
        if parameters:
            out[key] = _number(value, _where(where, key)) if value is not None else None
        elif isinstance(default, bool):
            if not isinstance(value, bool):
                raise SweepError(f"{_where(where, key)} = {_toml(value)}: expected true or false")
            out[key] = value
        elif (isinstance(default, int) and not isinstance(default, bool)) or (
                default is None and str(names[key].type).startswith("int")):  # lanes: int | None
            if (isinstance(value, bool) or not isinstance(value, int)) and (default is None or
                                                                            not _refused_by(cls, key, value)):
                # (a setting whose default is None, lanes: the class's message offers None, which TOML cannot write)
                leave_out = "; leave the key out for the default (automatic)" if default is None else ""
                raise SweepError(f"{_where(where, key)} = {_toml(value)}: expected an integer{leave_out}")
            out[key] = value  # a value of another type that the class refuses: its message names the valid range
        elif isinstance(default, float):
            out[key] = _number(value, _where(where, key))
        elif cls is Fronts and key == "event" and isinstance(value, list):  # several events: Fronts' tuple
            if not value or not all(isinstance(v, str) for v in value):
                raise SweepError(f"{_where(where, key)} = {_toml(value)}: expected an event name or a list of them")
            out[key] = tuple(value)
        else:
            if not isinstance(value, str):
                raise SweepError(f"{_where(where, key)} = {_toml(value)}: expected a string")
            out[key] = value
    return out


def _check_table_memory(total: int, columns: int, what: str, block_values: int = 0) -> None:
    """Raise SweepError where ``total`` members' values of ``columns`` parameters (float64), the two
    index temporaries of building their product, and the ``block_values`` values of the blocks it is
    built from (the peak that tracemalloc measures: 8 * (columns + 2)
    bytes a member beside the blocks), with a slice of members being validated, exceed this machine's
    memory: checked before such arrays are built."""
    table = 8 * (total * (columns + 2) + block_values) + VALIDATE_BYTES_PER_MEMBER * min(total, VALIDATE_ROWS)
    have = machine_memory_bytes()
    if have is not None and table > have:
        raise SweepError(f"{what} {total:,} members need about {table / 1e9:.1f} GB to build and check their "
                         f"parameter values alone, more than this machine's {have / 1e9:.1f} GB; fewer values, or several sweep files "
                         "with [run] member_offset")


def _range(spec: dict, where: str) -> tuple:
    """A checked range table {start, stop, num, spacing = 'linear' | 'log'}: (start, stop, num, spacing)."""
    unknown = set(spec) - set(RANGE_KEYS)
    if unknown:
        raise SweepError(f"unknown key {where}.{sorted(unknown)[0]}{_accepted(sorted(unknown)[0], RANGE_KEYS)}")
    for key in ("start", "stop", "num"):
        if key not in spec:
            raise SweepError(f"{where}: missing key {key!r} (a range needs start, stop, num)")
    start, stop = _number(spec["start"], f"{where}.start"), _number(spec["stop"], f"{where}.stop")
    num = spec["num"]
    if isinstance(num, bool) or not isinstance(num, int) or num < 1:
        raise SweepError(f"{where}.num = {_toml(num)}: expected an integer >= 1")
    spacing = spec.get("spacing", "linear")
    if spacing not in ("linear", "log"):
        raise SweepError(f"{where}.spacing = {_toml(spacing)}; accepted: linear, log")
    if spacing == "log" and (start <= 0 or stop <= 0):
        raise SweepError(f"{where}: log spacing needs start > 0 and stop > 0, got {_toml(start)}, {_toml(stop)}")
    return start, stop, num, spacing


def _length(spec, where: str) -> int:
    """How many values ``spec`` (as :func:`_values` takes it) gives, checked, without building them."""
    if isinstance(spec, list):
        if not spec:
            raise SweepError(f"{where} is empty: give at least one value")
        return len(spec)
    if isinstance(spec, dict):
        return _range(spec, where)[2]
    raise SweepError(f"{where} = {_toml(spec)}: expected a list of numbers or a table {{start, stop, num, spacing}}")


def _values(spec, where: str) -> np.ndarray:
    """A list of numbers or {start, stop, num, spacing = 'linear' | 'log'} (its length: _length, which a
    caller checks first where it may be large)."""
    if isinstance(spec, dict):
        start, stop, num, spacing = _range(spec, where)
        return np.linspace(start, stop, num) if spacing == "linear" else np.geomspace(start, stop, num)
    _length(spec, where)
    return np.array([_number(v, where) for v in spec], dtype=np.float64)


def _draw(name: str, spec, n: int, seed: int, where: str) -> np.ndarray:
    if not isinstance(spec, dict) or "distribution" not in spec:
        raise SweepError(f"{where} = {_toml(spec)}: expected "
                         '{distribution = "uniform" | "normal" | "loguniform", ...}')
    dist = spec["distribution"]
    if dist not in DISTRIBUTIONS:
        raise SweepError(f"{where}.distribution = {_toml(dist)}{_accepted(dist, DISTRIBUTIONS, value=True)}")
    keys = DISTRIBUTIONS[dist]
    unknown = set(spec) - set(keys) - {"distribution"}
    if unknown:
        key = sorted(unknown)[0]
        raise SweepError(f"unknown key {where}.{key} for {dist}{_accepted(key, keys)}")
    for key in keys:
        if key not in spec:
            raise SweepError(f"{where}: missing key {key!r} for the {dist} distribution")
    a, b = (_number(spec[k], f"{where}.{k}") for k in keys)
    for key, value in zip(keys, (a, b)):  # a bound or mean outside the parameter's range draws values outside it
        problem = bound_outside_range(name, key, value) if key in ("low", "high", "mean") else None
        if problem is not None:
            raise SweepError(f"{where}.{problem}")
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    if dist == "uniform":
        if not a < b:
            raise SweepError(f"{where}: low = {_toml(a)} must be below high = {_toml(b)}")
        return rng.uniform(a, b, n)
    if dist == "loguniform":
        if not 0 < a < b:
            raise SweepError(f"{where}: loguniform needs 0 < low < high, got low = {_toml(a)}, high = {_toml(b)}")
        return np.exp(rng.uniform(math.log(a), math.log(b), n))
    if not b > 0:
        raise SweepError(f"{where}.std = {_toml(b)}: expected a number > 0")
    return rng.normal(a, b, n)


def load_sweep(path) -> Sweep:
    """Read and validate a sweep file; raises SweepError (a ValueError) with a one-line message."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise SweepError(f"sweep file {str(path)!r}: {err.strerror}") from None
    except UnicodeDecodeError:  # e.g. an ensemble file (`warpfric run out.nc`, meant for info or plot)
        what = " (a netCDF file: warpfric info or warpfric plot read those)" if path.suffix == ".nc" else ""
        raise SweepError(f"sweep file {str(path)!r} is not text{what}; expected a TOML sweep file "
                         "(docs/sweeps.md)") from None
    return parse_sweep(text, str(path))


def parse_sweep(text: str, name: str = "<sweep>") -> Sweep:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise SweepError(f"{name}: not valid TOML ({err})") from None
    for key in doc:
        if key not in TOP_KEYS:
            raise SweepError(f"unknown key {key!r} in {name}{_accepted(key, TOP_KEYS)}")
    for key in ("scene", "model", "solver", "record", "grid", "zip", "sample", "design", "run"):
        if key in doc and not isinstance(doc[key], dict):
            raise SweepError(f"{key} = {_toml(doc[key])}: expected a table [{key}]")
    title = doc.get("title", "")
    if not isinstance(title, str):
        raise SweepError(f"title = {_toml(title)}: expected a string")
    try:
        scene = _said_in(f"{name}: [scene] ", Parameters,
                         **_dataclass_kwargs(doc.get("scene", {}), Parameters, "scene", parameters=True))
        model = _said_in(f"{name}: [model] ", Model, **_dataclass_kwargs(doc.get("model", {}), Model, "model"))
        solver = _said_in(f"{name}: [solver] ", Solver, **_dataclass_kwargs(doc.get("solver", {}), Solver, "solver"))
        check_precision(model, solver)  # before the run's first line, not inside its first chunk
        fronts_spec = doc.get("fronts", {})
        if fronts_spec is False:
            fronts = None
        elif isinstance(fronts_spec, dict):
            given = _dataclass_kwargs(fronts_spec, Fronts, "fronts")  # (its SweepError names the table once)
            try:
                fronts = Fronts(**given)
            except ValueError as err:  # the file's words: its table, and no fronts written as a file does
                raise SweepError(f"{name}: [fronts] " + str(err).replace(
                    "simulate(..., fronts=None)", "write `fronts = false` at the file's top level")) from None
        else:
            raise SweepError(f"fronts = {_toml(fronts_spec)}: expected a table [fronts] or false")
        check_fronts_method(fronts, solver)
    except TypeError as err:  # pragma: no cover - unknown keys are caught above
        raise SweepError(str(err)) from None

    blocks = []  # lists of {name: (k,) array}
    block_names = []  # where each block is written: "[grid] name", "[zip]", "[sample]"
    seen: dict[str, str] = {}

    def claim(pname: str, where: str):
        if pname not in PARAMETER_NAMES:
            raise SweepError(f"unknown parameter {where}{_accepted(pname, PARAMETER_NAMES)}")
        if pname in seen:
            raise SweepError(f"parameter {pname!r} is swept twice ({seen[pname]} and {where})")
        seen[pname] = where

    # the members' count and the memory of their values, checked before any array is built: a range
    # or a sample of 2e9 values took 16 GB (a MemoryError) before the product was checked
    grid, zipped, sample = doc.get("grid", {}), doc.get("zip", {}), dict(doc.get("sample", {}))
    sizes, size_names = [], []  # each block's length and parameters
    for pname, spec in grid.items():
        claim(pname, _where("grid", pname))
        sizes.append(_length(spec, _where("grid", pname)))
        size_names.append((pname,))
    if zipped:
        lengths = {}
        for pname, spec in zipped.items():
            claim(pname, _where("zip", pname))
            lengths[pname] = _length(spec, _where("zip", pname))
        if len(set(lengths.values())) != 1:
            raise SweepError(f"[zip] lists differ in length: {lengths}; all must have one length")
        sizes.append(next(iter(lengths.values())))
        size_names.append(tuple(zipped))
    if sample:
        n = sample.pop("n", None)
        seed = sample.pop("seed", 0)
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MEMBER_NUMBER_LIMIT:
            raise SweepError(f"[sample] n = {_toml(n)}: expected an integer in [1, {MEMBER_NUMBER_LIMIT}] (the number "
                             "of samples; member numbers are int32)")
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise SweepError(f"[sample] seed = {_toml(seed)}: expected an integer >= 0")
        if not sample:
            raise SweepError("[sample] has no parameters to sample")
        for pname in sample:
            claim(pname, _where("sample", pname))
        sizes.append(n)
        size_names.append(tuple(sample))
    if sizes:
        total = math.prod(sizes)
        if total > MEMBER_NUMBER_LIMIT:
            factors = " x ".join(f"{size:,} ({', '.join(names)})" for size, names in zip(sizes, size_names))
            raise SweepError(f"the sweep has {total:,} members ({factors}); at most {MEMBER_NUMBER_LIMIT:,} (member "
                             "numbers are int32): fewer values, or several sweep files with [run] member_offset")
        _check_table_memory(total, sum(len(names) for names in size_names), "the sweep's",
                            sum(size * len(names) for size, names in zip(sizes, size_names)))
    for pname, spec in grid.items():
        blocks.append({pname: _values(spec, _where("grid", pname))})
        block_names.append(f"[grid] {pname}")
    if zipped:
        blocks.append({pname: _values(spec, _where("zip", pname)) for pname, spec in zipped.items()})
        block_names.append("[zip]")
    if sample:
        blocks.append({pname: _draw(pname, spec, n, seed, _where("sample", pname)) for pname, spec in sample.items()})
        block_names.append("[sample]")
    members: dict[str, np.ndarray] = {}
    design = None
    if "design" in doc:
        from .sensitivity import generate, parse_design

        if blocks:
            raise SweepError("[design] cannot be combined with [grid], [zip] or [sample]: the analysis needs the "
                             "design's rows exactly (put fixed values in [scene])")
        design = parse_design(doc["design"])
        members = generate(design)
    for pname in doc.get("scene", {}):
        if pname in seen or pname in members:  # [grid], [zip], [sample]; or [design]'s generated members
            where = seen.get(pname) or f"[design] {pname}"
            raise SweepError(f"parameter {pname!r} is set in [scene] and swept in {where}: each member takes the "
                             "swept value, so [scene]'s would be ignored; remove one of them")
    for block, table in zip(blocks, block_names):
        if table == "[sample]":  # continuous draws
            continue
        rows_count = len(next(iter(block.values())))
        if rows_count > REPEAT_CHECK_ROWS:
            repeated, count = (([float(v[0]) for v in block.values()], rows_count)
                               if all(np.ptp(v) == 0 for v in block.values()) else (None, 0))
        else:
            rows = np.stack([np.asarray(v, dtype=np.float64) for v in block.values()], axis=1)
            unique, counts = np.unique(rows, axis=0, return_counts=True)
            k = int(np.argmax(counts > 1))
            repeated, count = (unique[k], int(counts[k])) if (counts > 1).any() else (None, 0)
        if repeated is not None:
            example = ", ".join(f"{n} = {v:g}" for n, v in zip(block, repeated))
            warnings.warn(f"{table} repeats {'a value' if len(block) == 1 else 'a row'} ({example}: "
                          f"{count} times): its members run more than once, with equal results, and "
                          "warpfric.io.by_parameters refuses such a file", stacklevel=2)
    if blocks:
        stride = total
        for size, block in zip(sizes, blocks):  # the product's order: the last block varies fastest
            stride //= size
            index = (np.arange(total, dtype=np.int64) // stride) % size
            for pname, values in block.items():
                members[pname] = values[index]
    record = None
    if "record" in doc:
        record = _record(doc["record"])
    if not members and "scene" not in doc:
        raise SweepError(f"{name}: nothing to run; {MEMBERS_NEEDED}")
    run = _dataclass_like(doc.get("run", {}), RUN_KEYS, "run")
    if run.get("chunk", 1) < 1:
        raise SweepError(f"[run] chunk = {run['chunk']}: expected an integer >= 1 (members per chunk file)")
    if run.get("workers", 1) < 1:
        raise SweepError(f"[run] workers = {run['workers']}: expected an integer >= 1 (Dask workers of a local cluster)")
    n_members = next(iter(members.values())).shape[0] if members else 1
    check_member_offset(run.get("member_offset", 0), n_members, "[run] member_offset")
    # validate every member now (ranges, protocol), before anything runs or is written: a swept value
    # out of range, or a protocol the scene's times break
    _validate_members(members, scene, f"{name}: ")
    varying = tuple(k for k in PARAMETER_NAMES if k in members)
    return Sweep(text, title, scene, model, solver, fronts, record, members, varying, run, design)


def _validate_members(members: dict, scene, where: str) -> None:
    """SweepError (beginning with ``where``) for the first member out of range or whose protocol
    breaks. resolve_members holds every parameter of every member (~33 float64, 272 bytes a member
    with its temporaries), so more than VALIDATE_ROWS members are checked slice by slice, after each
    swept column whole (which names the first bad member and counts the bad ones)."""
    n = next(iter(members.values())).shape[0] if members else 1
    if n <= VALIDATE_ROWS:
        _said_in(where, resolve_members, members or None, scene)
        return
    for pname in PARAMETER_NAMES:  # resolve_members' order: the same first fault where several parameters have one
        if pname in members:
            _said_in(where, validate_value, pname, members[pname])
    for start in range(0, n, VALIDATE_ROWS):
        _said_in(where, resolve_members, {k: v[start:start + VALIDATE_ROWS] for k, v in members.items()}, scene,
                 first_member=start)


def _said_in(where: str, make, *args, **kwargs):
    """``make(*args, **kwargs)``; its ValueError (a value out of range) as a SweepError that begins with
    ``where`` (the sweep file, and its table where one holds the value); a SweepError as it is."""
    try:
        return make(*args, **kwargs)
    except SweepError:
        raise
    except ValueError as err:
        raise SweepError(f"{where}{err}") from None


def check_member_offset(offset: int, n_members: int, where: str) -> int:
    """``offset`` if the member numbers offset .. offset + n_members - 1 fit in int32, else SweepError."""
    top = MEMBER_NUMBER_LIMIT - n_members
    if not 0 <= offset <= top:
        raise SweepError(f"{where} = {offset}: expected an integer in [0, {top}] (the number of the first of "
                         f"{plural(n_members, 'member')}; member numbers are int32)")
    return offset


def _record(spec: dict) -> Record | RecordDetachment:
    keys = ("members", "times", "start", "stop", "count", "window")
    for key in spec:
        if key not in keys:
            raise SweepError(f"unknown key [record] {key}{_accepted(key, keys)}")
    members = spec.get("members", [0])
    if not isinstance(members, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in members):
        raise SweepError(f"[record] members = {_toml(members)}: expected a list of member indices")
    # ascending: the chunks give the combined file its recorded members in their order, so a listed
    # order would hold only where the members share a chunk (the file's order would depend on --chunk)
    members = sorted(members)
    count = spec.get("count", RECORD_COUNT)  # as --record START STOP [COUNT]
    if "count" in spec and (isinstance(count, bool) or not isinstance(count, int)):
        raise SweepError(f"[record] count = {_toml(count)}: expected an integer >= 2")
    if "window" in spec:
        window = spec["window"]
        if window != "detachment":
            raise SweepError(f"[record] window = {_toml(window)}: expected \"detachment\" (the recorded members' "
                             "detachment, found by a first run), or give start and stop (s) instead")
        if any(k in spec for k in ("times", "start", "stop")):
            raise SweepError("[record]: give either window = \"detachment\", times, or start/stop/count, not two of them")
        try:  # the members and the count checked now, as a Record of one placeholder time would
            Record.window(0.0, 1.0, count, members=tuple(members))
        except ValueError as err:
            raise SweepError(f"[record] {err}") from None
        return RecordDetachment(members=tuple(members), count=int(count))
    if "times" in spec:
        if any(k in spec for k in ("start", "stop", "count")):
            raise SweepError("[record]: give either times or start/stop/count, not both")
        count = _length(spec["times"], "[record] times")  # before a range of that many is built
        if count > MAX_RECORD_TIMES:
            raise SweepError(f"[record] times has {count:,} times; valid: at most {MAX_RECORD_TIMES:,} "
                             f"{_RECORD_TIMES_WHY}")
        times = _values(spec["times"], "[record] times")
        return _said_in("[record] ", Record, members=tuple(members), times=tuple(times))
    for key in ("start", "stop"):
        if key not in spec:
            raise SweepError(f"[record]: missing key {key!r} (give times = [...], start, stop and optionally "
                             f"count, default {RECORD_COUNT}, or window = \"detachment\")")
    return _said_in("[record] ", Record.window, _number(spec["start"], "[record] start"),
                    _number(spec["stop"], "[record] stop"), count, members=tuple(members))


def _dataclass_like(table: dict, kinds: dict, where: str) -> dict:
    out = {}
    for key, value in table.items():
        if key not in kinds:
            raise SweepError(f"unknown key {_where(where, key)}{_accepted(key, kinds)}")
        kind = kinds[key]
        if (isinstance(value, bool) and kind is not bool) or not isinstance(value, kind):
            expected = {int: "an integer", str: "a string", bool: "true or false"}[kind]
            raise SweepError(f"{_where(where, key)} = {_toml(value)}: expected {expected}")
        out[key] = value
    return out

