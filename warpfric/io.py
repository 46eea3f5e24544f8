"""warpfric.io: ensembles as netCDF files for xarray (CF attributes, compression, chunked runs).

A file holds dims ``member`` and ``x`` (and ``recorded``, ``time`` for recorded fields). Every
input parameter is a variable along ``member``, a constant one too (:func:`parameters_along_member`:
files of different constants then combine under any xarray settings); :func:`open_ensemble` gives
the parameters that do not vary in the file (global attribute ``varying_parameters``) back as
scalars, where :func:`warpfric.simulate` keeps every parameter along ``member``
(``parameters_along_member(open_ensemble(path))`` has simulate()'s layout). Outputs carry CF
``units`` and ``long_name``;
the model switches, solver and front settings, package and Warp versions and the device are
global attributes.

Layout on disk (what ``xr.open_dataset``/``xr.open_mfdataset`` show) differs from the in-memory
layout of :func:`warpfric.simulate` in two ways, both so that the files of separate runs combine
however a user opens them:

- Member identity: coordinate ``member`` holds each member's label ``<run id>:<number>`` (run id:
  the run's UTC start time to the millisecond and 6 random hex digits; number: 10 digits,
  e.g. ``20261125T193512123-3f2a9c:0000000004``), unique across runs and sorted within a file;
  ``member_number`` (int32) holds the member numbers. The chunks of one sweep share its run id
  (kept in the manifest, also by ``--resume``). Two runs made without ``--member-offset`` number
  their members alike, but their labels differ, so xarray's default ``xr.open_mfdataset(files)``
  (combine="by_coords") concatenates them along ``member``, every member once, runs in the order
  they started (before the labels it kept 2 of 5 members, or padded mu_s to recorded_member x
  member with NaN). :func:`open_ensemble` gives back simulate()'s member identity: ``member`` the numbers,
  ``member_id`` the labels (which :func:`write_ensemble` keeps).
- Recorded fields live in the netCDF4 group ``recorded`` (``xr.open_dataset(path,
  group="recorded")``): dims (``recorded_member``, ``record_time``, ``x``), ``recorded_member``
  the labels of the recorded members, ``recorded_member_number`` their numbers, ``record_time``
  the recording time (not named ``time``: CF reserves that name for calendar time with
  ``units = "s since <epoch>"``). In the root group they made by_coords concatenate along a second
  dimension. :func:`open_ensemble` gives back (``recorded``, ``time``, ``x``) with
  ``recorded_member`` the numbers.

Files written before the labels (numbers as ``member``, recorded fields in the root) still open.
Coordinates carry no ``_FillValue``; integers are int32 or int8 (netCDF classic types, CF-1.8);
labels are zlib-compressed char arrays; the global attribute ``history`` says when and by which
command the file was written.

Combining files: :func:`open_ensembles` (refuses repeated member numbers, saying what to do), or
lazily (needs dask) ``xr.open_mfdataset(files)`` at xarray's defaults or with
``**COMBINE_KWARGS``, and ``xr.open_mfdataset(files, group="recorded")`` for the recorded fields.

Completeness: a file written by :func:`write_ensemble` has the global attribute
``warpfric_complete = 1`` and is written under a temporary name and renamed, so a killed run never
leaves a file that looks complete; a write that fails (a full disk) or is interrupted removes its
temporary file and raises :class:`OutputWriteError`. A chunked run (:class:`ChunkStore`) keeps its
finished chunks in ``OUT.nc.parts/`` until all are done, then combines them into ``OUT.nc``.

Before a run: :func:`lock_output` takes ``OUT.nc.lock`` (created with O_EXCL: the first proof that
the folder is writable, and the refusal of a second run on the same output, :class:`OutputBusy`),
:func:`check_free_space` compares the folder's free space with :func:`estimate_bytes`, and
:func:`remove_stale_temporaries` removes what an earlier killed run left.
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import hashlib
import json
import os
import re
import shlex
import shutil
import signal
import socket
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import xarray as xr

from .parameters import PARAMETER_NAMES

COMPLETE_ATTR = "warpfric_complete"
PARTS_SUFFIX = ".parts"
SWEEP_COPY = "sweep.toml"  # in OUT.nc.parts/: the sweep file's text the run started with (for --resume)
MANIFEST = "manifest.json"
FILE_TIME = "record_time"  # on-disk name of the recording-time coordinate (``time`` in memory)
RECORDED_GROUP = "recorded"  # netCDF4 group of the recorded fields
MEMBER_NUMBER = "member_number"  # on disk: the member numbers, beside the member labels
MEMBER_ID = "member_id"  # in memory: the member labels, beside the member numbers
RECORDED_NUMBER = "recorded_member_number"
MEMBER_LABEL_ATTRS = {"long_name": "member label: run id and member number", "units": "1",
                      "comment": "the id of the run that simulated the member (its UTC start time and a random "
                      "suffix) and its member number; unique across runs"}
RECORDED_MEMBER_ATTRS = {"long_name": "member label (value of coordinate member of the root group) of each recorded "
                         "member", "units": "1"}
RECORDED_NUMBER_ATTRS = {"long_name": "member number of each recorded member", "units": "1"}
NUMBER_DIGITS = 10  # member numbers are int32: at most 10 digits, zero-padded so that labels sort as numbers
# xr.open_mfdataset(files, **COMBINE_KWARGS) concatenates warpfric files along member in the order
# given (xarray's default, by_coords, orders them by their labels, i.e. by the runs' start), under
# both xarray's current and its announced combine defaults; recorded fields: group="recorded"
COMBINE_KWARGS = {"combine": "nested", "concat_dim": "member", "data_vars": "minimal", "coords": "minimal",
                  "compat": "no_conflicts", "join": "outer"}
INT32_MAX = 2**31 - 1
LOCK_SUFFIX = ".lock"
FULL_DISK_BYTES = 1 << 20  # a netCDF write that fails with less than this free: the disk is full
NO_SPACE_ERRNOS = (errno.ENOSPC, errno.EDQUOT)


class OutputUnwritable(ValueError):
    """The output's folder cannot be written (checked before anything runs; exit code 2)."""


class ChunksDoNotCombine(ValueError):
    """The finished chunks of a sweep refuse to combine into one file (concat_members' message, which
    names the chunk files); nothing was written and the chunks are where they were."""


class OutputWriteError(Exception):
    """Writing an output failed during a run: a full disk, or another I/O error (exit code 3). Its
    temporary file has been removed."""

    def __init__(self, message: str, disk_full: bool = False):
        super().__init__(message)
        self.disk_full = disk_full

    def __reduce__(self):
        # a Dask worker's error reaches the client pickled: keep disk_full (exit code 3's advice)
        return (type(self), (str(self), self.disk_full))


class OutputBusy(Exception):
    """Another run is writing the same output: its lock file exists (exit code 4)."""


def _size(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return ""  # pragma: no cover


def free_bytes(folder) -> int | None:
    """Free bytes in ``folder`` for this user, None where the file system does not say: also where
    it reports a size of 0 (a pseudo file system such as /proc or /sys, whose 0 bytes free are not
    a full disk)."""
    try:
        usage = shutil.disk_usage(folder)
    except OSError:
        return None
    return usage.free if usage.total > 0 else None


# what a file holds whatever its members: netCDF4/HDF5's headers and chunk indices of its variables,
# without fronts and for each front event (measured, 1 member of 11 nodes: 185 kB without fronts,
# 397 / 530 / 699 kB with 1 / 2 / 3 events; 32 members: 421 kB with 1 event, 568 kB at 101 nodes)
FILE_OVERHEAD_BYTES = 190_000
FRONT_EVENT_OVERHEAD_BYTES = 180_000


def estimate_bytes(n_members: int, nodes: int, *, final_fields: bool = True, front_events: int = 1,
                   recorded: int = 0, times: int = 0, files: int = 1) -> int:
    """Bytes of ``files`` ensemble files holding ``n_members`` members in all, before compression
    (zlib gains ~10 % on the fields): per file FILE_OVERHEAD_BYTES and FRONT_EVENT_OVERHEAD_BYTES per
    front event; per member ~100 scalars, each front event's arrival times and the final-state fields
    (8 per node); per recorded member 4 fields at every recording time and node, and mu(t)."""
    per_member = 8 * (100 + nodes * (front_events + (8 if final_fields else 0)))
    per_file = FILE_OVERHEAD_BYTES + front_events * FRONT_EVENT_OVERHEAD_BYTES
    return int(files * per_file + n_members * per_member + 8 * recorded * times * (4 * nodes + 1))


def check_free_space(path, need: int, what: str) -> None:
    """OutputWriteError (disk full) when the folder of ``path`` has less than half of ``need``
    bytes free: the file cannot fit even if compression halved it."""
    folder = Path(path).parent
    free = free_bytes(folder)
    if free is not None and free < need // 2:
        raise OutputWriteError(f"output {str(path)!r}: disk full: {_size(free)} free in {str(folder)!r}, {what} needs "
                               f"about {_size(need)}; free some space or choose another -o", disk_full=True)


def lock_path(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + LOCK_SUFFIX)


def _create_exclusive(path: Path) -> int:
    return os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)


