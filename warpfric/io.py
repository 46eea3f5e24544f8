"""warpfric.io: ensembles as netCDF files for xarray (CF attributes, compression, chunked runs).

A file holds dims ``member`` and ``x`` (and ``recorded``, ``time`` for recorded fields). Every
input parameter is a variable: along ``member`` where it varies in the run (or in the sweep the
file is a chunk of), a scalar where it does not. Outputs carry CF ``units`` and ``long_name``;
the model switches, solver and front settings, package and Warp versions and the device are
global attributes. Files from several runs or chunks combine with
``xr.open_mfdataset(files, combine="nested", concat_dim="member")`` (needs dask).

Completeness: a file written by :func:`write_ensemble` has the global attribute
``warpfric_complete = 1`` and is written under a temporary name and renamed, so a killed run never
leaves a file that looks complete. A chunked run (:class:`ChunkStore`) keeps its finished chunks
in ``OUT.nc.parts/`` until all are done, then combines them into ``OUT.nc``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import xarray as xr

from .parameters import PARAMETER_NAMES

COMPLETE_ATTR = "warpfric_complete"
PARTS_SUFFIX = ".parts"
MANIFEST = "manifest.json"


def _encoding(ds: xr.Dataset, complevel: int) -> dict:
    enc = {}
    for name, var in ds.variables.items():
        if var.ndim == 0 or var.dtype.kind not in "biuf":
            continue
        enc[name] = {"zlib": True, "complevel": complevel, "shuffle": True}
    return enc


def collapse_constants(ds: xr.Dataset, varying) -> xr.Dataset:
    """Parameters not in ``varying`` become scalars (they must be constant along member)."""
    out = ds.copy()
    for name in PARAMETER_NAMES:
        if name in out and name not in varying and "member" in out[name].dims:
            values = out[name].values
            if values.size and np.all(values == values.reshape(-1)[0]):
                out[name] = out[name].isel(member=0, drop=True)
    return out


def write_ensemble(ds: xr.Dataset, path, *, varying=None, complevel: int = 4) -> Path:
    """Write ``ds`` (from :func:`warpfric.simulate`) to netCDF4 at ``path``, atomically.

    varying:   names of the parameters to keep along ``member`` (default: those that vary in ds,
               ``ds.attrs['varying_parameters']``); the others are stored as scalars.
    complevel: zlib level (1..9) of every numeric variable.
    """
    path = Path(path)
    if varying is None:
        varying = ds.attrs.get("varying_parameters", "").split()
    out = collapse_constants(ds, set(varying))
    out.attrs["varying_parameters"] = " ".join(v for v in PARAMETER_NAMES if v in set(varying))
    out.attrs[COMPLETE_ATTR] = np.int8(1)
    tmp = path.with_name(path.name + ".tmp")
    out.to_netcdf(tmp, format="NETCDF4", engine="netcdf4", encoding=_encoding(out, complevel))
    os.replace(tmp, path)
    return path


def open_ensemble(path) -> xr.Dataset:
    """Open a warpfric netCDF file (loaded into memory). Raises ValueError for a missing or
    incomplete file, naming what to do."""
    path = Path(path)
    parts = parts_dir(path)
    if not path.exists():
        if parts.exists():
            store = ChunkStore.load(parts)
            raise ValueError(
                f"{path}: incomplete run, {store.done_count()}/{store.n_chunks} chunks finished in {parts}; "
                "run the same command again with --resume"
            )
        raise ValueError(f"{path}: no such file")
    with xr.open_dataset(path, engine="netcdf4") as ds:
        ds = ds.load()
    if int(ds.attrs.get(COMPLETE_ATTR, 0)) != 1:
        raise ValueError(f"{path}: not a complete warpfric ensemble (attribute {COMPLETE_ATTR} missing)")
    return ds


def parts_dir(path) -> Path:
    path = Path(path)
    return path.with_name(path.name + PARTS_SUFFIX)


def sweep_digest(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class ChunkStore:
    """Finished chunks of a chunked run: ``OUT.nc.parts/chunk-NNNNNN.nc`` and a manifest with the
    run's digest (sweep text, chunk size, number of members), so that --resume only continues the
    very same run."""

    def __init__(self, directory: Path, digest: str, n_members: int, chunk: int):
        self.directory = Path(directory)
        self.digest = digest
        self.n_members = int(n_members)
        self.chunk = int(chunk)
        self.n_chunks = -(-self.n_members // self.chunk)

    @classmethod
    def create(cls, directory, digest, n_members, chunk) -> "ChunkStore":
        directory = Path(directory)
        if directory.exists():
            shutil.rmtree(directory)
        directory.mkdir(parents=True)
        store = cls(directory, digest, n_members, chunk)
        manifest = {"digest": digest, "n_members": store.n_members, "chunk": store.chunk, "n_chunks": store.n_chunks}
        tmp = directory / (MANIFEST + ".tmp")
        tmp.write_text(json.dumps(manifest, indent=1))
        os.replace(tmp, directory / MANIFEST)
        return store

    @classmethod
    def load(cls, directory) -> "ChunkStore":
        directory = Path(directory)
        try:
            manifest = json.loads((directory / MANIFEST).read_text())
        except (OSError, ValueError) as err:
            raise ValueError(f"{directory}: unreadable chunk manifest ({err})") from None
        return cls(directory, manifest["digest"], manifest["n_members"], manifest["chunk"])

    def chunk_path(self, index: int) -> Path:
        return self.directory / f"chunk-{index:06d}.nc"

    def members(self, index: int) -> slice:
        return slice(index * self.chunk, min((index + 1) * self.chunk, self.n_members))

    def is_done(self, index: int) -> bool:
        path = self.chunk_path(index)
        if not path.exists():
            return False
        try:
            with xr.open_dataset(path, engine="netcdf4") as ds:
                return int(ds.attrs.get(COMPLETE_ATTR, 0)) == 1 and ds.sizes["member"] == len(range(self.n_members)[self.members(index)])
        except Exception:  # noqa: BLE001 - a damaged chunk is simply redone
            return False

    def done_count(self) -> int:
        return sum(self.is_done(i) for i in range(self.n_chunks))

    def combine(self, path) -> Path:
        """Concatenate the chunks along member into ``path`` (atomically) and remove the parts."""
        datasets = []
        for i in range(self.n_chunks):
            with xr.open_dataset(self.chunk_path(i), engine="netcdf4") as ds:
                datasets.append(ds.load())
        combined = concat_members(datasets)
        combined.attrs[COMPLETE_ATTR] = np.int8(1)
        combined.attrs["chunks"] = self.n_chunks
        tmp = Path(path).with_name(Path(path).name + ".tmp")
        combined.to_netcdf(tmp, format="NETCDF4", engine="netcdf4", encoding=_encoding(combined, 4))
        os.replace(tmp, path)
        shutil.rmtree(self.directory)
        return Path(path)


def concat_members(datasets) -> xr.Dataset:
    """Concatenate ensembles along member: variables with a member dim are concatenated,
    recorded fields along ``recorded``, scalars must agree. Global attributes of the first;
    wall_time_s summed."""
    first = datasets[0]
    member_vars = [v for v in first.data_vars if "member" in first[v].dims]
    parts = [ds[member_vars] for ds in datasets]
    out = xr.concat(parts, dim="member", data_vars="all", coords="minimal", compat="override", join="outer")
    for name, var in first.data_vars.items():
        if "member" in var.dims or "recorded" in var.dims:
            continue
        out[name] = var
    recorded = [ds for ds in datasets if "recorded" in ds.dims]
    if recorded:
        rec_vars = [v for v in recorded[0].data_vars if "recorded" in recorded[0][v].dims]
        rec = xr.concat([ds[rec_vars] for ds in recorded], dim="recorded", data_vars="all", coords="different",
                        compat="equals", join="exact")
        out = out.merge(rec)
    out.attrs = dict(first.attrs)
    out.attrs["wall_time_s"] = float(sum(float(ds.attrs.get("wall_time_s", 0.0)) for ds in datasets))
    return out
