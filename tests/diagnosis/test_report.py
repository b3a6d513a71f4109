"""The shared report vocabulary (also used by phfdi loop-diagnose)."""

from __future__ import annotations

import json

import pytest

from phfdi.diagnosis.report import CAUSES, REPORT_KEYS, VERDICTS, check_report, family_of, to_json


def test_catalogue_identifiers():
    assert set(CAUSES) == {"stiction", "backlash", "deadzone", "saturation", "coulomb_viscous_friction", "leakage",
                           "valve_gain", "sensor_delay", "sensor_lag", "sensor_bias", "sensor_drift", "sensor_gain",
                           "buffer", "reagent_concentration", "holdup", "disturbance_flow", "none",
                           # structural (--structure, or named with --candidates)
                           "mixing_zone", "feed_delay", "pump_curve", "carbonate", "probe_asymmetric_lag",
                           "two_point_calibration", "pump_lag", "sensor_second_order", "tanks_in_series",
                           "co2_absorption", "flask_contents"}
    assert VERDICTS == ("explained", "not_explained", "none", "not_identifiable")
    assert family_of("backlash+sensor_lag") == "actuator+sensor"
    assert family_of("buffer+holdup") == "process"
    with pytest.raises(ValueError):
        family_of("gremlins")


def test_check_report_and_json():
    rep = {k: None for k in REPORT_KEYS}
    rep.update({"verdict": "explained", "cause": "sensor_bias", "family": "sensor", "parameters": {"bias": 0.2},
                "ranking": [{"cause": "sensor_bias", "family": "sensor", "parameters": {"bias": 0.2},
                             "confidence_intervals": {"bias": [0.19, 0.21]}, "nrmse_validation": 0.01,
                             "aic": 1.0, "bic": float("nan")}], "reason": "x"})
    assert json.loads(to_json(check_report(rep)))["ranking"][0]["bic"] is None
    with pytest.raises(ValueError, match="family"):
        check_report(dict(rep, family="process"))
    with pytest.raises(ValueError, match="verdict"):
        check_report(dict(rep, verdict="probably"))
