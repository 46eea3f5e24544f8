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
        assert pc["members_without_peak"] == 0 and pc["failed_members"] == 0, (name, pc)
        assert set(pc["status_counts"]) == {"ok"}, (name, pc)
    # the engine's automatic end: the default scenes end near 20.48 s (not the old fixed 22 s), the
    # 1e-6 m/s members run past 22 s to their peak (~22.3-22.8 s) and end well before max_end_time
    assert 20.3 < claims["choices"]["peak_check"]["max_final_time"] < 21.0
    assert 20.3 < claims["fig4"]["peak_check"]["max_final_time"] < 21.0
    for name in ("fig10", "map"):
        assert 23.0 < claims[name]["peak_check"]["max_final_time"] < 30.0, name
    # fig3 and fig11 keep their explicit end times (recorded time grids)
    assert claims["fig3"]["peak_check"]["max_final_time"] == pytest.approx(20.6)
    assert claims["fig11"]["peak_check"]["max_final_time"] == pytest.approx(20.4)


def test_fig3_front_nucleates_inside_and_after_the_peak(claims):
    c = claims["fig3"]
    assert c["v_left"] < c["v_middle"] / 1.5 and c["v_right"] < c["v_middle"] / 1.5
    assert -0.06 < c["left_front_end"] < -0.04  # paper: -45 mm
    assert 0.0 < c["right_front_start"] < 0.03  # paper: +55 mm; the stress gate moves it to +11 mm (+9.5 mm at N = 200)
    assert 45 < c["v_middle"] < 60  # 52.6 m/s quick, 54.8 at N = 200 (the linear interpolation gave 44.2 there)
    assert c["nucleation_edge"] == 0 and -0.05 < c["nucleation_position"] < 0.0  # not the paper's left edge
    assert c["front_start_time"] > c["mu_s_time"] and 20.24 < c["front_start_time"] < 20.30  # paper: 20.14-20.18 s


def test_fig4_variation_and_sign_and_figs6_7(claims):
    c = claims["fig4"]
    assert 0.1 < c["variation_percent"] < 0.4  # paper: ~0.5 %
    assert c["trend_slope_per_unit_e"] < 0 and c["mu_s_trailing_half_minus_leading_half"] < 0  # paper: > 0
    assert c["fig7_mu_s_vs_left_length"]["r2"] > 0.6 and c["fig7_mu_s_vs_left_length"]["slope"] < 0
    assert c["fig6_mu_s_vs_v_left"]["r2"] < 0.7


def test_fig5_no_saturation_and_figs8_9_no_slowing(claims):
    c = claims["fig5"]
    assert c["increase_last_decade"] > c["increase_first_decade"] > 0
    assert c["left_present"] == len(c["normal_force"])
    assert c["v_middle_median"] < c["shear_wave_speed"] / 10
    assert c["fig8_log_v_left_vs_log_force"]["slope"] > 0 and c["fig8_log_v_middle_vs_log_force"]["slope"] > 0
    assert abs(c["fig8_log_v_right_vs_log_force"]["slope"]) < 0.1
    assert c["fig9_inverse_v_left_vs_force"]["slope"] < 0  # the paper's 1/v_left grows with F


def test_fig10_power_laws_and_figs13_14(claims):
    c = claims["fig10"]
    for seg in ("left", "middle", "right"):
        fit = c[f"log_v_{seg}_vs_log_vd"]
        assert 0.2 < fit["slope"] < 1.0 and fit["r2"] > (0.7 if seg == "middle" else 0.95), (seg, fit)
    f13 = c["fig13_mu_s_vs_log_vd_with_strengthening"]
    assert f13["slope"] > 0 and f13["r2"] > 0.95
    assert 0 <= c["fig14_drop_second_half"] < c["fig14_drop_first_half"] / 3


def test_fig11_motion_stops_together(claims):
    c = claims["fig11"]
    assert c["status"] == [0, 0]
    assert c["node_quiet_delay_max"] - c["node_quiet_delay_min"] < 0.01 and c["node_quiet_delay_max"] < 0.05


def test_fig12_quick_under_the_gate_scatters_over_two_orders_of_magnitude(claims):
    c = claims["fig12"]
    # every eccentricity pairs a middle front, and the single eta = 0 / eta ratios scatter over more
    # than two orders of magnitude, on both sides of 1 (located switches 0.035-9.4, predicted
    # switches 0.011-5.5). Their median
    # is not tested: it is not resolved at this size (studies/README.md, Fig. 12): changing how the
    # gate switches are located, within their tolerance, moved it from 1.24 to 0.11 and paired one
    # left front, and at rtol 1e-6 the eta = 0 members run out of 100,000 steps
    r = np.asarray(c["v_middle_ratio_without_over_with"], float)
    assert np.all(np.isfinite(r)) and r.min() < 1 < r.max() and r.max() / r.min() > 100


def test_choices_none_nucleates_at_the_left_edge(claims):
    rows = {k: v for k, v in claims["choices"].items() if k != "peak_check"}
    physical = {k: r for k, r in rows.items() if "counterfactual" not in k}
    assert all(r["nucleation_edge_e0"] != -1 for r in physical.values())
    assert all(r["dmu_de"] < 0 for r in physical.values())
    assert rows["torque_arm=2H"]["nucleation_edge_e0"] == 1
    assert rows["torque_arm=-H (counterfactual)"]["dmu_de"] > 0  # only the reversed torque flips the sign


def test_beyond_the_paper_runs(claims):
    m = claims["map"]
    assert m["ok"] == m["members"]
    assert m["left_precursor_fraction_by_velocity"][0] > 0.5  # at 1e-6 m/s, once the run reaches the peak
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
    """studies/readings_quick.json (python studies/readings.py --design factorial --device cpu) holds
    the pass counts studies/README.md quotes (physical readings: without the -H counterfactual); no
    claim is left unscored."""
    import json

    res = json.loads((Path(readings.__file__).with_name("readings_quick.json")).read_text())
    assert res["members"] == 192 * readings.M and res["nodes"] == 60 and len(res["readings"]) == 192
    assert all(s["failed_members"] == {} and s["members_without_peak"] == [] for r in res["readings"]
               for s in r["scores"].values())
    assert all(set(counts.values()) == {0} for counts in res["not_scored_by_claim"].values())
    physical = [r for r in res["readings"] if "counterfactual" not in r["reading"]["torque_arm"]]
    counts = {key: [sum(r["scores"][key]["claims"][c]["result"] == "pass" for r in physical) for c in readings.CLAIMS]
              for key in res["passed_by_claim"]}
    assert counts["contact/spec"] == [16, 44, 0, 8, 2, 20, 10, 0, 24, 22, 62, 31, 144, 144]
    assert counts["contact/mirrored"] == [28, 44, 0, 8, 142, 20, 2, 0, 14, 22, 62, 31, 144, 144]
    assert counts["velocity/spec"] == [24, 12, 22, 8, 2, 20, 0, 6, 8, 46, 62, 61, 144, 144]
    best = {key: max(r["scores"][key]["passed"] for r in physical) for key in res["passed_by_claim"]}
    assert best == {"contact/spec": 8, "contact/mirrored": 9, "strength/spec": 7, "strength/mirrored": 8,
                    "velocity/spec": 6, "velocity/mirrored": 7}