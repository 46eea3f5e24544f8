"""Studies: the paper's Figures 3-14, the open model choices, and ensembles beyond the paper.

    python studies/figures.py NAME [--quick] [--device cpu|cuda:0] [--outdir DIR]
                              [--relaxation-gate stress|none|velocity] [--front-event contact|strength|velocity]
    python studies/figures.py all --quick --device cpu --outdir /tmp/figures

NAME: fig3 fig4 fig5 fig10 fig11 fig12 choices map uncertainty (Figs. 6, 7 come with fig4, Figs.
8, 9 with fig5, Figs. 13, 14 with fig10). Each writes NAME[_quick].nc (the ensemble, warpfric.io format),
NAME[_quick].png and NAME[_quick].json (the numbers studies/README.md quotes, and that
tests/test_studies.py checks) into --outdir (default ./warpfric_studies; the committed outputs that
studies/README.md quotes are in studies/figures: --outdir studies/figures remakes them). --quick:
sizes for a 2-core CPU (seconds to a minute each); the full size is for the GPU. --relaxation-gate:
the friction law's yield gate (wf.Model(relaxation_gate=...), SPEC section 5; default "stress", the
GRL 2012 law); "none" (SPEC v1) writes NAME_nogate[_quick].*, "velocity" NAME_velgate[_quick].*;
--front-event other than the law's default adds _velocityfront, _strengthfront or _contactfront.
Figure by study: fig3 Fig. 3; fig4 Figs. 4, 6, 7; fig5 Figs. 5, 8, 9; fig10 Figs. 10, 13, 14; fig11
Fig. 11; fig12 Fig. 12. Units: SI in the .json and .nc files (positions m, speeds m/s, times s).

End of a run: every study uses the engine's automatic end (wf.Parameters(end_time=None), docs/model.md
"End of a run": a member stops once mu has passed its peak by 1 % and the front is over, at 80 s at
the latest), so every member that ends ok has reached its mu_s peak by construction, at every disc
velocity. Only fig3 and fig11 keep an explicit end_time, because they record the pad velocity on a
fixed time grid (Record.window) that must lie inside every recorded run; fig3's grid spans the
contact front (20.126-20.136 s at e = 0), the mu_s peak and the velocity rule's event. peak_check() counts the
members per status (no_peak, stalled, ... ) and the ok members whose mu_s_time is not before their
final_time (0 by construction) in claims["peak_check"].

Straggler rule: the engine's stall_factor (default 10) stays on except in the studies that
deliberately mix in members that are legitimately far more expensive than their peers: fig10 and
fig12 hold viscous_coefficient = 0 members, which under the stress gate are a dynamic rupture (many
more steps than the strengthening members), and the map's slowest disc velocity makes members ~10x
as expensive as its median one; those three run with stall_factor = inf.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

import warpfric as wf
from warpfric.io import write_ensemble

SHEAR_WAVE_SPEED = float(np.sqrt(wf.Parameters().shear_modulus / wf.Parameters().density))  # m/s
GATE_SUFFIX = {"stress": "", "none": "_nogate", "velocity": "_velgate"}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# members that end no_peak by design: fig11's stopped discs stop before their mu_s peak (docs/model.md,
# "Statuses"), so the largest mu each sees, at the stop, is no mu_s
EXPECTED_NO_PEAK = {"fig11": 2}


def peak_check(ds) -> dict:
    """Members per status, and the ok members whose mu_s peak is not inside the run (mu_s_time >=
    final_time; the engine gives those status no_peak, so 0 is expected)."""
    meanings = str(ds.status.attrs.get("flag_meanings", "ok")).split()
    status = ds.status.values
    ok = status == 0
    late = ok & ~(ds.mu_s_time.values < ds.final_time.values - 1e-9)
    counts = {meanings[k] if k < len(meanings) else str(k): int((status == k).sum()) for k in np.unique(status)}
    no_peak = int((status == meanings.index("no_peak")).sum()) if "no_peak" in meanings else 0
    return dict(members_without_peak=int(late.sum()) + no_peak, failed_members=int((~ok).sum()),
                status_counts=counts, max_final_time=float(np.nanmax(ds.final_time.values)))


# The detachment front the figures read (--front-event): the contact front under the stress gate
# (the engine's default, each node's stick-to-slip transition); the gate-less laws have no contact
# front, so their figures read the velocity front (the paper's 40 % rule). Another event writes
# NAME[_gate]_<event>front[_quick].*: the velocity front's figures of the stress gate
# (*_velocityfront*) are the numbers of the releases before the contact front.
FRONT_EVENT = {"stress": "contact", "none": "velocity", "velocity": "velocity"}
_front = {"event": "contact", "direction": "against_disc"}


def figure_fronts(direction: str | None = None) -> wf.Fronts:
    return wf.Fronts(event=_front["event"], direction=direction or _front["direction"])


def simulate(members, quick, device, scene=None, record=None, nodes=None, model=None, **solver_kw):
    scene = scene or wf.Parameters()  # end_time=None: the engine's automatic end (module docstring)
    solver = wf.Solver(nodes=nodes or (100 if quick else 200), rtol=1e-5, **solver_kw)
    return wf.simulate(members, scene=scene, model=model or wf.Model(), solver=solver, fronts=figure_fronts(),
                       record=record, device=device, progress=sys.stderr.isatty())


def linfit(x, y):
    """Slope, intercept and R^2 of a least-squares line (finite points only)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = np.asarray(x)[ok], np.asarray(y)[ok]
    if x.size < 3:
        return dict(slope=float("nan"), intercept=float("nan"), r2=float("nan"), points=int(x.size))
    slope, intercept = np.polyfit(x, y, 1)
    resid = y - (slope * x + intercept)
    r2 = 1 - resid.var() / y.var() if y.var() > 0 else float("nan")
    return dict(slope=float(slope), intercept=float(intercept), r2=float(r2), points=int(x.size))


