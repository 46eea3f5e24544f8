"""Every study's --quick mode runs under the default friction law (relaxation_gate = "stress", the
yield gate of GRL 2012), and its output still holds what studies/README.md says of it (the statements
marked "tested" there); plus a two-reading subset of studies/readings.py, and the committed
factorial (studies/readings_quick.json) against the README's score table."""

import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import DEVICE

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
import figures  # noqa: E402
import readings  # noqa: E402


@pytest.fixture(scope="module")
def claims(tmp_path_factory):
    out = tmp_path_factory.mktemp("studies")
    result = {name: figures.run_study(name, True, DEVICE, out) for name in figures.STUDIES}
    result["_files"] = sorted(p.name for p in out.iterdir())
    return result


def test_every_study_writes_its_files_and_every_member_ends_ok_after_its_peak(claims):
    for name in figures.STUDIES:
        for ext in ("nc", "png", "json"):
            assert f"{name}_quick.{ext}" in claims["_files"]
        pc = claims[name]["peak_check"]
        if name == "fig11":  # the stopped disc has no peak of its own (test_fig11_motion_stops_together)
            assert pc["status_counts"] == {"ok": 1, "no_peak": 2}, pc
            continue
        assert pc["members_without_peak"] == 0 and pc["failed_members"] == 0, (name, pc)
        assert set(pc["status_counts"]) == {"ok"}, (name, pc)
    # the engine's automatic end: the default scenes end 1 % past the peak, near 20.27-20.30 s (the
    # contact front does not wait for the pad to spring back), the 1e-6 m/s members run past 22 s to
    # their peak and end well before max_end_time
    assert 20.25 < claims["choices"]["peak_check"]["max_final_time"] < 21.0
    assert 20.25 < claims["fig4"]["peak_check"]["max_final_time"] < 21.0
    for name in ("fig10", "map"):
        assert 22.0 < claims[name]["peak_check"]["max_final_time"] < 30.0, name
    # fig3 and fig11 keep their explicit end times (recorded time grids)
    assert claims["fig3"]["peak_check"]["max_final_time"] == pytest.approx(20.6)
    assert claims["fig11"]["peak_check"]["max_final_time"] == pytest.approx(20.4)


def test_fig3_contact_front_starts_at_the_trailing_edge_before_the_peak(claims):
    """The contact front (default) at e = 0: it nucleates at the trailing edge +L/2 (the paper: the left
    edge, so the paper's left is our trailing edge, or torque_arm 0: test_choices...) and the pad has
    detached at 20.126-20.136 s, before the mu_s peak (20.232 s; the paper: 20.14-20.18 s). It is two
    fronts: the first runs from +100 mm at 16.3 m/s, with no slower segment at either end, a second
    starts at the leading edge -100 mm 8.8 ms later and runs at 33.0 m/s; they meet at -61.6 mm."""
    c = claims["fig3"]
    assert c["nucleation_edge"] == 1 and c["nucleation_position"] == pytest.approx(0.1)
    assert 20.12 < c["front_start_time"] < c["front_end_time"] < 20.14 < c["mu_s_time"]
    assert c["front_count"] == 2 and c["second_nucleation_position"] == pytest.approx(-0.1)
    assert c["front_start_time"] < c["second_front_start_time"] < c["collision_time"] == c["front_end_time"]
    assert 15 < c["v_first"] == c["v_middle"] < 18 and np.isnan(c["v_left"]) and np.isnan(c["v_right"])
    assert 30 < c["v_second"] < 36 and -0.07 < c["collision_position"] < -0.05


