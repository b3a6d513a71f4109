"""A stray writer on a running graph's domain, with the loop graph's default detector (the multichannel detector's
node with the shipped physics reference, since 2026-12-07): the strays (future, past, off-grid and invalid stamps on
the ring's topics, then a burst of stamp garbage on the detector's two inputs; tests/ros/stray_publisher.py) take no
sample's place on its grid, raise no alarm, and its /fault_alarm stays bounded; the node runs to the end. The ring's
own behaviour under the same strays is tests/ros/test_stray_messages.py's (with the physics detector's node)."""

from __future__ import annotations

import json
import math

import pytest

from phfdi_base import topics as T

from .test_stray_messages import BURST, DURATION_S, ROUNDS, N, _messages, _stray_report, launch_disturbed

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]

CHANNELS = ("valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm")


@pytest.fixture(scope="module")
def disturbed(tmp_path_factory):
    return launch_disturbed(tmp_path_factory.mktemp("stray_default"), ["--detector"])


def test_the_default_detector_uses_every_real_sample_and_no_stray(disturbed):
    _stray_report(disturbed)
    assert disturbed["launch_rc"] == 0, disturbed["stderr"]
    assert "Traceback" not in disturbed["stderr"]
    done = [json.loads(ln) for ln in (disturbed["logs"] / "detector.stdout").read_text().splitlines()
            if '"detector_done"' in ln]
    assert done, "the detector did not finish"
    report = done[-1]
    assert report["samples"] == N, report["samples"]
    counts = report["channel_map"]["counts"]
    for channel in CHANNELS:
        c = counts[channel]
        # each sample on the grid is a real one: none missing, none held
        assert c["used"] == N and c["missing"] == 0 and c["held"] == 0, (channel, c)
        # per round: one stamped beyond the run's end (a jump its stream never followed), one off the grid, three
        # that are no time; per burst cycle one far ahead (the 11 past ones come late)
        assert c["jumps_dropped"] == ROUNDS + BURST, (channel, c)
        assert c["off_grid"] == ROUNDS and c["invalid_stamps"] == 3 * ROUNDS, (channel, c)
    # no stray's value (-77 on every field) went into a sample: it would lie far outside the healthy runs' range
    assert report["outside_healthy_range"] == [], report["outside_healthy_range"]
    assert report["alarms"] == []  # 200 s of a run is inside the reference's 600 s warm-up: nothing to raise


def test_the_default_detectors_fault_alarm_stays_bounded(disturbed):
    _stray_report(disturbed)
    alarms = _messages(disturbed["bag"])[T.FAULT_ALARM.name]
    assert all(a.state == 0 for a in alarms), [a.message for a in alarms if a.state]
    # heartbeats, one per 60 s of simulated time (+ the first and the last), and the state at the start: the strays
    # change nothing the detector says (they are counted on /diagnostics, 'detector: channel map')
    assert len(alarms) <= math.ceil(DURATION_S / 60) + 3, [a.message for a in alarms]
