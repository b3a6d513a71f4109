"""A SKAB record as a bag through the learned detector NODE over ROS: the same alarms as the offline replay.

Real processes (phfdi replay --live starts a player and the node on a ROS domain it reserves for itself,
loopback discovery only); the record is the shared SKAB file valve1/3.csv (a real valve closure), the reference
learned on its first 400 rows.
"""

from __future__ import annotations

import json
import subprocess

import pytest

from phfdi.cli import main

from ..ros.conftest import phfdi_cmd

pytestmark = [pytest.mark.ros, pytest.mark.shared_data]


@pytest.fixture
def skab_file(shared_data):
    path = shared_data / "skab" / "valve1" / "3.csv"
    if not path.exists():
        pytest.skip(f"{path} not found")
    return path


def test_bag_of_a_skab_record_through_the_node_gives_the_offline_alarms(skab_file, tmp_path, capsys):
    ref, bag = tmp_path / "ref.json", tmp_path / "valve1_3.mcap"
    assert main(["calibrate", "--learn", str(skab_file), "--rows", "400", "--exclude", "anomaly,changepoint",
                 "--out", str(ref)]) == 0
    assert main(["bag", "from-csv", str(skab_file), str(bag), "--exclude", "anomaly,changepoint"]) == 0
    capsys.readouterr()
    assert main(["replay", str(skab_file), "--reference", str(ref), "--json"]) == 0
    offline = json.loads(capsys.readouterr().out)
    assert offline["alarms"], "the offline replay raised no alarm: nothing to compare"
    # phfdi replay --live reserves a ROS domain of its own (loopback discovery) and stops its processes
    proc = subprocess.run(phfdi_cmd("replay", "--live", str(bag), "--reference", str(ref), "--json"),
                          capture_output=True, text=True, timeout=240)
    assert proc.returncode == 0, proc.stderr
    live = json.loads(proc.stdout)
    assert live["samples"] == offline["samples"]
    keys = ("alarm_id", "detection_time", "detection_index", "onset_index", "onset_time", "statistic",
            "statistic_value", "threshold", "channels", "contributions", "cleared_time", "episode_contributions",
            # one numbering: the node's sample indices mapped onto the CSV's lines and stamps (bag from-csv keeps them)
            "where", "detection_line", "cleared_line", "onset_stamp", "detection_stamp", "cleared_stamp")
    assert [{k: a.get(k) for k in keys} for a in live["alarms"]] == \
        [{k: a.get(k) for k in keys} for a in offline["alarms"]]
    assert "/fault_alarm ALARM at" in proc.stderr and "through the detector node" in proc.stderr


@pytest.mark.parametrize("reference", ["", "missing.json", "bad.json"])
def test_node_refuses_a_bad_reference_in_one_line(reference, tmp_path):
    """The learned node with no, a missing or a broken reference file: exit 2, one line naming it."""
    from phfdi_base.ros.env import graph_env, reserve_domain_id

    from ..ros.conftest import node_cmd

    (tmp_path / "bad.json").write_text('{"format": "phfdi-learned-detector/1"}')
    params = {"graph_nodes": "[detector]"}
    if reference:
        params["reference"] = str(tmp_path / reference)
    lease = reserve_domain_id()
    try:
        proc = subprocess.run(node_cmd("wavelet_fdi.learned_node", **params), capture_output=True, text=True,
                              timeout=60, env=graph_env(lease.domain_id), cwd=tmp_path)
    finally:
        lease.release()
    assert proc.returncode == 2, proc.stderr
    errors = [ln for ln in proc.stderr.splitlines() if "error:" in ln]
    assert len(errors) == 1 and "reference" in errors[0] and "Traceback" not in proc.stderr
