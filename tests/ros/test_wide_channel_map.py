"""A channel map of many channels does not flood the log (issue 36 item 8).

A learned reference of 1000 channels on a map whose topics were all silent said 1000 WARN lines, one per topic.
Now the first few of each kind of problem are said one by one and the rest in one line that points to
/diagnostics, where every one of them still is. Here: a reference of 100 channels, a stand-in plant (a real
process, tests/ros/foreign_plant.py) publishing values far beyond the healthy runs on 50 of the topics, the other 50
silent; each kind (silent topic, beyond the healthy range) is said three times and summed up in one line.
"""

from __future__ import annotations

import numpy as np
import pytest

from wavelet_fdi.learned_detector import learn
from wavelet_fdi.map_inputs import SAY_EACH

from .test_foreign_topics import run_foreign_plant

pytestmark = [pytest.mark.ros, pytest.mark.timeout(400)]

CHANNELS = [f"c{i}" for i in range(100)]
PUBLISHED = CHANNELS[:50]


def test_a_hundred_channel_problems_are_said_in_a_few_lines(tmp_path):
    rng = np.random.default_rng(36)
    ref = tmp_path / "wide.json"
    learn(rng.normal(size=(400, len(CHANNELS))), CHANNELS).save(ref)
    cmap = tmp_path / "wide_map.yaml"
    cmap.write_text("align: sequence\nmax_wait_s: 0.5\nchannels:\n" + "".join(
        f"  {c}: {{topic: /wide/{c}, type: std_msgs/msg/Float64}}\n" for c in CHANNELS))
    rows = np.full((20, len(PUBLISHED)), 1000.0)  # healthy values are N(0, 1): every channel leaves its range
    silent_summary = "more silent topics like it"
    range_summary = "more channels beyond the reference's healthy runs like it"
    done, heard, err = run_foreign_plant(
        tmp_path, ref, cmap, rows, node_params={"silent_after_s": 1.0},
        plant_spec={"topics": [f"/wide/{c}" for c in PUBLISHED], "pace_hz": 0, "wait_samples": 0},
        expect_stderr=(silent_summary, range_summary))
    warnings = [ln for ln in err.splitlines() if "WARN" in ln]
    # each kind: SAY_EACH lines, then summing-up lines (one per check that found more; a silent topic that starts
    # publishing and falls silent again is said again)
    assert sum("has published nothing" in ln for ln in warnings) <= SAY_EACH + 1, warnings
    assert sum("left the range of the reference's healthy runs" in ln for ln in warnings) == SAY_EACH, warnings
    assert len(warnings) <= 2 * SAY_EACH + 4, warnings
    assert "each is on /diagnostics ('detector: channel map')" in err
    assert "each is on /diagnostics ('detector: healthy range')" in err
    # every one of them is still on /diagnostics and in the report
    silent = [p for p in done["channel_map"]["problems"] if "has published nothing" in p]
    assert len(silent) == len(CHANNELS) - len(PUBLISHED), done["channel_map"]["problems"]
    assert sorted(heard["healthy_range"][-1]["values"]) == sorted(PUBLISHED)
    assert [o["channel"] for o in done["outside_healthy_range"]] == PUBLISHED