def segments_summary(ds) -> dict:
    """Per segment of the first front (left, middle, right) and per whole front (first, second): how
    many members have it and its median speed (m/s); how many members have two fronts or more."""
    out = {}
    for seg in ("left", "middle", "right", "first", "second"):
        v = ds[f"v_{seg}"].values
        out[f"{seg}_present"] = int(np.isfinite(v).sum())
        out[f"v_{seg}_median"] = float(np.nanmedian(v)) if np.isfinite(v).any() else float("nan")
    out["members_with_two_fronts"] = int((ds.front_count.values >= 2).sum())
    return out


def left_edge_front_speed(ds) -> np.ndarray:
    """(members,) m/s: the mean speed of the front that starts at the left edge (-L/2, within the
    edge zone of 0.1 L), whether it is the first front (v_first) or the second (v_second); NaN where
    no front starts there. The paper's left precursor is a slow front from the left edge; with two
    fronts, ours is often the second one (studies/README.md, "Summary")."""
    first = ds.nucleation_edge.values == -1  # the segmentation's own edge decision
    zone = ds.attrs.get("fronts_edge_zone_fraction", 0.1) * ds.length.values  # none is stored for the second
    second = ds.second_nucleation_position.values <= -0.5 * ds.length.values + zone * (1 + 1e-9)
    return np.where(first, ds.v_first.values, np.where(second, ds.v_second.values, np.nan))


# ------------------------------------------------------------------------------------------------
def _space_time_png(ds, path) -> None:
    """warpfric's space-time map of the first recorded member, its x axis naming the pad's edges."""
    from warpfric.plots import space_time_figure

    fig = space_time_figure(ds, 0)
    fig.axes[0].set_xlabel("x (mm): leading edge -100, trailing edge +100 (disc towards +x)")
    fig.savefig(path, dpi=130)
    _plt().close(fig)


def fig3(quick, device, model=None):
    # 1 ms apart (quick; 0.5 ms full size) from before the contact front to past the velocity rule's event
    record = wf.Record.window(20.05, 20.36, 311 if quick else 621, members=(0,))
    # explicit end: the recorded window must lie inside the run (the automatic end may come before 20.36 s)
    ds = simulate(None, quick, device, scene=wf.Parameters(end_time=20.6), record=record, model=model)
    m = ds.isel(member=0)
    claims = {k: float(m[k]) for k in ("mu_s", "mu_s_time", "nucleation_position", "left_front_end",
                                        "right_front_start", "v_left", "v_middle", "v_right",
                                        "front_start_time", "front_end_time", "front_count", "v_first",
                                        "v_second", "second_nucleation_position", "second_front_start_time",
                                        "collision_position", "collision_time")}
    claims["nucleation_edge"] = int(m.nucleation_edge)
    return ds, claims, lambda path: _space_time_png(ds, path)


