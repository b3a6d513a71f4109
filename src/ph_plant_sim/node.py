"""ROS 2 node of the plant: owns simulated time (thin wrapper of :class:`PlantProcess`).

Each sample k: publish /plant/measurement and /clock for t_k, wait for
/valve/state of sample k, then :func:`ph_plant_sim.process.advance_plant` (the same
call the in-process simulation makes), go on with k + 1 and publish
/plant/state for k: as fast as the loop answers (lock-step, ``pace`` 0) or at
``pace`` times real time. Prints JSON lines on stdout for the launcher
(connected, progress, done): progress every twentieth of the run and, as
the launcher's watchdog needs, whenever a sample completes at least
``PROGRESS_PERIOD_S`` of wall time after the last report (and on a change
of ``pace``); the connected event announces that period.

    python -m ph_plant_sim.node --ros-args -p scenario:=paper -p fault:=backlash
"""

from __future__ import annotations

import json
import math
import sys
import time

from phfdi_interfaces.msg import Measurement, PlantState, ValveState
from rosgraph_msgs.msg import Clock

from phfdi_base.ros.graph_node import GraphNode, ParamSpec, main
from phfdi_base.spec_tools import load_plugins
from phfdi_base.stamps import split_ns
from phfdi_base.topics import CLOCK, MEASUREMENT, PLANT, PLANT_STATE, VALVE_STATE

from .build import build_plant, build_process, load_plant_model
from .process import Measurement as PlantMeasurement
from .process import advance_plant

#: a progress event at least this often (wall s) while samples complete: the launcher's watchdog takes a
#: silence as a stall (phfdi.ros.launcher); one clock read per sample costs well under a microsecond
PROGRESS_PERIOD_S = 1.0

PARAMS = (
    ParamSpec("pace", 0.0, "0: lock-step as fast as the graph answers; F > 0: F times real time (demos)",
              range=(0.0, 1e6), runtime=True),
    ParamSpec("exit_when_done", True, "end the process after the scenario's last sample"),
    ParamSpec("progress", True, "print progress as JSON lines on stdout (for the launcher)"),
)


