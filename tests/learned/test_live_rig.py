"""A rig record as a bag through the learned detector NODE over ROS gives the offline alarms (issue 21 acceptance).

The estimator reference (``phfdi calibrate --estimator`` on four shared rig runs) watches the held-out closed-loop
run with a probe bias of 1 pH hidden from 503 s (``phfdi inject``). Offline: ``phfdi replay RUN --map ph_rig
--reference rig.json``; live: the record as a bag (``phfdi bag from-csv --map ph_rig``) played by ``phfdi replay
--live`` into the node (real processes on a ROS domain reserved for them, loopback discovery only). The estimator
steps by the rows' time differences, so the node must take each row at the time offline replay does (the bag's
stamps carry the record's own time to the ns): every field of every alarm is the same, to the last bit.
"""

from __future__ import annotations

import json
import subprocess

import pytest

from phfdi.cli import main

from ..ros.conftest import phfdi_cmd

pytestmark = [pytest.mark.ros, pytest.mark.shared_data]

FIT_RUNS = ("2025.02.24-001_add_base_pH9.5-11.5.csv", "2025.02.24-add_acid_pH7-3.csv",
            "2025.03.03-001_acid_to_base_titration.csv", "2025.04.07-001-base_to_acid_titration.csv")
HELD_OUT = "2025.02.24-005_control_pH7_from_basic.csv"
ONSET_S = 503.0


@pytest.fixture
def rig(shared_data):
    folder = shared_data / "ph_rig"
    paths = [folder / name for name in (*FIT_RUNS, HELD_OUT)]
    missing = [p for p in paths if not p.exists()]
    if missing:
        pytest.skip(f"{missing[0]} not found")
    return folder


def test_bag_of_a_faulty_rig_run_through_the_node_gives_the_offline_alarms(rig, tmp_path, capsys):
    ref, faulty, bag = tmp_path / "rig.json", tmp_path / "faulty.csv", tmp_path / "faulty.mcap"
    assert main(["calibrate", "--estimator", *(str(rig / name) for name in FIT_RUNS), "--map", "ph_rig",
                 "--out", str(ref)]) == 0
    assert json.loads(ref.read_text())["reference"]["kind"] == "estimator"
    assert main(["inject", str(rig / HELD_OUT), "--map", "ph_rig", "--fault", "probe_bias", "--onset", str(ONSET_S),
                 "--size", "1", "--out", str(faulty)]) == 0
    assert main(["bag", "from-csv", str(faulty), str(bag), "--map", "ph_rig"]) == 0
    capsys.readouterr()
    assert main(["replay", str(faulty), "--map", "ph_rig", "--reference", str(ref), "--json"]) == 0
    offline = json.loads(capsys.readouterr().out)
    alarms = offline["alarms"]
    assert alarms, "the offline replay raised no alarm: nothing to compare"
    assert ONSET_S <= alarms[0]["detection_time"] < ONSET_S + 120.0 and alarms[0]["onset_time"] >= ONSET_S
    # the bag offline: read back as the record (the reference's stored rig map does not apply to a bag, whose
    # channels carry the project's names), the same alarms
    assert main(["replay", str(bag), "--reference", str(ref), "--json"]) == 0
    from_bag = json.loads(capsys.readouterr().out)
    assert from_bag["columns"] == "columns: the bag's own channel names"
    assert from_bag["alarms"] == alarms and from_bag["outside_healthy_range"] == offline["outside_healthy_range"]
    # phfdi replay --live reserves a ROS domain of its own (loopback discovery) and stops its processes
    proc = subprocess.run(phfdi_cmd("replay", "--live", str(bag), "--reference", str(ref), "--json"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    live = json.loads(proc.stdout)
    assert live["samples"] == offline["samples"] == 2885
    keys = ("alarm_id", "detection_time", "detection_index", "onset_index", "onset_time", "statistic",
            "statistic_value", "threshold", "channels", "contributions", "cleared_time", "episode_contributions")
    assert [{k: a.get(k) for k in keys} for a in live["alarms"]] == [{k: a.get(k) for k in keys} for a in alarms]
    assert "/fault_alarm ALARM at" in proc.stderr and "through the detector node" in proc.stderr
    # both say where the run leaves the calibration runs' healthy range: the base pump at 6.45 mL/s (3.87 at most)
    assert live["outside_healthy_range"] == offline["outside_healthy_range"]
    assert [o["channel"] for o in live["outside_healthy_range"]] == ["base_flow_ml_s"]
    assert "note: base_flow_ml_s left the range of the reference's healthy runs in 493 of 2885 rows" in proc.stderr