def test_fig4_variation_and_sign_and_figs6_7(claims):
    c = claims["fig4"]
    assert 0.1 < c["variation_percent"] < 0.4  # paper: ~0.5 %
    assert c["trend_slope_per_unit_e"] < 0 and c["mu_s_trailing_half_minus_leading_half"] < 0  # paper: > 0
    # two fronts where the load is not towards the trailing edge (e <= 0.05); a left segment of the
    # first front only at e >= 0.15 (one front, nucleating inside the pad): Figs. 6, 7 have 5 points
    assert c["members_with_two_fronts"] == 9 and c["left_present"] == 5
    assert c["fig7_mu_s_vs_left_length"]["slope"] < 0  # the paper: mu_s grows with the precursor length
    assert c["fig6_mu_s_vs_v_left"]["r2"] < 0.7


def test_fig5_no_saturation_and_figs8_9_the_left_precursor_appears_with_force(claims):
    """mu_s does not saturate with force. The first contact front has a left segment only at 100 N
    (the paper: a left precursor absent at 500 N, present at 1000-5000 N), so Fig. 9 has one point.
    A front from the left edge appears with force: none at 100-316 N, the second front at 562-1778 N,
    the first front from 3162 N on, and it slows down with force (log-log slope below -1); the
    first front's middle slows down too."""
    c = claims["fig5"]
    assert c["increase_last_decade"] > c["increase_first_decade"] > 0
    assert c["left_present"] == 1 and c["lowest_force_with_left_precursor"] == pytest.approx(100.0)
    assert c["fig9_inverse_v_left_vs_force"]["points"] == 1
    edge = np.asarray(c["left_edge_front_speed_by_force"], float)
    np.testing.assert_array_equal(np.isfinite(edge), [False] * 3 + [True] * 6)
    assert c["left_edge_front_is_the_second"] == [False] * 3 + [True] * 3 + [False] * 3
    assert c["log_left_edge_front_speed_vs_log_force"]["slope"] < -1
    assert c["v_middle_median"] < c["shear_wave_speed"] / 10
    assert c["fig8_log_v_middle_vs_log_force"]["slope"] < -0.1


def test_fig10_power_laws_and_figs13_14(claims):
    c = claims["fig10"]
    for seg in ("left", "middle", "right"):
        fit = c[f"log_v_{seg}_vs_log_vd"]
        assert 0.2 < fit["slope"] < 1.0 and fit["r2"] > (0.85 if seg == "middle" else 0.99), (seg, fit)
    f13 = c["fig13_mu_s_vs_log_vd_with_strengthening"]
    assert f13["slope"] > 0 and f13["r2"] > 0.95
    assert 0 <= c["fig14_drop_second_half"] < c["fig14_drop_first_half"] / 3


def test_fig11_motion_stops_together(claims):
    """The stopped members (0: at 20.15 s, 2: at 20.13 s) end no_peak: their discs stop before the
    uninterrupted member's mu_s peak (20.23 s), so the largest mu each saw, at the stop, is no mu_s.
    Every node of each falls below 1 % of its pre-stop peak within a spread of 10 ms and within 50 ms,
    also for the stop inside the contact front (20.126-20.136 s), where the paper's stop falls."""
    c = claims["fig11"]
    assert c["status"] == [4, 0, 4]  # no_peak, ok, no_peak (STATUS_MEANINGS)
    for prefix in ("", "inside_front_"):
        assert c[f"{prefix}node_quiet_delay_max"] - c[f"{prefix}node_quiet_delay_min"] < 0.01, prefix
        assert c[f"{prefix}node_quiet_delay_max"] < 0.05, prefix
    assert c["inside_front_stop_time"] == 20.13 and c["stop_time"] == 20.15


def test_fig12_contact_fronts_are_nearly_insensitive_to_eta0(claims):
    """Fig. 12 with the contact front: the eta = 0 / eta speed ratios have medians within 15 % of 1 for
    every segment (the paper's claim; the velocity rule's single ratios scattered over 0.03-9.4); one
    eccentricity's middle ratio is an outlier (e = 0.1: 6.4), not resolved at this size."""
    c = claims["fig12"]
    for seg in ("left", "middle", "right"):
        assert abs(c[f"v_{seg}_ratio_median"] - 1) < 0.15, seg
    r = np.asarray(c["v_middle_ratio_without_over_with"], float)
    assert np.all(np.isfinite(r)) and np.sum(np.abs(r - 1) < 0.3) >= 4


