"""The closed loop of the paper scenario: tuning facts, fault effects, determinism, open loop."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loop import simulate, simulate_open_loop
from phfdi.records.record import Record
from phfdi.scenario import load_scenario


def window(run: Record, name: str, t0: float, t1: float) -> np.ndarray:
    t = run.time_s
    return run[name][(t >= t0) & (t < t1)]


@pytest.fixture(scope="module")
def healthy() -> Record:
    return simulate(load_scenario("paper", fault="healthy"))


@pytest.fixture(scope="module")
def delayed() -> Record:
    return simulate(load_scenario("paper", fault="healthy", overrides=["sensors.ph.delay_s=10"]))


def test_healthy_loop_settles_within_a_tenth_of_each_setpoint(healthy):
    for sp, (t0, t1) in ((12.0, (3000, 5000)), (8.0, (6000, 10001))):
        ph = window(healthy, "ph_true", t0, t1)
        assert np.max(np.abs(ph - sp)) < 0.1
        assert np.ptp(ph) < 0.05  # no sustained oscillation
    # and it gets there within about ten minutes of the setpoint change
    ph = window(healthy, "ph_true", 5600, 6000)
    assert np.max(np.abs(ph - 8.0)) < 0.1


def test_same_tuning_oscillates_after_the_setpoint_change_with_10s_probe_delay(delayed):
    # settles at pH 12 (low process gain) ...
    assert np.ptp(window(delayed, "ph_true", 3000, 5000)) < 0.05
    # ... and oscillates around pH 8 (high gain) without dying out, as the paper's Figure 16
    early = np.ptp(window(delayed, "ph_true", 6000, 7000))
    late = np.ptp(window(delayed, "ph_true", 9000, 10001))
    assert late > 0.5
    assert late > 0.8 * early
    u = window(delayed, "ph_controller_output_pct", 9000, 10001)
    assert np.ptp(u) > 5.0  # considerable control effort (Figure 17)


def test_runs_are_deterministic_for_a_seed():
    short = ["duration_s=1500", "faults.0.onset_s=500", "setpoints.ph.changes.0.at_s=700"]
    spec = load_scenario("paper", fault="stiction", overrides=short)
    a, b = simulate(spec), simulate(spec)
    for name in a.names:
        assert np.array_equal(a[name], b[name], equal_nan=True), name
    other = simulate(load_scenario("paper", fault="stiction", overrides=short + ["seed=2"]))
    assert not np.array_equal(a["ph_measured"], other["ph_measured"])


@pytest.fixture(scope="module")
def faulty() -> dict[str, Record]:
    return {f: simulate(load_scenario("paper", fault=f))
            for f in ("backlash", "friction", "deadzone", "saturation", "stiction")}


def test_saturation_stops_the_loop_reaching_ph_8(faulty, healthy):
    after = window(faulty["saturation"], "ph_true", 7500, 10001)
    assert np.min(after) > 9.5
    assert np.max(window(faulty["saturation"], "valve_position_pct", 7000, 10001)) <= 50.0
    assert np.max(np.abs(window(healthy, "ph_true", 7500, 10001) - 8.0)) < 0.1


@pytest.mark.parametrize("fault", ["backlash", "friction", "stiction"])
def test_stem_faults_degrade_tracking_with_a_limit_cycle(faulty, healthy, fault):
    err_h = np.std(window(healthy, "ph_true", 7500, 10001) - 8.0)
    err_f = np.std(window(faulty[fault], "ph_true", 7500, 10001) - 8.0)
    assert err_f > 4 * err_h
    # a limit cycle: the valve keeps reversing with a sizeable amplitude long after the onset
    pos = window(faulty[fault], "valve_position_pct", 9000, 10001)
    assert np.ptp(pos) > 0.3


def test_deadzone_preset_costs_the_valve_its_upper_authority(faulty):
    pos = window(faulty["deadzone"], "valve_position_pct", 7000, 10001)
    assert np.max(pos) <= 50.0 + 1e-9
    assert np.min(window(faulty["deadzone"], "ph_true", 8000, 10001)) > 9.5


def test_open_loop_replays_the_closed_loop_from_its_recorded_commands():
    spec = load_scenario("paper", fault="backlash", overrides=["duration_s=1500", "faults.0.onset_s=300",
                                                               "setpoints.ph.changes.0.at_s=600"])
    closed = simulate(spec)
    inputs = Record.of({k: closed[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct",
                                         "buffer_flow_ml_s", "base_flow_ml_s")})
    opened = simulate_open_loop(spec, inputs, start="scenario")
    for name in ("ph_true", "level_true_cm", "valve_position_pct", "acid_flow_ml_s"):
        assert np.max(np.abs(opened[name] - closed[name])) < 1e-9, name
