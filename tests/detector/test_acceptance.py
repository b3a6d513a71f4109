"""Acceptance (issue 4): on the paper scenario with measurement noise every fault preset at the paper's
severity is detected after its 7000 s onset with no alarm before it, and the healthy run raises none;
isolation names each preset and estimates its main parameter."""

from __future__ import annotations

import pytest

from phfdi.replay import replay_run
from wavelet_fdi.config import DetectorSettings

from .detector_helpers import PAPER_FAULTS

ONSET_S = 7000.0
#: the library's paper severities (the fault catalogue, phfdi_base.faults)
TRUE_PARAMETER = {"backlash": 0.7, "friction": 1.0, "deadzone": 100.0, "saturation": 50.0, "stiction": 1.5,
                  "probe_delay": 10.0}


def test_the_healthy_paper_run_raises_no_alarm(paper_run, calibration):
    result = replay_run(paper_run("healthy"), calibration=calibration)
    assert result.alarms == []
    assert result.samples == 10001


@pytest.mark.parametrize("fault", PAPER_FAULTS)
def test_each_paper_fault_is_detected_after_its_onset_and_named(paper_run, calibration, fault):
    run = paper_run(fault)
    assert run.metadata["faults"][0]["onset_s"] == ONSET_S
    result = replay_run(run, calibration=calibration, settings=DetectorSettings())
    assert result.alarms, f"{fault} not detected"
    first = result.alarms[0]
    assert first.detection_time_s >= ONSET_S, f"{fault}: alarm at {first.detection_time_s} s, before the onset"
    assert first.detection_time_s < ONSET_S + 1000.0
    assert first.fault_class == fault, (first.fault_class, first.alternatives)
    assert first.parameter["value"] == pytest.approx(TRUE_PARAMETER[fault], rel=0.1)
    assert first.confidence > 0.9
