"""Sample by sample, in chunks of 7 or 64, or the whole record at once: the same bits, the same events."""

from __future__ import annotations

import numpy as np
import pytest

from phfdi.loop import simulate
from phfdi.replay import detector_inputs
from wavelet_fdi.calibration import alarm_positions
from wavelet_fdi.detector import StreamingDetector

from .detector_helpers import SHORT, short_spec


@pytest.fixture(scope="module")
def faulty():
    spec = short_spec("backlash", onset_s=1000.0, duration_s=1500.0)
    return spec, simulate(spec)


def replay(spec, run, calibration, chunk: int):
    det = StreamingDetector(spec, calibration, SHORT, record_trace=True)
    cols = detector_inputs(run, det.reference.feed_names, det.reference.valve_feed)
    events = []
    for a in range(0, len(run), chunk):
        events += det.process({k: v[a:a + chunk] for k, v in cols.items()})
    events += det.flush()
    return det, events


def test_any_chunking_gives_identical_statistics_alarms_and_diagnoses(faulty, calibration):
    spec, run = faulty
    whole, ev_whole = replay(spec, run, calibration, len(run))
    assert [e.kind for e in ev_whole] == ["alarm", "diagnosis"]
    assert ev_whole[0].time_s > 1000.0
    tr_whole = whole.trace()
    for chunk in (1, 7, 64):
        det, events = replay(spec, run, calibration, chunk)
        tr = det.trace()
        for key in tr_whole:
            assert np.array_equal(tr[key], tr_whole[key]), (chunk, key)
        assert [(e.kind, e.index, e.message) for e in events] == [(e.kind, e.index, e.message) for e in ev_whole]
        assert [a.to_dict() for a in det.alarms] == [a.to_dict() for a in whole.alarms]


def test_offline_alarm_logic_reproduces_the_detectors_alarms(faulty, calibration):
    """The offline alarm logic (wavelet_fdi.calibration.alarm_positions, which checks calibrations on long records) is
    the detector's."""
    spec, run = faulty
    det, _ = replay(spec, run, calibration, len(run))
    z = det.trace()["increments"].T
    got = alarm_positions(z, det.h, det.clear_samples)
    assert got == [a.detection_index for a in det.alarms]
