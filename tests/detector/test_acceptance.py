"""Acceptance (issue 4): on the paper scenario with measurement noise every fault preset at the paper's
severity is detected after its 7000 s onset with no alarm before it, and the healthy run raises none;
isolation names each preset and estimates its main parameter. Held for the default detector (the multichannel
detector with the shipped physics reference, what phfdi replay, launch and demo run since 2026-12-07; the physics
detector it replaced, StreamingDetector, was held to the same tests until it was retired)."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.replay import scenario_of, shipped_physics_model
from wavelet_fdi.learned_detector import run_record

from .detector_helpers import PAPER_FAULTS

ONSET_S = 7000.0
#: the library's paper severities (the fault catalogue, phfdi_base.faults)
TRUE_PARAMETER = {"backlash": 0.7, "friction": 1.0, "deadzone": 100.0, "saturation": 50.0, "stiction": 1.5,
                  "probe_delay": 10.0}


def _default_detector(run):
    """The run through the default detector as phfdi replay RUN runs it: the shipped physics reference of the run's
    own scenario, its model the run's plant."""
    model, _ = shipped_physics_model(scenario_of(run))
    x = np.column_stack([np.asarray(run[c], dtype=float) for c in model.channels])
    _, _, detector = run_record(model, np.asarray(run.time_s, dtype=float), x)
    return detector


def test_the_default_detector_raises_no_alarm_on_the_healthy_paper_run(paper_run):
    detector = _default_detector(paper_run("healthy"))
    assert detector.alarms == [] and detector.samples_processed == 10001


@pytest.mark.parametrize("fault", PAPER_FAULTS)
def test_the_default_detector_detects_each_paper_fault_after_its_onset_and_names_it(paper_run, fault):
    run = paper_run(fault)
    assert run.metadata["faults"][0]["onset_s"] == ONSET_S
    alarms = _default_detector(run).alarms
    assert alarms, f"{fault} not detected"
    first = alarms[0]
    assert ONSET_S <= first["detection_time"] < ONSET_S + 1000.0, (fault, first["detection_time"])
    named = first["isolation"]
    assert named["fault_class"] == fault, named
    assert named["parameter"]["value"] == pytest.approx(TRUE_PARAMETER[fault], rel=0.1)
    assert named["confidence"] > 0.9