def os_error_reason(err: OSError) -> str:
    """An OSError's reason as a message writes it: 'permission denied', 'read-only file system'."""
    return "read-only file system" if err.errno == errno.EROFS else (err.strerror or str(err)).lower()


def _unwritable(path: Path, folder: Path, err: OSError) -> OutputUnwritable:
    reason = os_error_reason(err)
    return OutputUnwritable(f"output {str(path)!r}: cannot write in folder {str(folder)!r} ({reason}); choose "
                            "another -o or make the folder writable")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True
    return True


def _stale(lock: Path) -> bool:
    """True for a lock that no living run holds: its process is gone (same host), or it is empty
    (its writer died before writing it) and older than 10 s."""
    try:
        holder = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        holder = {}
    if not holder:
        try:
            return time.time() - lock.stat().st_mtime > 10
        except OSError:
            return True
    return holder.get("host") == socket.gethostname() and not _pid_alive(int(holder.get("pid", -1)))


def _holder(lock: Path) -> str:
    try:
        h = json.loads(lock.read_text())
        return f"pid {h['pid']} on {h['host']}, since {h['started']}"
    except (OSError, ValueError, KeyError, TypeError):
        return "unknown process"


def running_writer(path) -> str | None:
    """Who holds ``OUT.nc.lock`` beside ``path`` ('pid P on HOST, since T'), where a living run holds it
    (or one on another host, which this host cannot check); None where there is no lock or a stale one."""
    lock = lock_path(path)
    if not lock.exists() or _stale(lock):
        return None
    return _holder(lock)


def lock_output(path, command: str | None = None) -> Path:
    """Take ``OUT.nc.lock`` beside ``path`` (O_EXCL) and return it; release with
    :func:`unlock_output`. A lock whose process is gone (same host) is taken over. Raises
    OutputBusy when a living run holds it, OutputUnwritable when the folder cannot be written."""
    path = Path(path)
    lock = lock_path(path)
    for _ in range(3):
        try:
            fd = _create_exclusive(lock)
        except FileExistsError:
            if _stale(lock):
                with contextlib.suppress(FileNotFoundError):
                    lock.unlink()
                continue
            raise OutputBusy(f"output {str(path)!r} is being written by another warpfric run ({_holder(lock)}); wait "
                             f"for it to end, or remove {str(lock)!r} if that run is gone") from None
        except OSError as err:
            raise _unwritable(path, path.parent, err) from None
        now = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        with os.fdopen(fd, "w") as f:
            json.dump({"pid": os.getpid(), "host": socket.gethostname(), "started": now, "command": command}, f)
        return lock
    raise OutputBusy(f"output {str(path)!r}: lock {str(lock)!r} keeps coming back; is another run starting?")


def unlock_output(lock: Path) -> None:
    """Remove a lock taken by :func:`lock_output` in this process (not one another run took over)."""
    with contextlib.suppress(OSError, ValueError):
        if json.loads(Path(lock).read_text()).get("pid") == os.getpid():
            Path(lock).unlink()


def refuse_if_locked(path) -> None:
    """OutputBusy when another living run holds ``OUT.nc.lock`` beside ``path``: a write from Python
    (:func:`write_ensemble`) beside a running ``warpfric run`` on the same output. A lock this
    process holds, or a stale one, does not stop it."""
    path = Path(path)
    lock = lock_path(path)
    try:
        text = lock.read_text()
    except OSError:
        return  # no lock (or none that can be read: the write itself will say what is wrong)
    try:
        holder = json.loads(text or "{}")
    except ValueError:
        holder = {}
    if holder.get("pid") == os.getpid() and holder.get("host") == socket.gethostname():
        return
    if _stale(lock):
        return
    raise OutputBusy(f"output {str(path)!r} is being written by another warpfric run ({_holder(lock)}); wait "
                     f"for it to end, or remove {str(lock)!r} if that run is gone")


@contextlib.contextmanager
def output_lock(path, command: str | None = None):
    """``with output_lock(path):`` holds ``OUT.nc.lock`` for the block (see :func:`lock_output`)."""
    lock = lock_output(path, command)
    try:
        yield lock
    finally:
        unlock_output(lock)


def probe_writable(folder, path) -> None:
    """OutputUnwritable unless a file can be created in ``folder`` (created and removed at once)."""
    folder = Path(folder)
    probe = folder / f".warpfric-probe-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        os.close(_create_exclusive(probe))
    except OSError as err:
        raise _unwritable(Path(path), folder, err) from None
    probe.unlink()


def _temporaries(folder: Path, prefix: str) -> list:
    return sorted(folder.glob(f"{prefix}*.tmp")) if folder.is_dir() else []


def remove_stale_temporaries(path) -> list:
    """Remove the temporary files that killed writers of ``path`` left (``OUT.nc.<pid>.<hex>.tmp``
    beside it and ``*.tmp`` in its parts folder); call it holding the output's lock, so that no
    living writer of this process's run owns them. Returns the removed paths."""
    path = Path(path)
    removed = []
    for tmp in _temporaries(path.parent, path.name + ".") + _temporaries(parts_dir(path), ""):
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
            removed.append(tmp)
    return removed


def write_failure(path, err: BaseException, free: int | None) -> OutputWriteError:
    """The OutputWriteError of a failed write. 'disk full' for ENOSPC/EDQUOT, and for any other
    I/O error when less than 1 MiB was left free: HDF5 reports a full disk as netCDF's generic
    'NetCDF: HDF error' (RuntimeError) while writing, or as EACCES when it creates a file."""
    path = Path(path)
    code = getattr(err, "errno", None)
    reason = " ".join(str(getattr(err, "strerror", None) or err).split())
    if code in NO_SPACE_ERRNOS or (free is not None and free < FULL_DISK_BYTES):
        where = f"{_size(free)} free" if free is not None else "no space left"
        return OutputWriteError(f"disk full while writing {str(path)!r} ({where}; its partial file removed)",
                                disk_full=True)
    return OutputWriteError(f"could not write {str(path)!r} ({type(err).__name__}: {reason}; its partial file removed)")


def _encoding(ds: xr.Dataset, complevel: int) -> dict:
    enc = {}
    for name, var in ds.variables.items():
        if name in ds.coords:
            enc[name] = {"_FillValue": None}  # CF: coordinate variables have no missing values
        if var.dtype.kind == "U":  # member labels: a compressed char array (a vlen string cannot be compressed)
            # the member labels share one; a user's text variable or coordinate has its own
            chars = "label_length" if name in ("member", "recorded_member") else f"{name}_strlen"
            enc.setdefault(name, {}).update({"dtype": "S1", "char_dim_name": chars, "zlib": True, "complevel": complevel})
        if var.ndim == 0 or var.dtype.kind not in "biuf":
            continue
        enc.setdefault(name, {}).update({"zlib": True, "complevel": complevel, "shuffle": True})
    return enc


