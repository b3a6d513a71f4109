"""The base of every node of the graph (imports rclpy).

A :class:`GraphNode` declares its parameters from :class:`ParamSpec` lists
(description, range, runtime-changeable or not), loads the scenario every node
of the graph shares, joins the start barrier and offers simulated-time stamps.
:func:`main` runs one node as a process: LOCALHOST discovery enforced, one
clear line and exit status 2 for bad parameters, clean shutdown on SIGINT or
SIGTERM (publishers flushed to their reliable readers first).

Start barrier (why: a reliable writer delivers only to readers it has already
matched, and in lock-step a lost first sample would stall the graph): every
node announces on /graph/ready the topics it subscribes to and publishes,
waits until each of its publishers has matched every announced reader of its
topic and each of its subscriptions every announced writer (both sides, so no
sample has to be repaired after the start), then announces ``ready``. The
plant starts sample 0 once every node named in ``graph_nodes`` is ready.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Sequence

from phfdi_base.errors import UserError
from phfdi_base.topics import GRAPH_READY, LOOP_NODES, sample_period_ns

from .env import ensure_localhost

try:
    ensure_localhost()  # before rclpy creates any DDS participant
except UserError as _exc:
    print(f"error: {_exc}", file=sys.stderr)
    raise SystemExit(2) from None

import rclpy  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue  # noqa: E402
from rcl_interfaces.msg import (  # noqa: E402
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    ParameterType,
    SetParametersResult,
)
from rclpy.exceptions import (  # noqa: E402
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.signals import SignalHandlerOptions  # noqa: E402

#: every data topic: nothing lost, the writer waits for slow reliable readers
DATA_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
#: /graph/ready: late joiners get each node's last announcement
READY_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)


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


class NodeStartError(Exception):
    """The node cannot start: one line naming the problem (exit status 2)."""


@dataclass(frozen=True)
class ParamSpec:
    """A node parameter. ``default`` may be a callable of the loaded scenario."""

    name: str
    default: Any
    description: str
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] | None = None
    runtime: bool = False  # may be changed while the node runs

    def default_for(self, spec) -> Any:
        return self.default(spec) if callable(self.default) else self.default

    def allowed(self) -> str:
        if self.range is not None:
            lo, hi = self.range
            if isinstance(self.default, int) and not isinstance(self.default, bool):
                return f"[{int(lo)}, {int(hi)}]"
            return f"[{lo:g}, {hi:g}]"
        if self.choices is not None:
            return "one of " + ", ".join(repr(c) for c in self.choices)
        return ""


#: parameters every node of the graph takes (the same values for all of them)
COMMON_PARAMS: tuple[ParamSpec, ...] = (
    ParamSpec("scenario", "paper", "scenario preset name or path of a scenario .yaml (every node loads the same)"),
    ParamSpec("fault", "", "fault from the library replacing the scenario's faults ('healthy' removes them); "
                           "'' keeps the scenario's"),
    ParamSpec("fault_onset_s", -1.0, "onset of the fault (s of simulated time); -1 keeps the fault's own onset",
              range=(-1.0, 1e9)),
    ParamSpec("overrides", [], "scenario overrides KEY=VALUE, as phfdi simulate --set"),
    ParamSpec("graph_nodes", list(LOOP_NODES), "names of the nodes of this graph; sample 0 waits until all are "
                                               "connected"),
    ParamSpec("connect_timeout_s", 60.0, "give up if the graph has not connected after this long (s, wall)",
              range=(0.1, 3600.0)),
    ParamSpec("executor", "events", "rclpy executor: events (fastest) or single_threaded",
              choices=("events", "single_threaded")),
)


def _param_type(value: Any) -> int:
    if isinstance(value, bool):
        return ParameterType.PARAMETER_BOOL
    if isinstance(value, int):
        return ParameterType.PARAMETER_INTEGER
    if isinstance(value, float):
        return ParameterType.PARAMETER_DOUBLE
    if isinstance(value, str):
        return ParameterType.PARAMETER_STRING
    if isinstance(value, list):
        return ParameterType.PARAMETER_STRING_ARRAY
    raise TypeError(f"unsupported parameter default {value!r}")


_TYPE_WORDS = {
    ParameterType.PARAMETER_BOOL: "a boolean (true or false)",
    ParameterType.PARAMETER_INTEGER: "an integer",
    ParameterType.PARAMETER_DOUBLE: "a double (write 2.0, not 2)",
    ParameterType.PARAMETER_STRING: "a string",
    ParameterType.PARAMETER_STRING_ARRAY: "a list of strings, e.g. \"[a, b]\"",
}


def to_time(ns: int) -> Time:
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def time_ns(stamp: Time) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class GraphNode(Node):
    """A node of the loop graph: parameters, scenario, start barrier, stamps."""

    #: parameters of this kind of node, besides COMMON_PARAMS
    PARAMS: tuple[ParamSpec, ...] = ()
    #: common parameters this kind of node lets change at runtime
    RUNTIME_COMMON: tuple[str, ...] = ()

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.finished = False  # set when the node's work is done (the main loop then ends)
        self.exit_code = 0
        common = tuple(ParamSpec(p.name, p.default, p.description, p.range, p.choices, True)
                       if p.name in self.RUNTIME_COMMON else p for p in COMMON_PARAMS)
        self._specs = {p.name: p for p in common + self.PARAMS}
        self._declare(common, None)
        self.spec = self._load_spec()
        self.dt_s = self.spec.sample_time_s
        try:
            self.dt_ns = sample_period_ns(self.dt_s)
        except ValueError as exc:
            raise NodeStartError(f"scenario: {exc}") from None
        self._declare(self.PARAMS, self.spec)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.published: dict[str, int] = {}  # messages per topic, printed on exit
        self._data_publishers: list = []
        self._data_subscriptions: list = []
        self._peers: dict[str, tuple[set[str], set[str]]] = {}  # node -> (subscribed, published) topics
        self._peers_ready: set[str] = set()
        self._last_k = -1  # last input sample taken (next_sample)
        self._connected = False
        self._announced_ready = False
        self._waiting_for = "announcements"
        self._barrier_t0 = time.monotonic()

    # ---- parameters -------------------------------------------------------------
    def _declare(self, specs: Sequence[ParamSpec], scenario) -> None:
        overrides = getattr(self, "_parameter_overrides", {})
        for p in specs:
            default = p.default_for(scenario)
            descriptor = ParameterDescriptor(name=p.name, type=_param_type(default), description=p.description,
                                             read_only=not p.runtime)
            if p.range is not None:
                lo, hi = p.range
                if isinstance(default, int) and not isinstance(default, bool):
                    descriptor.integer_range = [IntegerRange(from_value=int(lo), to_value=int(hi), step=0)]
                else:
                    descriptor.floating_point_range = [FloatingPointRange(from_value=float(lo), to_value=float(hi),
                                                                          step=0.0)]
            if p.choices is not None:
                descriptor.additional_constraints = p.allowed()
            value = Parameter.Type.STRING_ARRAY if default == [] else default
            try:
                self.declare_parameter(p.name, value, descriptor)
            except InvalidParameterValueException:
                given = overrides[p.name].value if p.name in overrides else default
                raise NodeStartError(f"parameter {p.name} = {given!r} is outside the allowed range "
                                     f"{p.allowed()}") from None
            except InvalidParameterTypeException:
                given = overrides[p.name].value if p.name in overrides else default
                raise NodeStartError(f"parameter {p.name} must be {_TYPE_WORDS[descriptor.type]}, "
                                     f"got {given!r}") from None
            if p.choices is not None and self.param(p.name) not in p.choices:
                raise NodeStartError(f"parameter {p.name} = {self.param(p.name)!r} is not allowed: "
                                     f"{p.allowed()}")

    def param(self, name: str) -> Any:
        if self._specs[name].default == [] and not self.has_parameter(name):
            return []
        try:
            value = self.get_parameter(name).value
        except ParameterUninitializedException:  # an empty list declared by type: not given
            return []
        return [] if value is None and self._specs[name].default == [] else value

    def _load_spec(self):
        from phfdi.scenario import load_scenario

        fault = self.param("fault") or None
        onset = self.param("fault_onset_s")
        try:
            return load_scenario(self.param("scenario"), fault=fault, overrides=list(self.param("overrides")),
                                 onset_s=None if onset < 0 else onset)
        except UserError as exc:
            raise NodeStartError(str(exc)) from None

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            spec = self._specs.get(p.name)
            if spec is not None and spec.choices is not None and p.value not in spec.choices:
                return SetParametersResult(successful=False,
                                           reason=f"{p.name} = {p.value!r} is not allowed: {spec.allowed()}")
        reason = self.check_parameters(params)
        if reason:
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params: list[Parameter]) -> None:
        self.apply_parameters(params)

    def check_parameters(self, params: list[Parameter]) -> str | None:
        """Why a runtime change cannot be accepted (None: accepted). Ranges are checked already."""
        return None

    def apply_parameters(self, params: list[Parameter]) -> None:
        """Put accepted runtime changes into effect."""

    # ---- endpoints and barrier --------------------------------------------------------
    def data_publisher(self, msg_type, topic: str):
        """A reliable keep-all publisher, counted, part of the start barrier."""
        pub = _CountingPublisher(self.create_publisher(msg_type, topic, DATA_QOS), self.published)
        self._data_publishers.append(pub)
        return pub

    def data_subscription(self, msg_type, topic: str, callback: Callable, raw: bool = False):
        sub = self.create_subscription(msg_type, topic, callback, DATA_QOS, raw=raw)
        self._data_subscriptions.append(sub)
        return sub

    def start_barrier(self) -> None:
        """Call once all data endpoints exist."""
        self._ready_pub = self.create_publisher(DiagnosticStatus, GRAPH_READY, READY_QOS)
        self.create_subscription(DiagnosticStatus, GRAPH_READY, self._on_peer_status, READY_QOS)
        self._barrier_timer = self.create_timer(0.05, self._check_barrier)
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

    def _unmatched(self) -> str | None:
        """Why this node's endpoints are not all matched yet (None: they are)."""
        missing = [n for n in self.param("graph_nodes") if n not in self._peers]
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
            self._announce()
        if why is None:
            waiting = [n for n in self.param("graph_nodes") if n not in self._peers_ready]
            why = "waiting for node(s) " + ", ".join(waiting) + " to connect" if waiting else None
        if why is None:
            self._connected = True
            self._barrier_timer.cancel()
            self._announce_timer.cancel()
            self._announce_timer = self.create_timer(1.0, self._announce)
            self._announce()
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

    # ---- time -----------------------------------------------------------------------
    def stamp(self, k: int) -> Time:
        return to_time(k * self.dt_ns)

    def sample_of(self, stamp: Time) -> int | None:
        """Sample index of a stamp; None if it is not on the sample grid."""
        k, rest = divmod(time_ns(stamp), self.dt_ns)
        return None if rest else k

    def next_sample(self, stamp: Time, what: str) -> int | None:
        """Sample index of a new input; None (with a warning) if off the grid or not newer than the last."""
        k = self.sample_of(stamp)
        if k is None or k <= self._last_k:
            self.get_logger().warning(f"ignored a {what} stamped {stamp.sec}.{stamp.nanosec:09d} s "
                                      f"(last sample {self._last_k})")
            return None
        self._last_k = k
        return k

    # ---- main loop hooks ----------------------------------------------------------------
    def spin_timeout_s(self) -> float:
        """How long the main loop may block waiting for work."""
        return 0.1

    def after_spin(self) -> None:
        """Called after every executor step (pacing, periodic work)."""

    def drain(self, executor) -> None:
        """On the way out, before :meth:`close`: take messages still queued (the recorder does)."""

    def close(self) -> None:
        """Called once on the way out, before the node is destroyed: deliver what was published."""
        self.flush_publishers()
        self.report_published()

    def report_published(self) -> None:
        print(json.dumps({"event": "published", "node": self.get_name(), "counts": self.published}), flush=True)

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


