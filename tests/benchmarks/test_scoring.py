"""The benchmark scorer on hand-made cases whose scores are worked out by hand from the definitions."""

import math

import numpy as np
import pytest

from phfdi.benchmarks.scoring import (
    NAB_PROFILES,
    binary_scores,
    detection_windows,
    match_changepoints,
    nab_reward,
    nab_scores,
    switches,
)


def test_binary_scores_pooled_over_files():
    # file 1: TP 2, FP 1, FN 1, TN 1; file 2: TP 0, FP 0, FN 1, TN 3
    y = [[1, 1, 1, 0, 0], [1, 0, 0, 0]]
    p = [[1, 1, 0, 1, 0], [0, 0, 0, 0]]
    s = binary_scores(y, p)
    assert (s.tp, s.fp, s.fn, s.tn) == (2, 1, 2, 4)
    assert s.f1 == pytest.approx(2 / (2 + 1.5))
    assert s.far_pct == pytest.approx(100 * 1 / 5)
    assert s.mar_pct == pytest.approx(100 * 2 / 4)


def test_binary_scores_reject_bad_input():
    with pytest.raises(ValueError):
        binary_scores([[0, 1]], [[0, 1, 1]])
    with pytest.raises(ValueError):
        binary_scores([[0, 2]], [[0, 1]])


def test_switches_count_a_leading_one():
    assert switches([1, 1, 0, 0, 1]).tolist() == [1, 0, 1, 0, 1]
    assert switches([0, 0, 1, 1]).tolist() == [0, 0, 1, 0]
    assert switches([]).tolist() == []


def test_reward_runs_from_a_tp_to_a_fp_along_tanh():
    a_tp, a_fp = 1.0, -0.11
    w = (100.0, 160.0)
    assert nab_reward(100.0, w, a_tp, a_fp) == pytest.approx(a_tp)
    assert nab_reward(160.0, w, a_tp, a_fp) == pytest.approx(a_fp)
    assert nab_reward(130.0, w, a_tp, a_fp) == pytest.approx((a_tp + a_fp) / 2)
    x = -math.pi / 2 + math.pi * 15 / 60
    assert nab_reward(115.0, w, a_tp, a_fp) == pytest.approx(
        (a_tp - a_fp) / 2 * (1 - math.tanh(x) / math.tanh(math.pi / 2)) + a_fp)


def test_overlapping_windows_are_cut_at_the_earlier_end():
    t = np.arange(0.0, 200.0)
    cp = np.zeros(200, dtype=int)
    cp[[10, 40, 150]] = 1
    assert detection_windows(t, cp, 60.0) == [(10.0, 70.0), (70.0, 100.0), (150.0, 210.0)]


def test_nab_by_hand():
    t = np.arange(0.0, 300.0)
    true_cp = np.zeros(300, dtype=int)
    true_cp[[100, 250]] = 1  # windows [100, 160] and [250, 310]
    pred = np.zeros(300, dtype=int)
    pred[[20, 100, 110, 200]] = 1  # FP, TP at the window start, ignored second hit, FP; second window missed
    m = match_changepoints(t, true_cp, pred, 60.0)
    assert m.first_detection_s == [100.0, None]
    assert m.false_positive_times_s == [20.0, 200.0]
    r = nab_scores([m])
    for name, (a_tp, a_fp, a_fn) in NAB_PROFILES.items():
        raw = a_tp + a_fn + 2 * a_fp
        assert r.raw[name] == pytest.approx(raw)
        assert r.scores[name] == pytest.approx(100 * (raw - 2 * a_fn) / (2 * a_tp - 2 * a_fn))
    assert (r.windows, r.missed, r.false_positives) == (2, 1, 2)
    assert r.mean_delay_s == 0.0


def test_null_and_perfect_detectors_score_0_and_100():
    t = np.arange(0.0, 100.0)
    true_cp = np.zeros(100, dtype=int)
    true_cp[[10, 60]] = 1
    null = nab_scores([match_changepoints(t, true_cp, np.zeros(100, dtype=int), 20.0)])
    perfect = nab_scores([match_changepoints(t, true_cp, true_cp, 20.0)])
    assert all(v == pytest.approx(0.0) for v in null.scores.values())
    assert all(v == pytest.approx(100.0) for v in perfect.scores.values())


def test_late_detection_scores_less_than_early():
    t = np.arange(0.0, 100.0)
    true_cp = np.zeros(100, dtype=int)
    true_cp[10] = 1
    scores = []
    for k in (10, 20, 40, 69):
        pred = np.zeros(100, dtype=int)
        pred[k] = 1
        scores.append(nab_scores([match_changepoints(t, true_cp, pred, 60.0)]).scores["standard"])
    assert scores == sorted(scores, reverse=True) and scores[0] == pytest.approx(100.0)
    assert scores[-1] < 50.0
