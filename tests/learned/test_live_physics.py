"""The paper loop's physics as a reference kind, live: a simulated run as a bag through the learned detector NODE
over ROS gives the offline alarm and its name (issue 37: one detector core behind one node).

``phfdi calibrate`` (a physics reference) on four short simulated healthy runs; a run with a sticky valve from 2000 s (``phfdi
simulate``) replayed offline (``phfdi replay RUN --reference``) and, as a bag (``phfdi bag from-csv``), played by
``phfdi replay --live`` into the node (real processes on a ROS domain reserved for them, loopback discovery only).
"""

from __future__ import annotations

import json
import subprocess

import pytest

from phfdi.cli import main

from ..ros.conftest import phfdi_cmd

pytestmark = [pytest.mark.ros]

SHORT = [x for o in ("duration_s=3000", "setpoints.ph.initial=8", "setpoints.ph.changes=[]") for x in ("--set", o)]
ONSET_S = 2000.0


@pytest.fixture(scope="module")
def physics_model(tmp_path_factory) -> str:
    model = tmp_path_factory.mktemp("physics") / "physics.json"
    assert main(["calibrate", "--physics", "--seeds", "1001-1004", *SHORT, "--out", str(model)]) == 0
    return str(model)


def test_a_sticky_valve_through_the_node_is_the_offline_alarm_and_name(physics_model, tmp_path, capsys):
    model, run, bag = physics_model, tmp_path / "sticky.csv", tmp_path / "sticky.mcap"
    assert main(["simulate", "--fault", "stiction", *SHORT, "--onset", str(ONSET_S), "--out", str(run)]) == 0
    assert main(["bag", "from-csv", str(run), str(bag)]) == 0
    capsys.readouterr()
    assert main(["replay", str(run), "--reference", str(model), "--json"]) == 0
    alarms = json.loads(capsys.readouterr().out)["alarms"]
    assert alarms and alarms[0]["detection_time"] >= ONSET_S
    assert alarms[0]["isolation"]["fault_class"] == "stiction"
    proc = subprocess.run(phfdi_cmd("replay", "--live", str(bag), "--reference", str(model), "--json"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    live = json.loads(proc.stdout)["alarms"]
    keys = ("alarm_id", "detection_time", "onset_time", "statistic", "statistic_value", "threshold", "cleared_time")
    assert [{k: a.get(k) for k in keys} for a in live] == [{k: a.get(k) for k in keys} for a in alarms]
    assert [a["isolation"]["fault_class"] for a in live] == [a["isolation"]["fault_class"] for a in alarms]
    assert "named: actuator fault, stiction" in proc.stderr


def test_the_launched_graph_with_a_physics_reference_gives_its_bags_offline_alarms(tmp_path, capsys):
    """phfdi launch --detector-param reference=paper_physics (the shipped physics reference, by name): the
    multichannel detector's node in the loop graph, on the graph's own topics (/plant/measurement,
    /controller/output; no channel map given), in place of the physics detector's node. Its alarms and their names
    equal the offline replay of the bag the same launch recorded, and /fault_alarm carried them."""
    physics_model = "paper_physics"
    bag, logs = tmp_path / "graph.mcap", tmp_path / "logs"
    proc = subprocess.run(phfdi_cmd("launch", "--fault", "stiction", "--onset", str(ONSET_S), *SHORT,
                                    "--detector-param", f"reference={physics_model}", "--record", str(bag),
                                    "--log-dir", str(logs), "--json"), capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    received = json.loads(proc.stdout)["alarms"]  # as the recorder heard them on /fault_alarm
    lines = [json.loads(x) for x in (logs / "detector.stdout").read_text().splitlines() if x.startswith("{")]
    done = [e for e in lines if e.get("event") == "detector_done"][-1]
    counts = done["channel_map"]["counts"]
    assert set(counts) == {"valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm"}
    assert all(c["used"] == 3001 and c["missing"] == c["late"] == 0 for c in counts.values()), counts
    capsys.readouterr()
    assert main(["replay", str(bag), "--reference", physics_model, "--json"]) == 0
    offline = json.loads(capsys.readouterr().out)["alarms"]
    assert offline and offline[0]["detection_time"] >= ONSET_S
    keys = ("alarm_id", "detection_time", "onset_time", "statistic", "statistic_value", "threshold", "cleared_time")
    assert [{k: a.get(k) for k in keys} for a in done["alarms"]] == [{k: a.get(k) for k in keys} for a in offline]
    assert [a["isolation"]["fault_class"] for a in done["alarms"]] == [a["isolation"]["fault_class"] for a in offline]
    assert [(a["detection_time"], a["fault_class"]) for a in received] == [
        (a["detection_time"], a["isolation"]["fault_class"]) for a in offline]
    assert offline[0]["isolation"]["fault_class"] == "stiction"


def test_the_launched_node_runs_the_launchs_own_plant_with_the_references_calibration(tmp_path):
    """A launch whose plant differs from the one the physics reference was calibrated on (a bigger acid valve:
    45 mL/s, the shipped reference's paper loop has 40): the node runs the launch's plant with the reference's band
    scales and thresholds, as the physics detector's node runs the launch's scenario with its shipped calibration,
    and says so; the healthy run raises no alarm (with the reference's own plant its prediction was 175 sensor
    sigmas off, and it alarmed)."""
    logs = tmp_path / "logs"
    proc = subprocess.run(phfdi_cmd("launch", *SHORT, "--set", "valves.ph.max_flow_ml_s=45",
                                    "--detector-param", "reference=paper_physics", "--log-dir", str(logs), "--json"),
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["alarms"] == []
    said = (logs / "detector.stderr").read_text() + (logs / "detector.stdout").read_text()
    assert "valves.ph.max_flow_ml_s differs from scenario 'paper'" in said, said[-2000:]
