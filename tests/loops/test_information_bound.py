"""benchmarks/stiction_information_bound.py: its cut follows the verdict's false-call rule, and its oracles read the truth."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from phfdi.loopdiag.synthetic import acceptance_cases
from phfdi.loopdiag.training import DrawnLoop

ROOT = Path(__file__).resolve().parents[2]


def _bound():
    spec = importlib.util.spec_from_file_location("stiction_information_bound",
                                                  ROOT / "benchmarks" / "stiction_information_bound.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_cut_lets_at_most_two_percent_of_each_group_reach_it():
    bound = _bound()
    values = np.arange(200.0)
    everyone = np.ones(200, bool)
    few = np.arange(200) >= 150  # 50 values: 2 % of them is one value
    cut = bound.false_call_cut(values, [everyone])
    assert np.sum(values >= cut) == 4 and np.sum(values >= np.nextafter(cut, -1.0)) == 5
    cut = bound.false_call_cut(values, [everyone, few])
    assert np.sum(values[few] >= cut) == 1 and np.sum(values >= cut) == 1


def test_the_oracles_read_the_sticky_valve_and_only_for_a_sticky_loop():
    bound = _bound()
    sticky = bound.loop_row(DrawnLoop(acceptance_cases()["stiction"].loop, True, ("quiet",), "self_regulating",
                                      "stiction"))
    # the stem itself explains PV's changes at least as well as the screen's best guess of it
    assert sticky["true_stem"] >= sticky["screen"] > 0.0
    # the true valve block, run over OP from rest, reproduces the simulated stem: the same gain
    assert abs(sticky["true_model_on_op"] - sticky["true_stem"]) < 0.01
    healthy = bound.loop_row(DrawnLoop(acceptance_cases()["backlash"].loop, False, ("quiet",), "self_regulating",
                                       "other_nonlinearity"))
    assert "true_stem" not in healthy and np.isfinite(healthy["screen"])
