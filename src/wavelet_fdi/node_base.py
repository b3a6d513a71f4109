"""The detector node's ROS side apart from its core (:mod:`wavelet_fdi.learned_node`: the multichannel detector; the
physics detector's own node, which shared it, was retired on 2026-12-07). Imports rclpy; no side effects at import.

* the states of /fault_alarm (phfdi_interfaces/FaultAlarm OK, WARN, ALARM) and their names in the JSON lines;
* the worker: the executor's callbacks only queue rows (:meth:`DetectorNodeBase.enqueue`); one worker thread
  hands everything queued since its last call to the core (:meth:`DetectorNodeBase.process`, the only place
  that touches the core and the publishers), so a slow core call never stops the executor from taking
  messages, and nothing is lost;
* the JSON lines on stdout the launcher and ``phfdi replay --live`` follow: one ``fault_alarm`` line per
  published state change (:meth:`DetectorNodeBase.publish_alarm`) and, on exit, a ``detector_done`` report
  (:meth:`DetectorNodeBase.done_report`);
* the end: take what the readers hold, stop the worker after it has processed everything queued, the
  node's last results (:meth:`DetectorNodeBase.finish`), deliver, report.
"""

from __future__ import annotations

import json
import math
import threading
from typing import Any

import numpy as np
from phfdi_interfaces.msg import FaultAlarm, MeasuredSample

from phfdi_base.ros.graph_node import GraphNode, ParamSpec
from phfdi_base.topics import DETECTOR, DETECTOR_MONITOR, FAULT_ALARM

#: both detector nodes' live-view monitor (docs/ros_graph.md, "Live view in Foxglove"): off unless asked for, so a
#: graph without it publishes and records exactly what it did before
MONITOR_PARAMS = (
    ParamSpec("monitor_topic", False, "publish the residuals and the statistics over their thresholds on "
                                      "/detector/monitor (phfdi_interfaces/MeasuredSample; phfdi launch --foxglove)"),
    ParamSpec("monitor_period_s", 1.0, "at most one /detector/monitor message (and live-view sample) per this many "
                                       "s of the record's (simulated) time; 0: one per batch the detector processes",
              range=(0.0, 1e9)),
)

#: FaultAlarm.state of the core's levels
STATE_OF_LEVEL = {"OK": FaultAlarm.OK, "WARN": FaultAlarm.WARN, "ERROR": FaultAlarm.ALARM}
#: names of the FaultAlarm states in the JSON lines
STATE_NAMES = {FaultAlarm.OK: "OK", FaultAlarm.WARN: "WARN", FaultAlarm.ALARM: "ALARM"}


