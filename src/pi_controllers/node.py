"""ROS 2 node of the pH and level PI loops (thin wrapper of :class:`ControllerBank`).

On /plant/measurement of sample k it calls ``ControllerBank.compute`` (the
same call the in-process simulation makes) and answers with
/controller/output stamped k. Tuning can be
changed while running (bumpless).

    python -m pi_controllers.node --ros-args -p scenario:=paper -p ph_kp:=4.0
"""

from __future__ import annotations

import sys

from phfdi_interfaces.msg import ControllerOutput, Measurement

from phfdi_base.ros.graph_node import GraphNode, ParamSpec, main
from phfdi_base.topics import CONTROLLER, CONTROLLERS, MEASUREMENT
from pi_controllers.build import build_controllers

KP_RANGE = (1e-3, 1e4)  # % of span per unit of the process value
TI_RANGE = (1e-2, 1e6)  # s


def _level(spec, key: str) -> float:
    level = spec.controllers.level
    return getattr(level, key) if level is not None else 1.0


PARAMS = (
    ParamSpec("ph_kp", lambda s: s.controllers.ph.kp, "pH loop proportional gain (% per pH)", range=KP_RANGE,
              runtime=True),
    ParamSpec("ph_ti_s", lambda s: s.controllers.ph.ti_s, "pH loop integral time (s)", range=TI_RANGE,
              runtime=True),
    ParamSpec("level_kp", lambda s: _level(s, "kp"), "level loop proportional gain (% per cm)", range=KP_RANGE,
              runtime=True),
    ParamSpec("level_ti_s", lambda s: _level(s, "ti_s"), "level loop integral time (s)", range=TI_RANGE,
              runtime=True),
)


class ControllersNode(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(CONTROLLERS)
        start = self.part.start  # the controllers' own part only, bumpless at the launcher's steady state
        self.bank = build_controllers(self.spec, start.valve_command_pct, start.outlet_command_pct, start.ph,
                                      start.level_cm)
        self._apply_tuning()
        self.pub_output = self.data_publisher(ControllerOutput, CONTROLLER.name)
        self.data_subscription(Measurement, MEASUREMENT.name, self._on_measurement)
        self._output = ControllerOutput()  # refilled each sample
        self.start_barrier()

    def _apply_tuning(self) -> None:
        """Launch or runtime tuning that differs from the controllers' current one (bumpless)."""
        ph = self.bank.ph
        if (self.param("ph_kp"), self.param("ph_ti_s")) != (ph.kp, ph.ti_s):
            ph.set_tuning(kp=self.param("ph_kp"), ti_s=self.param("ph_ti_s"))
        level = self.bank.level
        if level is not None and (self.param("level_kp"), self.param("level_ti_s")) != (level.kp, level.ti_s):
            level.set_tuning(kp=self.param("level_kp"), ti_s=self.param("level_ti_s"))

    def check_parameters(self, params) -> str | None:
        if self.bank.level is None and any(p.name.startswith("level_") for p in params):
            return f"scenario {self.spec.name} has no level controller"
        return None

    def apply_parameters(self, params) -> None:
        self._apply_tuning()
        self.get_logger().info("tuning now: " + ", ".join(f"{p.name} = {p.value:g}" for p in params))

    def _on_measurement(self, msg: Measurement) -> None:
        k = self.next_sample(msg.stamp, "measurement")
        if k is None:
            return
        bank = self.bank
        c = bank.compute(k * self.dt_s, msg.ph, msg.level_cm)
        out = self._output
        out.stamp = msg.stamp
        out.ph_setpoint, out.ph_output_pct, out.ph_manual = c.ph_setpoint, c.ph_output_pct, bank.ph.manual
        out.level_setpoint_cm, out.level_output_pct = c.level_setpoint_cm, c.level_output_pct
        out.level_manual = bank.level.manual if bank.level is not None else False
        self.pub_output.publish(out)


def run() -> int:
    return main(ControllersNode, "pi_controllers.node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
