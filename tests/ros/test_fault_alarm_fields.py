"""What /fault_alarm tells a ROS user (issue 36 item 10), from the learned detector node on a plant's own topics.

A record with gaps in its time (rows 3 s apart where the sample time is 1 s, every 60 rows) and a shift on one
channel is published by a stand-in plant (a real process, tests/ros/foreign_plant.py) with the record's own times
as stamps (sensor_msgs headers and a MeasuredSample stamp), align: sequence. The node's alarms are those of the
offline ``phfdi replay`` of the same record at the same times, not only at the same sample indices (before, the node
timed sample k at k x sample time, so every alarm after a gap was early); /fault_alarm carries them on the
plant's clock with the statistic's name; and the node sends a heartbeat on /fault_alarm every
``heartbeat_period_s`` of the record's time, as the physics detector node does.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from phfdi.cli import main
from phfdi_base.stamps import record_stamps_ns, seconds_to_ns
from wavelet_fdi.learned_detector import LearnedModel, learn

from .test_foreign_topics import run_foreign_plant

pytestmark = [pytest.mark.ros, pytest.mark.timeout(400)]

CHANNELS = ["a", "b", "c"]
T0_NS = 1_700_000_000 * 1_000_000_000  # the plant's clock at the record's first row
HEARTBEAT_S = 50.0
N_ROWS, SHIFT_FROM = 500, 300


def _record_times() -> np.ndarray:
    """1 s apart, with a gap of 2 missing samples after every 60th row."""
    k = np.arange(N_ROWS)
    return (k + 2 * (k // 60)).astype(float)


def test_learned_alarms_on_the_records_time_with_the_statistics_name_and_heartbeats(tmp_path, capsys):
    rng = np.random.default_rng(36)
    ref = tmp_path / "abc.json"
    learn(rng.normal(size=(600, 3)), CHANNELS).save(ref)
    rows = rng.normal(size=(N_ROWS, 3))
    rows[SHIFT_FROM:, 0] += 6.0  # six healthy standard deviations
    times = _record_times()
    record = tmp_path / "gappy.csv"
    record.write_text("time_s,a,b,c\n" + "".join(f"{t:g},{r[0]!r},{r[1]!r},{r[2]!r}\n"
                                                  for t, r in zip(times.tolist(), rows.tolist())))
    capsys.readouterr()
    assert main(["replay", str(record), "--reference", str(ref), "--json"]) == 0
    offline = json.loads(capsys.readouterr().out)
    assert offline["samples"] == N_ROWS and offline["alarms"], offline
    first = offline["alarms"][0]
    assert first["detection_time"] != first["detection_index"] * 1.0  # after gaps: time and index differ

    cmap = tmp_path / "gappy_map.yaml"
    cmap.write_text("align: sequence\nchannels:\n"
                    "  a: {topic: /gappy/a, type: sensor_msgs/msg/FluidPressure}\n"
                    "  b: {topic: /gappy/b, type: sensor_msgs/msg/Temperature}\n"
                    "  c: {topic: /gappy/rest, type: phfdi_interfaces/msg/MeasuredSample, name: c}\n")
    stamps = [int(ns) for ns in record_stamps_ns(times)]
    topics = [{"topic": "/gappy/a", "type": "sensor_msgs/msg/FluidPressure", "field": "fluid_pressure", "columns": [0]},
              {"topic": "/gappy/b", "type": "sensor_msgs/msg/Temperature", "field": "temperature", "columns": [1]},
              {"topic": "/gappy/rest", "type": "phfdi_interfaces/msg/MeasuredSample", "names": ["c"], "columns": [2]}]
    done, heard, err = run_foreign_plant(
        tmp_path, ref, cmap, rows, node_params={"heartbeat_period_s": HEARTBEAT_S},
        plant_spec={"stamped": {"t0_ns": T0_NS, "dt_ns": 0, "stamps_ns": stamps, "topics": topics}})
    assert done["channel_map"]["grid_origin_ns"] == T0_NS and done["channel_map"]["sample_times"] == "stamps"
    assert done["channel_map"]["stamps_not_increasing"] == 0 and done["samples"] == N_ROWS

    # the same alarms at the same times as the offline replay of the record
    keys = ("alarm_id", "detection_index", "detection_time", "onset_index", "onset_time", "statistic",
            "statistic_value", "threshold", "channels", "cleared_index", "cleared_time")
    assert [{k: a.get(k) for k in keys} for a in done["alarms"]] == [{k: a.get(k) for k in keys}
                                                                     for a in offline["alarms"]]
    # /fault_alarm: on the plant's clock, with the statistic's name
    received = heard["received"]
    raised = {}
    for m in received:
        if m["state"] == 2 and m["detection_ns"]:
            raised.setdefault(m["detection_ns"], m)
    assert sorted(raised) == [T0_NS + seconds_to_ns(a["detection_time"]) for a in offline["alarms"]]
    for a, (_, m) in zip(offline["alarms"], sorted(raised.items())):
        assert m["stamp_ns"] == m["detection_ns"] and m["statistic_name"] == a["statistic"]
        assert m["onset_ns"] == T0_NS + seconds_to_ns(a["onset_time"])
        assert m["statistic"] == a["statistic_value"] and m["threshold"] == a["threshold"]

    # heartbeats: the state every HEARTBEAT_S of the record's time (at most one per batch), and one at the end
    names = set(LearnedModel.load(ref).channels)
    beats = [m for m in received if " worst statistic " in m["message"]]
    assert len(beats) >= 2, [m["message"] for m in received]
    periods = [(m["stamp_ns"] - T0_NS) // seconds_to_ns(HEARTBEAT_S) for m in beats[:-1]]
    assert periods == sorted(set(periods)), periods  # one per period at most, in order
    assert beats[-1] is received[-1] and beats[-1]["stamp_ns"] == T0_NS + stamps[-1]
    for m in beats:
        assert m["statistic_name"].split(".")[0] in names, m
        assert np.isfinite(m["statistic"]) and m["threshold"] > 0
    assert any(m["state"] == 2 and m["detection_ns"] for m in beats), "no heartbeat during the alarm"
    assert '"kind": "state"' not in err  # heartbeats are no state changes: no JSON line


def test_a_bag_recorded_before_statistic_name_still_reads(tmp_path):
    """FaultAlarm gained statistic_name at its end. A bag recorded with the older definition (its schema embedded)
    reads as before, with an empty name; one with the new definition carries the name."""
    from pathlib import Path

    from mcap.writer import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from phfdi import bagio
    from phfdi_base import topics as T

    new_text = (Path(__file__).resolve().parents[2] / "interfaces" / "phfdi_interfaces" / "msg" /
                "FaultAlarm.msg").read_text()
    old_text = new_text.split("# Added after the fields above")[0]
    assert "string statistic_name" in new_text and "string statistic_name" not in old_text
    for text, name in ((old_text, None), (new_text, "ph.R.mean_down")):
        store = get_typestore(Stores.ROS2_JAZZY)
        store.register(get_types_from_msg(text, T.FAULT_ALARM.type))
        time_type = store.types["builtin_interfaces/msg/Time"]
        fields = dict(stamp=time_type(sec=7027, nanosec=0), loop="ph", state=2, fault_class="pending", confidence=0.0,
                      onset_time=time_type(sec=7020, nanosec=0), detection_time=time_type(sec=7027, nanosec=0),
                      severity=0.1, severity_unit="pH", statistic=12.2, threshold=11.7, wavelet_level=3,
                      message="fault detected", channels=[], channel_shares=np.zeros(0), channel_bands=[])
        if name is not None:
            fields["statistic_name"] = name
        msg = store.types[T.FAULT_ALARM.type](**fields)
        path = tmp_path / f"alarm_{'new' if name else 'old'}.mcap"
        with open(path, "wb") as f:
            w = Writer(f)
            w.start(profile="ros2", library="test")
            sid = w.register_schema(T.FAULT_ALARM.type, "ros2msg",
                                    store.generate_msgdef(T.FAULT_ALARM.type, ros_version=2)[0].encode())
            cid = w.register_channel(T.FAULT_ALARM.name, "cdr", sid)
            w.add_message(cid, log_time=7027 * 10**9, publish_time=7027 * 10**9,
                          data=store.serialize_cdr(msg, T.FAULT_ALARM.type))
            w.finish()
        (read,) = bagio.fault_alarms(path)
        assert read["statistic"] == 12.2 and read["detection_time"] == 7027.0 and read["state"] == "ALARM"
        assert read["statistic_name"] == (name or "")
