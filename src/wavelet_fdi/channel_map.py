"""Channel maps: which ROS topic, message type and field carries each channel of a reference (ROS-free).

A plant on ROS publishes its signals as its own topics. A channel map says, for every channel of the learned
detector's reference (its channel names), where the value is; it is a small YAML file in the spirit of the
column maps of :mod:`phfdi.records.columns`::

    align: hold                 # hold (default) or sequence: how the topics are put on the sample grid
    max_wait_s: 5.0             # wall time a sample waits for a late channel before it goes out without it
    hold_samples: 5             # hold: a channel's last value is used for at most this many samples
    reliability: reliable       # reliable (default: keep all, nothing lost) or best_effort (sensor-data topics)
    channels:
      Pressure: {topic: /rig/pressure, type: sensor_msgs/msg/FluidPressure}      # field fluid_pressure
      Current: {topic: /rig/current, type: std_msgs/msg/Float64}                 # field data
      Flow: {topic: /rig/flows, type: std_msgs/msg/Float64MultiArray, index: 2}  # data[2]
      ph_measured: {topic: /plant/measurement, type: phfdi_interfaces/msg/Measurement, field: ph}
      pH: {topic: /measured/sample, type: phfdi_interfaces/msg/MeasuredSample, name: pH}

The types the detector reads and their fields are declared here (:data:`MESSAGE_TYPES`), without rclpy, so a
map is checked (:func:`load_channel_map`, one line for an unknown type, field or channel) before any node starts;
``tests/ros/test_channel_map_types.py`` checks the table against the real message classes.

Stamps: a type with a ``std_msgs/Header`` is stamped with ``header.stamp``, the project's messages with their
``stamp``; every other type (std_msgs' numbers and arrays) with the time the detector received it. A channel
with ``stamp: receive`` is stamped on receipt whatever its type (a publisher that leaves its headers at 0).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Sequence

from phfdi_base.errors import UserError
from phfdi_base.topics import CONTROLLER, MEASUREMENT
from phfdi_base.yamlfile import read_mapping

#: how a sample is formed from the channels' messages (wavelet_fdi.channel_align)
ALIGN_RULES = ("hold", "sequence")
#: the subscriptions' reliability (a reliable reader hears no best-effort writer)
RELIABILITIES = ("reliable", "best_effort")
#: where a type's stamp is: a header, a bare stamp field, or none (receive time)
STAMP_HEADER, STAMP_FIELD, STAMP_RECEIVE = "header.stamp", "stamp", "receive time"


@dataclass(frozen=True)
class MessageType:
    """What the detector may read from one message type."""

    name: str  # "package/msg/Type"
    scalars: tuple[str, ...] = ()  # numeric fields read as they are
    arrays: tuple[str, ...] = ()  # numeric sequences: a channel gives ``index``
    named: tuple[str, str] | None = None  # (names field, values field): a channel gives ``name``
    stamp: str = STAMP_RECEIVE
    default_field: str | None = None  # the field taken when a channel names none

    @property
    def fields(self) -> tuple[str, ...]:
        return self.scalars + self.arrays + ((self.named[1],) if self.named else ())


def _types(*types: MessageType) -> dict[str, MessageType]:
    return {t.name: t for t in types}


#: the message types a channel can come from (fields of the .msg definitions; checked against rclpy's classes)
MESSAGE_TYPES: dict[str, MessageType] = _types(
    MessageType("std_msgs/msg/Float64", ("data",), default_field="data"),
    MessageType("std_msgs/msg/Float32", ("data",), default_field="data"),
    MessageType("std_msgs/msg/Int32", ("data",), default_field="data"),
    MessageType("std_msgs/msg/Int64", ("data",), default_field="data"),
    MessageType("std_msgs/msg/Float64MultiArray", arrays=("data",), default_field="data"),
    MessageType("std_msgs/msg/Float32MultiArray", arrays=("data",), default_field="data"),
    MessageType("sensor_msgs/msg/FluidPressure", ("fluid_pressure", "variance"), stamp=STAMP_HEADER,
                default_field="fluid_pressure"),
    MessageType("sensor_msgs/msg/Temperature", ("temperature", "variance"), stamp=STAMP_HEADER,
                default_field="temperature"),
    MessageType("sensor_msgs/msg/RelativeHumidity", ("relative_humidity", "variance"), stamp=STAMP_HEADER,
                default_field="relative_humidity"),
    MessageType("sensor_msgs/msg/Illuminance", ("illuminance", "variance"), stamp=STAMP_HEADER,
                default_field="illuminance"),
    MessageType("sensor_msgs/msg/Range", ("range", "field_of_view", "min_range", "max_range"), stamp=STAMP_HEADER,
                default_field="range"),
    MessageType("phfdi_interfaces/msg/Measurement", ("ph", "level_cm"), stamp=STAMP_FIELD),
    MessageType("phfdi_interfaces/msg/ControllerOutput",
                ("ph_setpoint", "ph_output_pct", "level_setpoint_cm", "level_output_pct"), stamp=STAMP_FIELD),
    MessageType("phfdi_interfaces/msg/ValveState",
                ("ph_command_pct", "ph_position_pct", "ph_opening", "ph_flow_ml_s", "ph_fault_severity",
                 "outlet_command_pct", "outlet_position_pct", "outlet_opening", "outlet_fault_severity"),
                stamp=STAMP_FIELD),
    MessageType("phfdi_interfaces/msg/MeasuredSample", named=("names", "values"), stamp=STAMP_FIELD,
                default_field="values"),
)

_CHANNEL_KEYS = {"topic", "type", "field", "index", "name", "stamp"}
_TOP_KEYS = {"align", "max_wait_s", "hold_samples", "reliability", "channels"}


@dataclass(frozen=True)
class ChannelSource:
    """Where one channel's value is: a field (``index``-th element, or the value named ``name``) of a topic."""

    channel: str
    topic: str
    type: MessageType
    field: str
    index: int | None = None
    name: str | None = None
    receive_stamp: bool = False  # ``stamp: receive``: stamped on receipt, whatever the type

    @property
    def stamp(self) -> str:
        return STAMP_RECEIVE if self.receive_stamp else self.type.stamp

    def describe(self) -> str:
        part = f"[{self.index}]" if self.index is not None else f"[{self.name!r}]" if self.name is not None else ""
        return f"{self.topic} ({self.type.name}) {self.field}{part}, stamped by {self.stamp}"


