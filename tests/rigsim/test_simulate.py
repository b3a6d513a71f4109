"""The simulated rig's physics and determinism: the plant core's numbers, reproducible runs, a controller that
controls, a probe bias the controller acts on, and the reading's statistics within the recorded runs' ranges.

Every run here has a fixed seed and day (no test draws fresh randomness), so each check either holds or fails
every time."""

from __future__ import annotations

import numpy as np
import pytest

from ph_plant_sim.mixing import ZonedPlant, zone_transition
from phfdi.rigsim import DAY_RANGES, OperationSpec, ProbeFault, draw_day, run_statistics, simulate_run
from phfdi.rigsim.day import FLOW_PER_PCT
from phfdi.rigsim.flask import RigFlask
from phfdi_base.errors import UserError

ON_OFF = OperationSpec(name="test_on_off", group="unseen", kind="on_off", description="on/off about pH 10",
                       duration_s=900.0, start_ph=9.0, switched="base", on_pct=40.0, other_pct=20.0,
                       setpoint_ph=10.0, band_ph=0.3)
PI = OperationSpec(name="test_pi", group="unseen", kind="pi", description="PI about pH 10", duration_s=1200.0,
                   start_ph=9.5, pump="base", kp_pct_per_ph=10.0, ti_s=60.0, other_pct=20.0, setpoint_ph=10.0)


def test_days_are_drawn_within_their_ranges():
    for number in range(30):
        day = draw_day(number).to_dict()
        litres = day["volume_ml"] / 1000.0
        day["acid_per_litre"], day["base_per_litre"] = -day["acid_strength_mM"] / litres, day["base_strength_mM"] / litres
        for name, r in DAY_RANGES.items():
            assert r.low <= day[name] <= r.high, name


def test_the_fast_zone_step_is_the_cores_zone_transition():
    flask = RigFlask(draw_day(1))
    rng = np.random.default_rng(0)
    for q, dt in ((0.0, 0.35), (4.31, 0.339), (10.76, 0.43), (1e-4, 0.353)):
        flows = np.array([0.4 * q, 0.6 * q])
        a, b = zone_transition(flask.zone, np.zeros(2), flows, flask.volume_ml, dt)
        x = rng.random((2, len(flask.names))) * 1e-3
        tr = flask.transition(q, dt)
        mine = tr.e @ x + np.outer(tr.p[:, 1], flask.inflow_per_volume(flows))
        assert np.allclose(mine, a @ x + b @ flask.feed_conc, rtol=1e-12, atol=1e-18)


def test_a_run_is_the_cores_zoned_vessel_stepped_with_its_flows():
    """Without the air exchange, the run's flask and probe-zone pH equal the core's ZonedPlant (expm per sample)
    driven by the run's recorded flows and times."""
    day = draw_day(2).with_values(co2_kla_per_s=0.0)
    run = simulate_run("shared_control_ph7", seed=2, day=day, duration_s=300.0)
    flask = RigFlask(day)
    zoned = ZonedPlant(flask.plant, flask.zone)
    zoned.set_state(flask.start_composition(float(run.operation.values["start_ph"])).tolist())
    zone_ph, bulk_ph = [zoned.ph], [zoned.bulk.ph]
    for k in range(len(run) - 1):
        zoned.step([run.acid_pct[k] * FLOW_PER_PCT["acid"], run.base_pct[k] * FLOW_PER_PCT["base"]], 1.0,
                   float(run.time_s[k + 1] - run.time_s[k]))
        zone_ph.append(zoned.ph)
        bulk_ph.append(zoned.bulk.ph)
    assert np.max(np.abs(run.ph_zone - zone_ph)) < 1e-8
    assert np.max(np.abs(run.ph_true - bulk_ph)) < 1e-8


