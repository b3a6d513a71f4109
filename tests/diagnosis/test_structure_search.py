"""Structure search, per-group parameters with adaptation of an unseen group, and the Wiener baseline."""

from __future__ import annotations

import numpy as np
import test_hidden_structure as rig  # the rig-like excitation of the hidden-effect tests

from phfdi.diagnosis.blackbox import fit_wiener
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.pipeline import Options, diagnose
from phfdi.loop import simulate_open_loop
from phfdi_base.spec import validate_scenario

NOMINAL = ["plant.tank.volume_ml=1000"]


def record(rng, name: str, base_factor: float, delay_s: float):
    """A rig-like run whose caustic is base_factor x nominal strength and whose base line has a dead time."""
    raw = nominal_raw("rig_flask", NOMINAL)
    raw["sensors"]["ph"]["noise_std"] = 0.0
    raw["plant"]["feeds"]["base"]["recipe"]["NaOH"] *= base_factor
    raw["plant"]["feeds"]["base"]["line"] = [{"type": "line_delay", "params": {"delay_s": delay_s}}]
    inp = rig.inputs(rng)
    raw["duration_s"] = rig.DURATION_S
    run = simulate_open_loop(validate_scenario(raw), inp)
    cols = {k: inp[k] for k in ("time_s", "acid_flow_ml_s", "base_flow_ml_s")}
    cols["ph_measured"] = run["ph_true"] + rng.normal(0.0, rig.NOISE_PH, len(inp["time_s"]))
    return make_record(cols, name)


def test_search_adds_the_dead_time_with_per_day_reagent_strength_and_adapts_an_unseen_day():
    rng = np.random.default_rng(11)
    fit = [record(rng, "dayA-1", 0.8, 10.0), record(rng, "dayB-1", 1.2, 10.0)]
    val = [record(rng, "dayC-1", 1.0, 10.0)]
    groups = ["A", "B", "C"]
    d = diagnose(fit, val, nominal_raw("rig_flask", NOMINAL), "rig_flask",
                 Options(structure=True, candidates=["reagent_concentration", "feed_delay", "sensor_lag"],
                         pairs=False, groups=groups, adapt=0.2, search_width=3, search_steps=3, workers=1))
    search = d.report["structure_search"]
    chosen = search["chosen"]
    assert chosen[0] == "feed_delay[base]" and any(c.startswith("reagent_concentration[") for c in chosen), \
        search["path"]
    final = [s for s in search["path"] if s["accepted"]][-1]
    # one strength per fitted day: only the acid/base balance is seen, so either feed's factor may carry it; the
    # ratio of the two days' factors is the truth's (1.2 / 0.8 in the base, or its inverse in the acid)
    variant = next(c for c in chosen if c.startswith("reagent_concentration["))
    key = "reagent_concentration.factor"
    ratio = final["parameters"][f"{key}[B]"] / final["parameters"][f"{key}[A]"]
    truth = 1.5 if variant.endswith("[base]") else 1 / 1.5
    assert abs(ratio / truth - 1.0) < 0.05, (variant, final["parameters"])
    assert abs(final["parameters"]["feed_delay.delay_s"] - 10.0) < 1.5
    assert final["validation_rmse_over_noise"] < 1.5  # at the noise floor on the unseen day's scored samples
    # the unseen day: its strength (only) fitted on its first 20 %, the rest scored
    adapted = final["fitted_where"]["adapted"]["dayC-1"]
    assert adapted["samples"] == round(0.2 * len(val[0]))
    assert list(adapted["parameters"]) == [f"{variant}.factor"]
    assert final["nrmse_by_record"]["dayC-1"] < 0.5 * search["nrmse_by_record_nominal"]["dayC-1"]
    # the black box, fitted on the same samples, predicts the unseen day too (finite, scored the same way)
    wf = fit_wiener(d.records, d.train, d.val, ["acid", "base"], "base", groups, 0.2)
    assert 0.0 < wf.nrmse_by_record["dayC-1"] < 2.0
    assert wf.adapted["dayC-1"]["samples"] == round(0.2 * len(val[0]))


def contents_record(rng, name: str, conc_mol_l: float, pka: float):
    """A rig-like run (an on/off loop's duty cycle) whose flask starts holding a weak acid of its own."""
    from phfdi.diagnosis.catalogue import _set_contents

    raw = nominal_raw("rig_flask", NOMINAL)
    raw["sensors"]["ph"]["noise_std"] = 0.0
    _set_contents(raw, "weak_acid", conc_mol_l, pka)
    inp = rig.balanced_inputs(rng)
    raw["duration_s"] = rig.DURATION_S
    run = simulate_open_loop(validate_scenario(raw), inp)
    cols = {k: inp[k] for k in ("time_s", "acid_flow_ml_s", "base_flow_ml_s")}
    cols["ph_measured"] = run["ph_true"] + rng.normal(0.0, rig.NOISE_PH, len(inp["time_s"]))
    return make_record(cols, name)


def test_the_flasks_contents_are_fitted_per_record_with_one_pka_and_a_held_out_record_sets_its_own():
    """Two runs whose flask held different amounts of one weak acid: one amount per run, one shared pKa; a third
    run, validation only, gets its amount (and start pH) from the samples that set its start."""
    rng = np.random.default_rng(23)
    fit = [contents_record(rng, "run-a", 0.6e-3, 7.6), contents_record(rng, "run-b", 1.8e-3, 7.6)]
    val = [contents_record(rng, "run-c", 1.0e-3, 7.6)]
    d = diagnose(fit, val, nominal_raw("rig_flask", NOMINAL), "rig_flask",
                 Options(initial="fit", candidates=["flask_contents"], pairs=False, workers=1))
    best = next(r for r in d.singles if r.label == "flask_contents[weak_acid]")
    assert abs(best.params["pka"] - 7.6) < 0.1, best.params
    assert abs(best.params["conc_mol_l[run-a]"] / 0.6e-3 - 1.0) < 0.1, best.params
    assert abs(best.params["conc_mol_l[run-b]"] / 1.8e-3 - 1.0) < 0.1, best.params
    assert best.fitted_where["per_record"] == ["conc_mol_l"]
    adapted = best.fitted_where["adapted"]["run-c"]
    assert adapted["samples"] == 20 and list(adapted["parameters"]) == ["flask_contents[weak_acid].conc_mol_l"]
    # the written model holds the first fitted run's amount; run-c's scored samples are all but its first 20
    assert best.raw["plant"]["initial_contents"]["conc_mol_l"] == best.params["conc_mol_l[run-a]"]
    assert best.record_raws[2]["plant"]["initial_contents"]["conc_mol_l"] == \
        adapted["parameters"]["flask_contents[weak_acid].conc_mol_l"]
