"""The start barrier and the data endpoints of a graph node.

Why a barrier: a reliable writer delivers only to readers it has already
matched, and in lock-step a lost first sample would stall the graph. Every
node announces on /graph/ready the topics it subscribes to and publishes,
waits until each of its publishers has matched every announced reader of its
topic and each of its subscriptions every announced writer (both sides, so no
sample has to be repaired after the start), then announces ``ready``. The
plant starts sample 0 once every node named in ``graph_nodes`` is ready.
"""

from __future__ import annotations

import json
import sys
import time
from typing import Any, Callable

import rclpy
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from phfdi_base.topics import GRAPH_READY

__all__ = ["DATA_QOS", "READY_QOS", "READY_READER_QOS", "VIEWER_QOS", "StartBarrierMixin"]

#: every data topic: nothing lost, the writer waits for slow reliable readers
DATA_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
#: /graph/ready: late joiners get each node's last announcement
READY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: its reader: the topic has no key, so a reader of depth 1 keeps one announcement of all writers together and
#: a burst from several nodes overwrote all but the last before the callback took them (a lost "ready" then
#: came back with the writer's next 1 s heartbeat: measured 1 to 2 s more start-up)
READY_READER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=64, reliability=ReliabilityPolicy.RELIABLE,
                              durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: a reader that only watches (the live view): best effort, so a writer never waits for it nor keeps samples for it;
#: matched at the start barrier all the same, so it sees the run from sample 0 when it keeps up
VIEWER_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=256, reliability=ReliabilityPolicy.BEST_EFFORT,
                        durability=DurabilityPolicy.VOLATILE)


#: libraries whose import costs a node 0.1 to 0.4 s of CPU at start-up (reported: which a node loaded)
HEAVY_MODULES = ("numpy", "pydantic", "pywt", "scipy", "mcap")


def heavy_modules() -> list[str]:
    """Which of :data:`HEAVY_MODULES` this process has imported."""
    return [m for m in HEAVY_MODULES if m in sys.modules]


class _CountingPublisher:
    """A publisher that counts what it published (reported on exit: published vs recorded)."""

    __slots__ = ("_pub", "_counts", "topic_name")

    def __init__(self, pub, counts: dict[str, int]) -> None:
        self._pub, self._counts, self.topic_name = pub, counts, pub.topic_name
        counts.setdefault(pub.topic_name, 0)

    def publish(self, msg) -> None:
        self._pub.publish(msg)
        self._counts[self.topic_name] += 1

    def get_subscription_count(self) -> int:
        return self._pub.get_subscription_count()

    def wait_for_all_acked(self, timeout):
        return self._pub.wait_for_all_acked(timeout)



