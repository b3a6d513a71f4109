"""Leave-one-loop-out: thresholds never see the held-out loop; the metrics add up."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loopdiag.evaluate import Method, leave_one_loop_out, metrics, tune_threshold


def rec(loop, stiction, gain, n=1):
    return [{"file": f"{loop}_{i}", "loop_tag": loop, "stiction": stiction, "gain_percent": gain,
             "extended_cause": "stiction"} for i in range(n)]


METHOD = Method("gain", lambda r: r["gain_percent"], 10.0, True, "test")


def test_threshold_is_tuned_without_the_held_out_loop():
    # loop C would pull the threshold up to 50 if it were seen; held out, the others say 20
    records = rec("A", True, 30.0, 3) + rec("B", False, 10.0, 2) + rec("C", False, 45.0) + rec("D", True, 60.0)
    _, thresholds = leave_one_loop_out(records, METHOD)
    others = [r for r in records if r["loop_tag"] != "C"]
    assert thresholds["C"] == tune_threshold(others, METHOD)
    assert thresholds["C"] <= 30.0 < 45.0  # so C's file is called stiction: a false positive
    preds, _ = leave_one_loop_out(records, METHOD)
    assert preds[records.index(rec("C", False, 45.0)[0])] is True


def test_metrics_count_files_and_loops():
    records = rec("A", True, 30.0, 3) + rec("B", False, 10.0, 2)
    m = metrics(records, [True, True, False, True, False])
    assert (m["tp"], m["fn"], m["fp"], m["tn"]) == (2, 1, 1, 1)
    assert m["accuracy"] == pytest.approx(3 / 5)
    assert m["precision"] == pytest.approx(2 / 3) and m["recall"] == pytest.approx(2 / 3)
    assert m["loops_right"] == 2  # A: 2 of 3 say stiction; B: 1 of 2 is no majority, so "no stiction"


def test_unscorable_files_count_as_no_stiction():
    records = rec("A", True, None, 2) + rec("B", False, 5.0)
    preds, _ = leave_one_loop_out(records, Method("g", lambda r: r["gain_percent"], 10.0, False, ""))
    assert preds == [False, False, False]


def test_a_record_repeating_another_is_found_and_a_partial_overlap_is_not():
    from phfdi.loopdiag.evaluate import repeated_records

    rng = np.random.default_rng(3)
    op, pv = 50 + np.cumsum(rng.normal(0, 0.1, 751)), 100 + rng.normal(0, 0.3, 751)
    other = (50 + np.cumsum(rng.normal(0, 0.1, 751)), 100 + rng.normal(0, 0.3, 751))
    # a later export of the same loop: 90 % of the first one's samples, then new ones
    later = (np.r_[op[75:], other[0][:75]], np.r_[pv[75:], other[1][:75]])
    # 60 % shared: a neighbouring window, not a repeat
    half = (np.r_[op[300:], other[0][:300]], np.r_[pv[300:], other[1][:300]])
    found = repeated_records({"a.txt": (op, pv), "b.txt": later, "c.txt": other, "d.txt": half})
    assert set(found) == {"b.txt"} and found["b.txt"][0] == "a.txt"
    assert 0.85 < found["b.txt"][1] < 0.95
