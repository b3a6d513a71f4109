"""Bags without ROS processes: run <-> bag round trip, truncated bag recovery, load_run on run files."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk, Message, Metadata
from mcap.stream_reader import StreamReader, breakup_chunk

from phfdi import bagio
from phfdi.loop import simulate
from phfdi.scenario import load_scenario
from phfdi_base import topics as T
from phfdi_base.errors import UserError

from .conftest import SHORT_OVERRIDES, phfdi_cmd
from .rosbag2_check import as_rosbag2_folder, read_with_rosbags, rosbag2_record


@pytest.fixture(scope="module")
def short_run():
    return simulate(load_scenario("paper", overrides=SHORT_OVERRIDES))


@pytest.fixture(scope="module")
def bag(short_run, tmp_path_factory):
    return bagio.write_run(short_run, tmp_path_factory.mktemp("bag") / "run.mcap")


def test_write_run_then_load_run_gives_the_run_back(short_run, bag):
    back = bagio.load_run(bag)
    assert back.names == short_run.names
    for name in short_run.names:
        assert np.array_equal(back[name], short_run[name], equal_nan=True), name
    assert back.metadata["scenario"] == short_run.metadata["scenario"]


def test_read_messages_of_a_topic_the_bag_lacks_is_none(short_run, bag):
    """One topic's messages, and none for a topic not in the bag (rosbags reads every topic when asked for no
    connection: the whole bag came back, as other topics' messages)."""
    measurements = bagio.read_messages(bag, T.MEASUREMENT.name)
    assert len(measurements) == len(short_run) and all(hasattr(m, "ph") for m in measurements)
    assert bagio.read_messages(bag, T.DETECTOR_MONITOR.name) == []


def test_load_run_reads_run_files_too(short_run, tmp_path):
    for suffix in (".csv", ".parquet"):
        path = short_run.save(tmp_path / f"run{suffix}")
        assert np.allclose(bagio.load_run(path)["ph_measured"], short_run["ph_measured"])
    other = tmp_path / "run.txt"
    other.write_text("not a run")
    with pytest.raises(UserError, match="expected .mcap"):
        bagio.load_run(other)


def _chunks(path):
    """(end offset, message count) of each chunk, in file order."""
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    with open(path, "rb") as f:
        chunks = [r for r in StreamReader(f, emit_chunks=True).records if isinstance(r, Chunk)]
    ends = [ci.chunk_start_offset + ci.chunk_length for ci in summary.chunk_indexes]
    counts = [sum(isinstance(r, Message) for r in breakup_chunk(c)) for c in chunks]
    assert len(ends) == len(counts) > 5
    return ends, counts


def test_a_truncated_bag_is_recovered_up_to_its_last_complete_chunk(bag, tmp_path):
    ends, counts = _chunks(bag)
    data = bag.read_bytes()
    j = len(ends) // 2
    cut = ends[j] + (ends[j + 1] - ends[j]) // 2  # in the middle of chunk j + 1
    truncated = tmp_path / "killed.mcap"
    truncated.write_bytes(data[:cut])
    info = bagio.bag_info(truncated)
    assert not info["finished"]
    fixed = tmp_path / "fixed.mcap"
    out = subprocess.run(phfdi_cmd("bag", "recover", str(truncated), str(fixed)), capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    recovered = bagio.bag_info(fixed)
    assert recovered["finished"]
    assert recovered["messages"] == sum(counts[: j + 1])
    run = bagio.load_run(fixed)  # readable as a run, the last sample may lack some topics
    assert 0 < len(run) <= 601
    assert "phfdi_run" in recovered["metadata"]
    # the killed file lacks rosbag2's metadata record (written at close); the recovered one has it, counted from
    # what was recovered, not copied from anywhere
    assert _metadata_names(truncated) == ["phfdi_run"]
    meta = rosbag2_record(fixed)
    assert meta["message_count"] == recovered["messages"] == sum(counts[: j + 1])
    by_topic = {t["topic"]: t["count"] for t in recovered["topics"]}
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]} == by_topic
    assert meta["relative_file_paths"] == ["fixed.mcap"]
    seen = read_with_rosbags(as_rosbag2_folder(fixed, tmp_path / "fixed_folder"))
    assert {t: v["count"] for t, v in seen["topics"].items()} == by_topic
    assert {t: v["read"] for t, v in seen["topics"].items()} == by_topic


def _metadata_names(path):
    """Names of the MCAP metadata records a (possibly truncated) file holds, read record by record."""
    out = []
    with open(path, "rb") as f:
        try:
            for r in StreamReader(f).records:
                if isinstance(r, Metadata):
                    out.append(r.name)
        except Exception:  # noqa: BLE001 - the truncated end
            pass
    return out


