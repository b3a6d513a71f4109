"""The base of every node of the graph (imports rclpy; no side effects at import).

A :class:`GraphNode` is made of small parts: its parameters
(:mod:`phfdi_base.ros.params`), its part of the resolved scenario
(:mod:`phfdi_base.parts`: read from the file the launcher wrote, or resolved
from scenario parameters when started by hand), the start barrier and data
endpoints (:mod:`phfdi_base.ros.barrier`), simulated-time stamps
(:mod:`phfdi_base.stamps`) and the hooks the main loop calls
(:func:`phfdi_base.ros.run.main` runs one node as a process).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.node import Node

from phfdi_base.errors import UserError
from phfdi_base.parts import NodePart, read_part, resolve_part
from phfdi_base.stamps import sample_index, sample_period_ns, split_ns, time_ns  # time_ns: re-exported
from phfdi_base.topics import DIAGNOSTICS, LOOP_NODES

from .barrier import DATA_QOS, READY_QOS, StartBarrierMixin
from .input_guard import REASONS, REPORT_PERIOD_S, InputGuard
from .params import COMMON_PARAMS, NodeStartError, ParametersMixin, ParamSpec, common_params, print_parameter_help
from .run import main

__all__ = ["COMMON_PARAMS", "DATA_QOS", "READY_QOS", "GraphNode", "NodeStartError", "ParamSpec", "main",
           "print_parameter_help", "time_ns", "to_time"]


def to_time(ns: int) -> Time:
    """A ROS time from nanoseconds."""
    sec, nanosec = split_ns(ns)
    return Time(sec=sec, nanosec=nanosec)


class GraphNode(ParametersMixin, StartBarrierMixin, Node):
    """A node of the loop graph: parameters, its part of the scenario, start barrier, stamps."""

    #: parameters of this kind of node, besides COMMON_PARAMS
    PARAMS: tuple[ParamSpec, ...] = ()
    #: common parameters this kind of node lets change at runtime
    RUNTIME_COMMON: tuple[str, ...] = ()

    def __init__(self, name: str) -> None:
        super().__init__(name)
        self.finished = False  # set when the node's work is done (the main loop then ends)
        self.exit_code = 0
        common = common_params(self.RUNTIME_COMMON)
        self._specs = {p.name: p for p in common + self.PARAMS}
        self._refuse_unknown_parameters()
        self._declare(common, None)
        self.part = self._load_part()
        self.spec = self.part.scenario
        self.dt_s = self.spec.sample_time_s
        try:
            self.dt_ns = sample_period_ns(self.dt_s)
        except ValueError as exc:
            raise NodeStartError(f"scenario: {exc}") from None
        self._declare(self.PARAMS, self.spec)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._init_barrier()
        self._last_k = -1  # last input sample taken (next_sample)
        self.input_guard = InputGuard(self.dt_ns)
        self._pub_diag = None  # /diagnostics (diagnostics_publisher), one per node

    def _load_part(self) -> NodePart:
        """The part the launcher wrote (``part``), or one resolved from the scenario parameters."""
        fault = self.param("fault") or None
        onset = self.param("fault_onset_s")
        try:
            if self.param("part"):
                return read_part(self.param("part"), validate=False)  # the launcher validated it
            return resolve_part(self.param("scenario"), fault, list(self.param("overrides")),
                                None if onset < 0 else onset)
        except UserError as exc:
            raise NodeStartError(str(exc)) from None

    # ---- time -----------------------------------------------------------------------
    def stamp(self, k: int) -> Time:
        return to_time(k * self.dt_ns)

    def sample_of(self, stamp: Time) -> int | None:
        """Sample index of a stamp; None if it is not on the sample grid."""
        return sample_index(time_ns(stamp), self.dt_ns)

    def next_sample(self, stamp: Time, what: str, waiting: bool = True) -> int | None:
        """Sample index of an input if it is the next sample (k == last + 1), and it becomes the last; else
        None: the input is dropped, counted by reason (:class:`~phfdi_base.ros.input_guard.InputGuard`),
        logged without flooding and reported on /diagnostics. ``waiting`` False (the plant between two
        samples): every input is a stray."""
        k, reason = self.input_guard.check(stamp.sec, stamp.nanosec, self._last_k, waiting)
        if k is not None and reason is None:
            self._last_k = k
            return k
        assert reason is not None
        expecting = f"sample {self._last_k + 1}" if waiting else f"nothing (last sample {self._last_k})"
        stamped = (f"{stamp.sec}.{stamp.nanosec:09d} s" if reason != "invalid_stamp"
                   else f"sec {stamp.sec}, nanosec {stamp.nanosec}")
        line = self.input_guard.drop(reason, f"a {what} stamped {stamped} while waiting for {expecting}")
        if line is not None:
            self.get_logger().warning(line)
        self._report_inputs()
        return None

    def diagnostics_publisher(self):
        """This node's /diagnostics publisher (one per node, made on the first call: before start_barrier)."""
        if self._pub_diag is None:
            self._pub_diag = self.data_publisher(DiagnosticArray, DIAGNOSTICS.name)
        return self._pub_diag

    def start_barrier(self) -> None:
        if self.get_name() in LOOP_NODES:  # lock-step inputs: the stray counts go on /diagnostics
            self.diagnostics_publisher()
            # counts held back by the once-a-second limit go out within a second even if no stray follows
            self.create_timer(REPORT_PERIOD_S, self._report_inputs)
        super().start_barrier()

    def _report_inputs(self, force: bool = False) -> None:
        """The stray-input counts on /diagnostics when they changed, at most once a second of wall time."""
        guard = self.input_guard
        if self._pub_diag is None or not (guard.report_due() or (force and guard.pending)):
            return
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if guard.total else DiagnosticStatus.OK,
            name=f"{self.get_name()}: inputs", hardware_id=self.get_name(), message=guard.summary(),
            values=[KeyValue(key=r, value=str(guard.counts[r])) for r in REASONS]
            + [KeyValue(key="dropped", value=str(guard.total)), KeyValue(key="last_sample", value=str(self._last_k)),
               KeyValue(key="last_dropped", value=guard.last_dropped)])
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.stamp(max(self._last_k, 0))
        self._pub_diag.publish(array)
        guard.reported()

    # ---- main loop hooks ----------------------------------------------------------------
    def spin_timeout_s(self) -> float:
        """How long the main loop may block waiting for work."""
        return 0.1

    def after_spin(self) -> None:
        """Called after every executor step (pacing, periodic work)."""

    def drain(self, executor) -> None:
        """On the way out, before :meth:`close`: take messages still queued (the recorder does)."""

    @staticmethod
    def spin_until_idle(executor, received: Callable[[], int], idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Spin until ``received()`` (a message count) has not moved for ``idle_s`` s, at most ``limit_s`` s:
        the :meth:`drain` of a node that takes what its readers already hold (acknowledged to the writers)."""
        t_end = time.monotonic() + limit_s
        last, idle_since = received(), time.monotonic()
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.05)
            now = received()
            if now != last:
                last, idle_since = now, time.monotonic()
            elif time.monotonic() - idle_since >= idle_s:
                break

    def close(self) -> None:
        """Called once on the way out, before the node is destroyed: deliver what was published."""
        self._report_inputs(force=True)  # counts the once-a-second limit still held back
        self.flush_publishers()
        self.report_published()

    def report_published(self) -> None:
        print(json.dumps({"event": "published", "node": self.get_name(), "counts": self.published}), flush=True)
