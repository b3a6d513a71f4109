"""Nested selection (phfdi.diagnosis.nested) and ``Options.effects``: a held-out record takes no part in a choice.

Rig-like records (``rig_flask``, on/off base pulses; tests/diagnosis/test_structure_search.py) whose base line has
a 10 s dead time. The held-out record is of a day the fit has not seen and its caustic is 0.7 x as strong: an
effect planted in it alone. Selected on it (the old rule of benchmarks/rig_holdout.py), the reagent strength, which
an unseen day adapts on its first 20 %, is its best single cause; selected on the training records (inner
leave-one-record-out), the dead time they all share is, and the strength is not added to the structure.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import test_hidden_structure as rig
from test_structure_search import NOMINAL, record

from phfdi.diagnosis import calibrate as calibrate_module
from phfdi.diagnosis import nested, pipeline
from phfdi.diagnosis.calibrate import calibrate
from phfdi.diagnosis.data import make_record
from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.pipeline import Options, context_for, diagnose
from phfdi.loop import simulate_open_loop
from phfdi.records.record import Record
from phfdi_base.spec import validate_scenario

CANDIDATES = ["reagent_concentration", "feed_delay"]


def _opts(**kw) -> Options:
    return Options(structure=True, candidates=CANDIDATES, pairs=False, adapt=0.2, search_width=2, search_steps=2,
                   workers=1, **kw)


@pytest.fixture(scope="module")
def fold():
    rng = np.random.default_rng(2026)
    train = [record(rng, f"day{g}-1", 1.0, 10.0) for g in "ABD"]
    held = record(rng, "dayC-1", 0.7, 10.0)  # another day, a weaker caustic: only here
    return train, held, ["A", "B", "D", "C"]


def test_the_choice_is_made_without_the_held_out_record_and_differs_from_selecting_on_it(fold, monkeypatch):
    train, held, groups = fold
    calls: list[tuple[list[str], list[str]]] = []
    real = nested.diagnose

    def spy(fit, val, *args, **kw):
        calls.append(([r.name for r in fit], [r.name for r in val]))
        return real(fit, val, *args, **kw)

    monkeypatch.setattr(nested, "diagnose", spy)
    sel = nested.select(train, groups[:3], nominal_raw("rig_flask", NOMINAL), "rig_flask", _opts())
    n_select = len(calls)
    pred = nested.predict(train, held, groups, nominal_raw("rig_flask", NOMINAL), "rig_flask", _opts(), sel)
    # instrumentation: no call before the choice was fixed saw the held-out record; after it, only as validation
    assert all(held.name not in fit + val for fit, val in calls[:n_select]), calls
    assert n_select == len(train) + sel.fits
    assert all(held.name not in fit and val == [held.name] for fit, val in calls[n_select:]), calls
    # the nested choice: the dead time the training records share, nothing for the held-out record's caustic
    assert sel.best_single == "feed_delay[base]", sel.singles
    assert sel.chosen == ["feed_delay[base]"], sel.path
    assert pred.best_single is not None and pred.best_single.label == "feed_delay[base]"
    assert pred.structure is not None and pred.structure.label == "feed_delay[base]"
    # the old rule, selecting on the held-out record, would pick the reagent strength planted there
    on_test = min(pred.diagnosis.singles, key=lambda r: r.val_by_record[held.name])
    assert on_test.cause == "reagent_concentration", {r.label: r.val_by_record for r in pred.diagnosis.singles}
    old = diagnose(train, [held], nominal_raw("rig_flask", NOMINAL), "rig_flask", _opts(groups=groups))
    assert any(c.startswith("reagent_concentration[") for c in old.report["structure_search"]["chosen"]), \
        old.report["structure_search"]["chosen"]


def test_options_effects_fits_exactly_the_given_set_without_selection(fold):
    train, held, groups = fold
    nominal = nominal_raw("rig_flask", NOMINAL)
    d = diagnose(train, [held], nominal, "rig_flask", _opts(groups=groups, effects=["feed_delay[base]"]))
    search = d.report["structure_search"]
    assert d.singles == [] and search["chosen"] == ["feed_delay[base]"]
    assert [s["model"] for s in search["path"]] == ["nominal", "feed_delay[base]"]
    assert d.structure is not None and abs(d.structure.params["delay_s"] - 10.0) < 1.5
    # an effect that does not help is kept all the same: the choice was made elsewhere
    d2 = diagnose(train, [held], nominal, "rig_flask", _opts(groups=groups, effects=["feed_delay[acid]"]))
    assert d2.report["structure_search"]["chosen"] == ["feed_delay[acid]"]
    assert diagnose(train, [held], nominal, "rig_flask", _opts(groups=groups, effects=[])).structure is None
    with pytest.raises(ValueError, match="not candidates"):
        diagnose(train, [held], nominal, "rig_flask", _opts(groups=groups, effects=["no_such_effect"]))


#: the nominal model's physical keys, calibrated per fold (as the rig's preset was: acid and base strengths and the
#: vessel volume), from first guesses away from the records' truth (caustic 20 mM, 1 L)
CAL_KEYS = ["plant.feeds.acid.recipe.H2SO4=0.0002:0.05", "plant.feeds.base.recipe.NaOH=0.0005:0.1",
            "plant.tank.volume_ml=50:20000"]
CAL_START = NOMINAL + ["plant.feeds.base.recipe.NaOH=0.03", "plant.tank.volume_ml=700"]


def planted(rng, name: str):
    """A held-out record whose presence in a calibration or a search context would move it: twice as long as
    the others, a caustic 0.4 x as strong dosed at 3 x the flow (its largest flow 19 mL/s; more base
    equivalents, so a higher pH)."""
    raw = nominal_raw("rig_flask", NOMINAL)
    raw["sensors"]["ph"]["noise_std"] = 0.0
    raw["plant"]["feeds"]["base"]["recipe"]["NaOH"] *= 0.4
    a, b = rig.inputs(rng), rig.inputs(rng)
    n = len(a["time_s"])
    t = np.arange(2 * n - 1) * rig.DT_S
    inp = {"time_s": t, "acid_flow_ml_s": np.r_[a["acid_flow_ml_s"], b["acid_flow_ml_s"][1:]],
           "base_flow_ml_s": 3.0 * np.r_[a["base_flow_ml_s"], b["base_flow_ml_s"][1:]]}
    raw["duration_s"] = float(t[-1])
    run = simulate_open_loop(validate_scenario(raw), Record.of(dict(inp)))
    cols = dict(inp, ph_measured=run["ph_true"] + rng.normal(0.0, rig.NOISE_PH, len(t)))
    return make_record(cols, name)


def _ctx(c) -> dict:
    return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in dataclasses.asdict(c).items()}


def test_a_fold_calibrates_and_sets_its_bounds_without_the_held_out_record(fold, monkeypatch):
    """benchmarks/rig_holdout.py's fold (nested.outer_fold with calibration and Options.setup_from_fit): only
    the held-out record changes, from an ordinary one to one planted to move a calibration and a search context
    (checked: with it among the records, both move). The fold's calibrated values, its bounds, its choice and
    every model it fits on the training records must not move; instrumented: no calibration or context sees it."""
    train, held, groups = fold
    held_b = planted(np.random.default_rng(7), held.name)  # the same name and day: only its data differ
    start = nominal_raw("rig_flask", CAL_START)
    opts = dataclasses.replace(_opts(setup_from_fit=True), search_steps=1)
    # the plant works: with the held-out record among the records, the calibration and the context move
    cal_a, cal_b = (calibrate(train + [h], [], start, CAL_KEYS, opts) for h in (held, held_b))
    assert abs(cal_b.params["plant.feeds.base.recipe.NaOH"] / cal_a.params["plant.feeds.base.recipe.NaOH"] - 1) \
        > 0.05, (cal_a.params, cal_b.params)
    ctx_a, ctx_b = (_ctx(context_for(start, train + [h], ["ph_measured"])) for h in (held, held_b))
    for key in ("duration_s", "ph_range", "feed_max_flow_ml_s"):
        assert ctx_a[key] != ctx_b[key], key
    seen: list[list[str]] = []
    for module in (pipeline, calibrate_module):  # instrument every search context and the calibration
        monkeypatch.setattr(module, "context_for", _spy(module.context_for, seen))
    monkeypatch.setattr(nested, "calibrate", _spy(nested.calibrate, seen))
    a, b = (nested.outer_fold(train, h, groups, start, "rig_flask", opts, CAL_KEYS) for h in (held, held_b))
    assert a.calibration is not None and b.calibration is not None
    assert a.calibration.params == b.calibration.params and a.calibration.intervals == b.calibration.intervals
    # the fold starts from its calibration, not from the first guesses
    assert a.nominal["plant"]["tank"]["volume_ml"] == a.calibration.params["plant.tank.volume_ml"] != 700.0
    assert _ctx(a.prediction.diagnosis.context) == _ctx(b.prediction.diagnosis.context)
    assert (a.selection.best_single, a.selection.chosen, a.selection.singles) == \
        (b.selection.best_single, b.selection.chosen, b.selection.singles)
    fitted = [(f.params, f.intervals) for f in a.prediction.diagnosis.singles]
    assert fitted == [(f.params, f.intervals) for f in b.prediction.diagnosis.singles]
    # and the held-out record was predicted: its scores differ
    assert a.prediction.diagnosis.report["structure_search"]["nrmse_by_record_nominal"] != \
        b.prediction.diagnosis.report["structure_search"]["nrmse_by_record_nominal"]
    assert seen and all(held.name not in names for names in seen), seen


def _spy(real, seen: list[list[str]]):
    def spy(*args, **kw):
        names = [r.name for arg in args if isinstance(arg, list) for r in arg if hasattr(r, "outputs")]
        seen.append(names)
        return real(*args, **kw)
    return spy
