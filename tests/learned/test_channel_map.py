"""Channel maps (topic, type, field per channel) and the alignment of separate topics onto the sample grid:
the ROS-free core the learned detector node uses (wavelet_fdi.channel_map, wavelet_fdi.channel_align)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from phfdi_base.errors import UserError
from wavelet_fdi.channel_align import ChannelAligner, align_messages
from wavelet_fdi.channel_map import load_channel_map, parse_channel_map

ROOT = Path(__file__).resolve().parents[2]
SEC = 1_000_000_000


def one(spec: dict) -> dict:
    return {"channels": {"x": spec}}


@pytest.mark.parametrize("spec, says", [
    ({"topic": "/x", "type": "std_msgs/msg/Float65"}, "unknown message type 'std_msgs/msg/Float65'"),
    ({"topic": "/x", "type": "std_msgs/msg/Float64", "field": "dat"}, "has no field 'dat' (it has: data)"),
    ({"topic": "/x", "type": "sensor_msgs/msg/Temperature", "field": "temp"}, "has no field 'temp'"),
    ({"topic": "/x", "type": "std_msgs/msg/Float64MultiArray"}, "give index: N"),
    ({"topic": "/x", "type": "std_msgs/msg/Float64", "index": 2}, "index is for array fields"),
    ({"topic": "/x", "type": "phfdi_interfaces/msg/MeasuredSample"}, "give name:"),
    ({"topic": "x", "type": "std_msgs/msg/Float64"}, "absolute ROS topic name"),
    ({"topic": "/x", "type": "std_msgs/msg/Float64", "feild": "data"}, "unknown key 'feild'"),
    ({"topic": "/x"}, "give its message type"),
])
def test_a_map_with_an_unknown_type_or_field_is_refused_in_one_line(spec, says):
    with pytest.raises(UserError) as err:
        parse_channel_map(one(spec), "map.yaml")
    assert says in str(err.value) and "\n" not in str(err.value) and "channel 'x'" in str(err.value)


def test_fields_default_and_stamps_come_from_the_header_the_stamp_or_the_receive_time():
    cmap = parse_channel_map({"align": "sequence", "channels": {
        "p": {"topic": "/p", "type": "sensor_msgs/FluidPressure"},
        "f": {"topic": "/f", "type": "std_msgs/Float64"},
        "q": {"topic": "/q", "type": "std_msgs/msg/Float32MultiArray", "index": 1},
        "ph": {"topic": "/plant/measurement", "type": "phfdi_interfaces/msg/Measurement", "field": "ph"}}},
        reference_channels=["ph", "q", "p", "f"])
    assert cmap.channels == ("ph", "q", "p", "f") and cmap.align == "sequence"  # the reference's order
    assert [(s.field, s.index, s.stamp) for s in cmap.sources] == [
        ("ph", None, "stamp"), ("data", 1, "receive time"), ("fluid_pressure", None, "header.stamp"),
        ("data", None, "receive time")]


def test_stamp_receive_overrides_the_header_for_every_channel_of_its_topic():
    spec = {"topic": "/p", "type": "sensor_msgs/msg/FluidPressure"}
    cmap = parse_channel_map({"channels": {"p": {**spec, "stamp": "receive"}}})
    assert cmap.sources[0].stamp == "receive time"
    with pytest.raises(UserError, match="stamp can only be 'receive'"):
        parse_channel_map({"channels": {"p": {**spec, "stamp": "header"}}})
    with pytest.raises(UserError, match="topic /p is stamped two ways"):
        parse_channel_map({"channels": {"p": {**spec, "stamp": "receive"}, "v": {**spec, "field": "variance"}}},
                          reference_channels=["p", "v"])


def test_a_map_must_cover_the_reference_channels_and_no_others():
    spec = {"topic": "/a", "type": "std_msgs/msg/Float64"}
    with pytest.raises(UserError, match="no source for the reference's channel 'b'"):
        parse_channel_map({"channels": {"a": spec}}, reference_channels=["a", "b"])
    with pytest.raises(UserError, match="channel 'c' is not one of the reference's"):
        parse_channel_map({"channels": {"a": spec, "c": {**spec, "topic": "/c"}}}, reference_channels=["a"])
    with pytest.raises(UserError, match="topic /a is given two types"):
        parse_channel_map({"channels": {"a": spec, "b": {"topic": "/a", "type": "std_msgs/msg/Float32"}}},
                          reference_channels=["a", "b"])


def test_the_shipped_example_map_is_valid_and_the_checker_says_so_in_one_line(tmp_path):
    cmap = load_channel_map(ROOT / "config" / "channel_map_skab.yaml")
    assert len(cmap.channels) == 8 and cmap.align == "sequence"
    ok = subprocess.run([sys.executable, "-m", "wavelet_fdi.channel_map", str(ROOT / "config" / "channel_map_skab.yaml")],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0 and "8 channels on 8 topics" in ok.stdout
    bad = tmp_path / "bad.yaml"
    bad.write_text("channels:\n  Current: {topic: /rig/current, type: std_msgs/msg/Float64, field: value}\n")
    out = subprocess.run([sys.executable, "-m", "wavelet_fdi.channel_map", str(bad)], capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 2 and out.stdout == "" and "Traceback" not in out.stderr
    assert out.stderr.strip().count("\n") == 0 and "has no field 'value'" in out.stderr


def test_sequence_takes_the_kth_message_of_each_channel_whatever_its_stamp():
    rows = np.arange(12.0).reshape(6, 2)
    # all received within the same millisecond, channel 1 running three rows behind channel 0
    msgs = [(0, SEC, v, 0.0) for v in rows[:3, 0]]
    for k in range(6):
        if k + 3 < 6:
            msgs.append((0, SEC, rows[k + 3, 0], 0.0))
        msgs.append((1, SEC, rows[k, 1], 0.0))
    t, x, al = align_messages(msgs, 2, SEC // 2, "sequence")
    assert np.array_equal(x, rows) and t.tolist() == [0.5 * k for k in range(6)] and al.origin_ns == SEC


def test_sequence_times_stamped_samples_by_their_stamps_gaps_included():
    """A record with gaps (rows 2 s apart where the grid says 1 s) published in order with its own stamps: the
    samples get the record's times from the first stamp, as the offline replay of the record gives them
    (issue 36 item 10); a receive-stamped channel beside the stamped one does not decide."""
    times_ns = [100 * SEC + t * SEC for t in (0, 1, 2, 4, 5, 8, 9)]  # gaps after 2 s and 5 s
    msgs = []
    for k, ns in enumerate(times_ns):
        msgs.append((0, 7 * SEC + k, float(k), 0.0))  # channel 0: received (receive-time stamps, another clock)
        msgs.append((1, ns, 10.0 + k, 0.0))  # channel 1: its header stamps
    t, x, al = align_messages(msgs, 2, SEC, "sequence", stamped=(False, True))
    assert t.tolist() == [0.0, 1.0, 2.0, 4.0, 5.0, 8.0, 9.0] and al.origin_ns == 100 * SEC
    assert x[:, 1].tolist() == [10.0 + k for k in range(7)] and al.times_from_stamps
    assert al.stamps_not_increasing == 0
    # receive-time stamps only: the grid (faster than real time they say nothing)
    t_grid, _, al_grid = align_messages(msgs, 2, SEC, "sequence")
    assert t_grid.tolist() == [float(k) for k in range(7)] and not al_grid.times_from_stamps


def test_sequence_times_a_stamp_that_does_not_increase_one_period_after_the_previous_sample():
    stamps = [5 * SEC, 6 * SEC, 6 * SEC, 0, 9 * SEC]  # a repeat, then a publisher's zero
    msgs = [(0, ns, float(k), 0.0) for k, ns in enumerate(stamps)]
    t, _, al = align_messages(msgs, 1, SEC, "sequence", stamped=(True,))
    assert t.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0] and al.stamps_not_increasing == 2


def test_hold_puts_stamps_on_the_nearest_grid_point_and_holds_a_slower_channel():
    dt = SEC
    msgs = []
    for k in range(6):  # channel 0 every sample (jitter 0.3 dt after the first), channel 1 every second sample
        jitter = 0 if k == 0 else 3 * dt // 10 if k % 2 else -3 * dt // 10
        msgs.append((0, 10 * SEC + k * dt + jitter, float(k), k))
        if k % 2 == 0:
            msgs.append((1, 10 * SEC + k * dt, 100.0 + k, k))
    t, x, al = align_messages(msgs, 2, dt, "hold", hold_samples=1)
    assert x[:, 0].tolist() == [0, 1, 2, 3, 4, 5]
    assert x[:, 1].tolist() == [100, 100, 102, 102, 104, 104]
    assert al.counts[1].held == 3 and al.counts[0].late == 0 and al.origin_ns == 10 * SEC


def test_hold_waits_for_every_channel_then_goes_out_after_max_wait_without_a_silent_one():
    al = ChannelAligner(2, SEC, "hold", max_wait_s=2.0, hold_samples=0)
    al.add(0, 0, 1.0, now_s=0.0)
    al.add(0, SEC, 2.0, now_s=1.0)
    assert al.take(now_s=1.5) == []  # sample 0 waits for channel 1
    out = al.take(now_s=3.0)  # 2 s after sample 0 fell due
    assert len(out) == 1 and out[0][1][0] == 1.0 and math.isnan(out[0][1][1])
    assert al.counts[1].missing == 1 and al.waited_out == 1
    al.add(1, 0, 5.0, now_s=3.1)  # too late for sample 0: dropped, counted
    assert al.counts[1].late == 1
    al.add(1, SEC, 6.0, now_s=3.2)
    al.add(0, 2 * SEC, 3.0, now_s=3.3)
    al.add(1, 2 * SEC, 7.0, now_s=3.3)
    assert [r.tolist() for _, r in al.take(now_s=3.3)] == [[2.0, 6.0]]
    assert [r.tolist() for _, r in al.flush()] == [[3.0, 7.0]]


def test_hold_names_a_channel_whose_stamps_are_on_another_clock():
    al = ChannelAligner(2, SEC, "hold", max_wait_s=1.0)
    for k in range(12):  # channel 0 on the plant's clock from 0 s, channel 1 stamped by a receive time of 2026
        al.add(0, k * SEC, float(k), now_s=k)
        al.add(1, 1_795_000_000 * SEC + k * SEC, 1.0, now_s=k)
        al.take(now_s=k)
    assert al.off_grid() == [1] and al.counts[1].late == 12


def test_sequence_goes_out_without_a_silent_channel_after_max_wait():
    al = ChannelAligner(2, SEC, "sequence", max_wait_s=1.0)
    al.add(0, 0, 1.0, now_s=0.0)
    assert al.take(now_s=0.5) == []
    (t, row), = al.take(now_s=1.0)
    assert row[0] == 1.0 and math.isnan(row[1]) and al.counts[1].missing == 1


def test_a_value_the_message_does_not_hold_is_nan_with_the_reason():
    from types import SimpleNamespace

    from wavelet_fdi.channel_map import value_of

    cmap = parse_channel_map({"channels": {
        "q": {"topic": "/q", "type": "std_msgs/msg/Float64MultiArray", "index": 2},
        "pH": {"topic": "/m", "type": "phfdi_interfaces/msg/MeasuredSample", "name": "pH"}}})
    q, ph = cmap.sources
    assert value_of(q, SimpleNamespace(data=[1.0, 2.0, 3.0])) == (3.0, None)
    value, why = value_of(q, SimpleNamespace(data=[1.0, 2.0]))
    assert math.isnan(value) and why == "data[2] is past the end of 2 values"
    assert value_of(ph, SimpleNamespace(names=["T", "pH"], values=[20.0, 7.1])) == (7.1, None)
    value, why = value_of(ph, SimpleNamespace(names=["T"], values=[20.0]))
    assert math.isnan(value) and why == "no value named 'pH'"


def test_one_message_stamped_far_ahead_does_not_move_the_grid_but_a_stream_that_goes_there_does():
    """hold: a stray stamped 500 s ahead of a 1 s stream (then the stream goes on) is dropped and counted; a stream
    that really jumps (a gap of 17 samples) is followed once its next message comes after the jump."""
    from wavelet_fdi.channel_align import align_messages

    s = 1_000_000_000

    def stream(stamps):
        return [(0, t * s, float(t), 0.1 * i) for i, t in enumerate(stamps)]

    t, rows, aligner = align_messages(stream([0, 1, 2, 500, 3, 4, 5]), 1, s)
    assert t.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0] and rows[:, 0].tolist() == [0, 1, 2, 3, 4, 5]
    assert aligner.counts[0].jumps_dropped == 1 and aligner.counts[0].used == 6
    t, rows, aligner = align_messages(stream([0, 1, 2, 20, 21]), 1, s, hold_samples=5)
    assert len(t) == 22 and rows[20, 0] == 20.0 and rows[21, 0] == 21.0
    assert rows[3:8, 0].tolist() == [2.0] * 5 and np.isnan(rows[8:20, 0]).all()  # held 5 samples, then missing
    assert aligner.counts[0].jumps_dropped == 0


def test_a_stamp_off_the_grid_is_dropped_where_the_map_says_samples_sit_on_it():
    """The loop graph stamps every sample on the grid (channel_map.loop_graph_map: grid_tolerance 0.01): a message
    stamped half-way is no sample of its and is dropped, counted; with the default tolerance (0.5) it lands on the
    nearest point, as a receive time does."""
    from wavelet_fdi.channel_align import align_messages
    from wavelet_fdi.channel_map import LOOP_GRAPH_GRID_TOLERANCE, loop_graph_map

    s = 1_000_000_000
    msgs = [(0, 0, 0.0, 0.0), (0, s, 1.0, 0.1), (0, 2 * s, 2.0, 0.2), (0, 2 * s + s // 2, -77.0, 0.3),
            (0, 3 * s, 3.0, 0.4), (0, 4 * s, 4.0, 0.5)]
    _, rows, aligner = align_messages(msgs, 1, s, grid_tolerance=LOOP_GRAPH_GRID_TOLERANCE)
    assert rows[:, 0].tolist() == [0, 1, 2, 3, 4] and aligner.counts[0].off_grid == 1
    _, rows, aligner = align_messages(msgs, 1, s)
    assert aligner.counts[0].off_grid == 0 and aligner.counts[0].superseded == 1  # -77 on sample 3, then 3.0 later
    assert loop_graph_map(["ph_measured"]).grid_tolerance == LOOP_GRAPH_GRID_TOLERANCE