def test_a_bag_carries_the_rosbag2_metadata_rosbag2_readers_take(bag, tmp_path):
    """The 'rosbag2' record (rosbag2 Jazzy's MCAP storage plugin writes it at close) holds the bag's counts, time
    range and per-topic QoS; rosbags reads the bare file, and a rosbag2 folder made of the record with its
    version-9 parser, and both agree with the bag's own summary."""
    info = bagio.bag_info(bag)
    counts = {t["topic"]: t["count"] for t in info["topics"]}
    meta = rosbag2_record(bag)
    assert (meta["version"], meta["storage_identifier"], meta["ros_distro"]) == (9, "mcap", "jazzy")
    assert meta["message_count"] == info["messages"] == 4 * 601
    assert meta["starting_time"] == {"nanoseconds_since_epoch": 0}
    assert meta["duration"] == {"nanoseconds": 600 * 10**9}
    assert meta["relative_file_paths"] == ["run.mcap"] and meta["files"][0]["message_count"] == 4 * 601
    topics = {t["topic_metadata"]["name"]: t for t in meta["topics_with_message_count"]}
    assert {name: t["message_count"] for name, t in topics.items()} == counts
    for name, t in topics.items():
        assert t["topic_metadata"]["type_description_hash"] == bagio.type_hash(t["topic_metadata"]["type"])
        assert t["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"
    for where in (bag, as_rosbag2_folder(bag, tmp_path / "folder")):
        seen = read_with_rosbags(where)
        assert seen["message_count"] == info["messages"], where
        assert {t: (v["type"], v["count"], v["read"]) for t, v in seen["topics"].items()} == \
            {t["topic"]: (t["type"], t["count"], t["count"]) for t in info["topics"]}, where
        for topic, v in seen["topics"].items():
            (qos,) = v["qos"]
            assert (qos.reliability.name, qos.durability.name, qos.history.name) == \
                ("RELIABLE", "VOLATILE", "UNKNOWN"), (where, topic)
            assert (qos.deadline.sec, qos.deadline.nsec) == (9223372036, 854775807)


def test_bag_info_says_whether_the_rosbag2_record_is_there(bag, tmp_path):
    out = subprocess.run(phfdi_cmd("bag", "info", str(bag)), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "rosbag2   metadata version 9 (jazzy), 2404 messages" in out.stdout
    truncated = tmp_path / "killed.mcap"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    out = subprocess.run(phfdi_cmd("bag", "info", str(truncated)), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "no metadata record" in out.stdout and "phfdi bag recover" in out.stdout


def test_bag_from_csv_writes_the_rosbag2_metadata_under_its_final_name(tmp_path):
    csv = tmp_path / "rig.csv"
    csv.write_text("time_s,flow,label\n" + "".join(f"{i},{1.0 + 0.1 * i},0\n" for i in range(50)))
    out_bag = tmp_path / "rig.mcap"
    out = subprocess.run(phfdi_cmd("bag", "from-csv", str(csv), str(out_bag), "--exclude", "label"),
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    meta = rosbag2_record(out_bag)
    assert meta["relative_file_paths"] == ["rig.mcap"]  # not the staging file's name
    assert meta["message_count"] == 50 and meta["duration"] == {"nanoseconds": 49 * 10**9}
    (topic,) = meta["topics_with_message_count"]
    assert topic["topic_metadata"]["name"] == T.MEASURED_SAMPLE.name and topic["message_count"] == 50
    seen = read_with_rosbags(as_rosbag2_folder(out_bag, tmp_path / "folder"))
    assert seen["topics"][T.MEASURED_SAMPLE.name]["read"] == 50
    assert seen["topics"][T.MEASURED_SAMPLE.name]["type"] == T.MEASURED_SAMPLE.type


def test_recover_refuses_to_overwrite_its_input(bag):
    with pytest.raises(UserError, match="other than the input"):
        bagio.recover(bag, bag)


def test_bag_topics_carry_the_graph_types(bag):
    info = bagio.bag_info(bag)
    types = {t["topic"]: t["type"] for t in info["topics"]}
    assert types == {t.name: t.type for t in T.RECORDED if t.per_sample}


def test_a_hostile_rosbag2_record_is_not_expanded(tmp_path):
    """A bag is input from anywhere: a 'rosbag2' record or a channel QoS with nested YAML aliases (a kilobyte that
    anything walking the parsed value expands into gigabytes) is reported unreadable, and recover takes no QoS
    from such a channel."""
    from mcap.writer import Writer

    laughs = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
        f"{n}: &{n} [*{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}, *{p}]\n"
        for p, n in zip("abcdefgh", "bcdefghi"))
    path = tmp_path / "hostile.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema(T.MEASUREMENT.type, "ros2msg", bagio.schema_text(T.MEASUREMENT.type).encode())
        as_list = "".join(f"- {line.split(': ', 1)[1]}\n" for line in laughs.splitlines())  # a list, like QoS
        w.register_channel(T.MEASUREMENT.name, "cdr", sid, {"offered_qos_profiles": as_list})
        w.add_metadata("rosbag2", {"serialized_metadata": laughs})
        w.finish()
    assert bagio.bag_info(path)["rosbag2"] == {"readable": False}
    out = subprocess.run(phfdi_cmd("bag", "info", str(path)), capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and "metadata record not readable" in out.stdout, out.stderr
    fixed = tmp_path / "fixed.mcap"
    bagio.recover(path, fixed)
    (topic,) = rosbag2_record(fixed)["topics_with_message_count"]
    assert topic["topic_metadata"]["offered_qos_profiles"] == [] and topic["message_count"] == 0
