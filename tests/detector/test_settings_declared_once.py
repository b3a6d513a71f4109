"""Detector settings and statistics are declared once (wavelet_fdi.config.DetectorSettings, the statistics
registry) and everything else is derived: the CLI options, the detector node's parameters, the docs table.

The toy statistic below is the "where to add a detector statistic" recipe of docs/architecture.md, done in this
file only: one class, registered, named in the settings, calibrated like the others; the detector runs it.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pytest

from phfdi.calibration import calibrate
from phfdi.commands.calibrate import add_detector_args, settings_from_args
from phfdi.loop import simulate
from phfdi.replay import replay_run
from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from wavelet_fdi.config import DetectorSettings, setting_specs, settings_table_markdown
from wavelet_fdi.statistics import STATISTICS, Statistic, register_statistic

ROOT = Path(__file__).resolve().parents[2]


def test_the_docs_table_is_the_declaration():
    from wavelet_fdi.learned_detector import LearnedSettings

    text = (ROOT / "docs" / "detector.md").read_text(encoding="utf-8")
    assert settings_table_markdown() in text, "regenerate the table: wavelet_fdi.config.settings_table_markdown()"
    assert settings_table_markdown(LearnedSettings, option_form="{flag}") in text, \
        "regenerate the learned detector's table (docs/detector.md, Learned detector settings)"


def test_the_learned_detector_checks_its_declared_ranges():
    """A range declared with the learned detector's setting is checked by its check(), with no second copy."""
    from wavelet_fdi.learned_detector import LearnedSettings

    ranged = [s for s in setting_specs(of=LearnedSettings) if s.range is not None]
    assert {s.name for s in ranged} >= {"level", "block_samples", "mean_k", "outside_hold_s"}
    for spec in ranged:
        lo, hi = spec.range
        below = lo - 1 if spec.type is int else lo - abs(lo) * 0.5 - 1e-3
        with pytest.raises(UserError, match=f"learned-detector setting {spec.name} must be a number in"):
            LearnedSettings(**{spec.name: below}).check()
        if hi != float("inf"):
            with pytest.raises(UserError, match=spec.name):
                LearnedSettings(**{spec.name: hi + 1}).check()
    with pytest.raises(UserError, match="mean_k"):
        LearnedSettings(mean_k=float("nan")).check()  # was accepted before the declaration checked it


def test_cli_options_are_derived_from_the_declaration():
    parser = argparse.ArgumentParser()
    add_detector_args(parser)
    exposed = setting_specs(exposed_only=True)
    assert {a.dest for a in parser._actions if a.dest != "help"} == {s.name for s in exposed}
    assert settings_from_args(parser.parse_args([])) == DetectorSettings()  # the defaults are the declaration's
    got = settings_from_args(parser.parse_args(["--arl0", "1e6", "--channels", "ph,level", "--level", "4"]))
    assert (got.arl0_samples, got.channels, got.level) == (1e6, ("ph", "level"), 4)
    with pytest.raises(UserError, match=r"level must be a number in 1\.\.10"):
        settings_from_args(parser.parse_args(["--level", "11"]))


def test_the_launcher_refuses_only_parameters_the_detector_node_does_not_take():
    """launcher.RETIRED_NODE_PARAMS (the retired physics detector node's parameters, refused with what does their
    work now) holds none of the detector node's own: no valid parameter is refused."""
    from phfdi.ros.launcher import RETIRED_NODE_PARAMS
    from wavelet_fdi import learned_node

    assert RETIRED_NODE_PARAMS and not set(RETIRED_NODE_PARAMS) & {p.name for p in learned_node.PARAMS}


def test_a_range_is_checked_where_it_is_declared():
    for spec in setting_specs():
        if spec.range is None or spec.type is not float:
            continue
        with pytest.raises(UserError, match=re.escape(spec.name)):
            DetectorSettings(**{spec.name: spec.range[1] * 2 + 1.0})


class _AbsMean(Statistic):
    """|u| - k on the residual R: a change of mean or variance either way (E|u| = 0.80 for healthy N(0, 1))."""

    kind = group = "toy_abs_mean"

    def rows(self, settings):
        return ("R",)

    def reference_value(self, settings, band):
        return 1.5

    def increments(self, u, k):
        return np.abs(u) - k


@pytest.fixture
def toy_statistic():
    register_statistic(_AbsMean)
    yield _AbsMean.kind
    del STATISTICS[_AbsMean.kind]  # the registry is process-wide: leave it as found


def test_a_new_statistic_is_one_class_and_its_calibration(toy_statistic):
    settings = DetectorSettings(statistics=(toy_statistic,), arl0_samples=1e4)  # the toy alone: any alarm is its
    assert settings.statistic_names() == [f"ph.R.{toy_statistic}"]
    cal = calibrate("paper", settings, seeds=[1001, 1002, 1003])
    assert list(cal.thresholds) == [f"ph.R.{toy_statistic}"] and np.isfinite(cal.thresholds[f"ph.R.{toy_statistic}"])
    model = load_scenario("paper", fault="healthy", overrides=["seed=7"])
    onset_s = load_scenario("paper", fault="leakage").faults[0].onset_s
    healthy = replay_run(simulate(model), model, cal, settings, isolate=False)
    leaking = replay_run(simulate(load_scenario("paper", fault="leakage", overrides=["seed=7"])), model, cal,
                         settings, isolate=False)
    assert healthy.alarms == []
    assert leaking.alarms and all(a.detection_time_s > onset_s for a in leaking.alarms)
    assert leaking.alarms[0].statistic == f"ph.R.{toy_statistic}"


def test_an_unknown_statistic_is_one_line():
    with pytest.raises(UserError, match="statistic kind 'nope' unknown; registered: mean_up, mean_down, energy"):
        DetectorSettings(statistics=("nope",))
