"""The paper loop's physics as a reference kind, live: a simulated run as a bag through the learned detector NODE
over ROS gives the offline alarm and its name (issue 37: one detector core behind one node).

``phfdi calibrate --physics`` on four short simulated healthy runs; a run with a sticky valve from 2000 s (``phfdi
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


def test_a_sticky_valve_through_the_node_is_the_offline_alarm_and_name(tmp_path, capsys):
    model, run, bag = tmp_path / "physics.json", tmp_path / "sticky.csv", tmp_path / "sticky.mcap"
    assert main(["calibrate", "--physics", "--seeds", "1001-1004", *SHORT, "--out", str(model)]) == 0
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