class StartBarrierMixin(Node):
    """Data endpoints, the start barrier and flushing on the way out (a part of ``GraphNode``)."""

    # given by the other parts of GraphNode
    finished: bool
    exit_code: int
    param: Callable[[str], Any]

    def _init_barrier(self) -> None:
        self.published: dict[str, int] = {}  # messages per topic, printed on exit
        self._data_publishers: list = []
        self._data_subscriptions: list = []
        self._peers: dict[str, tuple[set[str], set[str]]] = {}  # node -> (subscribed, published) topics
        self._peers_ready: set[str] = set()
        self._connected = False
        self._announced_ready = False
        self._waiting_for = "announcements"
        self._barrier_t0 = time.monotonic()
        #: wall clock (time.time()) of the start-up steps, printed as a "startup" JSON line once connected:
        #: main (imports done), init (rclpy.init), built (node and endpoints made), matched (own endpoints
        #: matched with every announced peer), connected (every node of the graph ready); startup_cpu: the
        #: process's CPU seconds at the same steps
        self.startup_times: dict[str, float] = {}
        self.startup_cpu: dict[str, float] = {}

    def data_publisher(self, msg_type, topic: str):
        """A reliable keep-all publisher, counted, part of the start barrier."""
        pub = _CountingPublisher(self.create_publisher(msg_type, topic, DATA_QOS), self.published)
        self._data_publishers.append(pub)
        return pub

    def data_subscription(self, msg_type, topic: str, callback: Callable, raw: bool = False,
                          qos: QoSProfile = DATA_QOS):
        """A subscription, part of the start barrier; ``qos`` other than the data QoS only for a reader that must
        never hold a writer back (the live view's :data:`VIEWER_QOS`)."""
        sub = self.create_subscription(msg_type, topic, callback, qos, raw=raw)
        self._data_subscriptions.append(sub)
        return sub

    def _startup_step(self, step: str, wall: float | None = None, cpu: float | None = None) -> None:
        self.startup_times[step] = time.time() if wall is None else wall
        self.startup_cpu[step] = time.process_time() if cpu is None else cpu

    def start_barrier(self) -> None:
        """Call once all data endpoints exist."""
        self._startup_step("built")
        self._ready_pub = self.create_publisher(DiagnosticStatus, GRAPH_READY, READY_QOS)
        self.create_subscription(DiagnosticStatus, GRAPH_READY, self._on_peer_status, READY_READER_QOS)
        self._barrier_timer = self.create_timer(0.025, self._check_barrier)
        self._announce_timer = self.create_timer(0.2, self._announce)
        self._announce()

    def _announce(self) -> None:
        # Repeated (transient local alone proved unreliable here for late joiners): every
        # 0.2 s until connected, then every 1 s as a heartbeat.
        state = "connected" if self._connected else "ready" if self._announced_ready else "waiting"
        self._ready_pub.publish(DiagnosticStatus(
            level=DiagnosticStatus.OK, name=self.get_name(), message=state,
            values=[KeyValue(key="subscriptions", value=",".join(s.topic_name for s in self._data_subscriptions)),
                    KeyValue(key="publications", value=",".join(p.topic_name for p in self._data_publishers))]))

    def _on_peer_status(self, msg: DiagnosticStatus) -> None:
        values = {v.key: set(v.value.split(",")) - {""} for v in msg.values}
        self._peers[msg.name] = (values.get("subscriptions", set()), values.get("publications", set()))
        if msg.message in ("ready", "connected"):
            self._peers_ready.add(msg.name)
        if not self._connected:
            self._check_barrier()  # the last peer's "ready" connects the graph now, not at the next timer tick

    def graph_node_names(self) -> list[str]:
        """The nodes this node waits for at the start barrier: ``graph_nodes`` (a node of a graph of its own may
        say otherwise: the detectors on a channel map)."""
        return list(self.param("graph_nodes"))

    def _unmatched(self) -> str | None:
        """Why this node's endpoints are not all matched yet (None: they are)."""
        missing = [n for n in self.graph_node_names() if n not in self._peers]
        if missing:
            return "waiting for node(s) " + ", ".join(missing)
        for pub in self._data_publishers:
            readers = sum(pub.topic_name in subs for subs, _ in self._peers.values())
            if pub.get_subscription_count() < readers:
                return f"{pub.topic_name}: {pub.get_subscription_count()} of {readers} readers matched"
        for sub in self._data_subscriptions:
            writers = sum(sub.topic_name in pubs for _, pubs in self._peers.values())
            if sub.get_publisher_count() < writers:
                return f"{sub.topic_name}: {sub.get_publisher_count()} of {writers} writers matched"
        return None

    def _check_barrier(self) -> None:
        if self._connected or self.finished:
            return
        why = self._unmatched()
        if why is None and not self._announced_ready:
            self._announced_ready = True
            self._startup_step("matched")
            self._announce()
        if why is None:
            waiting = [n for n in self.graph_node_names() if n not in self._peers_ready]
            why = "waiting for node(s) " + ", ".join(waiting) + " to connect" if waiting else None
        if why is None:
            self._connected = True
            self._barrier_timer.cancel()
            self._announce_timer.cancel()
            self._announce_timer = self.create_timer(1.0, self._announce)
            self._announce()
            self._startup_step("connected")
            print(json.dumps({"event": "startup", "node": self.get_name(), "times": self.startup_times,
                              "cpu": self.startup_cpu, "heavy_modules": heavy_modules()}), flush=True)
            self.on_connected()
            return
        if why != self._waiting_for:
            self.get_logger().debug(f"start barrier: {why}")
        self._waiting_for = why
        if time.monotonic() - self._barrier_t0 > self.param("connect_timeout_s"):
            self.get_logger().error(f"the graph did not connect within {self.param('connect_timeout_s'):g} s: "
                                    f"{why} (announcements from: {', '.join(sorted(self._peers)) or 'none'})")
            self.exit_code = 3
            self.finished = True
            self._barrier_timer.cancel()

    @property
    def connected(self) -> bool:
        return self._connected

    def on_connected(self) -> None:
        """Every node of the graph is connected (called once)."""

    def flush_publishers(self, timeout_s: float = 2.0) -> bool:
        """Wait until every reliable reader acknowledged everything published (shared deadline)."""
        deadline = time.monotonic() + timeout_s
        ok = True
        for pub in self._data_publishers:
            left = max(0.0, deadline - time.monotonic())
            try:
                ok = pub.wait_for_all_acked(rclpy.duration.Duration(seconds=left)) and ok
            except Exception:  # noqa: BLE001 - a destroyed context on the way out
                ok = False
        return ok