def _int32(value, where: str):
    """int64 (not a netCDF classic type) -> int32; python ints in attributes too."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iu" or arr.dtype.itemsize <= 4 or isinstance(value, bool):
        return value
    if arr.size and (arr.min() < -INT32_MAX - 1 or arr.max() > INT32_MAX):
        raise ValueError(f"{where}: integers beyond the int32 range of a CF-1.8 file")
    out = arr.astype(np.int32)
    return out if isinstance(value, np.ndarray) else out[()]


def new_run_id() -> str:
    """A run's id: its UTC start time to the millisecond (so that runs sort by it) and 6 random hex
    digits (two runs of one millisecond differ), e.g. '20261125T193512123-3f2a9c'."""
    now = datetime.datetime.now(datetime.timezone.utc)
    return f"{now:%Y%m%dT%H%M%S}{now.microsecond // 1000:03d}-{uuid.uuid4().hex[:6]}"


def member_labels(run_id: str, numbers) -> np.ndarray:
    """The labels ``<run id>:<number, 10 digits>`` of members ``numbers`` of run ``run_id``."""
    return np.array([f"{run_id}:{int(n):0{NUMBER_DIGITS}d}" for n in np.asarray(numbers).reshape(-1)], dtype=str)


def _labels(ds: xr.Dataset, run_id: str | None) -> np.ndarray:
    """The member labels to write: those ``ds`` carries (read from a file) where they are strictly
    increasing, as a file's coordinate must be; else new ones of run ``run_id`` (a new id if None)."""
    if MEMBER_ID in ds.coords and run_id is None:
        labels = np.asarray(ds[MEMBER_ID].values).astype(str)
        if labels.size < 2 or bool(np.all(labels[1:] > labels[:-1])):
            return labels
    return member_labels(run_id or new_run_id(), ds.member.values)


def _file_variables(ds: xr.Dataset) -> xr.Dataset:
    out = ds.copy()
    for name, var in list(out.variables.items()):
        if var.dtype == np.int64:
            out[name] = out[name].copy(data=_int32(var.values, name))
        out.variables[name].attrs = {k: _int32(v, f"{name}:{k}") for k, v in var.attrs.items()}
    out.attrs = {k: _int32(v, f"attribute {k}") for k, v in out.attrs.items()}
    return out


def _to_file_layout(ds: xr.Dataset, run_id: str | None = None) -> tuple[xr.Dataset, xr.Dataset | None]:
    """The in-memory layout of simulate() -> the on-disk layout: (root group, recorded group or None),
    see the module docstring."""
    labels = _labels(ds, run_id)
    numbers = _int32(np.asarray(ds.member.values), "member")
    rec_vars = [v for v in ds.data_vars if "recorded" in ds[v].dims]
    root = ds.drop_vars(rec_vars + [c for c in ("recorded_member", "time", MEMBER_ID) if c in ds.coords])
    root = root.drop_vars("member").assign_coords(member=("member", labels, MEMBER_LABEL_ATTRS),
                                                  **{MEMBER_NUMBER: ("member", numbers, dict(ds.member.attrs))})
    recorded = None
    if rec_vars:
        rec = ds[rec_vars].drop_vars([c for c in ("member", MEMBER_ID) if c in ds[rec_vars].coords])
        rec_numbers = _int32(np.asarray(ds.recorded_member.values), "recorded_member")
        where = {int(n): i for i, n in enumerate(ds.member.values)}
        rec = rec.drop_vars("recorded_member").assign_coords(
            recorded_member=("recorded", labels[[where[int(n)] for n in rec_numbers]], RECORDED_MEMBER_ATTRS),
            **{RECORDED_NUMBER: ("recorded", rec_numbers, RECORDED_NUMBER_ATTRS)}).swap_dims(recorded="recorded_member")
        rec = rec.rename(time=FILE_TIME)
        rec.attrs = {"Conventions": ds.attrs.get("Conventions", "CF-1.8"),
                     "title": "recorded fields of chosen members (the ensemble is in the root group)"}
        recorded = _file_variables(rec)
    return _file_variables(root), recorded


def _from_file_layout(ds: xr.Dataset, recorded: xr.Dataset | None = None) -> xr.Dataset:
    """The on-disk layout (root group, recorded group) -> the in-memory layout of simulate(). Reads
    the layout before member labels too (numbers as the member coordinate, recorded fields in the root)."""
    if MEMBER_NUMBER in ds.coords:
        labels, numbers = ds.member.values.astype(str), ds[MEMBER_NUMBER]
        ds = ds.drop_vars(["member", MEMBER_NUMBER]).assign_coords(
            member=("member", numbers.values, dict(numbers.attrs)), **{MEMBER_ID: ("member", labels, MEMBER_LABEL_ATTRS)})
    if recorded is not None:
        numbers = recorded[RECORDED_NUMBER]
        recorded = recorded.drop_vars(["recorded_member", RECORDED_NUMBER, "x"]).rename(
            {FILE_TIME: "time", "recorded_member": "recorded"}).assign_coords(
            recorded_member=("recorded", numbers.values, dict(numbers.attrs)))
        recorded.attrs = {}
        ds = ds.assign(recorded.data_vars).assign_coords(recorded_member=recorded.recorded_member, time=recorded.time)
    if FILE_TIME in ds.dims:
        ds = ds.rename({FILE_TIME: "time"})
    if "recorded_member" in ds.dims:
        ds = ds.swap_dims(recorded_member="recorded")
    return ds


def history_time() -> str:
    """Now, as a ``history`` line gives it (UTC, to the second)."""
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")


def history_line(command: str | None, started: str | None = None) -> str:
    """One ``history`` line: when the command started (``started``, from history_time; None: now),
    the command, and the version."""
    from . import __version__

    return f"{started or history_time()}: {command or 'warpfric.io.write_ensemble (Python)'} (warpfric {__version__})"


def parameters_along_member(ds: xr.Dataset) -> xr.Dataset:
    """Every parameter along ``member``, the constant ones too: how files store them, so that runs of
    different constants combine under any xarray settings (a scalar that differs between files is
    kept from the first file under xarray's announced defaults, compat="override")."""
    return ds.assign({name: ds[name].broadcast_like(ds.member) for name in PARAMETER_NAMES
                      if name in ds and "member" not in ds[name].dims})


def collapse_constants(ds: xr.Dataset, varying) -> xr.Dataset:
    """Parameters not in ``varying`` become scalars (they must be constant along member). One
    assignment for all of them: one per parameter took ~7 ms each, 0.2 s a chunk file read, 20 s of
    the combine of a sweep of 100 chunks."""
    constant = {}
    for name in PARAMETER_NAMES:
        if name in ds and name not in varying and "member" in ds[name].dims:
            values = ds[name].values
            if values.size and np.all(values == values.reshape(-1)[0]):
                constant[name] = ds[name].isel(member=0, drop=True)
    return ds.assign(constant) if constant else ds.copy()


MAX_EMPTY_FRACTION = 0.5  # by_parameters: refused where more of the array than this would be empty


