"""The open readings of SPEC section 10 scored against the paper's claims.

    python studies/readings.py [--design factorial|oat] [--nodes 60] [--device cpu] [--out FILE.json]

--out: default ./readings_<design>.json; the committed factorial that studies/README.md quotes is
studies/readings_quick.json (--out studies/readings_quick.json remakes it). Positions in the
output are in m, speeds in m/s, times in s (studies/README.md quotes mm).

A reading is one combination of the open choices:
    relaxation_gate            stress (GRL 2012, default), none (SPEC v1), velocity (PRE 2013)   [Model]
    interface_velocity_factor  1, 2                                                            [Parameters]
    torque_arm                 0, H, 2H, and -H (a COUNTERFACTUAL: the plate is held above the
                               interface, so a reversed friction torque has no physical support)
    poisson_coupling           on, off                                                          [Model]
    initial_age                3.33e-4 s (phi0), 1 s                                             [Parameters]
    damping                    0, 1e5 Pa s/m                                                     [Parameters]
--design factorial: all 3*2*4*2*2*2 = 192 readings; --design oat: each gate's default reading and
one factor changed at a time (24 readings).

Each reading is scored for every front event (one simulation gives all three: Fronts(event=(
"contact", "strength", "velocity"))) and for both identifications of the paper's edges: "spec"
(the left edge -L/2 is the leading edge, SPEC section 1: with v_d > 0 the disc leaves the pad at
+L/2) and "mirrored" (the paper's left is our trailing edge +L/2: left and right, the sign of e and
the nucleation edge swap). The paper never states its disc direction; its Fig. 4 text names leading
and trailing edges, its Fig. 3 the left edge.

Every reading runs the same 15 members (N nodes, rtol 1e-5, float64):
    0  e = 0,    F = 1000 N, v = 1e-4 m/s              (Fig. 3)
    1  e = -0.2, 2  e = +0.2 (F = 1000 N)               (Fig. 4)
    3  F = 500,  4  F = 2000, 5  F = 5000 N (e = 0)     (Figs. 5, 8, 9; with member 0)
    6  F = 500 N, v = 1e-5;   7  F = 500 N, v = 1e-3    (Figs. 10, 13; with member 3)
    8-10  viscous_coefficient = 0 at e = -0.2, 0, 0.2   (Fig. 12; with members 1, 0, 2)
    11-13 viscous_coefficient = 0, F = 500 N, v = 1e-5, 1e-4, 1e-3   (Fig. 14)
    14 e = 0, F = 1000 N, the disc stops at 20.15 s, pad velocity recorded 20.0-20.4 s (Fig. 11)
End times: the engine's automatic end (end_time=None: mu past its peak by 1 % and the front over,
80 s at most), so every member that ends ok has its peak inside the run; member 14 alone ends at
20.4 s, explicitly, because its pad velocity is recorded on the fixed grid 20.0-20.4 s.
Straggler rule off (stall_factor = inf) and max_steps = 400,000 (default 100,000): every reading
holds viscous_coefficient = 0 members, which under the stress gate are a dynamic rupture,
legitimately far more expensive than their peers (with max_steps = 100,000, 18 of them ended
max_steps_reached; one of those, k_if = 2, Poisson off, 500 N, 1e-5 m/s, ends ok after 135,546
attempted steps with only 60 gate switches: an expensive rupture, not chatter).

The claims and their pass rules are in CLAIMS below (paper figure numbers). A claim whose members
did not all end with status 0 (ok) is "not scored", never "pass"; failed_members names their status.
Member 14 (the stopped disc) ends no_peak, as it should: its disc stops before the mu_s peak, and
its claim (Fig. 11) reads its velocities only.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np

import warpfric as wf
from warpfric.kernels.types import STATUS_MEANINGS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from figures import linfit  # noqa: E402

H = wf.Parameters().height
FACTORS = {
    "relaxation_gate": ["stress", "none", "velocity"],
    "interface_velocity_factor": [1.0, 2.0],
    "torque_arm": ["0", "H", "2H", "-H (counterfactual)"],
    "poisson_coupling": [True, False],
    "initial_age": [3.33e-4, 1.0],
    "damping": [0.0, 1e5],
}
EVENTS = ("contact", "strength", "velocity")
NAMINGS = ("spec", "mirrored")
ARM = {"0": 0.0, "H": H, "2H": 2 * H, "-H (counterfactual)": -H}
DEFAULT = {k: v[0] for k, v in FACTORS.items()} | {"torque_arm": "H"}
STOP = 20.15
MAX_STEPS = 400_000  # the eta = 0 stress-gate members need up to ~1.4e5 attempted steps (docstring)
STATUS = STATUS_MEANINGS  # ok, max_steps_reached, non_finite_state, step_size_underflow, no_peak, stalled

# member table: (eccentricity, normal_force, disc_velocity, viscous_coefficient, stop_time)
ETA = wf.Parameters().viscous_coefficient
MEMBERS = [
    (0.0, 1000.0, 1e-4, ETA, np.inf), (-0.2, 1000.0, 1e-4, ETA, np.inf), (0.2, 1000.0, 1e-4, ETA, np.inf),
    (0.0, 500.0, 1e-4, ETA, np.inf), (0.0, 2000.0, 1e-4, ETA, np.inf), (0.0, 5000.0, 1e-4, ETA, np.inf),
    (0.0, 500.0, 1e-5, ETA, np.inf), (0.0, 500.0, 1e-3, ETA, np.inf),
    (-0.2, 1000.0, 1e-4, 0.0, np.inf), (0.0, 1000.0, 1e-4, 0.0, np.inf), (0.2, 1000.0, 1e-4, 0.0, np.inf),
    (0.0, 500.0, 1e-5, 0.0, np.inf), (0.0, 500.0, 1e-4, 0.0, np.inf), (0.0, 500.0, 1e-3, 0.0, np.inf),
    (0.0, 1000.0, 1e-4, ETA, STOP),
]
M = len(MEMBERS)
E0, EM, EP, F500, F2000, F5000, V5, V3, Z_EM, Z_E0, Z_EP, Z_V5, Z_V4, Z_V3, STOPPED = range(M)

CLAIMS = {
    "fig3_left_edge_nucleation": "Fig. 3: detachment starts at the left (leading) edge at e = 0. "
                                 "Pass: nucleation_edge = -1 (member e = 0, 1000 N).",
    "fig3_time_window": "Fig. 3: the fronts cross the pad in about 20.14-20.18 s. "
                        "Pass: front_start_time and front_end_time both in [20.12, 20.20] s.",
    "fig3_speed_change_positions": "Fig. 3: the front speed changes near -45 mm and +55 mm. "
                                   "Pass: left_front_end in [-60, -30] mm and right_front_start in [40, 70] mm.",
    "fig4_variation_half_percent": "Fig. 4: mu_s varies by about 0.5 % over e = -0.2..0.2. "
                                   "Pass: (max - min) / mean of mu_s at e = -0.2, 0, 0.2 in [0.25, 1.0] %.",
    "fig4_higher_towards_trailing_edge": "Fig. 4: mu_s is higher when the load is towards the trailing edge "
                                         "(e > 0: with v_d > 0 the disc leaves the pad at x = +L/2, SPEC "
                                         "section 1). Pass: mu_s(e = +0.2) > mu_s(e = -0.2).",
    "fig5_saturation_with_force": "Fig. 5: mu_s saturates with force. Pass: mu_s(1000) > mu_s(500) and the slope "
                                  "d mu_s / d ln F over 2000-5000 N < half the slope over 500-1000 N.",
    "fig8_left_precursor_500_1000_5000": "Fig. 8: no left precursor at 500 N, one at 1000 and 5000 N. "
                                         "Pass: v_left absent at 500 N and present at 1000 and 5000 N.",
    "fig8_left_middle_slow_down_right_not": "Fig. 8: the left and middle fronts slow down with force, the right "
                                            "one does not. Pass: log-log slope of v against F (500-5000 N, where "
                                            "present, >= 2 points) < -0.1 for left and middle, |slope| < 0.1 for "
                                            "right.",
    "fig9_inverse_v_left_linear_in_force": "Fig. 9: 1/v_left is linear in F (and grows). Pass: >= 3 forces with a "
                                           "left precursor, R^2 >= 0.9 and slope > 0.",
    "fig10_power_laws_in_v": "Fig. 10: the front speeds grow with v as power laws (F = 500 N). Pass: at least "
                             "two segments present at v = 1e-5, 1e-4, 1e-3 m/s, and each such segment has "
                             "log-log slope > 0 and R^2 >= 0.9.",
    "fig11_sudden_stop_stops_every_front": "Fig. 11: a sudden stop at 20.15 s stops every front. Pass: after the "
                                           "stop every node's velocity stays below 1 % of its pre-stop peak within "
                                           "50 ms and stays there to 20.4 s (so no front starts after the stop), "
                                           "and the quiet times of the nodes spread < 10 ms.",
    "fig12_fronts_insensitive_to_eta0": "Fig. 12: front speeds are nearly unchanged with viscous_coefficient = 0. "
                                        "Pass: the middle front is present in >= 1 pair and, for each segment "
                                        "present in both, the median ratio without/with over e = -0.2, 0, 0.2 "
                                        "is within 15 % of 1.",
    "fig13_mu_s_rises_in_log_v": "Fig. 13: with strengthening mu_s rises linearly in log v. Pass: mu_s strictly "
                                 "increasing over v = 1e-5, 1e-4, 1e-3 m/s (500 N) and R^2 >= 0.9 in log10 v.",
    "fig14_mu_s_falls_to_plateau": "Fig. 14: without strengthening mu_s falls to a plateau. Pass: mu_s(1e-5) > "
                                   "mu_s(1e-4) and |mu_s(1e-4) - mu_s(1e-3)| < 0.5 (mu_s(1e-5) - mu_s(1e-4)).",
}


def design(kind: str) -> list[dict]:
    if kind == "factorial":
        keys = list(FACTORS)
        return [dict(zip(keys, combo)) for combo in itertools.product(*FACTORS.values())]
    out = []
    for gate in FACTORS["relaxation_gate"]:
        base = DEFAULT | {"relaxation_gate": gate}
        out.append(base)
        for k, values in FACTORS.items():
            if k == "relaxation_gate":
                continue
            out += [base | {k: v} for v in values if v != base[k]]
    return out


def label(r: dict) -> str:
    return (f"gate={r['relaxation_gate']} k_if={r['interface_velocity_factor']:g} arm={r['torque_arm']} "
            f"poisson={'on' if r['poisson_coupling'] else 'off'} age={r['initial_age']:g} "
            f"damping={r['damping']:g}")


def _simulate_group(readings: list[dict], nodes: int, device: str):
    """One simulate call for readings that share the Model (gate, poisson); every front event."""
    r0 = readings[0]
    model = wf.Model(relaxation_gate=r0["relaxation_gate"], poisson_coupling=r0["poisson_coupling"])
    fronts = wf.Fronts(event=EVENTS)
    table = np.array(MEMBERS * len(readings))
    per = lambda key: np.repeat([float(ARM[r[key]]) if key == "torque_arm" else float(r[key])  # noqa: E731
                                 for r in readings], M)
    scene = wf.Parameters()
    members = {"eccentricity": table[:, 0], "normal_force": table[:, 1], "disc_velocity": table[:, 2],
               "viscous_coefficient": table[:, 3], "stop_time": table[:, 4],
               "interface_velocity_factor": per("interface_velocity_factor"), "torque_arm": per("torque_arm"),
               "initial_age": per("initial_age"), "damping": per("damping")}
    # inf: the automatic end; the recorded (stopped) member ends at the end of its recording window
    members["end_time"] = np.where(np.isfinite(table[:, 4]), 20.4, np.inf)
    stopped = tuple(int(i * M + STOPPED) for i in range(len(readings)))
    record = wf.Record.window(20.0, 20.4, 101, members=stopped)
    import warnings

    with warnings.catch_warnings():  # the contact front of the gate-less laws is NaN, as documented
        warnings.simplefilter("ignore", UserWarning)
        return wf.simulate(members, scene=scene, model=model, solver=wf.Solver(nodes=nodes, rtol=1e-5, stall_factor=np.inf, max_steps=MAX_STEPS), fronts=fronts,
                           record=record, device=device, progress=False)


_SWAP = {"left": "right", "right": "left", "middle": "middle"}


def reader(ds, i: int, event: str, naming: str):
    """g(name): the (M,) values of reading i for the event's front outputs, seen in the paper's frame:
    naming 'mirrored' swaps left and right, negates positions and the nucleation edge."""
    prefix = "" if event == EVENTS[0] else event + "_"
    front_names = ("nucleation_edge", "nucleation_position", "front_start_time", "front_end_time")

    def g(name):
        front = name in front_names or name.startswith(("v_", "left_", "right_", "middle_"))
        if naming == "spec" or not front:
            return ds[(prefix if front else "") + name].values[i * M:(i + 1) * M]
        if name == "nucleation_edge":  # the edges swap (-1 <-> 1); the flags -2 none, -3 unknown stay
            values = ds[prefix + name].values[i * M:(i + 1) * M]
            return np.where(values >= -1, -values, values)
        if name == "nucleation_position":
            return -ds[prefix + name].values[i * M:(i + 1) * M]
        if name.startswith("v_"):
            return ds[prefix + "v_" + _SWAP[name[2:]]].values[i * M:(i + 1) * M]
        seg, _, what = name.partition("_front_")
        if seg in _SWAP:  # left_front_end (mirrored) = -(right_front_start)
            other = {"start": "end", "end": "start", "length": "length"}[what]
            values = ds[f"{prefix}{_SWAP[seg]}_front_{other}"].values[i * M:(i + 1) * M]
            return values if what == "length" else -values
        return ds[prefix + name].values[i * M:(i + 1) * M]

    return g


def _f(x):
    x = float(x)
    return x if np.isfinite(x) else None


def score(ds, i: int, k: int, event: str = "contact", naming: str = "spec") -> dict:
    """Claims for reading number i of a group dataset (its members i*M .. i*M+M-1), read from the
    front event's outputs with the paper's edges named as ``naming`` says; k: its index among the
    recorded members."""
    g = reader(ds, i, event, naming)
    status = g("status")
    mu, vl, vm, vr = g("mu_s"), g("v_left"), g("v_middle"), g("v_right")
    # the stopped member's disc stops before its mu_s peak (20.15 s against ~20.23 s): no_peak is
    # its expected status (docs/model.md, "Statuses"), and its claim reads its velocities only
    expected = lambda j: status[j] == 0 or (j == STOPPED and STATUS[int(status[j])] == "no_peak")  # noqa: E731
    ok = lambda *idx: all(expected(j) for j in idx)  # noqa: E731
    out = {}

    def put(name, needed, passed, value):
        if not ok(*needed):
            out[name] = {"result": "not scored", "value": value,
                         "failed_members": {int(j): STATUS[int(status[j])] for j in needed if not expected(j)}}
        else:
            out[name] = {"result": "pass" if passed else "fail", "value": value}

    edge = int(g("nucleation_edge")[E0])
    put("fig3_left_edge_nucleation", [E0], edge == -1,
        {"nucleation_edge": edge, "nucleation_position_mm": _f(g("nucleation_position")[E0] * 1e3)})
    t0, t1 = g("front_start_time")[E0], g("front_end_time")[E0]
    put("fig3_time_window", [E0], bool(20.12 <= t0 <= 20.20 and 20.12 <= t1 <= 20.20),
        {"front_start_time": _f(t0), "front_end_time": _f(t1), "mu_s_time": _f(g("mu_s_time")[E0])})
    le, rs = g("left_front_end")[E0] * 1e3, g("right_front_start")[E0] * 1e3
    put("fig3_speed_change_positions", [E0], bool(-60 <= le <= -30 and 40 <= rs <= 70),
        {"left_front_end_mm": _f(le), "right_front_start_mm": _f(rs)})
    me = mu[[EM, E0, EP]]
    var = 100 * (me.max() - me.min()) / me.mean()
    put("fig4_variation_half_percent", [EM, E0, EP], bool(0.25 <= var <= 1.0), {"variation_percent": _f(var)})
    trailing, leading = (EP, EM) if naming == "spec" else (EM, EP)  # mirrored: e -> -e
    put("fig4_higher_towards_trailing_edge", [EM, EP], bool(mu[trailing] > mu[leading]),
        {"mu_s_trailing_minus_leading": _f(mu[trailing] - mu[leading])})
    fi = [F500, E0, F2000, F5000]
    F = np.array([500.0, 1000.0, 2000.0, 5000.0])
    low = (mu[E0] - mu[F500]) / np.log(2)
    high = (mu[F5000] - mu[F2000]) / np.log(2.5)
    put("fig5_saturation_with_force", fi, bool(low > 0 and high < 0.5 * low),
        {"slope_500_1000": _f(low), "slope_2000_5000": _f(high), "mu_s": [_f(x) for x in mu[fi]]})
    present = np.isfinite(vl[fi])
    put("fig8_left_precursor_500_1000_5000", [F500, E0, F5000],
        bool(not present[0] and present[1] and present[3]),
        {"left_present_at_500_1000_2000_5000": [bool(p) for p in present]})
    slopes = {}
    for seg, v in (("left", vl), ("middle", vm), ("right", vr)):
        fit = linfit(np.log(F), np.log(v[fi])) if np.isfinite(v[fi]).sum() >= 2 else None
        if fit is not None and fit["points"] == 2:  # linfit needs 3: two points give the secant
            x, y = np.log(F)[np.isfinite(v[fi])], np.log(v[fi][np.isfinite(v[fi])])
            fit = {"slope": float((y[1] - y[0]) / (x[1] - x[0]))}
        slopes[seg] = None if fit is None else _f(fit["slope"])
    passed = (slopes["left"] is not None and slopes["left"] < -0.1 and slopes["middle"] is not None
              and slopes["middle"] < -0.1 and slopes["right"] is not None and abs(slopes["right"]) < 0.1)
    put("fig8_left_middle_slow_down_right_not", fi, passed, {"loglog_slope_vs_force": slopes})
    fit = linfit(F[present], 1 / vl[fi][present]) if present.sum() >= 3 else None
    put("fig9_inverse_v_left_linear_in_force", fi,
        bool(fit is not None and fit["r2"] >= 0.9 and fit["slope"] > 0),
        {"points": int(present.sum()), "r2": None if fit is None else _f(fit["r2"]),
         "slope_s_per_m_per_N": None if fit is None else _f(fit["slope"])})
    vi = [V5, F500, V3]
    lv = np.log([1e-5, 1e-4, 1e-3])
    fits, good = {}, []
    for seg, v in (("left", vl), ("middle", vm), ("right", vr)):
        if np.isfinite(v[vi]).all():
            f = linfit(lv, np.log(v[vi]))
            fits[seg] = {"exponent": _f(f["slope"]), "r2": _f(f["r2"])}
            good.append(f["slope"] > 0 and f["r2"] >= 0.9)
        else:
            fits[seg] = None
    put("fig10_power_laws_in_v", vi, bool(len(good) >= 2 and all(good)), fits)
    # Fig. 11 from the recorded velocity of the stopped member
    t = ds.time.values
    v = ds.velocity_history.values[k]
    before = t <= STOP
    delays = []
    for j in range(v.shape[1]):
        peak = np.abs(v[before, j]).max()
        loud = np.flatnonzero((t > STOP) & (np.abs(v[:, j]) >= 0.01 * peak))
        delays.append(float(t[loud[-1] + 1] - STOP) if loud.size and loud[-1] + 1 < t.size else
                      (0.0 if not loud.size else np.inf))
    delays = np.array(delays)
    # (a front starting after the stop would keep its nodes above 1 % after it: the delays see it; the
    # stopped member's own front outputs are NaN, since it ends no_peak)
    put("fig11_sudden_stop_stops_every_front", [STOPPED],
        bool(np.all(delays <= 0.05) and np.ptp(delays) < 0.01),
        {"quiet_delay_min_ms": _f(delays.min() * 1e3), "quiet_delay_max_ms": _f(delays.max() * 1e3)})
    ratios, okr = {}, []
    for seg, v in (("left", vl), ("middle", vm), ("right", vr)):
        r = v[[Z_EM, Z_E0, Z_EP]] / v[[EM, E0, EP]]
        ratios[seg] = _f(np.nanmedian(r)) if np.isfinite(r).any() else None
        if ratios[seg] is not None:
            okr.append(abs(ratios[seg] - 1) < 0.15)
    put("fig12_fronts_insensitive_to_eta0", [EM, E0, EP, Z_EM, Z_E0, Z_EP],
        bool(ratios["middle"] is not None and all(okr)), {"median_ratio_without_over_with": ratios})
    m13 = mu[vi]
    f13 = linfit(np.log10([1e-5, 1e-4, 1e-3]), m13)
    put("fig13_mu_s_rises_in_log_v", vi, bool(m13[0] < m13[1] < m13[2] and f13["r2"] >= 0.9),
        {"mu_s": [_f(x) for x in m13], "slope_per_decade": _f(f13["slope"]), "r2": _f(f13["r2"])})
    m14 = mu[[Z_V5, Z_V4, Z_V3]]
    put("fig14_mu_s_falls_to_plateau", [Z_V5, Z_V4, Z_V3],
        bool(m14[0] > m14[1] and abs(m14[1] - m14[2]) < 0.5 * (m14[0] - m14[1])), {"mu_s": [_f(x) for x in m14]})
    no_peak = [int(j) for j in range(M) if j != STOPPED and status[j] == 0
               and not g("mu_s_time")[j] < g("final_time")[j] - 1e-9]
    return dict(claims=out, members_without_peak=no_peak,
                failed_members={int(j): STATUS[int(status[j])] for j in range(M) if not expected(j)},
                mu_s_e0=_f(mu[E0]))


def run(readings: list[dict], nodes: int = 60, device: str = "cpu") -> dict:
    groups: dict[tuple, list[dict]] = {}
    for r in readings:
        groups.setdefault((r["relaxation_gate"], r["poisson_coupling"]), []).append(r)
    results = []
    t0 = time.perf_counter()
    for key, rs in groups.items():
        tg = time.perf_counter()
        ds = _simulate_group(rs, nodes, device)
        for i, r in enumerate(rs):
            entry = {"reading": {k: (v if not isinstance(v, np.generic) else v.item()) for k, v in r.items()},
                     "label": label(r), "scores": {}}
            for event in EVENTS:
                for naming in NAMINGS:
                    s = score(ds, i, i, event, naming)
                    c = s["claims"].values()
                    s["passed"] = sum(x["result"] == "pass" for x in c)
                    s["scored"] = sum(x["result"] != "not scored" for x in c)
                    entry["scores"][f"{event}/{naming}"] = s
            results.append(entry)
        print(f"  group {key}: {len(rs)} readings x {M} members, {time.perf_counter() - tg:.1f} s", file=sys.stderr)
    wall = time.perf_counter() - t0
    keys = [f"{e}/{n}" for e in EVENTS for n in NAMINGS]
    passed_by = {key: {c: sum(r["scores"][key]["claims"][c]["result"] == "pass" for r in results) for c in CLAIMS}
                 for key in keys}
    not_scored = {key: {c: sum(r["scores"][key]["claims"][c]["result"] == "not scored" for r in results) for c in CLAIMS}
                  for key in keys}
    best = sorted(((r["label"], key, r["scores"][key]["passed"], r["scores"][key]["scored"]) for r in results for key in keys),
                  key=lambda x: (-x[2], x[0], x[1]))
    physical = [r for r in results if "counterfactual" not in r["reading"]["torque_arm"]]
    passed_physical = {key: {c: sum(r["scores"][key]["claims"][c]["result"] == "pass" for r in physical)
                             for c in CLAIMS} for key in keys}
    best_physical = [b for b in best if "counterfactual" not in b[0]]
    return dict(claims=CLAIMS, readings=results, passed_by_claim=passed_by, not_scored_by_claim=not_scored,
                best=best[:15], passed_by_claim_physical=passed_physical, best_physical=best_physical[:15],
                physical_readings=len(physical), wall_s=wall, members=len(readings) * M, nodes=nodes,
                device=str(device))


def compact(x):
    """Floats to 6 significant digits (keeps readings_quick.json small)."""
    if isinstance(x, float):
        return float(f"{x:.6g}") if np.isfinite(x) else None
    if isinstance(x, dict):
        return {k: compact(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [compact(v) for v in x]
    return x


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--design", choices=("factorial", "oat"), default="factorial",
                    help="factorial: all 192 readings (~30-55 s on this project's 2 cores: simulate uses every core); oat: "
                         "one factor at a time (24, ~6-10 s)")
    ap.add_argument("--nodes", type=int, default=60, help="grid nodes of every member (default 60)")
    ap.add_argument("--device", default="cpu", help="Warp device: cpu (default), cuda:0")
    ap.add_argument("--out", default=None, help="result file (default ./readings_<design>.json; the committed "
                    "factorial: studies/readings_quick.json)")
    args = ap.parse_args(argv)
    args.out = args.out or f"readings_{args.design}.json"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)  # before minutes of simulation, not after them
    readings = design(args.design)
    print(f"{len(readings)} readings x {M} members, N = {args.nodes}, device {args.device}", file=sys.stderr)
    res = run(readings, args.nodes, args.device)
    res["command"] = "python studies/readings.py " + " ".join(argv if argv is not None else sys.argv[1:])
    res["design"] = args.design
    Path(args.out).write_text(json.dumps(compact(res), separators=(",", ":"), default=float).replace(
        '{"reading":', '\n{"reading":'))
    print(f"wall time {res['wall_s']:.1f} s for {res['members']} members -> {args.out}")
    print(f"best scores of the {res['physical_readings']} physical readings (the -H counterfactual left out, as in "
          "studies/README.md): passed/scored, event/naming, reading")
    for lab, key, p, s in res["best_physical"]:
        print(f"  {p:2d}/{s:2d}  {key:<18} {lab}")
    print(f"passes per claim over the {res['physical_readings']} physical readings (event/naming, claims 1-14 in "
          "order; passed_by_claim in the file counts every reading)")
    for key, counts in res["passed_by_claim_physical"].items():
        print(f"  {key:<18} " + " ".join(f"{n:3d}" for n in counts.values()))


if __name__ == "__main__":
    main()