@dataclass(frozen=True)
class ChannelMap:
    """Every channel's source, the alignment rule and its limits (:mod:`wavelet_fdi.channel_align`)."""

    sources: tuple[ChannelSource, ...]
    align: str = "hold"
    max_wait_s: float = 5.0
    hold_samples: int = 5
    path: str = ""
    reliability: str = "reliable"
    #: hold: how far off its grid point (a fraction of the sample time) a stamp may lie; further, the message is
    #: dropped and counted (``off_grid``). 0.5: any stamp lands on its nearest point (receive times, jittery clocks);
    #: the loop graph stamps every sample on the grid exactly, so a stamp off it is no sample of its
    grid_tolerance: float = 0.5

    @property
    def channels(self) -> tuple[str, ...]:
        return tuple(s.channel for s in self.sources)

    def topics(self) -> dict[str, MessageType]:
        """Each topic once with its type (a topic may carry several channels)."""
        return {s.topic: s.type for s in self.sources}

    def ordered(self, channels: Sequence[str]) -> "ChannelMap":
        """The same map with its sources in the order of ``channels`` (the reference's)."""
        by_name = {s.channel: s for s in self.sources}
        return ChannelMap(tuple(by_name[c] for c in channels), self.align, self.max_wait_s, self.hold_samples,
                          self.path, self.reliability, self.grid_tolerance)


def type_named(name: str) -> MessageType | None:
    """A known type by ``pkg/msg/Type`` or ``pkg/Type``."""
    parts = name.split("/")
    if len(parts) == 2:
        name = f"{parts[0]}/msg/{parts[1]}"
    return MESSAGE_TYPES.get(name)


def parse_channel_map(data: dict[str, Any], where: str = "channel map",
                      reference_channels: Sequence[str] | None = None) -> ChannelMap:
    """A channel map from its YAML mapping; a :class:`UserError` of one line for anything wrong in it.

    With ``reference_channels`` every channel of the reference must be mapped and no other: the map comes
    back in the reference's order.

    Examples
    --------
    >>> m = parse_channel_map({"channels": {"p": {"topic": "/p", "type": "sensor_msgs/FluidPressure"}}})
    >>> m.sources[0].field, m.sources[0].stamp
    ('fluid_pressure', 'header.stamp')
    >>> try:
    ...     parse_channel_map({"channels": {"p": {"topic": "/p", "type": "std_msgs/msg/Float64", "field": "x"}}})
    ... except UserError as exc:
    ...     print(exc)
    channel map: channel 'p': std_msgs/msg/Float64 has no field 'x' (it has: data)
    """
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise UserError(f"{where}: unknown key {unknown[0]!r} (keys: {', '.join(sorted(_TOP_KEYS))})")
    align = data.get("align", "hold")
    if align not in ALIGN_RULES:
        raise UserError(f"{where}: align must be one of {', '.join(ALIGN_RULES)}, got {align!r}")
    max_wait_s = _number(data.get("max_wait_s", 5.0), f"{where}: max_wait_s")
    if not 0 < max_wait_s <= 3600:
        raise UserError(f"{where}: max_wait_s must be in (0, 3600] s, got {max_wait_s}")
    hold = data.get("hold_samples", 5)
    if isinstance(hold, bool) or not isinstance(hold, int) or hold < 0:
        raise UserError(f"{where}: hold_samples must be a whole number >= 0, got {hold!r}")
    reliability = data.get("reliability", "reliable")
    if reliability not in RELIABILITIES:
        raise UserError(f"{where}: reliability must be one of {', '.join(RELIABILITIES)}, got {reliability!r}")
    channels = data.get("channels")
    if not isinstance(channels, dict) or not channels:
        raise UserError(f"{where}: 'channels' must map each channel name to its topic, type and field")
    sources = tuple(_source(str(name), spec, where) for name, spec in channels.items())
    cmap = ChannelMap(sources, align, max_wait_s, hold, where, reliability)
    if reference_channels is not None:
        _check_against(cmap, reference_channels, where)
        cmap = cmap.ordered(reference_channels)
    return cmap