def by_parameters(ds: xr.Dataset, names=None) -> xr.Dataset:
    """The ensemble with its swept parameters as dimensions, to select and plot by them
    (``by_parameters(ds).mu_s.sel(normal_force=2000.0)``, ``.plot(...)``).

    names: the parameters to make dimensions (a name or a list), each a variable along ``member``;
           default the ensemble's swept ones (attribute ``varying_parameters``) that vary among its
           members (a selection may hold one value of some).
    A grid sweep becomes a full array (dims ``names`` then ``x``, ...); a combination that no member
    ran is NaN there (integer variables then turn float). The member numbers are kept as the
    variable ``member_number``. Variables not along ``member`` (the recorded fields) are unchanged.
    Raises ValueError, naming what to do, when two members share a combination of ``names``
    (unstacking would drop one), when a value is not finite, and when the members do not form a
    grid (random samples: more than MAX_EMPTY_FRACTION of the array would be empty; select them
    along ``member`` instead, e.g. ``ds.sel(member=ds.member[ds.normal_force > 2000])``).
    """
    if not isinstance(ds, xr.Dataset) or "member" not in ds.dims:
        got = type(ds).__name__ if not isinstance(ds, xr.Dataset) else f"a Dataset with dimensions {tuple(ds.dims)}"
        raise ValueError(f"by_parameters: expects the ensemble along the dimension member, got {got} (ds.isel(member=0) "
                         "drops the dimension; ds.isel(member=[0]) keeps it)")
    swept = ds.attrs.get("varying_parameters", "").split()
    if names is None:
        names = [n for n in swept if n in ds and ds[n].dims == ("member",) and np.unique(ds[n].values).size > 1]
    else:
        names = [names] if isinstance(names, str) else list(names)
    if not names:
        n = ds.sizes["member"]
        raise ValueError(f"by_parameters: no parameter varies among {'this member' if n == 1 else f'these {n} members'} "
                         f"(swept: {' '.join(swept) or 'none'}); valid: names of parameters that vary along member")
    bad = [n for n in names if n not in ds or ds[n].dims != ("member",)]
    if bad:
        along = sorted(n for n in PARAMETER_NAMES if n in ds and ds[n].dims == ("member",))
        raise ValueError(f"by_parameters: {', '.join(map(repr, bad))} not a variable along member; valid: "
                         f"{', '.join(along) or 'none (every parameter is constant)'}")
    swept_text = " ".join(swept) or "none"
    keys = np.stack([np.asarray(ds[n].values, dtype=np.float64) for n in names], axis=1)
    for n, values in zip(names, keys.T):
        units = ds[n].attrs.get("units", "")
        if not np.isfinite(values).all():
            where = np.flatnonzero(~np.isfinite(values))
            raise ValueError(f"by_parameters: {n!r} is not finite in {where.size} member(s) (numbers "
                             f"{', '.join(str(int(k)) for k in ds.member.values[where][:5])}); valid: finite values "
                             f"({units}); select the other members first")
        if ds.sizes["member"] > 1 and np.all(values == values[0]):
            raise ValueError(f"by_parameters: {n!r} is {values[0]:g} {units} in every member, so it cannot tell "
                             f"members apart; valid: parameters that vary (swept: {swept_text})")
    combos, counts = np.unique(keys, axis=0, return_counts=True)
    if (counts > 1).any():
        k = int(np.argmax(counts > 1))
        example = ", ".join(f"{n} = {v:g}" for n, v in zip(names, combos[k]))
        shared = int((counts > 1).sum())
        raise ValueError(f"by_parameters: {shared} combination{'s' if shared > 1 else ''} of {', '.join(names)} "
                         f"{'occur' if shared > 1 else 'occurs'} in more than one member (e.g. {example}: "
                         f"{int(counts[k])} members); valid: names that tell every member apart (swept: "
                         f"{swept_text}; or select members first)")
    cells = float(np.prod([np.unique(keys[:, k]).size for k in range(len(names))]))
    if 1.0 - ds.sizes["member"] / cells > MAX_EMPTY_FRACTION:
        raise ValueError(f"by_parameters: the {ds.sizes['member']} members are not a grid of {', '.join(names)}: "
                         f"as dimensions they would fill {ds.sizes['member']} of {cells:.3g} combinations; valid: a "
                         "grid sweep (random samples stay along member: select them with ds.sel(member=ds.member[...]))")
    # int32, as a file holds it (int64 in memory made the two differ)
    numbered = ds if "member_number" in ds else ds.assign(member_number=ds.member.astype(np.int32))
    if len(names) == 1:  # one name: a plain index, which unstack does not take
        return numbered.set_coords(names).swap_dims(member=names[0]).transpose(*names, ...)
    return numbered.set_coords(names).set_index(member=names).unstack("member").transpose(*names, ...)


def _in_process_locks():
    """A context in which xarray writes with an in-process lock. Inside a Dask worker xarray would take
    a distributed.Lock (a round trip to the scheduler per variable): that made each chunk's file 6x
    slower to write on a worker (0.24 s against 0.04 s, 60 members, CPU) and the worker ~10 % slower
    than a plain process on the H200s. The data are in memory, so no Dask scheduler is needed."""
    try:
        import dask
    except ImportError:
        return contextlib.nullcontext()
    return dask.config.set(scheduler="synchronous")


# the integer outputs of simulate and their types (a front event's nucleation_edge also prefixed):
# xarray's where() and by_parameters' padding turn them into floats, which a file must not keep
# (CF: flag_values of the variable's own type; the layout: integers are int32 or int8)
INTEGER_OUTPUTS = {"status": np.int32, "working_precision": np.int8, "lift_off": np.int8, "nucleation_edge": np.int8,
                   **{name: np.int32 for name in ("steps_accepted", "steps_rejected", "rejected_error_test",
                                                  "rejected_newton", "rejected_switch", "missed_predictions",
                                                  "newton_iterations", "gate_switches", "unlocated_switches")}}


def _integer_outputs_restored(ds: xr.Dataset) -> xr.Dataset:
    """``ds`` with its integer outputs (INTEGER_OUTPUTS) back in their types where an xarray operation
    made them floats of whole values (``ds.where(cond, drop=True)``); ValueError, naming the variable
    and what to do, where one holds NaN (a where() without drop masks members, by_parameters pads
    missing combinations): a file holds each member's status and counts, not gaps."""
    out = ds
    for name, var in ds.data_vars.items():
        kind = INTEGER_OUTPUTS.get(name) or (np.int8 if name.endswith("_nucleation_edge") else None)
        if kind is None or var.dtype.kind != "f":
            continue
        values = var.values
        missing = int((~np.isfinite(values)).sum())
        if missing:
            raise ValueError(f"write_ensemble: {name!r} is {var.dtype} with {missing} NaN values (masked members: an "
                             "xarray where() without drop=True, or by_parameters' padding); write the members "
                             "themselves: ds.sel(member=...) or ds.where(..., drop=True)")
        if (values != np.round(values)).any():
            raise ValueError(f"write_ensemble: {name!r} holds values that are not whole numbers (e.g. "
                             f"{values[values != np.round(values)].flat[0]:g}); it is a count or a flag: write it "
                             "as simulate gave it")
        out = out.assign({name: var.astype(kind)})
    return out


