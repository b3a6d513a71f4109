"""Scoring of the rig benchmark (phfdi.benchmarks.rig_detection): what counts as the right class and size."""

from __future__ import annotations

import pytest

from phfdi.benchmarks.rig_detection import SIZES, _class_and_size, expected_class, expected_size, outcome


def test_every_injected_kind_has_a_class_a_right_name_gives():
    for kind in SIZES:
        pump = "acid" if kind.startswith("pump") else None
        classes = expected_class(kind, pump)
        if pump:
            assert classes == ["pump:acid_flow_ml_s"]
        else:  # the exact hypothesis first, then the ones a right-family name may give
            assert classes and set(classes) <= {"probe_bias", "probe_drift", "probe_noise"}, (kind, classes)


@pytest.mark.parametrize("kind,size,true", [("probe_bias", 0.3, 0.3), ("pump_low", 0.2, 0.8), ("pump_high", 0.5, 1.5),
                                            ("pump_stuck", 3.0, 0.0), ("probe_drift", 1.0, None)])
def test_the_true_size_in_the_named_classs_unit(kind, size, true):
    assert expected_size(kind, size) == true


def test_the_first_alarm_after_the_onset_gives_the_name_and_only_right_classes_give_a_size():
    alarms = [{"t": 5.0, "family": "sensor", "fault_class": "probe_bias", "size": 9.0},
              {"t": 12.0, "family": "actuator", "fault_class": "pump:base_flow_ml_s", "size": 0.45},
              {"t": 20.0, "family": "sensor", "fault_class": "probe_bias", "size": 1.0}]
    o = outcome(alarms, 10.0)
    assert (o.alarms_before, o.first_after_s, o.fault_class, o.size) == (1, 12.0, "pump:base_flow_ml_s", 0.45)
    rows = [{"size": 0.5, "class": "pump:base_flow_ml_s", "class_named": "pump:base_flow_ml_s", "size_named": s}
            for s in (0.4, 0.45, 0.7)]
    rows.append({"size": 0.5, "class": "pump:base_flow_ml_s", "class_named": "probe_bias", "size_named": 3.0})
    assert _class_and_size(rows, "pump_low") == {"class_right": 3, "median_size_named": 0.45, "size_expected": 0.5}
    assert _class_and_size([], "pump_low") == {"class_right": 0, "median_size_named": None, "size_expected": None}


def test_every_fold_trains_without_its_held_out_runs():
    from phfdi.benchmarks.rig_detection import held_out_sets

    runs = [f"run{i}.csv" for i in range(5)]
    for k, n_folds in ((1, 5), (2, 10), (4, 5)):
        folds = held_out_sets(runs, k)
        assert len(folds) == n_folds
        for train, held in folds:
            assert len(held) == k and not set(train) & set(held) and sorted(train + held) == runs
        # each run is held out equally often
        assert {r: sum(r in h for _, h in folds) for r in runs} == {r: n_folds * k // 5 for r in runs}
    with pytest.raises(ValueError, match="leave_out"):
        held_out_sets(runs, 5)


def test_the_summary_counts_replays_outside_the_healthy_range():
    from phfdi.benchmarks.rig_detection import summary

    rows = [{"detector": "estimator", "case": "healthy", "hours": 0.1, "false_alarms": fa,
             "outside_healthy_range": out} for fa, out in ((1, ["acid_flow_ml_s"]), (0, ["base_flow_ml_s"]), (0, []),
                                                           (2, []))]
    rows[0]["false_alarms_marked"] = 1
    (e,) = summary({"rows": rows})
    assert (e["healthy_false_alarms"], e["healthy_runs_with_alarm"], e["healthy_replays"]) == (3, 2, 4)
    assert (e["outside_range_with_alarm"], e["outside_range_without_alarm"], e["false_alarms_marked"]) == (1, 1, 1)


def test_an_alarm_beyond_the_healthy_range_is_counted_before_and_at_the_detection():
    alarms = [{"t": 5.0, "outside": ["acid_flow_ml_s"]}, {"t": 8.0, "outside": []},
              {"t": 12.0, "outside": ["base_flow_ml_s"]}, {"t": 20.0, "outside": ["acid_flow_ml_s"]}]
    o = outcome(alarms, 10.0)
    assert (o.alarms_before, o.marked_before, o.first_after_s, o.outside) == (2, 1, 12.0, ["base_flow_ml_s"])
    assert outcome([{"t": 1.0}], 0.5).outside is None  # a detector without ranges (plain CUSUM) lists none