def print_parameter_help(prog: str, summary: str, specs: Sequence[ParamSpec]) -> None:
    print(f"usage: python -m {prog} [--ros-args -p NAME:=VALUE ...]\n\n{summary}\n\nparameters:")
    for p in specs:
        default = "the scenario's" if callable(p.default) else repr(p.default)
        extra = f"; allowed {p.allowed()}" if p.allowed() else ""
        change = "; changeable at runtime" if p.runtime else ""
        print(f"  {p.name:22s} {p.description} (default {default}{extra}{change})")


def _make_executor(kind: str):
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    return rclpy.executors.SingleThreadedExecutor()


def main(factory: Callable[[], GraphNode], prog: str, summary: str, specs: Sequence[ParamSpec],
         argv: list[str] | None = None) -> int:
    """Run one graph node as this process; returns the exit status."""
    argv = list(sys.argv if argv is None else argv)
    own = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if "-h" in own or "--help" in own:
        runtime = getattr(factory, "RUNTIME_COMMON", ())
        common = tuple(ParamSpec(p.name, p.default, p.description, p.range, p.choices, True)
                       if p.name in runtime else p for p in COMMON_PARAMS)
        print_parameter_help(prog, summary, common + tuple(specs))
        return 0
    stop: list[int] = []

    def on_signal(signum, _frame) -> None:
        stop.append(signum)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    name = prog.split(".")[0]
    try:
        node = factory()
    except NodeStartError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    executor = _make_executor(node.param("executor"))
    executor.add_node(node)
    try:
        while not stop and not node.finished:
            executor.spin_once(timeout_sec=node.spin_timeout_s())
            node.after_spin()
    finally:
        try:
            node.drain(executor)
        finally:
            node.close()
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if stop and not node.finished:
        return 0  # stopped on request: a normal end
    return node.exit_code