def write_ensemble(ds: xr.Dataset, path, *, varying=None, complevel: int = 4, command: str | None = None,
                   run_id: str | None = None, started: str | None = None, keep_interrupted: bool = False) -> Path:
    """Write ``ds`` (from :func:`warpfric.simulate`) to netCDF4 at ``path``, atomically; an existing
    file there is replaced (the command line asks for --overwrite first).

    varying:   names of the swept parameters (default: those that vary in ds,
               ``ds.attrs['varying_parameters']``), the file's ``varying_parameters``. Every
               parameter is stored along ``member``; :func:`open_ensemble` gives back the others,
               where constant, as scalars.
    complevel: zlib level (1..9) of every numeric variable.
    command:   what produced the file, for the ``history`` attribute (a line
               "<UTC time>: <command> (warpfric <version>)" put before any earlier history, where
               it is not there already).
    started:   that line's time, when the command started (from :func:`history_time`,
               "YYYY-MM-DDTHH:MM:SSZ"); None: now.
    run_id:    the id in the member labels (coordinate ``member`` of the file, ``<run id>:<number>``;
               the chunks of one sweep share it). None: the labels ``ds`` was read with
               (``member_id``), else a new id (:func:`new_run_id`).
    keep_interrupted: a Ctrl-C (or the command line's SIGTERM) during the write is held until the
               write ends (always); True: the whole file is then moved into place before
               KeyboardInterrupt is raised (a sweep's chunk, whose members then need not run again);
               False: ``path`` is left as it was (a combined file, whose chunks are still there).
    ``recorded_member`` must hold member numbers (values of ``member``). The file holds the members
    in the order of their numbers (a selection out of order is sorted).
    Raises OutputWriteError when the file cannot be written (its temporary file removed), and
    OutputBusy when another run holds the output's lock (``OUT.nc.lock``, :func:`lock_output`).
    """
    if not isinstance(ds, xr.Dataset) or "member" not in ds.dims:
        found = type(ds).__name__ if not isinstance(ds, xr.Dataset) else f"a Dataset with dimensions {tuple(ds.dims)}"
        back = (" (a by_parameters grid: write the ensemble it was made from)"
                if isinstance(ds, xr.Dataset) and "member_number" in ds else "")
        raise ValueError(f"write_ensemble: expects the ensemble's Dataset along the dimension member (from simulate or "
                         f"open_ensemble), got {found}{back}")
    import pandas as pd

    if isinstance(ds.indexes.get("member"), pd.MultiIndex):
        raise ValueError("write_ensemble: member is a MultiIndex (set_index or stack); write the ensemble with member "
                         "numbers: .reset_index('member')")
    if np.asarray(ds.member.values).dtype.kind in "USO":  # xr.open_dataset / open_mfdataset of a file
        raise ValueError("write_ensemble: the members are labels (the file's layout, as xr.open_dataset or "
                         "xr.open_mfdataset read it); read the files with warpfric.io.open_ensemble or open_ensembles "
                         "to write them again")
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"write_ensemble: path = {path!r} is invalid; valid: a file name (str or pathlib.Path)")
    if isinstance(complevel, bool) or not isinstance(complevel, (int, np.integer)) or not 1 <= complevel <= 9:
        raise ValueError(f"write_ensemble: complevel = {complevel!r} is invalid; valid: an integer in [1, 9] (zlib)")
    if started is not None and not re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", str(started)):
        raise ValueError(f"write_ensemble: started = {started!r} is invalid; valid: None (now) or a UTC time as "
                         "warpfric.io.history_time() gives it, 'YYYY-MM-DDTHH:MM:SSZ'")
    if np.any(np.diff(np.asarray(ds.member.values)) < 0):  # a file's labels are sorted (open_mfdataset needs it)
        ds = ds.sortby("member")
    path = Path(path)
    _require_folder(path)
    refuse_if_locked(path)
    ds = _integer_outputs_restored(ds)
    if varying is None:
        varying = ds.attrs.get("varying_parameters", "").split()
    broadcast = [name for name, var in ds.data_vars.items() if "recorded" in var.dims and "member" in var.dims]
    if broadcast:  # ds.where(...) does that: a file of them would hold each recorded field once per member
        raise ValueError(f"write_ensemble: {', '.join(broadcast[:3])}{', ...' if len(broadcast) > 3 else ''} lie along "
                         "both recorded and member: the recorded fields were broadcast over the members (ds.where(...) "
                         "does that); select members with ds.sel(member=ds.member[ds.status == 0]) instead")
    if "recorded_member" in ds.coords and not np.isin(ds.recorded_member.values, ds.member.values).all():
        kept = np.isin(ds.recorded_member.values, ds.member.values)
        keep = (f"keep the recorded members with the others, ds.isel(recorded={np.flatnonzero(kept).tolist()}), or "
                if kept.any() else "")
        raise ValueError(f"write_ensemble: recorded_member {ds.recorded_member.values.tolist()}: not among the member "
                         f"numbers {ds.member.values.min()}..{ds.member.values.max()} of the ensemble; {keep}drop the "
                         "recorded fields (ds.drop_dims(['recorded', 'time']))")
    out = parameters_along_member(ds)
    out.attrs["varying_parameters"] = " ".join(v for v in PARAMETER_NAMES if v in set(varying))
    out.attrs[COMPLETE_ATTR] = np.int8(1)
    line = history_line(command, started)  # the chunks of a sweep carry the line of the run that combines them
    earlier = [old for old in str(out.attrs.get("history", "")).splitlines() if old and old != line]
    out.attrs["history"] = "\n".join([line, *earlier])
    root, recorded = _to_file_layout(out, run_id)

    def write(tmp):
        with _in_process_locks():
            root.to_netcdf(tmp, format="NETCDF4", engine="netcdf4", encoding=_encoding(root, complevel))
            if recorded is not None:
                recorded.to_netcdf(tmp, mode="a", group=RECORDED_GROUP, format="NETCDF4", engine="netcdf4",
                                   encoding=_encoding(recorded, complevel))
        refuse_if_locked(path)  # again: a run may have started on this output during the write

    return replace_atomically(path, write, keep_interrupted=keep_interrupted)


def _require_folder(path: Path) -> None:
    """OutputWriteError where ``path``'s folder does not exist (HDF5 reports that as "Permission
    denied")."""
    if not path.parent.is_dir():
        raise OutputWriteError(f"could not write {str(path)!r}: folder {str(path.parent)!r} does not exist")


def sigterm_as_ctrl_c(signum, frame):
    """The command line's SIGTERM handler (warpfric.cli): SIGINT's Python handler of the moment where
    there is one (a netCDF write's hold, or Python's KeyboardInterrupt), else KeyboardInterrupt
    (SIGINT ignored, as in a job started with & from a script)."""
    handler = signal.getsignal(signal.SIGINT)
    (handler if callable(handler) else signal.default_int_handler)(signal.SIGINT, frame)


