"""The diagnosis's fast open-loop simulation is phfdi.loop.simulate_open_loop, arranged for speed."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import Evaluator, Start, nominal_raw
from phfdi.loop import simulate, simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.spec import validate_scenario

NO_NOISE = ["sensors.ph.noise_std=0", "sensors.level.noise_std=0", "duration_s=1500",
            "setpoints.ph.changes.0.at_s=600"]


@pytest.fixture(scope="module")
def closed_loop_run():
    raw = nominal_raw("paper", NO_NOISE)
    raw["faults"] = [{"type": "backlash", "params": {"width_pct": 2.0}, "onset_s": 0.0}]
    return simulate(validate_scenario(raw))


@pytest.mark.parametrize("extension", [
    None,
    {"faults": [{"type": "stiction", "params": {"s_pct": 2.0, "j_pct": 0.8}}]},
    {"faults": [{"type": "coulomb_viscous_friction", "params": {"coulomb_pct": 1.0, "mobility_per_s": 0.1}}]},
    {"sensors": {"ph": {"extra": [{"type": "sensor_lag", "params": {"tau_s": 12.0}},
                                  {"type": "sensor_delay", "params": {"delay_s": 3.5}},
                                  {"type": "sensor_gain", "params": {"gain": 0.9}}]}}},
    {"plant": {"tank": {"area_cm2": 260.0}}},
])
def test_evaluator_equals_simulate_open_loop(closed_loop_run, extension):
    run = closed_loop_run
    inputs = Record.of({k: run[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct")})
    raw = nominal_raw("paper", NO_NOISE)
    if extension:
        for key, value in extension.items():
            if key == "plant":
                raw["plant"]["tank"].update(value["tank"])
            elif key == "sensors":
                raw["sensors"]["ph"]["extra"] = value["ph"]["extra"]
            else:
                raw[key] = copy.deepcopy(value)
    reference = simulate_open_loop(validate_scenario(raw), inputs)
    record = make_record({k: run[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct",
                                              "ph_measured", "level_measured_cm")}, "run")
    pred = Evaluator(record, raw, level_from_data=False).predict(raw)
    assert np.max(np.abs(pred.outputs["ph_measured"] - reference["ph_measured"])) < 1e-8
    assert np.max(np.abs(pred.outputs["level_measured_cm"] - reference["level_measured_cm"])) < 1e-9
    assert np.max(np.abs(pred.flows_ml_s[:, 0] - reference["acid_flow_ml_s"])) < 1e-12


def test_stages_are_reused_and_starts_matter(closed_loop_run):
    run = closed_loop_run
    record = make_record({k: run[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct",
                                              "ph_measured", "level_measured_cm")}, "run")
    raw = nominal_raw("paper")
    ev = Evaluator(record, raw)
    a = ev.predict(raw)
    lagged = copy.deepcopy(raw)
    lagged["sensors"]["ph"]["extra"] = [{"type": "sensor_lag", "params": {"tau_s": 20.0}}]
    b = ev.predict(lagged)
    assert a.ph_true is b.ph_true or np.array_equal(a.ph_true, b.ph_true)  # plant stage from the cache
    assert not np.allclose(a.outputs["ph_measured"], b.outputs["ph_measured"])
    backlash = copy.deepcopy(raw)
    backlash["faults"] = [{"type": "backlash", "params": {"width_pct": 2.0}}]
    c0 = ev.predict(backlash, Start(valve_offset_pct=0.0))
    c1 = ev.predict(backlash, Start(valve_offset_pct=0.9))
    # the valve rests 0.9 % higher until the command crosses the band: more acid, lower pH at first
    assert c1.flows_ml_s[0, 0] > c0.flows_ml_s[0, 0]
