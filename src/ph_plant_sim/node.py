"""ROS 2 node of the plant: owns simulated time (thin wrapper of :class:`PlantProcess`).

Each sample k: publish /clock and /plant/measurement for t_k, wait for both
valves' states of sample k, then :func:`phfdi.loop.advance_plant` (the same
call the in-process simulation makes), publish /plant/state for k and go on
with k + 1: as fast as the loop answers (lock-step, ``pace`` 0) or at
``pace`` times real time. Prints JSON lines on stdout for the launcher
(connected, progress, done).

    python -m ph_plant_sim.node --ros-args -p scenario:=paper -p fault:=backlash
"""

from __future__ import annotations

import json
import sys
import time

from phfdi.ros.node import GraphNode, ParamSpec, main, to_time
from phfdi.ros.topics import CLOCK, MEASUREMENT, PLANT, PLANT_STATE, VALVE_OUTLET, VALVE_PH

from phfdi_interfaces.msg import Measurement, PlantState, ValveState
from rosgraph_msgs.msg import Clock

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
        from phfdi.loop import build_parts

        parts = build_parts(self.spec)
        self.process = parts.process  # the plant's own part; valves and controllers live in their nodes
        self.valve_feed = self.spec.valves.ph.feed
        self.n_samples = parts.n_samples
        self.feed_names = [f.name for f in self.process.plant.feeds]
        self.pub_clock = self.data_publisher(Clock, CLOCK.name)
        self.pub_measurement = self.data_publisher(Measurement, MEASUREMENT.name)
        self.pub_state = self.data_publisher(PlantState, PLANT_STATE.name)
        self.data_subscription(ValveState, VALVE_PH.name, self._on_valve_ph)
        self.data_subscription(ValveState, VALVE_OUTLET.name, self._on_valve_outlet)
        self.k = -1  # sample waiting for the valves
        self._m = None  # its measurement
        self._valve_ph: ValveState | None = None
        self._valve_outlet: ValveState | None = None
        self._next_k: int | None = None  # paced mode: sample due at _next_due (wall, monotonic)
        self._next_due = 0.0
        self._report_every = max(1, self.n_samples // 20)
        self.start_barrier()

    def _emit(self, event: str, **fields) -> None:
        if self.param("progress"):
            print(json.dumps({"event": event, **fields}), flush=True)

    def on_connected(self) -> None:
        self._t0 = time.perf_counter()
        self._wall0 = time.monotonic()
        self._emit("connected", samples=self.n_samples, sample_time_s=self.dt_s, scenario=self.spec.name)
        self.get_logger().info(f"graph connected: running {self.n_samples} samples of {self.spec.name}")
        self._schedule(0)

    # ---- one sample ---------------------------------------------------------------
    def _publish_sample(self, k: int) -> None:
        t = k * self.dt_s
        self._m = self.process.measure(t)
        self.k = k
        self._valve_ph = self._valve_outlet = None
        stamp = to_time(k * self.dt_ns)
        self.pub_clock.publish(Clock(clock=stamp))
        msg = Measurement(ph=self._m.ph_measured, level_cm=self._m.level_measured_cm)
        msg.header.stamp = stamp
        self.pub_measurement.publish(msg)

    def _on_valve_ph(self, msg: ValveState) -> None:
        if self._accept(msg):
            self._valve_ph = msg
            self._maybe_advance()

    def _on_valve_outlet(self, msg: ValveState) -> None:
        if self._accept(msg):
            self._valve_outlet = msg
            self._maybe_advance()

    def _accept(self, msg: ValveState) -> bool:
        k = self.sample_of(msg.header.stamp)
        if k != self.k:
            self.get_logger().warning(f"ignored a valve state stamped for sample {k} while at sample {self.k}")
            return False
        return True

    def _maybe_advance(self) -> None:
        if self._valve_ph is None or self._valve_outlet is None:
            return
        from phfdi.loop import advance_plant

        k, m = self.k, self._m
        flows, outlet_flow = advance_plant(self.process, self.valve_feed, k * self.dt_s,
                                           self._valve_ph.flow_ml_s, self._valve_outlet.opening)
        state = PlantState(ph=m.ph_true, level_cm=m.level_true_cm, feed_names=self.feed_names,
                           feed_flows_ml_s=flows, outlet_flow_ml_s=outlet_flow,
                           sensor_fault_severity=m.sensor_fault_severity)
        state.header.stamp = to_time(k * self.dt_ns)
        self.pub_state.publish(state)
        self.k = -1
        if (k + 1) % self._report_every == 0:
            self._emit("progress", sample=k + 1, of=self.n_samples)
        if k + 1 >= self.n_samples:
            self._finish()
        else:
            self._schedule(k + 1)

    def _schedule(self, k: int) -> None:
        pace = self.param("pace")
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
            if p.name == "pace" and self.connected:
                # keep the current sample's schedule continuous: restart the wall reference here
                k = self._next_k if self._next_k is not None else max(self.k, 0)
                if p.value > 0:
                    self._wall0 = time.monotonic() - k * self.dt_s / p.value
                elif self._next_k is not None:
                    self._next_k = None
                    self._publish_sample(k)


def run() -> int:
    return main(PlantNode, "ph_plant_sim.node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