@contextlib.contextmanager
def sigint_held():
    """Ctrl-C (SIGINT), and SIGTERM where the command line turns it into one (sigterm_as_ctrl_c; a
    handler of the user's own is left alone), held back while the block runs; yields a list that
    holds True once one came. A netCDF write cannot be interrupted halfway: a KeyboardInterrupt
    inside xarray's file locks left one half taken, and the writer's own close then waited on it for
    ever (a Ctrl-C while a sweep wrote its combined file hung `warpfric run`); SALib's sampling
    (warpfric.sensitivity.generate) is held too, since scipy's compiled Sobol set-up swallows a
    KeyboardInterrupt raised inside it. SIGINT only where
    Python's own handler is in place; all in the main thread only; elsewhere the block runs as it is."""
    interrupted = []
    if threading.current_thread() is not threading.main_thread():
        yield interrupted
        return
    previous = {}

    def hold(signum, frame):
        interrupted.append(True)

    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, hold)
    if signal.getsignal(signal.SIGTERM) is sigterm_as_ctrl_c:
        previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, hold)
    try:
        yield interrupted
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def replace_atomically(path, write, suffix: str = "", keep_interrupted: bool = False) -> Path:
    """Write ``path`` through ``write(tmp)`` into a temporary file beside it, then move that over
    ``path``: a write that fails or is interrupted leaves ``path`` as it was and no temporary file.
    The temporary's name is ``PATH.<pid>.<hex>.tmp`` (a name of its own per writer: two writers of
    one chunk, a task run twice, never share a file; for an ensemble, remove_stale_temporaries
    finds those that killed writers left), with ``suffix`` after it where the writer needs one (a
    figure's ``.png``). A Ctrl-C during the write is held until the write ends (a netCDF write
    interrupted halfway could hang: sigint_held), then raised as KeyboardInterrupt, ``path`` as
    it was (``keep_interrupted``: the written file moved into place first). Raises
    OutputWriteError for an I/O error (a full disk, a folder that does not exist)."""
    path = Path(path)
    _require_folder(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp{suffix}")
    try:
        with sigint_held() as interrupted:
            write(tmp)
        if interrupted and not keep_interrupted:  # Ctrl-C during the write: raised now, the file not moved
            raise KeyboardInterrupt
        os.replace(tmp, path)
        if interrupted:  # the whole file kept (a chunk that then need not run again), then stopped
            raise KeyboardInterrupt
    except BaseException as err:  # a full disk, an I/O error, Ctrl-C: no temporary file stays behind
        free = free_bytes(path.parent)
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(err, (OSError, RuntimeError)):  # netCDF4 reports HDF5's failures as RuntimeError
            raise write_failure(path, err, free) from err
        raise
    return path


def _has_group(path, group: str) -> bool:
    import netCDF4

    with netCDF4.Dataset(path, "r") as nc:
        return group in nc.groups


def _read(path) -> xr.Dataset:
    """A netCDF file, loaded, in the in-memory layout; ValueError (one line) if it is not netCDF."""
    try:
        with xr.open_dataset(path, engine="netcdf4") as ds:
            ds = ds.load()
        if "member" not in ds.dims and ("warpfric_version" in ds.attrs or COMPLETE_ATTR in ds.attrs):
            # e.g. a by_parameters grid saved with to_netcdf: warpfric's attributes, no members
            dims = ", ".join(f"{name} ({size})" for name, size in ds.sizes.items()) or "none"
            raise _NotAnEnsemble(f"{path}: no dimension member (its dimensions: {dims}), so not an ensemble file as "
                                 "write_ensemble writes one; a by_parameters grid saved with to_netcdf opens with "
                                 "xr.open_dataset")
        recorded = None
        if _has_group(path, RECORDED_GROUP):
            with xr.open_dataset(path, engine="netcdf4", group=RECORDED_GROUP) as rec:
                recorded = rec.load()
        ds = collapse_constants(_from_file_layout(ds, recorded), set(ds.attrs.get("varying_parameters", "").split()))
        if "friction_stress_history" in ds and "friction_coefficient_history" not in ds:
            from .simulate import friction_coefficient_history  # a file of an earlier version: the same as a new one

            ds["friction_coefficient_history"] = friction_coefficient_history(ds)
        if "final_time" in ds and "detachment_end_time" not in ds:  # a file of an earlier version
            ds["detachment_end_time"] = xr.full_like(ds.final_time, np.nan, dtype=np.float64).assign_attrs(
                units="s", long_name="time at which the detachment was over: unknown (the file was written by a "
                "warpfric without this output, whose front outputs were given whatever ended the run)")
        return ds
    except _NotAnEnsemble:
        raise
    except (OSError, ValueError, RuntimeError) as err:
        reason = " ".join(str(err).split())
        raise ValueError(f"{path}: not a readable netCDF file ({reason})") from None


class _NotAnEnsemble(ValueError):
    """A readable netCDF file that is no ensemble (_read)."""


def resume_command(store, path) -> str:
    """The command that finishes an interrupted chunked run (chunk size and member offset come
    from the manifest), led by the copy that puts the run's sweep file back where the file has
    changed or gone since (--resume refuses another text; the run keeps its own in the parts)."""
    sweep_file = store.manifest.get("sweep_file", "SWEEP.toml")
    words = ["warpfric", "run", sweep_file, "-o", str(path), "--resume"]
    if store.manifest.get("device"):
        words += ["--device", store.manifest["device"]]
    kept = store.directory / SWEEP_COPY
    try:
        changed = kept.exists() and Path(sweep_file).read_text() != kept.read_text()
    except OSError:  # the sweep file gone (or unreadable)
        changed = kept.exists()
    put_back = f"cp {shlex.quote(str(kept))} {shlex.quote(sweep_file)} && " if changed else ""
    return put_back + shlex.join(words)


def open_ensemble(path) -> xr.Dataset:
    """Open a warpfric netCDF file (loaded into memory): simulate()'s layout, but for the parameters
    that do not vary in the file (not in its ``varying_parameters``), which come back as scalars
    (``parameters_along_member`` puts them along ``member`` again). Raises ValueError for a missing
    or incomplete file, naming what to do."""
    path = Path(path)
    parts = parts_dir(path)
    if not path.exists():
        if parts.exists():
            store = ChunkStore.load(parts)
            writer = running_writer(path)
            raise ValueError(
                f"{path}: incomplete run, {store.done_count()}/{store.n_chunks} chunks finished in {parts}; "
                + (f"its run is still going ({writer}): open it when that ends" if writer is not None else
                   f"`{resume_command(store, path)}` finishes it")
            )
        raise ValueError(f"{path}: no such file")
    if path.is_dir():
        raise ValueError(f"{path}: a folder, not a netCDF file")
    ds = _read(path)
    if "warpfric_version" not in ds.attrs and COMPLETE_ATTR not in ds.attrs:
        raise ValueError(f"{path}: a netCDF file, but not a warpfric ensemble (no attribute warpfric_version or "
                         f"{COMPLETE_ATTR}: another program wrote it)")
    if int(ds.attrs.get(COMPLETE_ATTR, 0)) != 1:
        raise ValueError(f"{path}: not a complete warpfric ensemble (attribute {COMPLETE_ATTR} missing)")
    return ds


def open_ensembles(paths, recorded: bool = True) -> xr.Dataset:
    """Open several complete warpfric files and concatenate them along ``member`` (recorded fields
    along ``recorded``). Raises ValueError when member numbers repeat (runs made without distinct
    ``--member-offset``), naming the files and the numbers, instead of mixing them up, and when the
    files are not one ensemble (:func:`concat_members`: settings, node counts or outputs differ).
    ``recorded=False`` leaves the recorded fields out: files recorded at different times (two
    sweeps' own detachment windows) combine then."""
    if isinstance(paths, (str, os.PathLike)):  # one path: iterated, a string gave its characters ("n: no such file")
        paths = [paths]
    paths = [Path(p) for p in paths]
    if not paths:
        raise ValueError("open_ensembles: no files given")
    first_named = {}
    for path in paths:  # one file twice: its members repeat, which read as a selection written apart
        same = first_named.setdefault(path.resolve(), path)
        if same is not path:
            raise ValueError(f"{path}: the same file is given twice ({same} and {path}); give each file once")
    datasets = [open_ensemble(p) for p in paths]
    if not recorded:
        datasets = [ds.drop_dims([d for d in ("recorded", "time") if d in ds.dims]) for ds in datasets]
    # in member order whatever order the files came in (["b.nc", "a.nc"] gave members 3 4 5 0 1 2: an
    # index that is not monotonic), with every file's history
    order = sorted(range(len(paths)), key=lambda i: int(np.min(datasets[i].member.values)))
    out = concat_members([datasets[i] for i in order], names=[str(paths[i]) for i in order])
    if not np.all(np.diff(out.member.values) > 0):  # files whose members interleave
        out = out.sortby("member")
    history = merged_history(datasets)
    if history:
        out.attrs["history"] = history
    return out


def merged_history(datasets) -> str:
    """The ``history`` lines of ``datasets`` ("<time>: <command>"), each once, latest first (the
    commands that wrote the parts of a combined file). A line's time is when its command started,
    so the chunks of one run share one line and two runs of the same command (an interrupted
    --resume and the one that finished) keep a line each."""
    lines = {line for ds in datasets for line in str(ds.attrs.get("history", "")).splitlines() if line}
    return "\n".join(sorted(lines, reverse=True))


def parts_dir(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + PARTS_SUFFIX)


def sweep_digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _summary_columns(nc) -> dict:
    """Of an open chunk (netCDF4): ``status`` (int64), its ``flag_meanings``, and ``disc_velocity``,
    ``lift_off`` and ``working_precision`` per member (float; NaN where a file lacks them: an edited
    one), for the warning of an interrupted run's members not ok (runner._warn_members_not_ok_kept)."""
    n = nc["status"].shape[0]
    columns = {"status": np.asarray(nc["status"][:], dtype=np.int64).reshape(-1),
               "flag_meanings": nc["status"].getncattr("flag_meanings")}
    for name in ("disc_velocity", "lift_off", "working_precision"):
        values = np.asarray(nc[name][:], dtype=float).reshape(-1) if name in nc.variables else np.nan
        columns[name] = np.broadcast_to(values, (n,))
    return columns


class ChunkStore:
    """Finished chunks of a chunked run: ``OUT.nc.parts/chunk-NNNNNN.nc`` and a manifest with the
    run's digest (sweep text, chunk size, member offset), the number of members and what
    ``--resume`` needs to continue the very same run (``chunk``, ``member_offset``, ``sweep_file``,
    ``device``: ``info`` holds them in ``self.manifest``)."""

    def __init__(self, directory: Path, digest: str, n_members: int, chunk: int, manifest: dict | None = None):
        self.directory = Path(directory)
        self.digest = digest
        self.n_members = int(n_members)
        self.chunk = int(chunk)
        self.n_chunks = -(-self.n_members // self.chunk)
        self.manifest = dict(manifest or {})
        self.member_offset = int(self.manifest.get("member_offset", 0))
        # chunks found done: {index: ((inode, size, mtime_ns) of the file then, its summary columns)}, so
        # that asking again (an interrupt counts, then keeps, then warns) does not open the file again
        self._done: dict = {}

    @classmethod
    def create(cls, directory, digest, n_members, chunk, **extra) -> "ChunkStore":
        """A new, empty store; ``extra`` (JSON values: member_offset, sweep_file, device) go into
        the manifest."""
        directory = Path(directory)
        if directory.exists():
            shutil.rmtree(directory)
        directory.mkdir(parents=True)
        manifest = {"digest": digest, "n_members": int(n_members), "chunk": int(chunk),
                    "n_chunks": -(-int(n_members) // int(chunk)), **extra}
        tmp = directory / (MANIFEST + ".tmp")
        tmp.write_text(json.dumps(manifest, indent=1))
        os.replace(tmp, directory / MANIFEST)
        return cls(directory, digest, n_members, chunk, manifest)

    @classmethod
    def load(cls, directory) -> "ChunkStore":
        directory = Path(directory)
        try:
            manifest = json.loads((directory / MANIFEST).read_text())
            return cls(directory, manifest["digest"], manifest["n_members"], manifest["chunk"], manifest)
        except (OSError, ValueError, KeyError, TypeError) as err:
            reason = os_error_reason(err) if isinstance(err, OSError) else f"{type(err).__name__}: {err}"
            kept = sorted(directory.glob("chunk-*.nc")) if directory.is_dir() else []
            one = len(kept) == 1
            what, them = (("its chunk file is a whole ensemble", "it") if one else
                          (f"its {len(kept)} chunk files are whole ensembles each", "them"))
            files = (f"; {what}, which warpfric.io.open_ensembles reads (copy {them} elsewhere first: --overwrite "
                     f"removes {them})" if kept else "")
            raise ValueError(f"{directory}: unreadable chunk manifest ({reason}); nothing can be resumed from it: "
                             f"--overwrite starts the run again{files}") from None

    def chunk_path(self, index: int) -> Path:
        return self.directory / f"chunk-{index:06d}.nc"

    def members(self, index: int) -> slice:
        """Indices (within the sweep) of the members of chunk ``index``; their member numbers are
        ``member_offset`` + these."""
        return slice(index * self.chunk, min((index + 1) * self.chunk, self.n_members))

    def is_done(self, index: int) -> bool:
        path = self.chunk_path(index)
        try:
            stat = path.stat()
        except OSError:
            self._done.pop(index, None)
            return False
        signature = (stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)  # ctime: not settable
        if index in self._done and self._done[index][0] == signature:
            return True
        self._done.pop(index, None)
        sl = self.members(index)
        run_id = self.manifest.get("run_id")
        try:  # netCDF4 directly: xarray's open takes ~2.5x as long, and info, --resume and an interrupt
            # ask every chunk (400 chunks: 4.0 -> 1.6 s on this project's CPU)
            import netCDF4

            with netCDF4.Dataset(path) as nc:
                if int(getattr(nc, COMPLETE_ATTR, 0)) != 1:
                    return False
                labelled = MEMBER_NUMBER in nc.variables
                numbers = np.ma.filled(np.ma.asarray(nc[MEMBER_NUMBER if labelled else "member"][:], dtype=float),
                                       np.nan)  # a fill value is no member number
                labels = np.asarray(nc["member"][:]) if labelled else None
                if labels is not None and labels.dtype.kind == "S" and labels.ndim == 2:  # chars without _Encoding
                    labels = netCDF4.chartostring(labels)
                # a chunk of this run (its id in the member labels), not one that a cluster's worker of
                # an earlier, interrupted run wrote after that run had ended
                own = run_id is None or not labelled or np.array_equal(
                    labels.astype(str), member_labels(run_id, numbers.astype(np.int64)))
                done = own and np.array_equal(numbers, np.arange(sl.start, sl.stop) + self.member_offset)
                if done:
                    self._done[index] = (signature, _summary_columns(nc))
                return done
        except Exception:  # noqa: BLE001 - a damaged chunk is simply redone
            return False

    def summary_columns(self, index: int) -> dict:
        """A finished chunk's status (with its flag meanings), disc_velocity, lift_off and
        working_precision per member (:func:`_summary_columns`), from the reading of ``is_done`` where
        the file is unchanged."""
        if not self.is_done(index):
            raise ValueError(f"{self.chunk_path(index)}: not a finished chunk of this run")
        return self._done[index][1]

    def done_count(self) -> int:
        return sum(self.is_done(i) for i in range(self.n_chunks))

    def combine(self, path, command: str | None = None, on_combined=None, started: str | None = None) -> Path:
        """Concatenate the chunks along member into ``path`` (atomically) and remove the parts;
        ``on_combined(ds)`` is called with the combined Dataset once it is written (the run's warnings)."""
        datasets = [_read(self.chunk_path(i)) for i in range(self.n_chunks)]
        try:
            combined = concat_members(datasets, names=[self.chunk_path(i).name for i in range(self.n_chunks)])
        except ValueError as err:  # nothing written or removed yet
            raise ChunksDoNotCombine(str(err)) from None
        combined.attrs.pop("chunk_index", None)
        # the commands that wrote the chunks (an interrupted run's and its --resume), latest first,
        # under the line of the command that combines them (write_ensemble)
        history = merged_history(datasets)
        if history:
            combined.attrs["history"] = history
        else:
            combined.attrs.pop("history", None)
        combined.attrs["chunks"] = self.n_chunks
        write_ensemble(combined, path, command=command, run_id=self.manifest.get("run_id"), started=started)
        shutil.rmtree(self.directory)
        if on_combined is not None:
            on_combined(combined)
        return Path(path)


def duplicate_members(datasets, names=None) -> str:
    """'' when the member numbers of ``datasets`` are distinct, else a sentence naming the
    repeated numbers and the datasets (``names``) that share them."""
    names = names or [f"dataset {i}" for i in range(len(datasets))]
    numbers = np.concatenate([np.asarray(ds.member.values) for ds in datasets])
    values, counts = np.unique(numbers, return_counts=True)
    repeated = values[counts > 1]
    if not repeated.size:
        return ""
    where = [n for n, ds in zip(names, datasets) if np.isin(ds.member.values, repeated).any()]
    shown = ", ".join(map(str, repeated[:5].tolist())) + (f", ... ({repeated.size} in all)" if repeated.size > 5 else "")
    labelled = all(MEMBER_ID in ds.coords for ds in datasets)
    labels = np.concatenate([np.asarray(ds[MEMBER_ID].values).astype(str) for ds in datasets]) if labelled else None
    if labels is not None and np.unique(labels).size < labels.size:  # e.g. a selection written from the same run
        return (f"member numbers {shown} occur more than once (in {', '.join(where)}), with the same member labels: "
                "the same members of one run (a selection of it written to a file of its own?); combine files of "
                "different members")
    return (f"member numbers {shown} occur more than once (in {', '.join(where)}); give separate runs distinct "
            "numbers with `warpfric run --member-offset K` (or [run] member_offset, or simulate(member_offset=K)), "
            "or open these files with xr.open_mfdataset(files), which keeps them apart by their member labels")


def _plain(value):
    """A netCDF attribute's value as a reader writes it: 24, not np.int32(24)."""
    return value.item() if isinstance(value, np.generic) else value


def _check_settings(datasets, names) -> None:
    """ValueError unless every dataset has the first's model, solver and front settings: the union
    of their model_/solver_/fronts_ attributes, so that a setting one lacks (a run without fronts has
    no fronts_* attributes) is a difference too."""
    prefixes = ("model_", "solver_", "fronts_")
    keys = list(dict.fromkeys(k for ds in datasets for k in ds.attrs if k.startswith(prefixes)))
    first = datasets[0]
    missing = object()
    for key in keys:
        value = first.attrs.get(key, missing)
        for name, ds in zip(names[1:], datasets[1:]):
            other = ds.attrs.get(key, missing)
            if (value is missing) != (other is missing) or (value is not missing and not _same_attr(value, other)):
                def shown(v):
                    return "not set" if v is missing else repr(_plain(v))
                why = (" (a run without fronts, fronts = false, has no fronts_* settings and no front outputs)"
                       if key.startswith("fronts_") and (value is missing or other is missing) else "")
                raise ValueError(f"{names[0]} and {name} differ in {key} ({shown(value)}, {shown(other)}): "
                                 f"not one ensemble{why}")


def _same_attr(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return np.array_equal(np.asarray(a), np.asarray(b))
    return bool(a == b)


def _check_variables(parts, what: str) -> None:
    """ValueError unless every dataset of ``parts`` (name, variable names) holds the first's
    variables: one that lacks some (written with [run] final_fields = false, another version)
    would otherwise lose them from the combined ensemble or fail inside xarray."""
    (first_name, first_vars), rest = parts[0], parts[1:]
    for name, variables in rest:
        only_first = [v for v in first_vars if v not in variables]
        only_other = [v for v in variables if v not in first_vars]
        if only_first or only_other:
            def listed(vs):
                return ", ".join(vs[:6]) + (f", ... ({len(vs)} in all)" if len(vs) > 6 else "")
            said = [f"{a} has {listed(vs)}, which {b} lacks" for a, b, vs in
                    ((first_name, name, only_first), (name, first_name, only_other)) if vs]
            raise ValueError(f"{first_name} and {name} hold different {what} ({'; '.join(said)}): not one "
                             "ensemble (runs with other outputs, e.g. [run] final_fields = false); drop them "
                             "from the one that has them (ds.drop_vars) to combine the rest")


def ensemble_x(datasets, names) -> xr.DataArray | None:
    """The x coordinate of ``datasets`` combined, as simulate() gives it for all their members run
    together (:func:`warpfric.simulate._x_coordinate` of their lengths: positions in m where every
    member has the same length, else positions / length); None where no dataset has an x dim.
    ValueError where their node counts differ (naming two of them)."""
    with_x = [(name, ds) for name, ds in zip(names, datasets) if "x" in ds.dims]
    if not with_x:
        return None
    first_name, first = with_x[0]
    for name, ds in with_x[1:]:
        if ds.sizes["x"] != first.sizes["x"]:
            raise ValueError(f"{first_name} and {name} have different node counts ({first.sizes['x']} and "
                             f"{ds.sizes['x']} nodes along x): not one ensemble")
    if all("length" in ds for ds in datasets):
        from .simulate import _x_coordinate

        length = np.concatenate([np.broadcast_to(np.asarray(ds["length"].values, dtype=float), (ds.sizes["member"],))
                                 for ds in datasets])
        return _x_coordinate(length, first.sizes["x"])
    for name, ds in with_x[1:]:  # no lengths to build it from: every part must have the same x
        if not np.array_equal(ds.x.values, first.x.values) or ds.x.attrs.get("units") != first.x.attrs.get("units"):
            raise ValueError(f"{first_name} and {name} have different x coordinates and no parameter length to "
                             "build the combined one from: not one ensemble")
    return xr.DataArray(first.x.values, dims=("x",), attrs=dict(first.x.attrs))


# how a part was run (simulate's attributes): a combination of parts that differ in one gives all
HOW_RUN_ATTRS = ("device", "lanes", "team_exchange", "block_members", "work_memory", "member_order",
                 "integration_passes", "device_bytes_per_member")


def concat_members(datasets, names=None) -> xr.Dataset:
    """Concatenate ensembles (in-memory layout) along member: variables with a member dim are
    concatenated, recorded fields along ``recorded``; a parameter that is a scalar in one and
    differs or varies in another becomes a variable along member. The x coordinate is the one
    simulate() gives all the members run together (:func:`ensemble_x`: m where they share one
    length, else x / length), never the parts' own axes joined. Refuses repeated member numbers,
    different model/solver/front settings (a setting that one has and another lacks too), different
    node counts and different sets of output variables (ValueError). Global attributes of the first,
    but those of HOW_RUN_ATTRS where the parts differ ("mixed: cpu, cuda:0"); wall_time_s and
    kernel_build_time_s summed."""
    names = names or [f"dataset {i}" for i in range(len(datasets))]
    message = duplicate_members(datasets, names)
    if message:
        raise ValueError(message)
    _check_settings(datasets, names)
    varying = set()
    for ds in datasets:
        varying |= set(ds.attrs.get("varying_parameters", "").split())
    along_member = set()
    for pname in PARAMETER_NAMES:
        present = [ds[pname] for ds in datasets if pname in ds]
        if present and np.unique(np.concatenate([np.ravel(v.values) for v in present])).size > 1:
            varying.add(pname)
        if present and (pname in varying or any("member" in v.dims for v in present)):
            along_member.add(pname)
    datasets = [ds.assign({p: ds[p].broadcast_like(ds.member) for p in along_member
                           if p in ds and "member" not in ds[p].dims}) for ds in datasets]
    if not all(MEMBER_ID in ds.coords for ds in datasets):  # labels only where every part has them
        datasets = [ds.drop_vars(MEMBER_ID, errors="ignore") for ds in datasets]
    # every part holds the same outputs (the recorded fields: where a part has recorded members)
    _check_variables([(name, [v for v in ds.data_vars if "recorded" not in ds[v].dims])
                      for name, ds in zip(names, datasets)], "outputs")
    x = ensemble_x(datasets, names)
    if x is not None:  # each part's own x (m of its one length, or x / L) gives way to the ensemble's
        datasets = [ds.assign_coords(x=x) for ds in datasets]
    first = datasets[0]
    member_vars = [v for v in first.data_vars if "member" in first[v].dims]
    parts = [ds[member_vars] for ds in datasets]
    out = xr.concat(parts, dim="member", data_vars="all", coords="minimal", compat="override", join="exact")
    for name, var in first.data_vars.items():
        if "member" in var.dims or "recorded" in var.dims:
            continue
        for other, ds in zip(names[1:], datasets[1:]):
            if name in ds and not var.equals(ds[name]):
                raise ValueError(f"{names[0]} and {other} differ in {name}: not one ensemble")
        out[name] = var
    recorded = [(name, ds) for name, ds in zip(names, datasets) if "recorded" in ds.dims]
    for name, ds in recorded[1:]:
        times, first_times = ds.time.values, recorded[0][1].time.values
        if times.shape != first_times.shape or not np.array_equal(times, first_times):
            raise ValueError(f"{recorded[0][0]} and {name} recorded their fields at different times ({first_times.size} "
                             f"and {times.size} times in [{first_times.min():g}, {first_times.max():g}] and "
                             f"[{times.min():g}, {times.max():g}] s): open_ensembles needs one recording grid; "
                             "open_ensembles(files, recorded=False) combines the rest, and xr.open_mfdataset(files, "
                             "group='recorded') the recorded groups (times joined)")
    if recorded:
        _check_variables([(name, [v for v in ds.data_vars if "recorded" in ds[v].dims]) for name, ds in recorded],
                         "recorded fields")
    recorded = [ds for _, ds in recorded]
    if recorded:
        rec_vars = [v for v in recorded[0].data_vars if "recorded" in recorded[0][v].dims]
        rec = xr.concat([ds[rec_vars] for ds in recorded], dim="recorded", data_vars="all", coords="different",
                        compat="equals", join="exact")
        out = out.merge(rec)
    for name in [v for v in out.data_vars if v.endswith("nucleation_edge")]:  # the widest flags of the parts: a
        # file of an earlier version has no -3 (unknown), which a newer part may hold
        widest = max((ds[name].attrs for ds in datasets if name in ds), key=lambda a: len(a.get("flag_values", ())))
        out[name].attrs = dict(widest)
    out.attrs = dict(first.attrs)
    for key in HOW_RUN_ATTRS:  # where the parts ran differently (a --resume on another device): all of them
        values = list(dict.fromkeys(str(ds.attrs[key]) for ds in datasets if key in ds.attrs))
        if len(values) > 1:
            out.attrs[key] = "mixed: " + ", ".join(values)
    out.attrs["varying_parameters"] = " ".join(p for p in PARAMETER_NAMES if p in varying)
    for key in ("wall_time_s", "kernel_build_time_s"):
        out.attrs[key] = float(sum(float(ds.attrs.get(key, 0.0)) for ds in datasets))
    if any("workers" in ds.attrs for ds in datasets):  # worker processes of the parts (pool.py): theirs, not the first's
        out.attrs["workers"] = max(int(ds.attrs.get("workers", 1)) for ds in datasets)
        out.attrs["worker_chunks"] = sum(int(ds.attrs.get("worker_chunks", 1)) for ds in datasets)
        out.attrs["worker_start_time_s"] = float(sum(float(ds.attrs.get("worker_start_time_s", 0.0)) for ds in datasets))
    return out
