"""Nested selection (phfdi.diagnosis.nested) and ``Options.effects``: a held-out record takes no part in a choice.

Rig-like records (``rig_flask``, on/off base pulses; tests/diagnosis/test_structure_search.py) whose base line has
a 10 s dead time. The held-out record is of a day the fit has not seen and its caustic is 0.7 x as strong: an
effect planted in it alone. Selected on it (the old rule of benchmarks/rig_holdout.py), the reagent strength, which
an unseen day adapts on its first 20 %, is its best single cause; selected on the training records (inner
leave-one-record-out), the dead time they all share is, and the strength is not added to the structure.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_structure_search import NOMINAL, record

from phfdi.diagnosis import nested
from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.pipeline import Options, diagnose

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
