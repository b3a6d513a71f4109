"""The vessel's own initial contents: they wash out with the outflow, run in the loop, and the diagnosis simulates
them identically."""

from __future__ import annotations

import numpy as np
import pytest

from ph_plant_sim.build import build_plant, load_plant_model
from phfdi.diagnosis.catalogue import _set_air_exchange, _set_contents
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import Evaluator, Start, mix_for_ph, nominal_raw
from phfdi.loop import build_parts, simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.errors import UserError
from phfdi_base.spec import validate_scenario

T = np.arange(0.0, 501.0)
ACID = np.where(T < 250, 3.0, 5.0)
BASE = np.where((T > 60) & (T < 110) | (T > 300) & (T < 340), 6.45, 0.0)


def _rig(edit=None):
    raw = nominal_raw("rig_flask", ["plant.tank.volume_ml=1000", "sensors.ph.noise_std=0"])
    if edit is not None:
        edit(raw)
    raw["duration_s"] = 500.0
    return raw


def _run(raw):
    return simulate_open_loop(validate_scenario(raw), Record.of({"time_s": T, "acid_flow_ml_s": ACID,
                                                          "base_flow_ml_s": BASE}))


def test_contents_wash_out_with_the_flasks_residence_time():
    """Carried by no feed, the contents' total falls as exp(-integral q dt / V) in the overflow flask."""
    raw = _rig(lambda r: _set_contents(r, "weak_acid", 2e-3, 7.2))
    parts = build_parts(validate_scenario(raw))
    plant = parts.process.plant
    j = plant.chemistry.names.index("flask_weak_acid")
    assert plant.concentrations[j] == pytest.approx(2e-3, rel=1e-12)
    flows = np.column_stack([ACID, BASE])
    out = plant.simulate_flows(flows, 1.0, 1.0)
    washed = 2e-3 * np.exp(-np.r_[0.0, np.cumsum(flows.sum(axis=1))] / 1000.0)
    assert np.max(np.abs(out["conc_mol_l"][:, j] - washed)) < 1e-12


@pytest.mark.parametrize("how", ["weak_acid", "carbonate", "carbonate_with_air_exchange", "mixing_zone"])
def test_contents_run_in_the_loop_and_the_diagnosis_simulates_them_identically(how):
    def edit(raw):
        _set_contents(raw, "carbonate" if how.startswith("carbonate") else "weak_acid", 1.5e-3, 7.6)
        if how == "carbonate_with_air_exchange":  # the same component: its steady level plus the contents
            _set_air_exchange(raw, 0.01, 3e-3)
        if how == "mixing_zone":
            raw["plant"]["mixing"] = {"zone_volume_ml": 30.0, "exchange_ml_s": 5.0, "feeds": ["base"]}

    raw = _rig(edit)
    run = _run(raw)
    plain = _run(_rig((lambda r: _set_air_exchange(r, 0.01, 3e-3)) if how == "carbonate_with_air_exchange" else
                      (lambda r: r["plant"].update(mixing={"zone_volume_ml": 30.0, "exchange_ml_s": 5.0,
                                                           "feeds": ["base"]})) if how == "mixing_zone" else None))
    assert np.max(np.abs(run["ph_true"] - plain["ph_true"])) > 0.3  # the contents change the pH
    record = make_record({"time_s": T, "acid_flow_ml_s": ACID, "base_flow_ml_s": BASE,
                          "ph_measured": run["ph_true"]}, "run")
    pred = Evaluator(record, raw).predict(raw)
    assert np.max(np.abs(pred.outputs["ph_measured"] - run["ph_true"])) < 1e-6
    if how != "carbonate_with_air_exchange":  # a fitted start at the run's first pH: the same trajectory
        fitted = Evaluator(record, raw, "fit").predict(raw, Start(float(run["ph_true"][0])))
        assert np.max(np.abs(fitted.outputs["ph_measured"] - run["ph_true"])) < 1e-6


def test_a_fitted_start_keeps_its_ph_with_the_contents():
    raw = _rig(lambda r: _set_contents(r, "weak_acid", 1e-3, 7.5))
    plant = build_plant(load_plant_model(validate_scenario(raw).plant))
    j = plant.chemistry.names.index("flask_weak_acid")
    extra = [1e-3 if i == j else 0.0 for i in range(len(plant.chemistry.names))]
    for ph in (3.0, 7.5, 10.8):
        conc = mix_for_ph(plant, ph, extra)
        assert plant.balance.ph(conc) == pytest.approx(ph, abs=1e-8)
        assert conc[j] == pytest.approx(1e-3)


def test_contents_are_validated():
    raw = _rig(lambda r: _set_contents(r, "weak_acid", 1e-3, 7.5))
    raw["plant"]["initial_contents"]["conc_mol_l"] = -1e-3
    with pytest.raises(UserError, match="initial_contents"):
        validate_scenario(raw)
    raw = _rig()
    raw["plant"]["initial_contents"] = {"component": "no_such_acid", "conc_mol_l": 1e-3}
    with pytest.raises(UserError, match="no_such_acid"):
        build_parts(validate_scenario(raw))
    raw = _rig()  # a library component (phosphate, pKa 2.15, 7.20, 12.35) needs no declaration; added as H3PO4
    raw["plant"]["initial_contents"] = {"component": "phosphate", "conc_mol_l": 1e-3}
    start = build_parts(validate_scenario(raw)).process
    assert start.plant.ph < build_parts(validate_scenario(_rig())).process.plant.ph - 0.5
    assert start.measure(0.0).ph_true == start.plant.ph