class PlantNode(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(PLANT)
        spec, start = self.spec, self.part.start
        load_plugins(spec.plugins)
        model = load_plant_model(self.part.plant_model or spec.plant)  # the part's: read and validated once
        # the plant's own part, at the steady state the launcher computed; valves and controllers live in their nodes
        self.process = build_process(spec, build_plant(model), model, list(start.flows_ml_s), start.outlet_opening)
        assert spec.valves.ph.feed is not None  # the scenario schema requires it
        self.valve_feed: str = spec.valves.ph.feed
        self.n_samples = int(math.floor(spec.duration_s / spec.sample_time_s + 1e-9)) + 1
        self.feed_names = [f.name for f in self.process.plant.feeds]
        self.pub_measurement = self.data_publisher(Measurement, MEASUREMENT.name)
        self.pub_clock = self.data_publisher(Clock, CLOCK.name)
        self.pub_state = self.data_publisher(PlantState, PLANT_STATE.name)
        self.data_subscription(ValveState, VALVE_STATE.name, self._on_valve_state)
        # one message object per topic, refilled each sample (building one costs more than filling it)
        self._measurement_msg, self._clock_msg = Measurement(), Clock()
        self._state_msg = PlantState(feed_names=self.feed_names)
        self.k = -1  # sample waiting for the valves
        self._m: PlantMeasurement | None = None  # its measurement
        self._next_k: int | None = None  # paced mode: sample due at _next_due (wall, monotonic)
        self._next_due = 0.0
        self._pace = self.param("pace")
        self._report_every = max(1, self.n_samples // 20)
        self._last_report = 0.0  # monotonic time of the last progress event
        self.start_barrier()

    def _emit(self, event: str, **fields) -> None:
        if self.param("progress"):
            print(json.dumps({"event": event, **fields}), flush=True)

    def on_connected(self) -> None:
        self._t0 = time.perf_counter()
        self._wall0 = self._last_report = time.monotonic()
        self._emit("connected", samples=self.n_samples, sample_time_s=self.dt_s, scenario=self.spec.name,
                   pace=self._pace, progress_period_s=PROGRESS_PERIOD_S)
        self.get_logger().info(f"graph connected: running {self.n_samples} samples of {self.spec.name}")
        self._schedule(0)

    # ---- one sample ---------------------------------------------------------------
    def _publish_sample(self, k: int) -> None:
        self._m = m = self.process.measure(k * self.dt_s)
        self.k = k
        sec, nanosec = split_ns(k * self.dt_ns)
        msg = self._measurement_msg
        msg.stamp.sec, msg.stamp.nanosec = sec, nanosec
        msg.ph, msg.level_cm = m.ph_measured, m.level_measured_cm
        self.pub_measurement.publish(msg)
        if self.pub_clock.get_subscription_count():  # only nodes with use_sim_time listen
            clock = self._clock_msg
            clock.clock.sec, clock.clock.nanosec = sec, nanosec
            self.pub_clock.publish(clock)

    def _on_valve_state(self, msg: ValveState) -> None:
        # only the sample it waits for (self.k; -1: none, between paced samples); strays counted (GraphNode)
        k = self.next_sample(msg.stamp, "valve state", waiting=self.k >= 0)
        if k is None:
            return
        m = self._m
        assert m is not None  # measured when sample k was published
        flows, outlet_flow = advance_plant(self.process, self.valve_feed, k * self.dt_s, msg.ph_flow_ml_s,
                                           msg.outlet_opening)
        self.k = -1
        done = k + 1 >= self.n_samples
        if not done:
            self._schedule(k + 1)  # the loop goes on while the ground truth of k is published
        state = self._state_msg
        state.stamp = msg.stamp
        state.ph, state.level_cm = m.ph_true, m.level_true_cm
        state.feed_flows_ml_s = flows
        state.outlet_flow_ml_s, state.sensor_fault_severity = outlet_flow, m.sensor_fault_severity
        self.pub_state.publish(state)
        if (k + 1) % self._report_every == 0 or time.monotonic() - self._last_report >= PROGRESS_PERIOD_S:
            self._report(k + 1)
        if done:
            self._finish()

    def _report(self, samples_done: int) -> None:
        self._last_report = time.monotonic()
        self._emit("progress", sample=samples_done, of=self.n_samples, pace=self._pace)

    def _schedule(self, k: int) -> None:
        pace = self._pace
        if pace <= 0.0:
            self._publish_sample(k)
            return
        self._next_k = k
        self._next_due = self._wall0 + k * self.dt_s / pace

    def _finish(self) -> None:
        wall = time.perf_counter() - self._t0
        self.flush_publishers(10.0)
        self._emit("done", samples=self.n_samples, wall_s=wall, simulated_s=(self.n_samples - 1) * self.dt_s)
        self.get_logger().info(f"done: {self.n_samples} samples in {wall:.2f} s")
        if self.param("exit_when_done"):
            self.finished = True

    # ---- paced mode -------------------------------------------------------------------
    def spin_timeout_s(self) -> float:
        if self._next_k is None:
            return 0.1
        return min(0.1, max(0.0, self._next_due - time.monotonic()))

    def after_spin(self) -> None:
        if self._next_k is not None and time.monotonic() >= self._next_due:
            k, self._next_k = self._next_k, None
            self._publish_sample(k)

    def apply_parameters(self, params) -> None:
        for p in params:
            if p.name == "pace":
                self._pace = p.value
            if p.name == "pace" and self.connected:
                # keep the current sample's schedule continuous: restart the wall reference here
                k = self._next_k if self._next_k is not None else max(self.k, 0)
                if p.value > 0:
                    self._wall0 = time.monotonic() - k * self.dt_s / p.value
                elif self._next_k is not None:
                    self._next_k = None
                    self._publish_sample(k)
                self._report(k)  # the launcher's watchdog follows the new pace at once


def run() -> int:
    return main(PlantNode, "ph_plant_sim.node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