def test_choices_torque_arm_0_nucleates_at_the_left_edge(claims):
    """Which edge the contact front starts from: the trailing edge with the plate's friction torque at
    H or 2H, the leading (left) edge with torque_arm 0 (the paper's Fig. 3) and with the
    counterfactual -H; mu_s falls with e in every physical reading."""
    rows = {k: v for k, v in claims["choices"].items() if k != "peak_check"}
    physical = {k: r for k, r in rows.items() if "counterfactual" not in k}
    assert rows["torque_arm=0"]["nucleation_edge_e0"] == -1
    assert all(r["nucleation_edge_e0"] == 1 for k, r in physical.items() if k != "torque_arm=0")
    assert all(r["dmu_de"] < 0 for r in physical.values())
    assert rows["torque_arm=-H (counterfactual)"]["dmu_de"] > 0  # only the reversed torque flips the sign


def test_beyond_the_paper_runs(claims):
    m = claims["map"]
    assert m["ok"] == m["members"]
    # the first front's left segment: none at e = -0.3, in every member at e = +0.3 (one front, nucleating
    # inside the pad), about half of the members at every disc velocity
    by_e = m["left_precursor_fraction_by_eccentricity"]
    assert by_e[0] == 0 and by_e[-1] == 1 and all(a <= b for a, b in zip(by_e, by_e[1:]))
    assert all(0.3 < f < 0.7 for f in m["left_precursor_fraction_by_velocity"])
    u = claims["uncertainty"]
    # the 47 members whose steady sliding stays below tau_c used to chatter on the gate until
    # max_steps; with the implicit Filippov sliding every member ends ok
    assert u["ok"] == u["members"] == 200 and u["failed_status"] == []
    assert u["steady_stress_below_tau_c"] == 47 and u["failed_and_below_tau_c"] == 0
    assert 0.55 < u["mu_s_mean"] < 0.70 and 0.15 < u["mu_s_std"] < 0.32
    assert u["correlation_mu_s"]["interface_stiffness"] > 0.5 and u["correlation_mu_s"]["memory_length"] > 0.3


def _marks(score):
    return "".join("P" if v["result"] == "pass" else ("-" if v["result"] == "not scored" else ".")
                   for v in score["claims"].values())


def test_readings_two_reading_subset():
    """The stress-gate and gate-less defaults, every front event, both edge namings: every member
    ends ok, and the scores studies/README.md quotes for them (its score table)."""
    res = readings.run([readings.DEFAULT, readings.DEFAULT | {"relaxation_gate": "none"}], nodes=60, device=DEVICE)
    stress, none = res["readings"]
    assert all(s["failed_members"] == {} and s["members_without_peak"] == [] for r in res["readings"]
               for s in r["scores"].values())
    # the contact front of the stress gate: the paper's time window (claim 2) and, with the paper's
    # left read as our trailing edge, its left-edge nucleation and the sign of Fig. 4
    assert _marks(stress["scores"]["contact/spec"]) == ".P.......PP.PP"
    assert _marks(stress["scores"]["contact/mirrored"]) == "PP..P....PP.PP"
    assert _marks(stress["scores"]["velocity/spec"]) == ".........PP.PP"
    assert _marks(none["scores"]["velocity/spec"]) == "..P......PPPPP"
    # no yield threshold: no contact front, so no front claim passes with it
    assert _marks(none["scores"]["contact/spec"]) == "..........P.PP"


