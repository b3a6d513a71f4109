"""The recorder's split_after_s (phfdi launch --split-s): one run in several complete bag files, nothing lost
or repeated between them (why: the MCAP writer's per-chunk index grows in memory until a file is finished)."""

from __future__ import annotations

import json
import subprocess

import numpy as np
import pytest
from mcap.reader import make_reader

from phfdi import bagio
from phfdi_base import topics as T

from .conftest import SHORT_RUN, phfdi_cmd
from .rosbag2_check import rosbag2_record

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]
PER_SAMPLE = [t.name for t in T.RECORDED if t.per_sample]


def _stamps_s(path) -> dict[str, np.ndarray]:
    """Stamps (whole seconds: the sample time is 1 s) of the per-sample topics in one file."""
    out: dict[str, list] = {t: [] for t in PER_SAMPLE}
    with open(path, "rb") as f:
        for _s, channel, message in make_reader(f).iter_messages(topics=PER_SAMPLE, log_time_order=False):
            out[channel.topic].append(message.log_time // 1_000_000_000)
    return {t: np.asarray(v) for t, v in out.items()}


def test_split_run_is_complete_bags_that_together_hold_every_sample_once(tmp_path):
    bag = tmp_path / "run.mcap"
    proc = subprocess.run(phfdi_cmd("launch", *SHORT_RUN, "--record", str(bag), "--split-s", "250", "--json"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    parts = [tmp_path / "run.mcap", tmp_path / "run.1.mcap", tmp_path / "run.2.mcap"]  # 0-249, 250-499, 500-600 s
    assert summary["bag"]["parts"] == [str(p) for p in parts] and not (tmp_path / "run.3.mcap").exists()
    assert all(summary["bag"]["counts"][t] == 601 for t in PER_SAMPLE)
    together: dict[str, list] = {t: [] for t in PER_SAMPLE}
    last_of_topic: dict[str, int] = {t: -1 for t in PER_SAMPLE}
    for i, part in enumerate(parts):
        info = bagio.bag_info(part)
        assert info["finished"], part
        assert bagio.load_run(part).metadata["scenario"] == summary["scenario"]  # each file: the run's metadata
        meta = rosbag2_record(part)  # and rosbag2's metadata of that file alone
        assert meta["relative_file_paths"] == [part.name] and meta["message_count"] == info["messages"]
        assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == \
            {t["topic"]: t["count"] for t in info["topics"]}
        for topic, s in _stamps_s(part).items():
            assert len(s) > 0, (part, topic)
            # a file never holds a later interval's sample, and never one older than the previous file's: the
            # recorder splits when a sample of the next interval arrives, so what of a topic is still in its queue
            # goes to the next file (under a full suite's load once 190 samples of /controller/output, 310-499 s,
            # at 600 x real time), but each topic's stamps run on from one file to the next
            assert s.max() < 250 * (i + 1), (part, topic, s.min(), s.max())
            assert s.min() > last_of_topic[topic], (part, topic, s.min(), last_of_topic[topic])
            last_of_topic[topic] = int(s.max())
            together[topic] += s.tolist()
    for topic, s in together.items():
        assert sorted(s) == list(range(601)), topic


def test_split_needs_a_record_and_no_parts_of_an_earlier_bag(tmp_path):
    proc = subprocess.run(phfdi_cmd("launch", "--split-s", "100"), capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--split-s needs --record" in proc.stderr and "Traceback" not in proc.stderr
    (tmp_path / "old.1.mcap").write_bytes(b"")
    proc = subprocess.run(phfdi_cmd("launch", "--record", str(tmp_path / "old.mcap"), "--split-s", "100"),
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "old.1.mcap exists" in proc.stderr and "Traceback" not in proc.stderr
