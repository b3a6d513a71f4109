"""The learned detector node's inputs from a channel map (imports rclpy; no side effects at import).

One subscription per topic of the map (:mod:`wavelet_fdi.channel_map`); each message gives the values of the
channels it carries and a stamp (``header.stamp``, the project's ``stamp``, or the node's clock when it was
taken: wall time, or /clock with ``use_sim_time``); the ROS-free :class:`~wavelet_fdi.channel_align.ChannelAligner`
puts them on the sample grid and the rows go to the node's worker. What cannot be read is said once, in one line,
on the log and on /diagnostics (``detector: channel map``), and the node keeps running: a topic that publishes
nothing, a topic published with another type than the map says (DDS then never delivers it), a QoS that does not
match, an array index past the end, a stamp that repeats (a publisher that does not fill it in).
"""

from __future__ import annotations

import importlib
import time
from functools import partial
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from phfdi_base.ros.barrier import DATA_QOS
from phfdi_base.ros.params import NodeStartError
from phfdi_base.stamps import time_ns

from .channel_align import ChannelAligner
from .channel_map import STAMP_HEADER, STAMP_RECEIVE, ChannelMap, ChannelSource, value_of

#: a best-effort reader keeps this many messages per topic until the executor takes them
BEST_EFFORT_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.VOLATILE)


#: hold: this many messages of a topic in a row with the same stamp are said (its publisher does not stamp them)
STAMP_REPEATS = 3
#: problems of one kind said one by one on the log; the rest of that kind summed up in one line (a map of 1000
#: channels on silent topics said 1000 WARN lines)
SAY_EACH = 3
#: the kinds of problem (the first word of a problem's key), as the summing-up line names them
PROBLEM_KINDS = {"silent": "silent topics", "type": "topics of another type", "qos": "topics whose QoS does not match",
                 "value": "channels without their value", "stamp": "topics whose stamp repeats",
                 "grid": "channels stamped off the grid"}


class SummedWarnings:
    """WARN lines of one kind: the first :data:`SAY_EACH` one by one, the others held and summed up in one line at
    the next :meth:`flush` (each one stays on /diagnostics, where the summing-up line points)."""

    def __init__(self, logger, where: str) -> None:
        self.logger, self.where = logger, where
        self._said: dict[str, int] = {}
        self._held: dict[str, list[str]] = {}

    def warn(self, kind: str, subject: str, line: str) -> None:
        n = self._said.get(kind, 0)
        self._said[kind] = n + 1
        if n < SAY_EACH:
            self.logger.warning(line)
        else:
            self._held.setdefault(kind, []).append(subject)

    def flush(self, words: dict[str, str]) -> None:
        """One line per kind for the warnings held since the last flush."""
        for kind, subjects in self._held.items():
            shown = ", ".join(subjects[:SAY_EACH]) + (", ..." if len(subjects) > SAY_EACH else "")
            self.logger.warning(f"... and {len(subjects)} more {words.get(kind, kind)} like it ({shown}): each is "
                                f"on {self.where}")
        self._held.clear()


def message_class(type_name: str) -> Any:
    """The rclpy message class of ``pkg/msg/Type`` (a one-line start error when its package is not installed)."""
    pkg, _, name = type_name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.msg"), name)
    except (ImportError, AttributeError):
        raise NodeStartError(f"channel map: message type {type_name} is not installed here") from None