def load_channel_map(path: str | Path, reference_channels: Sequence[str] | None = None) -> ChannelMap:
    """The channel map in a YAML file (checked; see :func:`parse_channel_map`)."""
    return parse_channel_map(read_mapping(path, "channel map"), str(path), reference_channels)


#: where the simulated loop graph publishes each signal a physics reference reads: (topic, field)
LOOP_GRAPH_SOURCES = {
    "valve_command_pct": (CONTROLLER, "ph_output_pct"),
    "level_controller_output_pct": (CONTROLLER, "level_output_pct"),
    "ph_setpoint": (CONTROLLER, "ph_setpoint"),
    "ph_measured": (MEASUREMENT, "ph"),
    "level_measured_cm": (MEASUREMENT, "level_cm"),
}


#: the loop graph's stamps are k * sample time to the ns: a stamp more than 1 % of it off the grid is a stray
LOOP_GRAPH_GRID_TOLERANCE = 0.01
#: wall time a sample waits for a late channel of the loop graph's own topics (reliable and keep-all: nothing is
#: lost, a late message is a stalled one): full-speed replays stalled one topic for 2.7-5.2 s while the other flowed
#: (5 of 9 runs, measured for the physics detector's node; docs/detector.md), past a map's default 5 s, which would
#: let samples out with a held value and the live alarms differ from the offline ones; 15 s keeps a margin of three
#: and says a command topic that really stopped (detection held) 15 s after it did
LOOP_GRAPH_MAX_WAIT_S = 15.0


def loop_graph_map(reference_channels: Sequence[str]) -> ChannelMap:
    """The loop graph's own topics as a channel map (``align: hold`` on their stamps): what the physics detector
    node reads without a map, for a reference of the paper loop's signals (the ``physics`` kind).

    Examples
    --------
    >>> m = loop_graph_map(["valve_command_pct", "ph_measured"])
    >>> [(s.channel, s.topic, s.field) for s in m.sources]
    [('valve_command_pct', '/controller/output', 'ph_output_pct'), ('ph_measured', '/plant/measurement', 'ph')]
    """
    unknown = [c for c in reference_channels if c not in LOOP_GRAPH_SOURCES]
    if unknown:
        raise UserError(f"the loop graph publishes no {', '.join(unknown)} (it has: {', '.join(LOOP_GRAPH_SOURCES)}): "
                        f"give a channel map")
    channels = {c: {"topic": LOOP_GRAPH_SOURCES[c][0].name, "type": LOOP_GRAPH_SOURCES[c][0].type,
                    "field": LOOP_GRAPH_SOURCES[c][1]} for c in reference_channels}
    cmap = parse_channel_map({"align": "hold", "max_wait_s": LOOP_GRAPH_MAX_WAIT_S, "channels": channels},
                             "the loop graph's topics", reference_channels)
    return replace(cmap, grid_tolerance=LOOP_GRAPH_GRID_TOLERANCE)