def test_committed_factorial_holds_the_readme_score_table():
    """studies/readings_quick.json (python studies/readings.py --design factorial --device cpu --out
    studies/readings_quick.json) holds the pass counts studies/README.md quotes (physical readings:
    without the -H counterfactual); no claim is left unscored."""
    import json

    res = json.loads((Path(readings.__file__).with_name("readings_quick.json")).read_text())
    assert res["members"] == 192 * readings.M and res["nodes"] == 60 and len(res["readings"]) == 192
    assert all(s["failed_members"] == {} and s["members_without_peak"] == [] for r in res["readings"]
               for s in r["scores"].values())
    assert all(set(counts.values()) == {0} for counts in res["not_scored_by_claim"].values())
    physical = [r for r in res["readings"] if "counterfactual" not in r["reading"]["torque_arm"]]
    counts = {key: [sum(r["scores"][key]["claims"][c]["result"] == "pass" for r in physical) for c in readings.CLAIMS]
              for key in res["passed_by_claim"]}
    assert counts["contact/spec"] == [16, 44, 0, 8, 2, 20, 0, 0, 8, 24, 62, 30, 144, 144]
    assert counts["contact/mirrored"] == [28, 44, 0, 8, 142, 20, 0, 0, 8, 24, 62, 30, 144, 144]
    assert counts["velocity/spec"] == [24, 12, 22, 8, 2, 20, 0, 6, 8, 46, 62, 80, 144, 144]
    best = {key: max(r["scores"][key]["passed"] for r in physical) for key in res["passed_by_claim"]}
    assert best == {"contact/spec": 8, "contact/mirrored": 9, "strength/spec": 7, "strength/mirrored": 8,
                    "velocity/spec": 6, "velocity/mirrored": 8}

def test_work_precision_simulates_with_its_reference_s_law():
    """work_precision.py simulated with the package defaults (the stress gate, the contact front)
    against whatever reference it was given, the committed gate-less one among them: two laws in one
    error. It takes the law and the event from the reference: the committed files name theirs (the
    stress one) or predate the names (the gate-less one: its defaults then)."""
    import work_precision
    from warpfric.io import open_ensemble

    root = Path(__file__).resolve().parents[1] / "studies" / "reference"
    for name, gate, event in (("reference_scenes.nc", "none", "velocity"),
                              ("reference_scenes_stress.nc", "stress", "contact")):
        ref = open_ensemble(root / name)
        model, fronts = work_precision.reference_law(ref)
        assert (model.relaxation_gate, fronts.events) == (gate, (event,)), name
        members, idx = work_precision.scene_members(ref, 20)  # 18 scenes tiled
        assert idx.tolist() == list(range(18)) + [0, 1]
        np.testing.assert_array_equal(members["eccentricity"][:18], ref.eccentricity.values)
        assert ref.sizes["member"] == 18 and (ref.viscous_coefficient.values == 0).sum() == 9


def test_work_precision_runs_its_reference_s_law(tmp_path, monkeypatch):
    """run() itself: every simulate it calls (warm-up and timed) gets the reference's Model and
    Fronts, and its rows name them (two scenes, N = 11, rtol 1e-3: a fraction of a second)."""
    import argparse

    import work_precision

    calls = []
    real = work_precision.wf.simulate

    def simulate(*args, **kwargs):
        calls.append((kwargs["model"].relaxation_gate, kwargs["fronts"].events))
        return real(*args, **kwargs)

    monkeypatch.setattr(work_precision.wf, "simulate", simulate)
    out = tmp_path / "wp.nc"
    args = argparse.Namespace(device=DEVICE, members=2, nodes=[11], rtols=[1e-3], dtypes=["float64"],
                              reference=str(work_precision.REFERENCE), out=str(out), argv=[],
                              error_filter_nodes=work_precision.wf.Solver().error_filter_nodes)
    work_precision.run(args)
    assert calls == [("none", ("velocity",))] * 2
    import json
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [(r["relaxation_gate"], r["front_event"], r["ok"]) for r in rows] == [("none", "velocity", 2)]
    assert rows[0]["mean_steps_viscous"] > 0 and rows[0]["mean_steps_inviscid"] > 0