def fig4(quick, device, model=None):
    e = np.linspace(-0.35, 0.35, 15 if quick else 141)
    ds = simulate({"eccentricity": e}, quick, device, model=model)
    mu = ds.mu_s.values
    claims = dict(mu_s_mean=float(mu.mean()), variation_percent=float(100 * (mu.max() - mu.min()) / mu.mean()),
                  e_at_max=float(e[np.argmax(mu)]), e_at_min=float(e[np.argmin(mu)]),
                  trend_slope_per_unit_e=linfit(e, mu)["slope"],
                  mu_s_trailing_half_minus_leading_half=float(mu[e > 0].mean() - mu[e < 0].mean()))
    # Figs. 6, 7: mu_s against the left precursor's speed and length over these events
    claims["fig6_mu_s_vs_v_left"] = linfit(ds.v_left.values, mu)
    claims["fig7_mu_s_vs_left_length"] = linfit(ds.left_front_length.values, mu)
    claims.update(segments_summary(ds))

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
        ax[0].plot(e, mu, "o-", ms=3)
        ax[0].set_xlabel("eccentricity 2e/L (+: towards the trailing edge)")
        ax[0].set_ylabel("mu_s")
        ax[0].set_title("Fig. 4: F = 1000 N, v = 0.1 mm/s")
        ax[1].plot(ds.v_left, mu, "o", ms=3)
        ax[1].set_xlabel("left precursor speed (m/s)")
        ax[1].set_ylabel("mu_s")
        ax[1].set_title("Fig. 6")
        ax[2].plot(ds.left_front_length * 1e3, mu, "o", ms=3)
        ax[2].set_xlabel("left precursor length (mm)")
        ax[2].set_ylabel("mu_s")
        ax[2].set_title("Fig. 7")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


def fig5_8(quick, device, model=None):
    F = np.geomspace(100.0, 10000.0, 9 if quick else 41)
    ds = simulate({"normal_force": F}, quick, device, model=model)
    mu = ds.mu_s.values
    claims = dict(mu_s=[float(v) for v in mu], normal_force=[float(v) for v in F],
                  increase_first_decade=float(mu[F <= 1000].max() - mu[0]),
                  increase_last_decade=float(mu[-1] - mu[F >= 1000].min()))
    claims.update(segments_summary(ds))
    vl = ds.v_left.values
    present = np.isfinite(vl)
    claims["lowest_force_with_left_precursor"] = float(F[present].min()) if present.any() else float("nan")
    claims["highest_force_without_left_precursor"] = float(F[~present].max()) if (~present).any() else float("nan")
    claims["fig9_inverse_v_left_vs_force"] = linfit(F[present], 1 / vl[present])
    claims["shear_wave_speed"] = SHEAR_WAVE_SPEED
    for seg in ("left", "middle", "right"):
        claims[f"fig8_log_v_{seg}_vs_log_force"] = linfit(np.log(F), np.log(ds[f"v_{seg}"].values))
    # the front from the left edge, first or second (not the paper's reading of a precursor segment:
    # an observation beside it)
    v_edge = left_edge_front_speed(ds)
    claims["left_edge_front_speed_by_force"] = [float(v) for v in v_edge]
    claims["left_edge_front_is_the_second"] = [bool(np.isfinite(v) and np.isfinite(w) and v == w)
                                               for v, w in zip(v_edge, ds.v_second.values)]
    edge_present = np.isfinite(v_edge)
    claims["lowest_force_with_left_edge_front"] = float(F[edge_present].min()) if edge_present.any() else float("nan")
    claims["log_left_edge_front_speed_vs_log_force"] = linfit(np.log(F[edge_present]), np.log(v_edge[edge_present]))

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 3, figsize=(13, 3.8))
        ax[0].semilogx(F, mu, "o-", ms=3)
        ax[0].set_xlabel("normal force (N)")
        ax[0].set_ylabel("mu_s")
        ax[0].set_title("Fig. 5: e = 0, v = 0.1 mm/s")
        for seg, mk in (("left", "v"), ("middle", "o"), ("right", "^")):
            ax[1].loglog(F, ds[f"v_{seg}"], mk + "-", ms=3, label=f"v_{seg} (first front)")
        ax[1].loglog(F, v_edge, "s--", ms=4, mfc="none", color="k", label="front from the left edge")
        ax[1].axhline(SHEAR_WAVE_SPEED, color="k", ls=":", label="shear wave speed")
        ax[1].set_xlabel("normal force (N)")
        ax[1].set_ylabel("front speed (m/s)")
        ax[1].set_title("Fig. 8")
        ax[1].legend(fontsize=7)
        ax[2].plot(F[present], 1 / vl[present], "o", ms=3, label=f"1 / v_left (first front; {present.sum()} of "
                   f"{F.size} forces)")
        ax[2].plot(F[edge_present], 1 / v_edge[edge_present], "s", ms=4, mfc="none", color="k",
                   label="1 / speed of the front from the left edge")
        if present.sum() < 2:  # the quick set: a line needs two points; said on the panel, not left blank
            where = f"at {present.sum()} force only" if present.any() else "at no force"
            ax[2].text(0.03, 0.95, f"v_left present {where}: no line to read", transform=ax[2].transAxes,
                       fontsize=7, va="top")
        ax[2].set_xlabel("normal force (N)")
        ax[2].set_ylabel("1 / speed (s/m)")
        ax[2].set_title("Fig. 9")
        ax[2].legend(fontsize=7, loc="lower right")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


