"""The node graph, run as real processes by ``phfdi launch``: equals the in-process loop, records every topic."""

from __future__ import annotations

import json
import subprocess
import time

import numpy as np
import pytest

from phfdi import bagio
from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base import topics as T

from .conftest import SHORT_OVERRIDES, SHORT_RUN, phfdi_cmd, processes_with, stale_shm_files
from .rosbag2_check import as_rosbag2_folder, read_with_rosbags, rosbag2_record

pytestmark = [pytest.mark.ros, pytest.mark.timeout(300)]


@pytest.fixture(scope="module")
def graph_run(tmp_path_factory):
    """One lock-step launch of the short scenario, recorded."""
    tmp = tmp_path_factory.mktemp("graph")
    bag = tmp / "run.mcap"
    t0 = time.time()
    proc = subprocess.run(phfdi_cmd("launch", *SHORT_RUN, "--record", str(bag), "--log-dir", str(tmp / "logs"),
                                    "--json"), capture_output=True, text=True, timeout=240)
    return {"proc": proc, "bag": bag, "logs": tmp / "logs", "t0": t0}


def test_launch_succeeds_and_leaves_nothing_behind(graph_run):
    proc = graph_run["proc"]
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["samples"] == summary["of"] == 601
    assert summary["failure"] is None
    assert processes_with(str(graph_run["logs"])) == []
    assert stale_shm_files(summary["domain_id"]) == []


def test_every_node_reports_its_start_up_steps_in_order(graph_run):
    assert graph_run["proc"].returncode == 0, graph_run["proc"].stderr
    steps = ("main", "init", "built", "matched", "connected")
    for node in ("plant", "valve", "controllers", "recorder"):
        lines = (graph_run["logs"] / f"{node}.stdout").read_text().splitlines()
        startup = [json.loads(ln) for ln in lines if ln.startswith('{"event": "startup"')]
        assert len(startup) == 1, (node, lines)
        times, cpu = startup[0]["times"], startup[0]["cpu"]
        assert [times[s] for s in steps] == sorted(times[s] for s in steps), (node, times)
        assert graph_run["t0"] < times["main"] < time.time()
        assert 0 < cpu["main"] <= cpu["connected"], (node, cpu)
        # the scenario came validated in the node's part: no schema library, no root finder at start-up
        assert not {"pydantic", "scipy"} & set(startup[0]["heavy_modules"]), (node, startup[0])


def test_graph_run_equals_in_process_simulation(graph_run):
    assert graph_run["proc"].returncode == 0, graph_run["proc"].stderr
    spec = load_scenario("paper", overrides=SHORT_OVERRIDES)
    expected = simulate(spec)
    got = bagio.load_run(graph_run["bag"])
    assert got.names == expected.names
    assert len(got) == len(expected) == 601
    for name in expected.names:
        diff = np.abs(got[name] - expected[name])
        both_nan = np.isnan(got[name]) & np.isnan(expected[name])
        assert np.all((diff <= 1e-9) | both_nan), f"{name}: max difference {np.nanmax(diff)}"
    # the run really exercised what it claims: setpoint step, both faults switched on
    assert set(np.unique(got["ph_setpoint"])) == {12.0, 8.0}
    assert got["fault_severity"][got.time_s >= 300].min() == 1.0
    assert got.metadata["scenario"] == spec.name


def test_every_topic_is_in_the_bag_with_its_count(graph_run):
    assert graph_run["proc"].returncode == 0, graph_run["proc"].stderr
    info = bagio.bag_info(graph_run["bag"])
    assert info["finished"] and info["profile"] == "ros2"
    counts = {t["topic"]: t["count"] for t in info["topics"]}
    types = {t["topic"]: t["type"] for t in info["topics"]}
    for topic in T.RECORDED:
        assert types[topic.name] == topic.type
        if topic.per_sample:
            assert counts[topic.name] == 601, topic.name
    # the valve reports every 60 s of simulated time: samples 0, 60, ..., 600
    assert counts[T.DIAGNOSTICS.name] == 11
    assert counts[T.FAULT_ALARM.name] == 0  # no detector in this graph
    assert info["start_s"] == 0.0 and info["end_s"] == 600.0
    summary = json.loads(graph_run["proc"].stdout)
    assert summary["bag"]["counts"] == counts


def test_bag_is_readable_by_the_ros_tools(graph_run):
    """rosbags' AnyReader and mcap-ros2-support decode every message with the embedded schemas."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    bag = graph_run["bag"]
    with AnyReader([bag]) as reader:
        n_any = sum(1 for _ in reader.messages())
        qos = {c.topic: c.ext.offered_qos_profiles for c in reader.connections}
    assert qos[T.MEASUREMENT.name][0].reliability.name == "RELIABLE"
    assert qos[T.MEASUREMENT.name][0].history.name == "UNKNOWN"  # as rosbag2 stores it: discovery has no history
    with open(bag, "rb") as f:
        decoded = [(ch.topic, msg) for _s, ch, _m, msg in make_reader(f, decoder_factories=[DecoderFactory()])
                   .iter_decoded_messages()]
    assert len(decoded) == n_any == bagio.bag_info(bag)["messages"]
    valve = [m for topic, m in decoded if topic == T.VALVE_STATE.name]
    assert valve[0].stamp.sec == 0 and valve[-1].stamp.sec == 600


def test_rosbag2_readers_take_the_recorded_bag_with_the_recorder_counts(graph_run, tmp_path):
    """Acceptance (issue 23 item 5): rosbags' rosbag2 reader, on the bare .mcap and on a rosbag2 folder made of
    the bag's 'rosbag2' metadata record, sees every recorded topic with its type and the count the launcher's
    summary reports (from the recorder), reads that many messages, and parses each channel's QoS."""
    assert graph_run["proc"].returncode == 0, graph_run["proc"].stderr
    summary = json.loads(graph_run["proc"].stdout)["bag"]["counts"]
    assert summary[T.MEASUREMENT.name] == 601 and summary[T.DIAGNOSTICS.name] == 11
    bag = graph_run["bag"]
    meta = rosbag2_record(bag)
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == summary
    assert meta["message_count"] == sum(summary.values())
    assert (meta["version"], meta["ros_distro"], meta["duration"]) == (9, "jazzy", {"nanoseconds": 600 * 10**9})
    for where in (bag, as_rosbag2_folder(bag, tmp_path / "run")):
        seen = read_with_rosbags(where)
        assert seen["message_count"] == sum(summary.values()), where
        assert {t: v["count"] for t, v in seen["topics"].items()} == summary, where
        assert {t: v["read"] for t, v in seen["topics"].items()} == summary, where
        assert {t: v["type"] for t, v in seen["topics"].items()} == {t.name: t.type for t in T.RECORDED}, where
        for topic, v in seen["topics"].items():
            (qos,) = v["qos"]
            assert (qos.reliability.name, qos.durability.name, qos.liveliness.name) == \
                ("RELIABLE", "VOLATILE", "AUTOMATIC"), (where, topic)


def test_bag_info_command(graph_run):
    out = subprocess.run(phfdi_cmd("bag", "info", str(graph_run["bag"])), capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert "/valve/state" in out.stdout and "601" in out.stdout and "complete" in out.stdout
    assert "rosbag2   metadata version 9 (jazzy)" in out.stdout
