"""phfdi demo, the product's main job, on a shortened paper scenario: through the graph, and without ROS."""

from __future__ import annotations

import json
import subprocess

import pytest

from .conftest import phfdi_cmd

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]

SHORT = ["--onset", "1000", "--set", "duration_s=1600", "--set", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]


def _check_outputs(out, files: list[str]) -> None:
    for name in files:
        assert (out / name).stat().st_size > 0, name
    (alarm,) = json.loads((out / "alarms.json").read_text())  # the multichannel detector's, physics reference
    assert alarm["isolation"]["fault_class"] == "backlash" and 1000.0 < alarm["detection_time"] < 1200.0


def test_demo_through_the_graph_confirms_the_live_alarms_offline(tmp_path):
    out = tmp_path / "demo"
    proc = subprocess.run(phfdi_cmd("demo", "--out", str(out), *SHORT), capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    text = proc.stdout
    for step in ("[1/4] ROS 2 graph", "[2/4] alarms the recorder received", "[3/4] offline replay", "[4/4] figures"):
        assert step in text
    assert "/fault_alarm ALARM at" in text  # printed as it arrived
    assert "same alarms as published live on /fault_alarm (1:" in text
    assert "healthy run of the same scenario (in-process, replayed): no alarm" in text
    assert "lock-step run: 100 %" in proc.stderr  # progress
    _check_outputs(out, ["run.mcap", "run.png", "detection.png"])


def test_demo_without_ros(tmp_path, capsys):
    from phfdi.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "--no-ros", "--out", str(out), *SHORT]) == 0
    assert "[1/4] in-process loop (no ROS)" in capsys.readouterr().out
    _check_outputs(out, ["run.parquet", "run.png", "detection.png"])
