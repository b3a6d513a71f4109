"""The soak benchmark (benchmarks/soak.py): its loss and growth arithmetic, and its measuring on a short real run."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

from phfdi import bagio
from phfdi_base import topics as T

from .conftest import processes_with

SOAK = Path(__file__).resolve().parents[2] / "benchmarks" / "soak.py"
NODES = {"plant", "valve", "controllers", "recorder", "detector"}


@pytest.fixture(scope="module")
def soak():
    spec = importlib.util.spec_from_file_location("soak_benchmark", SOAK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_stamp_check_counts_missing_duplicated_and_off_grid_stamps(soak, tmp_path):
    path = tmp_path / "holes.mcap"
    bag = bagio.BagWriter(path)
    cid = bag.add_topic(T.MEASUREMENT.name, T.MEASUREMENT.type)
    dt = 1_000_000_000
    for k in [0, 1, 2, 3, 5, 6, 7, 7, 8]:  # 4 and 9 missing, 7 twice
        bag.write(cid, k * dt, b"\0\1\0\0")
    bag.write(cid, 8 * dt + 5, b"\0\1\0\0")  # off the grid
    bag.close()
    got = soak.stamp_check([path], [T.MEASUREMENT.name], 10, dt)[T.MEASUREMENT.name]
    assert got == {"messages": 10, "off_grid": 1, "missing_stamps": 2, "duplicate_stamps": 1, "in_order": False}


def test_memory_summary_takes_start_middle_end_inside_the_run(soak):
    rows = []
    for t in range(0, 21):  # steady node; growing node: +1 MB a second after t = 10
        rows.append({"wall_s": float(t), "node": "steady", "pid": 1, "VmRSS": 100_000, "RssAnon": 50_000,
                     "RssFile": 40_000, "RssShmem": 10_000, "Threads": 9})
        grow = 100_000 + 1000 * max(0, t - 10)
        rows.append({"wall_s": float(t), "node": "leaky", "pid": 2, "VmRSS": grow, "RssAnon": grow - 50_000,
                     "RssFile": 40_000, "RssShmem": 10_000, "Threads": 9})
    got = soak.memory_summary(rows, t_connected=2.0, t_done=18.0)  # samples outside 2..18 s do not count
    assert got["steady"]["growth_middle_to_end"] == 0.0
    leaky = got["leaky"]
    assert (leaky["start_s"], leaky["middle_s"], leaky["end_s"]) == (2.0, 10.0, 18.0)
    assert leaky["VmRSS"]["end_kb"] == 108_000
    assert leaky["growth_middle_to_end"] == pytest.approx(0.08)
    assert leaky["anon_growth_middle_to_end"] == pytest.approx(0.16)
    assert leaky["rss_slope_kb_per_h"] == pytest.approx(1000 * 3600)


@pytest.mark.timeout(240)
def test_short_soak_measures_every_node_and_counts_lost_messages(tmp_path):
    proc = subprocess.run([sys.executable, str(SOAK), "--sim-s", "600", "--sample-s", "0.1", "--load", "1",
                           "--load-nice", "19", "--out", str(tmp_path), "--name", "short"],
                          capture_output=True, text=True, timeout=220)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    summary = json.loads((tmp_path / "short.json").read_text())
    assert set(summary["memory"]) == NODES
    for name, m in summary["memory"].items():
        assert m["samples"] >= 1, name
        assert m["VmRSS"]["middle_kb"] > 10_000 and m["VmRSS"]["end_kb"] > 10_000, name  # a Python + rclpy process
    msgs = summary["messages"]
    assert msgs["ring_complete"] and msgs["samples_done"] == 601
    for topic in (T.MEASUREMENT, T.CONTROLLER, T.VALVE_STATE, T.PLANT_STATE):
        t = msgs["topics"][topic.name]
        assert t["published"] == t["recorded"] == 601 and t["missing_stamps"] == 0, topic.name
    assert msgs["detector"]["measurements_received"] == 601
    assert msgs["lost_total"] == 0
    assert summary["bag_bytes"] > 10_000 and not (tmp_path / "short.mcap").exists()  # measured, then deleted
    assert (tmp_path / "short_rss.png").stat().st_size > 1000
    assert "messages lost in all: 0" in proc.stdout
    # nothing of the run is left: the nodes (their logs are under tmp_path) and the busy process
    assert processes_with(str(tmp_path)) == []
    assert summary["load"]["busy_pids"] and all(not Path(f"/proc/{p}").exists() for p in summary["load"]["busy_pids"])
