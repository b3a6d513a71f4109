"""Tanks in series and air exchange: analytic limits, and the same answer in the loop and in the diagnosis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ph_plant_sim.build import build_plant, load_plant_model
from ph_plant_sim.exchange import AirExchange
from ph_plant_sim.series import TanksInSeries, series_trajectory
from phfdi.diagnosis.catalogue import _set_air_exchange, _set_series
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import Evaluator, nominal_raw
from phfdi.loop import simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.errors import UserError
from phfdi_base.spec import validate_scenario


@pytest.mark.parametrize("n_tanks", [1, 3, 7])
def test_series_outlet_after_a_feed_step_is_the_erlang_distribution(n_tanks):
    """A tracer stepped 0 -> 1 in the only feed: the outlet of n equal tanks follows 1 - sum_k e^-x x^k / k!,
    x = n q t / V (Levenspiel's tanks-in-series residence time)."""
    q, vol, dt = 5.0, 1000.0, 1.0
    flows = np.full((600, 1), q)
    out = series_trajectory(TanksInSeries(n_tanks), np.array([[1.0]]), flows, vol, dt, np.array([0.0]))
    t = np.arange(601) * dt
    x = n_tanks * q * t / vol
    erlang = 1.0 - sum(np.exp(-x) * x ** k / math.factorial(k) for k in range(n_tanks))
    assert np.max(np.abs(out[:, 0] - erlang)) < 1e-9
    # the mean residence time is V / q whatever n: the outlet crosses 1/2 later as n grows toward plug flow
    assert out[int(vol / q), 0] == pytest.approx(erlang[int(vol / q)], abs=1e-9)


def test_air_exchange_relaxes_toward_its_equilibrium_and_its_steady_state_balances():
    x = AirExchange("absorbed_co2", 0.01, 2e-3)
    # steady state: inflow + air uptake = outflow
    c = x.steady_conc(feed_rate_mmol_s=5.0 * 1e-3, q_in_ml_s=5.0, volume_ml=1000.0)
    assert 5.0 * 1e-3 + 0.01 * 1000.0 * (2e-3 - c) == pytest.approx(5.0 * c, rel=1e-12)
    assert x.steady_conc(0.0, 0.0, 1000.0) == 2e-3


def _rig_case(edit):
    """The rig's flask (1 L), acid steps and base pulses, open loop in the loop's core and in the diagnosis."""
    raw = nominal_raw("rig_flask", ["plant.tank.volume_ml=1000", "sensors.ph.noise_std=0"])
    edit(raw)
    t = np.arange(0.0, 501.0)
    acid = np.where(t < 250, 3.0, 5.0)
    base = np.where((t > 60) & (t < 110) | (t > 300) & (t < 340), 6.45, 0.0)
    raw["duration_s"] = 500.0
    spec = validate_scenario(raw)
    run = simulate_open_loop(spec, Record.of({"time_s": t, "acid_flow_ml_s": acid, "base_flow_ml_s": base}))
    record = make_record({"time_s": t, "acid_flow_ml_s": acid, "base_flow_ml_s": base,
                          "ph_measured": run["ph_true"]}, "run")
    pred = Evaluator(record, raw).predict(raw)
    plain = nominal_raw("rig_flask", ["plant.tank.volume_ml=1000", "sensors.ph.noise_std=0"])
    plain["duration_s"] = 500.0
    base_run = simulate_open_loop(validate_scenario(plain), Record.of({"time_s": t, "acid_flow_ml_s": acid,
                                                                 "base_flow_ml_s": base}))
    return spec, run, pred, base_run


@pytest.mark.parametrize("what", ["series", "air_exchange"])
def test_structure_runs_in_the_loop_and_the_diagnosis_simulates_it_identically(what):
    if what == "series":
        spec, run, pred, plain = _rig_case(lambda raw: _set_series(raw, 4))
        assert type(build_plant(load_plant_model(spec.plant))).__name__ == "SeriesPlant"
    else:
        spec, run, pred, plain = _rig_case(lambda raw: _set_air_exchange(raw, 0.01, 3e-3))
        assert type(build_plant(load_plant_model(spec.plant))).__name__ == "ExchangePlant"
    assert np.max(np.abs(run["ph_true"] - plain["ph_true"])) > 0.3  # the structure changes the pH
    assert np.max(np.abs(pred.outputs["ph_measured"] - run["ph_true"])) < 1e-6


def test_one_vessel_structure_at_a_time_and_series_needs_an_overflow_vessel():
    raw = nominal_raw("rig_flask")
    _set_series(raw, 3)
    raw["plant"]["mixing"] = {"zone_volume_ml": 10.0, "exchange_ml_s": 5.0, "feeds": ["base"]}
    with pytest.raises(UserError, match="mixing and series together"):
        validate_scenario(raw)
    paper = nominal_raw("paper")
    _set_series(paper, 3)
    with pytest.raises(UserError, match="overflow vessel"):
        validate_scenario(paper)
