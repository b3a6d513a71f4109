"""phfdi launch --detector and phfdi replay (offline and --live) on one recorded faulty run: same alarms.

The detector is the multichannel detector's node with the paper's shipped physics reference (the default since
2026-12-07), on the graph's own topics; replay without --reference runs the same."""

from __future__ import annotations

import json
import math
import subprocess

import pytest

from phfdi import bagio
from phfdi_base import topics as T
from wavelet_fdi import alarm_messages

from .conftest import SHORT_FAULTY, phfdi_cmd, processes_with

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


@pytest.fixture(scope="module")
def launched(tmp_path_factory):
    """One lock-step run of the short faulty scenario with the detector, recorded."""
    tmp = tmp_path_factory.mktemp("launch")
    bag = tmp / "run.mcap"
    proc = subprocess.run(phfdi_cmd("launch", *SHORT_FAULTY, "--detector", "--record", str(bag),
                                    "--log-dir", str(tmp / "logs"), "--json"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    return {"proc": proc, "bag": bag, "logs": tmp / "logs", "summary": json.loads(proc.stdout)}


@pytest.fixture(scope="module")
def offline(launched):
    """phfdi replay BAG --json: the bag recorded by phfdi launch, offline (phfdi.bagio.load_run)."""
    proc = subprocess.run(phfdi_cmd("replay", str(launched["bag"]), "--json"), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)["alarms"]


def test_launch_reports_the_backlash_after_its_onset(launched):
    summary = launched["summary"]
    assert summary["samples"] == summary["of"] == 1601 and summary["failure"] is None
    (alarm,) = summary["alarms"]  # as the recorder received them on /fault_alarm
    assert 1000.0 < alarm["detection_time"] < 1200.0
    assert alarm["fault_class"] == "backlash" and alarm["confidence"] > 0.9
    assert alarm["severity"] == pytest.approx(0.7, rel=0.1) and alarm["severity_unit"].startswith("% of span")
    assert "/fault_alarm ALARM at" in launched["proc"].stderr  # printed as it came
    assert processes_with(str(launched["logs"])) == []  # every node stopped


def test_bag_holds_the_alarm_the_heartbeat_and_the_detector_diagnostics(launched):
    msgs = bagio.fault_alarms(launched["bag"])
    states = [m["state"] for m in msgs]
    assert states[0] == "OK" and "ALARM" in states
    first_alarm = next(m for m in msgs if m["state"] == "ALARM")
    assert first_alarm["time"] == first_alarm["detection_time"] > 1000.0
    assert first_alarm["fault_class"] == "pending"  # isolation comes 300 s later
    diagnosed = [m for m in msgs if m["fault_class"] == "backlash"]
    # named on the last sample of the 300 s after the detection
    assert diagnosed and diagnosed[0]["time"] == pytest.approx(first_alarm["time"] + 300.0, abs=1.0)
    # heartbeat every 60 s of simulated time, besides the state changes: the first sample past each multiple of
    # 60 s, one per batch the worker takes. Batches are a few samples at ~600 x real time, but a busy machine can
    # stall the worker for a second or more (364 samples once, with the other test worker fitting models; 257 s of
    # simulated time, 62 to 319 s, once in a full suite), and a backlog worked off in one batch gives one heartbeat.
    # So the grid is asserted as: never two in one 60 s period, and heartbeats recur before the fault (three at
    # least in its 1000-odd s: the schedule goes on after a stall).
    times = [m["time"] for m in msgs]
    assert times == sorted(times)
    heartbeats = [m["time"] for m in msgs if m["time"] < first_alarm["time"] and not m["message"].startswith("state now")]
    cells = [math.floor(t / 60.0) for t in heartbeats]
    assert len(cells) == len(set(cells)), f"two heartbeats in one 60 s period: {heartbeats}"
    assert len(heartbeats) >= 3, f"heartbeats before the fault: {heartbeats}"
    status = [s for a in bagio.read_messages(launched["bag"], T.DIAGNOSTICS.name) for s in a.status
              if s.name.startswith("detector:")]
    inputs = {kv.key: kv.value for kv in [s for s in status if s.name == "detector: channel map"][-1].values}
    assert inputs["samples"] == "1601" and inputs["reference"] == "paper_physics"
    for channel in ("valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm"):
        assert inputs[f"{channel} counts"].startswith("received 1601, used 1601, held 0, missing 0, late 0"), inputs


def test_offline_replay_of_the_launched_bag_gives_the_alarms_the_graph_published(launched, offline):
    published = alarm_messages.per_alarm(bagio.fault_alarms(launched["bag"]))
    replayed = alarm_messages.from_summaries(offline)
    assert len(replayed) == len(published) == 1
    for off, live in zip(replayed, published):
        assert off["detection_time"] == live["detection_time"]
        assert off["onset_time"] == live["onset_time"]
        assert off["fault_class"] == live["fault_class"] and off["confidence"] == live["confidence"]
        assert off["severity"] == live["severity"] and off["severity_unit"] == live["severity_unit"]


def test_live_replay_gives_the_same_alarms_as_offline_replay(launched, offline):
    proc = subprocess.run(phfdi_cmd("replay", "--live", str(launched["bag"]), "--json"), capture_output=True,
                          text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    live = json.loads(proc.stdout)
    # every field, the naming's alternatives included (on failure: which fields differ, and the samples each saw)
    assert live["alarms"] == offline, (live["samples"], [
        (k, live_a.get(k), off_a.get(k)) for live_a, off_a in zip(live["alarms"], offline)
        for k in sorted(set(live_a) | set(off_a)) if live_a.get(k) != off_a.get(k)])
    assert live["notes"] == [] and live["samples"] == 1601
    assert "/fault_alarm ALARM at" in proc.stderr and "through the detector node" in proc.stderr


def test_live_replay_without_naming_gives_the_offline_detections(launched, offline):
    """--live --no-isolation: the node runs without naming (its name_faults parameter), as offline."""
    proc = subprocess.run(phfdi_cmd("replay", "--live", str(launched["bag"]), "--json", "--no-isolation"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    live = json.loads(proc.stdout)["alarms"]
    assert [(a["detection_time"], a["statistic"]) for a in live] == \
        [(a["detection_time"], a["statistic"]) for a in offline]
    assert live and all(a.get("isolation") is None for a in live)


def test_without_a_bag_the_launcher_reports_what_the_detector_published(launched):
    """phfdi launch --detector without --record lists the detector's own report: the same alarms as the bag."""
    from phfdi.commands.launch import received_alarms
    from phfdi.ros.launcher import LaunchResult

    lines = (launched["logs"] / "detector.stdout").read_text().splitlines()
    events = [json.loads(line) for line in lines if line.startswith("{")]
    result = LaunchResult(status=0, samples=1601, samples_done=1601, connect_s=0.0, run_wall_s=0.0, domain_id=0,
                          node_events={"detector": events})
    reported, source = received_alarms(result)
    assert source == "as the detector reported them"
    in_bag = alarm_messages.per_alarm(bagio.fault_alarms(launched["bag"]))
    keys = ("onset_time", "detection_time", "fault_class", "confidence", "severity", "severity_unit")
    assert [{k: a[k] for k in keys} for a in reported] == [{k: a[k] for k in keys} for a in in_bag]
