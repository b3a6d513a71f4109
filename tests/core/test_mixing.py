"""The mixing zone: limits, conservation, and the same answer in the loop and in the diagnosis."""

from __future__ import annotations

import numpy as np

from ph_plant_sim.build import build_plant, load_plant_model
from ph_plant_sim.mixing import MixingZone, zone_trajectory
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import Evaluator, nominal_raw
from phfdi.loop import simulate, simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.spec import validate_scenario

FEEDS = ["acid", "base"]
CONC = np.array([[2e-3, 0.0], [0.0, 20e-3]])  # components: acid equivalents, base (mol/L)


def flows(n=400):
    q = np.zeros((n, 2))
    q[:, 0] = 4.0
    q[100:160, 1] = 6.0
    return q


def test_a_fast_exchange_is_the_perfectly_mixed_vessel_and_amounts_balance():
    q, v, dt = flows(), np.full(401, 1000.0), 0.5
    c0 = np.array([1e-3, 0.0])
    z, b = zone_trajectory(MixingZone(5.0, 1e6, ("base",)), FEEDS, CONC, q, v, dt, c0)
    # perfectly mixed: dc/dt = (sum q c_feed - q_in c) / V, exact per held sample
    ref = [c0]
    for k in range(len(q)):
        qin = q[k].sum()
        c_in = q[k] @ CONC / qin
        ref.append(c_in + (ref[-1] - c_in) * np.exp(-qin * dt / 1005.0))  # zone + bulk
    assert np.max(np.abs(z - np.array(ref))) < 1e-4 * np.max(np.abs(z))  # z - b = q_zone (c_feed - b) / Qx
    # a real zone: the amounts in zone + bulk change by what flowed in minus what left the bulk
    zone = MixingZone(20.0, 15.0, ("base",))
    z, b = zone_trajectory(zone, FEEDS, CONC, q, v, 0.01, c0)
    amounts = 20.0 * z + 1000.0 * b
    inflow = (q @ CONC) * 0.01
    out = q.sum(axis=1)[:, None] * b[:-1] * 0.01  # first-order in dt
    assert np.allclose(amounts[1:] - amounts[:-1], inflow - out, atol=2e-4 * np.abs(inflow).max())


def test_base_dosed_into_the_zone_reaches_the_probe_before_the_bulk():
    q, v = flows(), np.full(401, 1000.0)
    z, b = zone_trajectory(MixingZone(20.0, 10.0, ("base",)), FEEDS, CONC, q, v, 0.5, np.array([1e-3, 0.0]))
    k = 110  # 5 s after the base starts
    assert z[k, 1] > 5 * b[k, 1]


SHORT = ["duration_s=1200", "setpoints.ph.changes.0.at_s=500", "sensors.ph.noise_std=0",
         "sensors.level.noise_std=0"]


def test_a_zoned_vessel_runs_in_the_loop_and_the_diagnosis_simulates_it_identically():
    raw = nominal_raw("paper", SHORT)
    raw["plant"]["mixing"] = {"zone_volume_ml": 150.0, "exchange_ml_s": 30.0, "feeds": ["acid"]}
    spec = validate_scenario(raw)
    assert type(build_plant(load_plant_model(spec.plant))).__name__ == "ZonedPlant"
    run = simulate(spec)
    plain = simulate(validate_scenario(nominal_raw("paper", SHORT)))
    assert np.max(np.abs(run["ph_true"] - plain["ph_true"])) > 0.05
    inputs = Record.of({k: run[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct")})
    reference = simulate_open_loop(spec, inputs)
    record = make_record({k: run[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct",
                                              "ph_measured", "level_measured_cm")}, "run")
    pred = Evaluator(record, raw, level_from_data=False).predict(raw)
    # the loop integrates the zone with the bulk volume at the start of each sample, the diagnosis likewise
    assert np.max(np.abs(pred.outputs["ph_measured"] - reference["ph_measured"])) < 1e-6


def test_mixing_zone_names_an_unknown_feed():
    import pytest

    from phfdi_base.errors import UserError

    raw = nominal_raw("paper", SHORT)
    raw["plant"]["mixing"] = {"zone_volume_ml": 150.0, "exchange_ml_s": 30.0, "feeds": ["lye"]}
    with pytest.raises(UserError):
        validate_scenario(raw)
    from pydantic import ValidationError

    from phfdi_base.spec import PlantModelSpec
    with pytest.raises(ValidationError, match="mixing.feeds: no feed 'lye'"):
        PlantModelSpec.model_validate(raw["plant"])