def _source(name: str, spec: Any, where: str) -> ChannelSource:
    here = f"{where}: channel {name!r}"
    if not isinstance(spec, dict):
        raise UserError(f"{here}: give {{topic: ..., type: ...}}, got {spec!r}")
    unknown = sorted(set(spec) - _CHANNEL_KEYS)
    if unknown:
        raise UserError(f"{here}: unknown key {unknown[0]!r} (keys: {', '.join(sorted(_CHANNEL_KEYS))})")
    topic, type_name = spec.get("topic"), spec.get("type")
    if not isinstance(topic, str) or not topic.startswith("/") or len(topic) < 2 or " " in topic:
        raise UserError(f"{here}: topic must be an absolute ROS topic name such as /plant/ph, got {topic!r}")
    if not isinstance(type_name, str):
        raise UserError(f"{here}: give its message type, e.g. std_msgs/msg/Float64")
    mtype = type_named(type_name)
    if mtype is None:
        raise UserError(f"{here}: unknown message type {type_name!r} (known: {', '.join(MESSAGE_TYPES)})")
    fname = spec.get("field", mtype.default_field)
    if fname is None:
        raise UserError(f"{here}: {mtype.name} has several fields; give one with field: (it has: "
                        f"{', '.join(mtype.fields)})")
    if fname not in mtype.fields:
        raise UserError(f"{here}: {mtype.name} has no field {fname!r} (it has: {', '.join(mtype.fields)})")
    index, label = spec.get("index"), spec.get("name")
    if fname in mtype.arrays:
        if isinstance(index, bool) or not isinstance(index, int) or index < 0:
            raise UserError(f"{here}: {mtype.name} field {fname} is an array; give index: N (0 for the first)")
    elif index is not None:
        raise UserError(f"{here}: index is for array fields; {mtype.name} field {fname} is a number")
    if mtype.named and fname == mtype.named[1]:
        if not isinstance(label, str) or not label:
            raise UserError(f"{here}: {mtype.name} holds named values; give name: (the value's name in "
                            f"{mtype.named[0]})")
    elif label is not None:
        raise UserError(f"{here}: name is for {', '.join(t.name for t in MESSAGE_TYPES.values() if t.named)}")
    stamp = spec.get("stamp")
    if stamp not in (None, "receive"):
        raise UserError(f"{here}: stamp can only be 'receive' (stamped on receipt), got {stamp!r}")
    return ChannelSource(name, topic, mtype, fname, index, label, stamp == "receive")


def _check_against(cmap: ChannelMap, reference_channels: Sequence[str], where: str) -> None:
    mapped = set(cmap.channels)
    missing = [c for c in reference_channels if c not in mapped]
    if missing:
        raise UserError(f"{where}: no source for the reference's channel {missing[0]!r} (the reference has: "
                        f"{', '.join(reference_channels)})")
    extra = [c for c in cmap.channels if c not in set(reference_channels)]
    if extra:
        raise UserError(f"{where}: channel {extra[0]!r} is not one of the reference's ({', '.join(reference_channels)})")
    by_topic: dict[str, ChannelSource] = {}
    for s in cmap.sources:
        first = by_topic.setdefault(s.topic, s)
        if first.type.name != s.type.name:
            raise UserError(f"{where}: topic {s.topic} is given two types ({first.type.name} and {s.type.name})")
        if first.stamp != s.stamp:
            raise UserError(f"{where}: topic {s.topic} is stamped two ways (channel {first.channel!r} by "
                            f"{first.stamp}, {s.channel!r} by {s.stamp}): give stamp: receive to all or none")


def _number(value: Any, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{what} must be a number, got {value!r}")
    return float(value)


def value_of(source: ChannelSource, msg: Any) -> tuple[float, str | None]:
    """The channel's value in a decoded message (any object with the fields); NaN and the reason when the
    message does not hold it (an index past the array's end, a name it does not carry)."""
    data = getattr(msg, source.field)
    if source.index is not None:
        if source.index >= len(data):
            return math.nan, f"{source.field}[{source.index}] is past the end of {len(data)} values"
        return float(data[source.index]), None
    if source.name is not None:
        names = list(getattr(msg, source.type.named[0]))  # type: ignore[index]
        if source.name not in names:
            return math.nan, f"no value named {source.name!r}"
        return float(data[names.index(source.name)]), None
    return float(data), None


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m wavelet_fdi.channel_map MAP.yaml [REFERENCE.json]``: check a map, one line either way."""
    args = list(sys.argv[1:] if argv is None else argv)
    if not 1 <= len(args) <= 2 or args[0] in ("-h", "--help"):
        print("usage: python -m wavelet_fdi.channel_map MAP.yaml [REFERENCE.json]", file=sys.stderr)
        return 2
    try:
        channels = None
        if len(args) == 2:
            from .learned_detector import LearnedModel

            channels = LearnedModel.load(args[1]).channels
        cmap = load_channel_map(args[0], channels)
    except UserError as exc:
        print(f"channel map: error: {exc}", file=sys.stderr)
        return 2
    print(f"{args[0]}: {len(cmap.sources)} channels on {len(cmap.topics())} topics, align {cmap.align}")
    for s in cmap.sources:
        print(f"  {s.channel}: {s.describe()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
