"""The pH detector's alarm clears when its statistics fall back (a fault that goes away), reporting the episode,
the same for any chunking; a fault that stays keeps it up."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loop import simulate
from wavelet_fdi.calibration import alarm_positions

from .detector_helpers import SHORT, short_spec
from .test_stream_equals_batch import replay

#: a pH probe bias added to a healthy run between these times (s), and its size (pH)
BIAS_FROM_S, BIAS_TO_S, BIAS_PH = 1000.0, 1300.0, 0.3


@pytest.fixture(scope="module")
def bias_episode():
    spec = short_spec("healthy", duration_s=2400.0)
    run = simulate(spec)
    ph = run["ph_measured"].copy()
    ph[(run["time_s"] >= BIAS_FROM_S) & (run["time_s"] < BIAS_TO_S)] += BIAS_PH
    run.signals["ph_measured"] = ph
    return spec, run


def test_a_fault_that_goes_away_clears_its_alarm_with_the_episode(bias_episode, calibration):
    spec, run = bias_episode
    det, events = replay(spec, run, calibration, len(run))
    (alarm,) = det.alarms
    assert BIAS_FROM_S <= alarm.detection_time_s <= BIAS_FROM_S + 60
    # the statistics fell back within a minute of the bias ending; the clear follows clear_quiet_s after that
    assert BIAS_TO_S <= alarm.episode_end_s <= BIAS_TO_S + 60
    assert alarm.cleared_time_s == pytest.approx(alarm.episode_end_s + SHORT.clear_quiet_s, abs=2.0)
    assert alarm.cleared_time_s < BIAS_TO_S + 1800.0  # before, only clear_after_s (1800 s) without a crossing
    summary = alarm.summary()
    assert summary["episode_end_time"] == alarm.episode_end_s and summary["cleared_time"] == alarm.cleared_time_s
    assert [e.kind for e in events].count("cleared") == 1
    # any chunking clears at the same sample with the same message
    for chunk in (1, 64):
        other, ev = replay(spec, run, calibration, chunk)
        assert [(e.kind, e.index, e.message) for e in ev] == [(e.kind, e.index, e.message) for e in events]
        assert [a.to_dict() for a in other.alarms] == [a.to_dict() for a in det.alarms]
    # the offline copy of the alarm logic (wavelet_fdi.calibration.alarm_positions) agrees
    z = det.trace()["increments"].T
    assert alarm_positions(z, det.h, det.clear_samples, det.quiet_samples, SHORT.clear_fraction) == \
        [a.detection_index for a in det.alarms]


def test_a_fault_that_stays_keeps_its_alarm(calibration):
    spec = short_spec("backlash", onset_s=1000.0, duration_s=1800.0)
    det, _ = replay(spec, simulate(spec), calibration, 4096)
    assert len(det.alarms) == 1 and det.alarms[0].cleared_time_s is None
    assert np.isfinite(det.alarms[0].detection_time_s)
