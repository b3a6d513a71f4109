"""The stiction classifier: deterministic training, weights that follow the evidence, nested
leave-one-loop-out that never lets a fold see the loop it scores, and the shipped model."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loopdiag.classifier import (
    Data,
    LogisticModel,
    best_threshold,
    fit_logistic,
    load_model,
    nested_lolo,
    training_weights,
)
from phfdi.loopdiag.features import FEATURE_NAMES


def _toy(seed: int, n_groups: int = 8, per_group: int = 3, n_syn: int = 40) -> Data:
    """Feature 0 carries the label, feature 1 is noise; half the groups are positive."""
    rng = np.random.default_rng(seed)
    xs, ys, gs, real = [], [], [], []
    for g in range(n_groups):
        lab = g % 2 == 0
        for _ in range(per_group):
            xs.append([(1.0 if lab else -1.0) + 0.7 * rng.standard_normal(), rng.standard_normal()])
            ys.append(lab), gs.append(f"L{g}"), real.append(True)
    for k in range(n_syn):
        lab = k % 2 == 0
        xs.append([(1.0 if lab else -1.0) + 0.7 * rng.standard_normal(), rng.standard_normal()])
        ys.append(lab), gs.append(f"S{k}"), real.append(False)
    return Data(np.array(xs), np.array(ys), gs, np.array(real), ["signal", "noise"])


def test_training_is_reproducible_and_weights_follow_the_evidence():
    d = _toy(1)
    w = training_weights(d.groups, d.real, 1.0)
    a = fit_logistic(d.x, d.y, w, 0.1, d.features)
    b = fit_logistic(d.x, d.y, w, 0.1, d.features)
    assert np.array_equal(a.weights, b.weights) and a.bias == b.bias
    assert a.weights[0] > 1.0 and abs(a.weights[1]) < 0.5 * a.weights[0]
    # a stronger L2 shrinks the weights
    assert np.all(np.abs(fit_logistic(d.x, d.y, w, 10.0, d.features).weights) < np.abs(a.weights) + 1e-12)


def test_each_real_loop_weighs_one_whatever_its_file_count():
    w = training_weights(["A", "A", "A", "B", "S1", "S2"], np.array([1, 1, 1, 1, 0, 0], bool), 2.0)
    assert w[:3].sum() == pytest.approx(1.0) and w[3] == pytest.approx(1.0)
    assert w[4:].sum() == pytest.approx(2.0 * 2)  # twice the two real loops


def test_contributions_sum_to_the_log_odds():
    d = _toy(2)
    m = fit_logistic(d.x, d.y, training_weights(d.groups, d.real, 1.0), 0.1, d.features)
    x = d.x[0]
    logit = np.log(m.probability(x) / (1 - m.probability(x)))
    assert m.contributions(x).sum() + m.bias == pytest.approx(logit)


def test_threshold_ties_go_to_one_half():
    prob = np.array([0.1, 0.2, 0.8, 0.9])
    th, acc = best_threshold(prob, np.array([0, 0, 1, 1], bool), ["a", "b", "c", "d"])
    assert acc == 1.0 and th == 0.5


def test_nested_lolo_separates_and_never_uses_the_held_out_loop(monkeypatch):
    import phfdi.loopdiag.classifier as clf

    # small grids keep it fast; the nesting is what is tested
    monkeypatch.setattr(clf, "L2_GRID", (0.1, 1.0))
    monkeypatch.setattr(clf, "SYNTHETIC_RATIO_GRID", (1.0,))
    d = _toy(3)
    prob, pred, choices = nested_lolo(d)
    real = np.flatnonzero(d.real)
    assert np.mean(pred[real] == d.y[real]) >= 0.8
    assert set(choices) == {f"L{g}" for g in range(8)}
    # a loop whose labels are flipped cannot be learned from the others: the held-out loop is
    # predicted from the others only, so its (flipped) label is missed
    flipped = Data(d.x.copy(), d.y.copy(), list(d.groups), d.real.copy(), d.features)
    held = np.array([g == "L0" for g in flipped.groups])
    flipped.y[held] = ~flipped.y[held]
    _, pred_f, _ = nested_lolo(flipped, criterion="real")
    assert np.mean(pred_f[held] == flipped.y[held]) <= 0.34


def test_model_json_round_trip(tmp_path):
    d = _toy(4)
    m = fit_logistic(d.x, d.y, training_weights(d.groups, d.real, 1.0), 0.1, d.features)
    m.threshold = 0.37
    m.save(tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert isinstance(back, LogisticModel)
    assert np.allclose(back.probability(d.x), m.probability(d.x)) and back.threshold == 0.37


def test_shipped_model_matches_the_features():
    m = load_model()
    assert m.features == list(FEATURE_NAMES)
    assert len(m.weights) == len(FEATURE_NAMES) and np.all(m.scale > 0) and 0 < m.threshold < 1


def test_weights_are_held_to_the_published_sign():
    d = _toy(5)
    flipped_x = d.x.copy()
    flipped_x[:, 0] = -flipped_x[:, 0]  # the evidence now points the other way
    w = training_weights(d.groups, d.real, 1.0)
    free = fit_logistic(flipped_x, d.y, w, 0.1, d.features)
    bound = fit_logistic(flipped_x, d.y, w, 0.1, d.features, signs=[1, 0])
    assert free.weights[0] < -1.0
    assert bound.weights[0] == 0.0 and bound.signs == [1, 0]


def test_operating_point_bounds_false_calls_on_all_negatives_and_on_the_hard_ones():
    """The cut lets at most 2 % of the negatives through, and at most 2 % of the hard ones: here the hard
    negatives score higher, so they set the cut."""
    from phfdi.loopdiag.classifier import SIM_FALSE_CALL, operating_point

    rng = np.random.default_rng(7)
    easy, hard_p, pos = rng.uniform(0.0, 0.6, 600), rng.uniform(0.3, 0.95, 200), rng.uniform(0.5, 1.0, 400)
    p = np.concatenate([easy, hard_p, pos])
    y = np.concatenate([np.zeros(800, bool), np.ones(400, bool)])
    hard = np.concatenate([np.zeros(600, bool), np.ones(200, bool), np.zeros(400, bool)])
    op = operating_point(p, y, hard)
    assert op["false_call_rate"] <= SIM_FALSE_CALL and op["hard_false_call_rate"] <= SIM_FALSE_CALL
    assert op["cut"] > np.quantile(hard_p, 0.95)  # the hard negatives' tail sets it
    assert op["recall"] == pytest.approx(np.mean(pos >= op["cut"]))
    # one fewer allowed false call would have been possible only with a higher cut: the cut is the lowest
    assert np.sum(hard_p >= np.nextafter(op["cut"], 0.0)) > np.floor(SIM_FALSE_CALL * 200)


def test_operating_point_counts_the_final_calls_when_the_valve_model_fit_decides_or_takes_back():
    """With the valve-model fit's outcomes, the rate bounded is that of the verdict's final calls: loops the fit
    decides for stiction are called from p 0.5 whatever the cut, so the cut rises to make room for them; loops it
    takes back are never called, so they do not count. The cut is still the lowest that keeps the bound."""
    from phfdi.loopdiag.classifier import SIM_FALSE_CALL, final_calls, operating_point

    rng = np.random.default_rng(8)
    p = np.concatenate([rng.uniform(0.0, 0.95, 1000), rng.uniform(0.4, 1.0, 500)])
    y = np.concatenate([np.zeros(1000, bool), np.ones(500, bool)])
    hard = np.zeros(1500, bool)
    plain = operating_point(p, y, hard)
    decides = np.zeros(1500, bool)
    decides[np.flatnonzero(~y & (p >= 0.5) & (p < 0.6))[:10]] = True  # 10 negatives the fit calls (1 %)
    decides[np.flatnonzero(y & (p >= 0.5))[:100]] = True
    op = operating_point(p, y, hard, decides=decides)
    called = final_calls(p, op["cut"], decides)
    assert op["with_valve_model_fit"] and not plain["with_valve_model_fit"]
    assert np.sum(called[~y]) <= np.floor(SIM_FALSE_CALL * 1000) and op["false_call_rate"] == np.mean(called[~y])
    assert op["cut"] > plain["cut"]  # room made for the fit's 10
    below = np.nextafter(op["cut"], 0.0)
    assert np.sum(final_calls(p, below, decides)[~y]) > np.floor(SIM_FALSE_CALL * 1000)  # the lowest cut
    # taken back: the highest-scoring negatives do not count, so the cut falls below the plain one
    back = ~y & (p >= plain["cut"])
    assert operating_point(p, y, hard, takes_back=back)["cut"] < plain["cut"]
    # without outcomes: the same cut as p alone
    assert operating_point(p, y, hard, decides=None, takes_back=None)["cut"] == plain["cut"]
