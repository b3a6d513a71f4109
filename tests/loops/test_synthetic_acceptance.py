"""Acceptance: closed loops with known valve faults, disturbances and tunings are named correctly.

Loops of :func:`phfdi.loopdiag.synthetic.acceptance_cases`: FOPTD (and one level) processes
under PI control with each valve block of valve_actuator at known parameters, and clean valves
with an external oscillating disturbance, an aggressive tuning, or nothing wrong.
"""

from __future__ import annotations

import pytest

from phfdi.loopdiag.synthetic import acceptance_cases

CASES = acceptance_cases()
#: stated tolerance of the Kano parameters: S within 10 % of S, J within 10 % of S
S_TOL = 0.10


@pytest.mark.parametrize("name", list(CASES))
def test_cause_is_named(synthetic_reports, name):
    rep = synthetic_reports[name]
    case = CASES[name]
    assert rep["cause"] == case.cause, f"{name}: {rep['cause']} ({rep['reason']})"
    expected_verdict = "none" if case.cause == "none" else "explained"
    assert rep["verdict"] == expected_verdict


@pytest.mark.parametrize("name", [n for n, c in CASES.items() if c.cause == "stiction"])
def test_kano_parameters_recovered(synthetic_reports, name):
    truth = CASES[name].parameters
    got = synthetic_reports[name]["parameters"]
    s = truth["s_pct"]
    assert abs(got["s_pct"] - s) <= S_TOL * s, got
    assert abs(got["j_pct"] - truth["j_pct"]) <= S_TOL * s, got


def test_other_parameters_near_the_truth(synthetic_reports):
    assert synthetic_reports["backlash"]["parameters"]["width_pct"] == pytest.approx(2.0, rel=0.1)
    assert synthetic_reports["saturation"]["parameters"]["high_pct"] == pytest.approx(54.0, abs=1.5)
    dz = synthetic_reports["deadzone"]["parameters"]
    assert dz["center_pct"] == pytest.approx(50.0, abs=0.5)
    assert dz["width_pct"] == pytest.approx(3.0, rel=0.25)


def test_valve_faults_beat_the_linear_model_on_held_out_data(synthetic_reports):
    for name, case in CASES.items():
        rep = synthetic_reports[name]
        if rep["family"] == "actuator":
            assert rep["nrmse_extended"] < rep["nrmse_nominal"]
            assert rep["gain_percent"] >= 10.0
            assert rep["ranking"][0]["nrmse_validation"] <= rep["ranking"][-1]["nrmse_validation"]


def test_non_oscillating_healthy_loop_is_reported_as_such(synthetic_reports):
    rep = synthetic_reports["healthy"]
    assert rep["oscillation"]["oscillating"] is False
    assert rep["family"] == "none" and rep["parameters"] == {}
    assert "does not oscillate" in rep["reason"]


def test_stiction_limit_cycle_is_detected_first(synthetic_reports):
    osc = synthetic_reports["stiction"]["oscillation"]
    assert osc["oscillating"] and osc["regularity"] > 1 and osc["period_s"] > 0