def fig10(quick, device, model=None):
    v = np.geomspace(1e-6, 1e-2, 9 if quick else 33)
    eta = np.array([2.7e13, 0.0])
    # stall_factor = inf: the eta = 0 members are a dynamic rupture under the stress gate, legitimately
    # far more expensive than the strengthening half of the ensemble (module docstring)
    ds = simulate({"viscous_coefficient": eta[:, None], "disc_velocity": v[None, :]}, quick, device,
                  scene=wf.Parameters(normal_force=500.0), model=model, stall_factor=np.inf)
    mu = ds.mu_s.values.reshape(2, -1)
    claims = {}
    for seg in ("left", "middle", "right"):
        claims[f"log_v_{seg}_vs_log_vd"] = linfit(np.log(v), np.log(ds[f"v_{seg}"].values.reshape(2, -1)[0]))
    claims["fig13_mu_s_vs_log_vd_with_strengthening"] = linfit(np.log10(v), mu[0])
    claims["fig14_mu_s_without_strengthening"] = [float(x) for x in mu[1]]
    claims["fig14_drop_first_half"] = float(mu[1][0] - mu[1][len(v) // 2])
    claims["fig14_drop_second_half"] = float(mu[1][len(v) // 2] - mu[1][-1])
    claims["disc_velocity"] = [float(x) for x in v]

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.8))
        for seg, mk in (("left", "v"), ("middle", "o"), ("right", "^")):
            ax[0].loglog(v, ds[f"v_{seg}"].values.reshape(2, -1)[0], mk + "-", ms=3, label=f"v_{seg}")
        ax[0].set_xlabel("disc velocity (m/s)")
        ax[0].set_ylabel("front speed (m/s)")
        ax[0].set_title("Fig. 10: F = 500 N, e = 0")
        ax[0].legend(fontsize=7)
        ax[1].semilogx(v, mu[0], "o-", ms=3, label="with strengthening (Fig. 13)")
        ax[1].semilogx(v, mu[1], "s-", ms=3, label="viscous_coefficient = 0 (Fig. 14)")
        ax[1].set_xlabel("disc velocity (m/s)")
        ax[1].set_ylabel("mu_s")
        ax[1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


def _quiet_delays(t, v, stop) -> list:
    """Per node of one member's recorded pad velocity v (time, x) at times t (s): the delay after
    ``stop`` (s) of the first recorded time at which |v| is below 1 % of the node's pre-stop peak
    (NaN where it never is)."""
    after = t > stop + 1e-9
    delays = []
    for i in range(v.shape[1]):
        peak = np.abs(v[t <= stop, i]).max()
        quiet = np.abs(v[:, i]) < 0.01 * peak
        later = np.flatnonzero(after & quiet)
        delays.append(float(t[later[0]] - stop) if later.size else float("nan"))
    return delays


def fig11(quick, device, model=None):
    """The disc stopped at 20.15 s (the paper's stop, member 0), never (member 1) and at 20.13 s
    (member 2: inside the default scene's contact front, 20.126-20.136 s, where the paper's stop
    falls inside its front)."""
    stop, inside = 20.15, 20.13
    record = wf.Record.window(20.0, 20.4, 201 if quick else 801, members=(0, 1, 2))
    # explicit end: the recorded window (20.0-20.4 s) must lie inside every run
    ds = simulate({"stop_time": [stop, np.inf, inside]}, quick, device, scene=wf.Parameters(end_time=20.4),
                  record=record, model=model)
    t = ds.time.values
    v = ds.velocity_history.values[0]  # (time, x)
    delays = _quiet_delays(t, v, stop)
    inside_delays = _quiet_delays(t, ds.velocity_history.values[2], inside)
    claims = dict(stop_time=stop, max_velocity_before=float(np.abs(v[t < stop]).max()),
                  max_velocity_after_5ms=float(np.abs(v[t > stop + 0.005]).max()),
                  node_quiet_delay_min=float(np.nanmin(delays)), node_quiet_delay_max=float(np.nanmax(delays)),
                  inside_front_stop_time=inside, inside_front_node_quiet_delay_min=float(np.nanmin(inside_delays)),
                  inside_front_node_quiet_delay_max=float(np.nanmax(inside_delays)),
                  status=[int(s) for s in ds.status.values])
    return ds, claims, lambda path: _space_time_png(ds, path)


def fig12(quick, device, model=None):
    e = np.linspace(-0.3, 0.3, 7 if quick else 25)
    eta = np.array([2.7e13, 0.0])
    # stall_factor = inf: as in fig10, the eta = 0 half is legitimately more expensive under the stress gate
    ds = simulate({"viscous_coefficient": eta[:, None], "eccentricity": e[None, :]}, quick, device, model=model,
                  stall_factor=np.inf)
    claims = {"eccentricity": [float(x) for x in e]}
    for seg in ("left", "middle", "right"):
        vv = ds[f"v_{seg}"].values.reshape(2, -1)
        ratio = vv[1] / vv[0]
        claims[f"v_{seg}_ratio_without_over_with"] = [float(x) for x in ratio]
        claims[f"v_{seg}_ratio_median"] = float(np.nanmedian(ratio)) if np.isfinite(ratio).any() else float("nan")

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        for seg, mk in (("left", "v"), ("middle", "o"), ("right", "^")):
            vv = ds[f"v_{seg}"].values.reshape(2, -1)
            ax.semilogy(e, vv[0], mk + "-", ms=4, label=f"v_{seg} with strengthening")
            ax.semilogy(e, vv[1], mk + "--", ms=4, mfc="none", label=f"v_{seg} without")
        ax.set_xlabel("eccentricity 2e/L")
        ax.set_ylabel("front speed (m/s)")
        ax.set_title("Fig. 12: F = 1000 N, v = 0.1 mm/s")
        ax.legend(fontsize=6)
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


CHOICES = {
    "default": {},
    "fronts direction=with_disc": "with_disc",
    "interface_velocity_factor=2": {"interface_velocity_factor": 2.0},
    "torque_arm=0": {"torque_arm": 0.0},
    "torque_arm=2H": {"torque_arm": 0.03},
    "torque_arm=-H (counterfactual)": {"torque_arm": -0.015},
    "damping=1e5": {"damping": 1e5},
    "initial_age=1s": {"initial_age": 1.0},
}


def choices(quick, device, model=None):
    """Each open choice of SPEC section 10 against three readings of the paper: which edge
    nucleates at e = 0 (paper: left), the sign of d mu_s / d e (paper: + , higher towards the
    trailing edge), and whether the left precursor vanishes at low force (paper: none below
    1000 N). poisson_coupling is a Model switch and is run separately."""
    e = np.array([-0.3, 0.0, 0.3])
    F = np.array([200.0, 1000.0, 5000.0])
    rows = {}
    datasets = []
    for label, change in list(CHOICES.items()) + [("poisson_coupling=off", None)]:
        if isinstance(change, str) and _front["event"] != "velocity":
            continue  # the direction is a setting of the velocity front only
        fronts = figure_fronts(direction=change) if isinstance(change, str) else figure_fronts()
        scene = wf.Parameters(**(change if isinstance(change, dict) else {}))
        base = model or wf.Model()
        m = dataclasses.replace(base, poisson_coupling=False) if change is None else base
        members = {"eccentricity": np.concatenate([e, np.zeros(2)]), "normal_force": np.concatenate([np.full(3, 1000.0), F[[0, 2]]])}
        ds = wf.simulate(members, scene=scene, model=m, solver=wf.Solver(nodes=100 if quick else 200),
                         fronts=fronts, device=device, progress=False)
        mu = ds.mu_s.values
        rows[label] = dict(
            nucleation_position_e0=float(ds.nucleation_position.values[1]),
            nucleation_edge_e0=int(ds.nucleation_edge.values[1]),
            dmu_de=float((mu[2] - mu[0]) / 0.6),
            left_precursor_at_200N=bool(np.isfinite(ds.v_left.values[3])),
            left_precursor_at_1000N=bool(np.isfinite(ds.v_left.values[1])),
            left_precursor_at_5000N=bool(np.isfinite(ds.v_left.values[4])),
            v_middle_e0=float(ds.v_middle.values[1]), mu_s_e0=float(mu[1]),
        )
        ds = ds.expand_dims(choice=[label])
        datasets.append(ds[["mu_s", "mu_s_time", "final_time", "status", "stop_time", "v_left", "v_middle", "v_right", "nucleation_position", "eccentricity", "normal_force"]])
    import xarray as xr

    combined = xr.concat(datasets, dim="choice")
    combined.attrs = datasets[0].attrs
    combined.attrs["warpfric_complete"] = 1

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(figsize=(7, 3.5))
        labels = list(rows)
        ax.barh(labels, [rows[k]["nucleation_position_e0"] * 1e3 for k in labels])
        ax.set_xlabel("nucleation position at e = 0 (mm); paper: left edge, -100 mm")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return combined, rows, draw


def ensemble_map(quick, device, model=None):
    e = np.linspace(-0.35, 0.35, 5 if quick else 29)
    F = np.geomspace(100.0, 10000.0, 4 if quick else 25)
    v = np.geomspace(1e-6, 1e-2, 3 if quick else 17)
    members = {"eccentricity": e[:, None, None], "normal_force": F[None, :, None], "disc_velocity": v[None, None, :]}
    # the disc velocity spans four decades, and the slowest members legitimately take ~10x the median
    # member's steps (quick, gate-less: 2,774 against 289), next to the straggler rule's limit
    # (Solver.stall_factor = 10): every member here is integrated to its end
    ds = simulate(members, quick, device, nodes=60 if quick else 100, model=model, stall_factor=math.inf)
    mu = ds.mu_s.values.reshape(e.size, F.size, v.size)
    left = np.isfinite(ds.v_left.values).reshape(mu.shape)
    claims = dict(members=int(ds.sizes["member"]), ok=int((ds.status.values == 0).sum()),
                  mu_s_min=float(np.nanmin(mu)), mu_s_max=float(np.nanmax(mu)),
                  left_precursor_fraction=float(left.mean()),
                  left_precursor_fraction_by_velocity=[float(left[:, :, k].mean()) for k in range(v.size)],
                  left_precursor_fraction_by_eccentricity=[float(left[i].mean()) for i in range(e.size)],
                  mu_s_range_over_velocity=float(np.nanmax(mu.max(axis=2) - mu.min(axis=2))),
                  mu_s_range_over_eccentricity=float(np.nanmax(mu.max(axis=0) - mu.min(axis=0))),
                  mu_s_range_over_force=float(np.nanmax(mu.max(axis=1) - mu.min(axis=1))))

    def edges(values, log=False):
        """Cell edges around sorted values: midpoints (geometric on a log axis), ends mirrored."""
        c = np.log(values) if log else np.asarray(values, float)
        mid = 0.5 * (c[1:] + c[:-1])
        out = np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])
        return np.exp(out) if log else out

    def draw(path):
        plt = _plt()
        k = v.size // 2
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        # cells centred on the forces on the log axis (shading="nearest" centres them linearly: the
        # 100 N column was a sliver)
        F_edges, e_edges = edges(F, log=True), edges(e)
        im = ax[0].pcolormesh(F_edges, e_edges, mu[:, :, k], shading="flat")
        ax[0].set_xscale("log")
        ax[0].set_xlabel("normal force (N)")
        ax[0].set_ylabel("eccentricity 2e/L")
        ax[0].set_title(f"mu_s at v = {v[k]:.1e} m/s")
        fig.colorbar(im, ax=ax[0])
        im = ax[1].pcolormesh(F_edges, e_edges, left[:, :, k], shading="flat", cmap="Greys", vmin=0, vmax=1)
        ax[1].set_xscale("log")
        ax[1].set_xlabel("normal force (N)")
        ax[1].set_ylabel("eccentricity 2e/L")
        ax[1].set_title("left precursor present (black)")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


def uncertainty(quick, device, model=None):
    """Friction parameters drawn around Table 1 (distributions in the docstring of
    studies/sweeps/uncertainty.toml, the same here)."""
    n = 200 if quick else 10000
    rng = lambda k: np.random.default_rng([2014, k])  # noqa: E731
    members = {
        "aging_coefficient": rng(0).normal(0.075, 0.0075, n),
        "memory_length": np.exp(rng(1).uniform(np.log(3e-7), np.log(8e-7), n)),
        "viscous_coefficient": rng(2).uniform(1.35e13, 4.05e13, n),
        "interface_stiffness": np.exp(rng(3).uniform(np.log(1.5e14), np.log(6e14), n)),
        "hardness": rng(4).normal(5.4e8, 5.4e7, n),
    }
    ds = simulate(members, quick, device, nodes=60 if quick else 100, model=model)
    mu = ds.mu_s.values
    ok = ds.status.values == 0
    p = wf.Parameters()
    # steady sliding |tau_f|/A at v (SPEC section 5): mu0*D/h + eta*v_star*ln(1 + v/v_star); the gate stays shut below tau_c
    steady = members["interface_stiffness"] * members["memory_length"] + members["viscous_coefficient"] * \
        p.reference_velocity * np.log1p(p.disc_velocity / p.reference_velocity)
    below = steady < p.shear_strength
    claims = dict(members=n, ok=int(ok.sum()), failed_status=sorted({int(x) for x in ds.status.values[~ok]}),
                  steady_stress_below_tau_c=int(below.sum()), failed_and_below_tau_c=int((~ok & below).sum()),
                  mu_s_mean=float(np.nanmean(mu)),
                  mu_s_std=float(np.nanstd(mu)), mu_s_p05=float(np.nanpercentile(mu, 5)),
                  mu_s_p95=float(np.nanpercentile(mu, 95)),
                  v_middle_p05=float(np.nanpercentile(ds.v_middle.values, 5)),
                  v_middle_p95=float(np.nanpercentile(ds.v_middle.values, 95)),
                  correlation_mu_s={k: float(np.corrcoef(v[ok], mu[ok])[0, 1]) for k, v in members.items()})
    claims.update(segments_summary(ds))

    def draw(path):
        plt = _plt()
        fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
        ax[0].hist(mu[np.isfinite(mu)], bins=40)
        ax[0].set_xlabel("mu_s")
        speeds = ds.v_middle.values[np.isfinite(ds.v_middle.values) & (ds.v_middle.values > 0)]
        # a few members read 1000+ m/s (a meeting point's flat top) beside a bulk near 10-30 m/s: log bins
        ax[1].hist(speeds, bins=np.geomspace(speeds.min(), speeds.max(), 41) if speeds.size > 1 else 10)
        ax[1].set_xscale("log")
        ax[1].set_xlabel("v_middle (m/s)")
        ax[1].set_ylabel("members")
        ax[0].set_ylabel("members")
        fig.suptitle(f"{n} members, friction parameters drawn around Table 1")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)

    return ds, claims, draw


