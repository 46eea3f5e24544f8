"""warpfric.plots: quick-look figures of an ensemble (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _axis_scale(values: np.ndarray) -> str:
    v = values[np.isfinite(values)]
    return "log" if v.size and v.min() > 0 and v.max() / v.min() > 100 else "linear"


def _label(ds, name: str) -> str:
    units = ds[name].attrs.get("units", "")
    return f"{name} ({units})" if units and units != "1" else name


def quick_look(ds, outdir, max_curves: int = 12) -> list:
    """Write PNGs into ``outdir``: mu_s and front speeds against each swept parameter, arrival-time
    curves, and the space-time map of every recorded member. Returns the paths written."""
    plt = _plt()
    outdir = Path(outdir)
    written = []
    swept = ds.attrs.get("varying_parameters", "").split()
    ok = ds.status.values == 0
    for pname in swept:
        x = np.broadcast_to(ds[pname].values, ok.shape)
        fig, ax = plt.subplots(figsize=(5, 3.6))
        ax.plot(x[ok], ds.mu_s.values[ok], ".", ms=4)
        ax.set_xscale(_axis_scale(x))
        ax.set_xlabel(_label(ds, pname))
        ax.set_ylabel("mu_s")
        ax.set_title(f"static friction coefficient ({ok.sum()} ok members)")
        fig.tight_layout()
        written.append(outdir / f"mu_s_vs_{pname}.png")
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)
        if "v_middle" in ds:
            fig, ax = plt.subplots(figsize=(5, 3.6))
            for seg, marker in (("left", "v"), ("middle", "o"), ("right", "^")):
                v = ds[f"v_{seg}"].values
                sel = ok & np.isfinite(v)
                ax.plot(x[sel], v[sel], marker, ms=3, ls="none", label=f"v_{seg} ({sel.sum()})")
            ax.set_xscale(_axis_scale(x))
            ax.set_yscale("log")
            ax.set_xlabel(_label(ds, pname))
            ax.set_ylabel("front speed (m/s)")
            ax.legend(fontsize=8)
            fig.tight_layout()
            written.append(outdir / f"front_speeds_vs_{pname}.png")
            fig.savefig(written[-1], dpi=120)
            plt.close(fig)
    if not swept and ds.sizes["member"] > 1:
        fig, ax = plt.subplots(figsize=(5, 3.6))
        ax.hist(ds.mu_s.values[ok & np.isfinite(ds.mu_s.values)], bins=40)
        ax.set_xlabel("mu_s")
        ax.set_ylabel("members")
        fig.tight_layout()
        written.append(outdir / "mu_s_histogram.png")
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)
    if "arrival_time" in ds:
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        members = np.flatnonzero(ok)[: max_curves]
        for m in members:
            ta = ds.arrival_time.values[m]
            x = ds.x.values * (1e3 if ds.x.attrs.get("units") == "m" else 1.0)
            ax.plot(x, (ta - np.nanmin(ta)) * 1e3 if np.isfinite(ta).any() else ta, lw=1, label=f"member {int(ds.member[m])}")
        ax.set_xlabel("x (mm)" if ds.x.attrs.get("units") == "m" else "x / L")
        ax.set_ylabel("t_a - first arrival (ms)")
        ax.set_title("detachment front arrival times")
        if len(members) <= 8:
            ax.legend(fontsize=7)
        fig.tight_layout()
        written.append(outdir / "arrival_times.png")
        fig.savefig(written[-1], dpi=120)
        plt.close(fig)
    if "velocity_history" in ds:
        for r, member in enumerate(ds.recorded_member.values):
            written.append(space_time_map(ds, r, outdir / f"space_time_member{int(member)}.png"))
    return written


def space_time_map(ds, recorded_index: int, path) -> Path:
    """Pad velocity over (x, t) of one recorded member, with the front's threshold contour when the
    dataset has front metrics (the paper's Fig. 3 style)."""
    plt = _plt()
    member = int(ds.recorded_member.values[recorded_index])
    v = ds.velocity_history.values[recorded_index]
    t = ds.time.values
    x = ds.x.values * (1e3 if ds.x.attrs.get("units") == "m" else 1.0)
    fig, ax = plt.subplots(figsize=(6, 4))
    scale = np.nanmax(np.abs(v)) or 1.0
    mesh = ax.pcolormesh(x, t, v * 1e9, cmap="RdBu_r", vmin=-scale * 1e9, vmax=scale * 1e9, shading="nearest")
    fig.colorbar(mesh, ax=ax, label="pad velocity (nm/s)")
    if "event_max_velocity" in ds and np.isfinite(float(ds.event_max_velocity[member])):
        sign = -np.sign(float(ds.disc_velocity[member] if ds.disc_velocity.ndim else ds.disc_velocity))
        level = float(ds.attrs.get("fronts_threshold", 0.4)) * float(ds.event_max_velocity[member])
        if ds.attrs.get("fronts_direction", "against_disc") == "against_disc" and np.nanmax(sign * v) >= level:
            ax.contour(x, t, sign * v, levels=[level], colors="k", linewidths=1)
        ta = ds.arrival_time.values[member]
        ax.plot(x, ta, "k:", lw=1, label="arrival time t_a")
        ax.legend(fontsize=7, loc="upper right")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("t (s)")
    ax.set_title(f"member {member}: pad velocity")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return Path(path)
