"""Feed-line blocks (dead time, pump curve, pump lag) and the new probe blocks, alone and inside a run."""

from __future__ import annotations

import math

import numpy as np
import pytest

import ph_plant_sim.feedlines  # noqa: F401
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import Evaluator, nominal_raw
from phfdi.loop import simulate, simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.blocks import make_block
from phfdi_base.spec import validate_scenario


def run_block(name, params, x, dt_s=1.0):
    b = make_block(name, params, dt_s=dt_s)
    b.reset(x[0])
    return np.array([b.step(v, k * dt_s) for k, v in enumerate(x)])


def test_line_delay_shifts_a_pulse_by_its_dead_time():
    x = np.zeros(40)
    x[10:20] = 5.0
    y = run_block("line_delay", {"delay_s": 3.0}, x)
    assert np.array_equal(np.flatnonzero(y > 0), np.arange(13, 23))


def test_pump_curve_threshold_and_gain():
    y = run_block("pump_curve", {"gain": 0.8, "threshold_ml_s": 1.0}, np.array([0.0, 0.5, 1.0, 3.0, 6.0]))
    assert np.allclose(y, [0.0, 0.0, 0.0, 1.6, 4.0])
    with pytest.raises(ValueError, match="gain"):
        make_block("pump_curve", {"gain": -1.0})


def test_pump_lag_starts_and_stops_with_its_own_time_constants():
    x = np.r_[np.zeros(5), np.full(30, 6.0), np.zeros(30)]
    y = run_block("pump_lag", {"tau_start_s": 2.0, "tau_stop_s": 8.0}, x)
    # one time constant after the start 63 % delivered; after the stop the slower decay
    assert y[5 + 1] == pytest.approx(6.0 * (1 - math.exp(-1.0)))
    assert y[35 + 7] == pytest.approx(y[34] * math.exp(-8 / 8.0), rel=1e-9)


def test_asymmetric_lag_rises_and_falls_at_different_rates():
    x = np.r_[np.full(3, 3.0), np.full(40, 10.0), np.full(40, 3.0)]
    y = run_block("sensor_asymmetric_lag", {"tau_up_s": 2.0, "tau_down_s": 10.0}, x)
    up = np.argmax(y[3:] > 3.0 + 0.632 * 7.0)
    down = np.argmax(y[43:] < 10.0 - 0.632 * (10.0 - 3.0))
    assert up in (1, 2) and 9 <= down <= 11


def test_second_order_probe_starts_with_zero_slope_and_two_point_calibration():
    x = np.r_[np.full(3, 7.0), np.full(60, 9.0)]
    y = run_block("sensor_second_order", {"tau1_s": 5.0, "tau2_s": 5.0}, x)
    first = run_block("sensor_lag", {"tau_s": 10.0}, x)
    assert y[3] - 7.0 < 0.5 * (first[3] - 7.0)  # slower start than one lag of the same total time
    assert y[-1] == pytest.approx(9.0, abs=0.01)
    z = run_block("two_point_calibration", {"slope": 0.95, "offset": 0.1}, np.array([4.0, 7.0, 10.0]))
    assert np.allclose(z, [7.0 - 2.85 + 0.1, 7.1, 7.0 + 2.85 + 0.1])


LINE = {"acid": [{"type": "line_delay", "params": {"delay_s": 20.0}},
                 {"type": "pump_curve", "params": {"gain": 0.9, "threshold_ml_s": 0.5}},
                 {"type": "pump_lag", "params": {"tau_start_s": 3.0, "tau_stop_s": 6.0}}]}
SHORT = ["duration_s=1500", "setpoints.ph.changes.0.at_s=600", "sensors.ph.noise_std=0",
         "sensors.level.noise_std=0"]


def test_a_feed_line_is_a_scenario_edit_the_loop_runs_and_the_diagnosis_simulates_identically():
    raw = nominal_raw("paper", SHORT)
    plain = simulate(validate_scenario(raw))
    raw["plant"]["feeds"]["acid"]["line"] = LINE["acid"]
    spec = validate_scenario(raw)
    lined = simulate(spec)
    assert np.max(np.abs(lined["ph_true"] - plain["ph_true"])) > 0.05  # the line changes the loop
    inputs = Record.of({k: lined[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct")})
    reference = simulate_open_loop(spec, inputs)
    record = make_record({k: lined[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct",
                                                "ph_measured", "level_measured_cm")}, "run")
    pred = Evaluator(record, raw, level_from_data=False).predict(raw)
    assert np.max(np.abs(pred.outputs["ph_measured"] - reference["ph_measured"])) < 1e-8


def test_a_bad_line_block_names_its_key():
    from phfdi_base.errors import UserError

    raw = nominal_raw("paper", SHORT)
    raw["plant"]["feeds"]["acid"]["line"] = [{"type": "pump_curve", "params": {"gain": -2.0}}]
    with pytest.raises(UserError, match=r"plant.feeds.acid.line.0: gain"):
        simulate(validate_scenario(raw))