STUDIES = {
    "fig3": fig3, "fig4": fig4, "fig5": fig5_8,
    "fig10": fig10, "fig11": fig11, "fig12": fig12, "choices": choices, "map": ensemble_map,
    "uncertainty": uncertainty,
}


def run_study(name, quick, device, outdir, relaxation_gate="stress", front_event=None) -> dict:
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    front_event = front_event or FRONT_EVENT[relaxation_gate]
    _front["event"] = front_event
    front_suffix = "" if front_event == FRONT_EVENT[relaxation_gate] else f"_{front_event}front"
    stem = name + GATE_SUFFIX[relaxation_gate] + front_suffix + ("_quick" if quick else "")
    t0 = time.perf_counter()
    ds, claims, draw = STUDIES[name](quick, device, wf.Model(relaxation_gate=relaxation_gate))
    wall = time.perf_counter() - t0
    if "choice" in ds.dims:
        peaks = [peak_check(ds.sel(choice=c)) for c in ds.choice.values]
        counts = {}
        for p in peaks:
            for k, n in p["status_counts"].items():
                counts[k] = counts.get(k, 0) + n
        peak = dict(members_without_peak=sum(p["members_without_peak"] for p in peaks),
                    failed_members=sum(p["failed_members"] for p in peaks), status_counts=counts,
                    max_final_time=max(p["max_final_time"] for p in peaks))
    else:
        peak = peak_check(ds)
    expected = EXPECTED_NO_PEAK.get(name, 0)
    if (peak["members_without_peak"], peak["failed_members"]) != (expected, expected) or (
            expected and peak["status_counts"].get("no_peak", 0) != expected):
        print(f"WARNING {stem}: {peak['members_without_peak']} member(s) end before their mu_s peak, "
              f"{peak['failed_members']} failed (status != 0): {peak['status_counts']}", file=sys.stderr)
    claims = dict(claims) if isinstance(claims, dict) else claims
    claims["peak_check"] = peak
    if "choice" in ds.dims:
        ds.to_netcdf(outdir / f"{stem}.nc")
    else:  # the final-state fields are not needed by the figures: keep the files small
        final_fields = ["displacement", "velocity", "elastic_stress", "contact_age", "normal_stress", "friction_stress"]
        write_ensemble(ds.drop_vars([v for v in final_fields if v in ds]), outdir / f"{stem}.nc")
    draw(outdir / f"{stem}.png")
    meta = dict(study=name, quick=quick, device=str(device), wall_s=wall, warpfric=wf.__version__,
                relaxation_gate=relaxation_gate, front_event=front_event,
                command=f"python studies/figures.py {name}" + (" --quick" if quick else "") + f" --device {device}"
                + f" --relaxation-gate {relaxation_gate} --front-event {front_event}")
    (outdir / f"{stem}.json").write_text(json.dumps(dict(meta=meta, claims=claims), indent=1, default=float))
    print(f"{stem}: {wall:.1f} s -> {outdir / stem}.nc/.png/.json")
    return claims


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("name", choices=sorted(STUDIES) + ["all"], help="the study (see above), or all of them")
    ap.add_argument("--quick", action="store_true", help="sizes for a 2-core CPU (every study in ~15 s)")
    ap.add_argument("--device", default=None, help="Warp device: cpu, cuda:0 (default: the first GPU, else cpu)")
    ap.add_argument("--outdir", default="warpfric_studies",
                    help="folder of the outputs (default ./warpfric_studies; studies/figures holds the committed ones)")
    ap.add_argument("--relaxation-gate", choices=sorted(GATE_SUFFIX), default="stress",
                    help="the friction law's yield gate (default stress; none = SPEC v1)")
    ap.add_argument("--front-event", choices=("contact", "strength", "velocity"), default=None,
                    help="the detachment front the figures read (default: contact under the stress gate, "
                         "velocity under the gate-less laws)")
    args = ap.parse_args(argv)
    device = args.device or wf.default_device()
    names = sorted(STUDIES) if args.name == "all" else [args.name]
    for name in names:
        run_study(name, args.quick, device, args.outdir, args.relaxation_gate, args.front_event)


if __name__ == "__main__":
    main()