class MappedInputs:
    """Subscriptions of a channel map feeding an aligner; ``deliver`` gets the rows that are ready."""

    def __init__(self, node: Any, cmap: ChannelMap, dt_ns: int, deliver: Callable[[list], None],
                 silent_after_s: float) -> None:
        self.node, self.cmap, self.deliver, self.silent_after_s = node, cmap, deliver, silent_after_s
        self.aligner = ChannelAligner(len(cmap.sources), dt_ns, cmap.align, cmap.max_wait_s, cmap.hold_samples,
                                      stamped=tuple(s.stamp != STAMP_RECEIVE for s in cmap.sources),
                                      grid_tolerance=cmap.grid_tolerance)
        self.received = 0
        self.problems: dict[str, str] = {}  # key -> the one line said about it (each said once)
        self.warnings = SummedWarnings(node.get_logger(), f"/diagnostics ('{node.get_name()}: channel map')")
        self._start = time.monotonic()
        self._last_arrival: dict[str, float] = {}
        self._last_stamp: dict[str, tuple[int | None, int]] = {}  # topic -> (last stamp, repeats of it in a row)
        qos = DATA_QOS if cmap.reliability == "reliable" else BEST_EFFORT_QOS
        for topic, mtype in cmap.topics().items():
            sources = [(i, s) for i, s in enumerate(cmap.sources) if s.topic == topic]
            events = SubscriptionEventCallbacks(incompatible_qos=partial(self._on_incompatible_qos, topic),
                                                incompatible_type=partial(self._on_incompatible_type, topic))
            node.create_subscription(message_class(mtype.name), topic, partial(self._on_message, sources), qos,
                                     event_callbacks=events)

    # ---- executor thread ---------------------------------------------------------------------
    def _on_message(self, sources: list[tuple[int, ChannelSource]], msg: Any) -> None:
        now = time.monotonic()
        self.received += 1
        topic = sources[0][1].topic
        self._last_arrival[topic] = now
        self.problems.pop(f"silent {topic}", None)
        stamp_ns = self._stamp_ns(sources[0][1], msg)
        if stamp_ns is None:  # no time: dropped, counted on each of its channels
            for i, _ in sources:
                self.aligner.invalid_stamp(i)
            return
        for i, source in sources:
            value, problem = value_of(source, msg)
            if problem:
                self.say(f"value {source.channel}", f"channel {source.channel}: {source.topic} {problem}: the "
                         "channel is missing (NaN) in those samples")
            self.aligner.add(i, stamp_ns, value, now)
        self.deliver(self.aligner.take(now))

    def report(self) -> dict:
        """The ``channel_map`` part of the node's ``detector_done`` report."""
        a = self.aligner
        return {"file": self.cmap.path, "align": a.rule, "grid_origin_ns": a.origin_ns,
                "sample_times": "stamps" if a.times_from_stamps else "grid",
                "stamps_not_increasing": a.stamps_not_increasing, "samples_waited_out": a.waited_out,
                "counts": {s.channel: vars(c) for s, c in zip(self.cmap.sources, a.counts)},
                "problems": list(self.problems.values())}

    def _stamp_ns(self, source: ChannelSource, msg: Any) -> int | None:
        """The message's stamp (ns), None for one that is no time (nanoseconds outside 0..1e9, before 0 s)."""
        if source.stamp == STAMP_RECEIVE:
            return self.node.get_clock().now().nanoseconds
        stamp = msg.header.stamp if source.stamp == STAMP_HEADER else msg.stamp
        if not 0 <= stamp.nanosec < 1_000_000_000 or stamp.sec < 0:
            self.say(f"invalid stamp {source.topic}", f"{source.topic}: a message stamped {stamp.sec} s "
                     f"{stamp.nanosec} ns, which is no time: dropped (each is counted)")
            return None
        ns = time_ns(stamp)
        # a stamp that repeats is a publisher that does not fill it in (hold would keep one value of many);
        # sequence does not place by stamp
        last, repeats = self._last_stamp.get(source.topic, (None, 0))
        repeats = repeats + 1 if ns == last else 0
        self._last_stamp[source.topic] = (ns, repeats)
        if repeats >= STAMP_REPEATS and self.cmap.align == "hold":
            self.say(f"stamp {source.topic}", f"{source.topic}: {repeats + 1} messages in a row stamped "
                     f"{ns / 1e9:.9g} s by {source.stamp}: does its publisher fill it in? (stamp: receive in the "
                     "channel map stamps them on receipt)")
        return ns

    def _on_incompatible_qos(self, topic: str, event: Any) -> None:
        self.say(f"qos {topic}", f"{topic}: a publisher's QoS does not match this reader's ({self.cmap.reliability}; "
                 f"policy {getattr(event, 'last_policy_kind', '?')}): nothing is received from it; set reliability "
                 "in the channel map")

    def _on_incompatible_type(self, topic: str, event: Any) -> None:
        self._say_type(topic)

    def _say_type(self, topic: str) -> bool:
        """A publisher of ``topic`` with another type than the map's: said once; True if there is one."""
        mtype = self.cmap.topics()[topic]
        others = sorted({p.topic_type for p in self.node.get_publishers_info_by_topic(topic)} - {mtype.name})
        if others:
            channels = ", ".join(s.channel for s in self.cmap.sources if s.topic == topic)
            self.say(f"type {topic}", f"{topic} is published as {', '.join(others)}; the channel map says "
                     f"{mtype.name}: channel {channels} gets nothing from it")
        return bool(others)

    def tick(self) -> None:
        """Timer (wall time): samples whose wait is over, and the checks of topics that deliver nothing."""
        now = time.monotonic()
        self.deliver(self.aligner.take(now))
        for c in self.aligner.off_grid():
            source, origin = self.cmap.sources[c], self.aligner.origin_ns or 0
            off_s = ((self.aligner.counts[c].last_stamp_ns or 0) - origin) / 1e9
            self.say(f"grid {source.channel}", f"channel {source.channel}: every message of {source.topic} is "
                     f"stamped off the grid ({off_s:.6g} s from its origin, {source.stamp}): "
                     "are its stamps on another clock than the other channels'?")
        if self.aligner.stamps_not_increasing:
            topic = next(s.topic for s, stamped in zip(self.cmap.sources, self.aligner.stamped) if stamped)
            self.say(f"stamp order {topic}", f"{topic}: a sample stamped no later than the one before it (the sample "
                     "times come from its stamps with align: sequence): timed one sample period after it; does its "
                     "publisher fill in its stamps? (stamp: receive in the channel map stamps them on receipt)")
        for topic in self.cmap.topics():
            last = self._last_arrival.get(topic, self._start)
            if now - last < self.silent_after_s:
                continue
            channels = ", ".join(s.channel for s in self.cmap.sources if s.topic == topic)
            if not self._say_type(topic):
                what = "has published nothing" if topic not in self._last_arrival else "has been silent"
                self.say(f"silent {topic}", f"{topic} {what} for {now - last:.0f} s (channel {channels}): its "
                         "samples go out without it")
        self.warnings.flush(PROBLEM_KINDS)

    def flush(self) -> None:
        """The end of the stream: every sample begun goes to the core."""
        self.deliver(self.aligner.flush())
        self.warnings.flush(PROBLEM_KINDS)

    def say(self, key: str, line: str) -> None:
        """A problem, once: on the log (one line; beyond :data:`SAY_EACH` of its kind summed up at the next tick)
        and, in the next status, on /diagnostics."""
        if key not in self.problems:
            self.problems[key] = line
            kind, _, subject = key.partition(" ")
            self.warnings.warn(kind, subject, line)

    # ---- /diagnostics ---------------------------------------------------------------------------
    def status(self) -> DiagnosticStatus:
        """``detector: channel map``: each channel's source and stamp rule, its counts, the problems seen."""
        a = self.aligner
        values = [KeyValue(key="align", value=f"{self.cmap.align} (max_wait_s {self.cmap.max_wait_s:g}, "
                                                f"hold_samples {self.cmap.hold_samples})"),
                  KeyValue(key="samples", value=str(a.samples_out)),
                  KeyValue(key="samples_waited_out", value=str(a.waited_out)),
                  KeyValue(key="grid_origin_ns", value=str(a.origin_ns))]
        for source, c in zip(self.cmap.sources, a.counts):
            values.append(KeyValue(key=source.channel, value=source.describe()))
            values.append(KeyValue(key=f"{source.channel} counts",
                                   value=f"received {c.received}, used {c.used}, held {c.held}, missing {c.missing}, "
                                         f"late {c.late}, superseded {c.superseded}, jumps dropped {c.jumps_dropped}, "
                                         f"off grid {c.off_grid}, invalid stamps {c.invalid_stamps}"))
        values += [KeyValue(key="problem", value=line) for line in self.problems.values()]
        lines = list(self.problems.values())
        summary = "; ".join(lines[:SAY_EACH]) + (f"; and {len(lines) - SAY_EACH} more problems (each under "
                                                 "'problem')" if len(lines) > SAY_EACH else "")
        summary = summary or (
            f"{len(self.cmap.sources)} channels on {len(self.cmap.topics())} topics, {a.samples_out} samples")
        level = DiagnosticStatus.WARN if self.problems else DiagnosticStatus.OK
        return DiagnosticStatus(level=level, name=f"{self.node.get_name()}: channel map",
                                hardware_id=self.node.get_name(), message=summary, values=values)