def test_same_seed_same_run_other_seed_other_run():
    a, b = simulate_run("pi_acid", seed=11, duration_s=200.0), simulate_run("pi_acid", seed=11, duration_s=200.0)
    for name in ("time_s", "acid_pct", "base_pct", "ph", "ph_true", "room_temp_c"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.operation.values == b.operation.values and a.day == b.day
    c = simulate_run("pi_acid", seed=12, duration_s=200.0)
    assert c.operation.values != a.operation.values and not np.array_equal(c.ph[:500], a.ph[:500])
    # the day alone: same run seed on another day changes the rig, not the drawn operation
    d = simulate_run("pi_acid", seed=11, day=5, duration_s=200.0)
    assert d.operation.values == a.operation.values and d.day != a.day


def test_a_probe_fault_changes_nothing_before_its_onset():
    healthy = simulate_run(ON_OFF, seed=3)
    for kind, size in (("probe_bias", 0.4), ("probe_frozen", None), ("probe_noise", 0.1), ("probe_lag", 20.0),
                       ("probe_drift", 0.5), ("probe_gain", 0.1)):
        faulty = simulate_run(ON_OFF, seed=3, probe_fault=ProbeFault(kind, 400.0, size))
        k0 = faulty.fault["onset_index"]
        assert faulty.time_s[k0] >= 400.0 > faulty.time_s[k0 - 1]
        for name in ("ph", "ph_true", "acid_pct", "base_pct"):
            assert np.array_equal(getattr(faulty, name)[:k0], getattr(healthy, name)[:k0]), (kind, name)
        assert not np.array_equal(faulty.ph[k0:], healthy.ph[k0:]), kind
    frozen = simulate_run(ON_OFF, seed=3, probe_fault=ProbeFault("probe_frozen", 400.0))
    assert len(set(frozen.ph[frozen.fault["onset_index"]:].tolist())) == 1


def test_the_on_off_controller_keeps_the_ph_in_its_band():
    """About pH 10 with a 0.3 pH band, on six days: after 2 minutes the reading's 1st-99th percentiles stay within
    the band plus 0.4 pH (the overshoot of the zone and probe lag: 0.28 at most on these days) and the pump
    switches; the same pumps without the controller (base left on) end above pH 11.5."""
    for day in range(6):
        run = simulate_run(ON_OFF, seed=day)
        settled = run.time_s - run.time_s[0] > 120.0
        lo, hi = np.percentile(run.ph[settled], [1, 99])
        assert 10.0 - 0.7 < lo and hi < 10.0 + 0.7, (day, lo, hi)
        assert np.sum(np.diff(run.base_pct[settled]) != 0) >= 6, day
        assert np.all(run.setpoint_ph == 10.0)
        left_on = OperationSpec(name="test_left_on", group="unseen", kind="open_loop", description="base on",
                                duration_s=900.0, start_ph=9.0, acid_pct=20.0, base_pct=40.0)
        assert simulate_run(left_on, seed=day).ph[-1] > 11.5, day


@pytest.mark.parametrize("bias", [0.5, -0.3])
def test_a_probe_bias_in_closed_loop_moves_the_true_ph_by_minus_the_bias(bias):
    """A PI holds the reading at its setpoint; after a probe bias b the reading returns to the setpoint and the
    flask's true pH settles b lower (b / slope: the probe's slope is 0.98-1.01), on six days."""
    for day in range(6):
        run = simulate_run(PI, seed=day, probe_fault=ProbeFault("probe_bias", 600.0, bias))
        t = run.time_s - run.time_s[0]
        before, after = (t > 300.0) & (t < 600.0), t > 900.0
        shift = run.ph_true[after].mean() - run.ph_true[before].mean()
        assert abs(shift + bias) < 0.05, (day, shift)
        assert abs(run.ph[after].mean() - 10.0) < 0.02, day  # the controller sees its setpoint
        assert abs(run.ph_probe[after].mean() - (10.0 - bias)) < 0.05, day  # a healthy probe would read the truth


def test_statistics_within_the_recorded_runs_ranges():
    """The reading's noise statistics (phfdi.rigsim.stats, the same functions measured on the recorded runs:
    docs/simulation.md) on the replays of the recorded operations and two unseen ones, each on three days:
    noise after the detrend 0.015-0.075 pH (recorded 0.024-0.057), lag-1 autocorrelation -0.3..0.05 (-0.15..-0.08),
    lag-2 -0.55..-0.2 (-0.39..-0.34), the ripple's period 1.1-1.6 s (1.23-1.48), the meter's 0.01 pH, readings
    repeating in 3-20 % of samples (7-13 %), never more than 8 in a row (3-4)."""
    for name in ("shared_add_base", "shared_add_acid", "shared_control_ph7", "shared_acid_to_base",
                 "shared_base_to_acid", "on_off_base", "add_acid_new_setting"):
        for seed in range(3):
            run = simulate_run(name, seed=seed, duration_s=None if name.startswith("shared") else 600.0)
            s = run_statistics(run.time_s, run.ph)
            where = (name, seed, s)
            assert s.on_grid and abs(s.quantum_ph - 0.01) < 1e-9, where
            assert 0.015 <= s.noise_ph <= 0.075, where
            assert -0.3 <= s.lag1_autocorrelation <= 0.05, where
            assert -0.55 <= s.lag2_autocorrelation <= -0.2, where
            assert 1.1 <= s.ripple_period_s <= 1.6, where
            assert 0.03 <= s.repeat_share <= 0.2 and s.longest_repeat <= 8, where


def test_bad_input_is_one_line():
    with pytest.raises(UserError, match="no operation 'nope'"):
        simulate_run("nope", seed=0)
    with pytest.raises(UserError, match="outside the run"):
        simulate_run(PI, seed=0, probe_fault=ProbeFault("probe_bias", 5000.0, 0.5))
    with pytest.raises(UserError, match="needs a finite size"):
        ProbeFault("probe_bias", 10.0)
    with pytest.raises(UserError, match="seed must be a non-negative integer"):
        simulate_run(PI, seed=-1)