class DetectorNodeBase(GraphNode):
    """A detector node: publishes /fault_alarm, runs its core on a worker thread, reports in JSON lines.

    A subclass builds its core, calls :meth:`open_alarm_output`, subscribes its inputs (callbacks call
    :meth:`enqueue`), then :meth:`start_worker` and ``start_barrier()``; it implements :meth:`process`,
    :meth:`received` and :meth:`done_report` (and :meth:`finish` for work after the last rows).
    """

    #: name of the worker thread
    WORKER_NAME = "detector-core"

    def __init__(self) -> None:
        super().__init__(DETECTOR)
        self._loop = self.param("loop")
        self._state = FaultAlarm.OK
        self.core_errors = 0
        self._queue: list[Any] = []
        self._cond = threading.Condition()
        self._closing = False
        self._poked = False  # the worker calls process([]) once: work that is due without new rows
        self._worker: threading.Thread | None = None

    def graph_node_names(self) -> list[str]:
        """With a channel map the plant is your own, not the simulator: unless ``graph_nodes`` is given, the start
        barrier waits for no other node (the default, the simulator's plant, controllers and valve, would never come:
        the node used to stop after ``connect_timeout_s`` waiting for them)."""
        if self.alone_on_a_map():
            return [self.get_name()]
        return super().graph_node_names()

    def alone_on_a_map(self) -> bool:
        """A channel map and no ``graph_nodes`` given (``-p`` or a parameter file): a graph of this node alone."""
        given = getattr(self, "_parameter_overrides", {})
        return bool(self.param("channel_map_file")) and "graph_nodes" not in given

    def start_barrier(self) -> None:
        """The start barrier; a mapped node alone says in one line that it waits for no other node."""
        if self.alone_on_a_map():
            self.get_logger().info("channel map: your plant's own topics; the start barrier waits for no other node "
                                   "(set graph_nodes to wait for some)")
        super().start_barrier()

    def open_alarm_output(self) -> None:
        self.pub_alarm = self.data_publisher(FaultAlarm, FAULT_ALARM.name)

    def open_monitor_output(self) -> None:
        """The /detector/monitor publisher when ``monitor_topic`` asks for it (:data:`MONITOR_PARAMS`)."""
        self._monitor_period_s = self.param("monitor_period_s")
        self._last_monitor_t = -math.inf
        self.pub_monitor = self.data_publisher(MeasuredSample, DETECTOR_MONITOR.name) if self.param(
            "monitor_topic") else None

    def monitor_due(self, t_s: float) -> bool:
        """A monitor sample at record time ``t_s`` is due (``monitor_period_s`` after the last one)."""
        return self._monitor_period_s <= 0 or t_s >= next_multiple(self._last_monitor_t, self._monitor_period_s)

    def publish_monitor(self, t_s: float, values: dict[str, float], stamp) -> None:
        """One monitor sample (worker thread): ``values`` by name on /detector/monitor, if it is open."""
        self._last_monitor_t = t_s
        if self.pub_monitor is not None:
            msg = MeasuredSample(source=DETECTOR_MONITOR.publisher, names=list(values), values=list(values.values()))
            msg.stamp = stamp
            self.pub_monitor.publish(msg)

    # ---- executor thread: queue only ------------------------------------------------------
    def enqueue(self, rows: list) -> None:
        """Hand rows to the worker (the only thing an executor callback does with them)."""
        if rows:
            with self._cond:
                self._queue.extend(rows)
                self._cond.notify()

    def poke(self) -> None:
        """Have the worker call ``process([])`` (time-due work such as held-back messages; executor thread)."""
        with self._cond:
            self._poked = True
            self._cond.notify()

    def received(self) -> int:
        """Messages taken from the readers so far (the end waits until it stops moving)."""
        raise NotImplementedError

    # ---- worker thread ------------------------------------------------------------------------
    def start_worker(self) -> None:
        self._worker = threading.Thread(target=self._work, name=self.WORKER_NAME, daemon=True)
        self._worker.start()

    def _work(self) -> None:
        while True:
            with self._cond:
                while not self._queue and not self._closing and not self._poked:
                    self._cond.wait()
                rows, self._queue = self._queue, []
                closing, poked, self._poked = self._closing, self._poked, False
            if rows or (poked and not closing):
                self.process(rows)
            if closing and not rows:
                return

    def process(self, rows: list) -> None:
        """Everything queued since the last call through the core; publish the results (worker thread)."""
        raise NotImplementedError

    def stop_worker(self) -> None:
        """Let the worker process everything queued, then end it."""
        with self._cond:
            self._closing = True
            self._cond.notify()
        if self._worker is not None:
            self._worker.join()

    # ---- output --------------------------------------------------------------------------------
    def publish_alarm(self, msg: FaultAlarm, kind: str, time_s: float, alarm: dict | None,
                      report: bool = True) -> None:
        """Publish ``msg`` on /fault_alarm; with ``report`` also its JSON line (a state change)."""
        self.pub_alarm.publish(msg)
        if report:
            self.report({"event": "fault_alarm", "kind": kind, "state": STATE_NAMES[msg.state], "time_s": time_s,
                         "message": msg.message, "alarm": alarm})

    @staticmethod
    def report(event: dict) -> None:
        """One JSON line on stdout (the launcher and phfdi replay --live follow them)."""
        print(json.dumps(event, default=json_default), flush=True)

    # ---- the end ---------------------------------------------------------------------------------
    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers already hold (acknowledged to the writers)."""
        self.spin_until_idle(executor, self.received, idle_s, limit_s)

    def finish(self) -> None:
        """After the worker has ended: the node's last results (worker-free, so on this thread)."""

    def done_report(self) -> dict:
        """The fields of the ``detector_done`` report: samples, alarms, ..."""
        raise NotImplementedError

    def close(self) -> None:
        """Process everything queued, the last results, then deliver and report."""
        self.stop_worker()
        self.finish()
        self.flush_publishers(5.0)
        self.report_published()
        self.report({"event": "detector_done", **self.done_report()})


def next_multiple(t_s: float, period_s: float) -> float:
    """The first multiple of the period after t_s: periodic messages (heartbeats) stay on their grid of the stream's
    time (0, 60, 120 s, ...) whatever the chunks the core was given."""
    return (math.floor(t_s / period_s) + 1) * period_s if math.isfinite(t_s) else -math.inf


def json_default(x):
    """numpy scalars as numbers, anything else as its text."""
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return str(x)
