"""ROS 2 node of the loop's valves (thin wrapper of :class:`Valve`): the pH valve and the outlet valve.

On /controller/output of sample k it calls :func:`valve_actuator.build.step_valves`
(the same call the in-process simulation makes) and answers with
/valve/state stamped k.

Bad commands never crash it: a command that is not finite, or outside
[command_min_pct, command_max_pct] (default -2.5..106.25 %, the NAMUR NE 43
failure limits of a 4-20 mA signal), is not applied; the valve holds its last
position, counts it and reports it on /diagnostics.

Faults: ``fault`` / ``fault_onset_s`` at launch, and changed at runtime by a
parameter set (bumpless: the new fault blocks start from the current stem
position).

    python -m valve_actuator.node --ros-args -p scenario:=paper -p fault:=stiction
"""

from __future__ import annotations

import math
import sys

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from phfdi_interfaces.msg import ControllerOutput, ValveState

from phfdi_base.ros.graph_node import GraphNode, ParamSpec, main
from phfdi_base.spec_tools import load_plugins
from phfdi_base.topics import CONTROLLER, VALVE, VALVE_STATE

from .build import build_valves, step_valves

#: fault sites this node owns (sensor faults belong to the plant node)
VALVE_SITES = ("valve", "valve_flow", "outlet_valve", "outlet_valve_flow")

PARAMS = (
    ParamSpec("command_min_pct", -2.5, "commands below this are rejected and the valve holds (% of span)",
              range=(-100.0, 0.0), runtime=True),
    ParamSpec("command_max_pct", 106.25, "commands above this are rejected and the valve holds (% of span)",
              range=(100.0, 200.0), runtime=True),
    ParamSpec("diagnostics_period_s", 60.0, "publish /diagnostics every this many s of simulated time "
                                            "(and whenever a command is rejected); 0: only then",
              range=(0.0, 1e9), runtime=True),
)


class _Held:
    """Counts of commands one valve did not apply."""

    def __init__(self) -> None:
        self.not_finite = 0
        self.out_of_range = 0
        self.last_rejected = math.nan

    @property
    def total(self) -> int:
        return self.not_finite + self.out_of_range


class ValveNode(GraphNode):
    PARAMS = PARAMS
    RUNTIME_COMMON = ("fault", "fault_onset_s")

    def __init__(self) -> None:
        super().__init__(VALVE)
        self._install_valves(self._build_valves(self.spec))
        self.held = {"ph": _Held(), "outlet": _Held()}
        self.pub_state = self.data_publisher(ValveState, VALVE_STATE.name)
        self.pub_diag = self.diagnostics_publisher()  # shared with the input-stamp counts (GraphNode)
        self.data_subscription(ControllerOutput, CONTROLLER.name, self._on_output)
        self._state = ValveState()  # refilled each sample
        self._last_report_k: int | None = None
        self._reported_total = 0
        self._pending_change = None
        self._read_limits()
        self.start_barrier()

    def _read_limits(self) -> None:
        """Parameters used every sample, read once per change."""
        self._command_min, self._command_max = self.param("command_min_pct"), self.param("command_max_pct")
        self._diagnostics_period_s = self.param("diagnostics_period_s")

    # ---- valves from the scenario ---------------------------------------------------------
    def _build_valves(self, spec, runtime: bool = False):
        for f in spec.faults if runtime else ():
            if f.where not in VALVE_SITES:  # the plant node owns sensor faults, fixed at launch
                raise ValueError(f"fault {f.type} acts on the {f.where.replace('_', ' ')}, not on a valve: "
                                 f"set it on the plant node at launch")
        load_plugins(spec.plugins)
        start = self.part.start  # the steady state the launcher computed (faults do not move it)
        valve, outlet_valve = build_valves(spec, start.valve_command_pct, start.outlet_command_pct)
        return spec, valve, outlet_valve, start

    def _install_valves(self, built) -> None:
        spec, self.valve, self.outlet_valve, start = built
        self.fixed_outlet_opening = start.outlet_opening
        if not hasattr(self, "position"):  # stem positions (%) the valves rest at before sample 0
            self.position = {"ph": min(max(start.valve_command_pct, 0.0), 100.0),
                             "outlet": min(max(start.outlet_command_pct, 0.0), 100.0)}
        self.faults = [f"{f.type}@{f.where} from {f.onset_s:g} s" for f in spec.faults] or ["none"]

    def check_parameters(self, params) -> str | None:
        self._pending_change = None
        names = {p.name for p in params}
        if not names & {"fault", "fault_onset_s"}:
            return None
        value = {p.name: p.value for p in params}
        fault = value.get("fault", self.param("fault")) or None
        onset = value.get("fault_onset_s", self.param("fault_onset_s"))
        try:
            from phfdi_base.spec import resolve_scenario  # the schema only on a runtime fault change

            spec = resolve_scenario(self.part.raw_scenario, fault, self.part.fault_library,
                                    list(self.param("overrides")), None if onset < 0 else onset,
                                    source=f"scenario {self.param('scenario')}")
            self._pending_change = self._build_valves(spec, runtime=True)
        except Exception as exc:  # noqa: BLE001 - UserError or ValueError: the reason goes back to the caller
            return str(exc)
        return None

    def apply_parameters(self, params) -> None:
        self._read_limits()
        if self._pending_change is None:
            return
        old = {"ph": self.valve, "outlet": self.outlet_valve}
        self._install_valves(self._pending_change)
        self._pending_change = None
        # bumpless: the new fault blocks start at rest at the current stem positions
        for key, new in (("ph", self.valve), ("outlet", self.outlet_valve)):
            if new is not None and old[key] is not None:
                new.reset(self.position[key])
                new.rejected_commands = old[key].rejected_commands
        self.get_logger().info("valve faults now: " + "; ".join(self.faults))
        self._report(self._last_k, force=True)

    # ---- one sample -------------------------------------------------------------------
    def _admit(self, which: str, command_pct: float) -> float:
        """The command to apply, or NaN (the core Valve then holds and counts it)."""
        if math.isfinite(command_pct) and \
                self._command_min <= command_pct <= self._command_max:
            return command_pct
        held = self.held[which]
        if math.isfinite(command_pct):
            held.out_of_range += 1
        else:
            held.not_finite += 1
        held.last_rejected = command_pct
        return math.nan

    def _on_output(self, out: ControllerOutput) -> None:
        k = self.next_sample(out.stamp, "command")
        if k is None:
            return
        ph_cmd = self._admit("ph", out.ph_output_pct)
        level_cmd = out.level_output_pct
        if self.outlet_valve is not None:
            level_cmd = self._admit("outlet", level_cmd)
        vs = step_valves(self.valve, self.outlet_valve, self.fixed_outlet_opening, k * self.dt_s, ph_cmd, level_cmd)
        v, o = vs.valve, vs.outlet
        self.position["ph"], self.position["outlet"] = v.position_pct, vs.outlet_position_pct
        msg = self._state
        msg.stamp = out.stamp
        msg.ph_command_pct, msg.ph_position_pct, msg.ph_opening = out.ph_output_pct, v.position_pct, v.opening
        msg.ph_flow_ml_s, msg.ph_fault_severity = v.flow_ml_s, v.fault_severity
        msg.ph_rejected_commands = self.valve.rejected_commands
        msg.outlet_command_pct, msg.outlet_position_pct = out.level_output_pct, vs.outlet_position_pct
        msg.outlet_opening = vs.outlet_opening
        # no outlet valve in the scenario: the outlet stays at its fixed opening
        msg.outlet_fault_severity = o.fault_severity if o is not None else 0.0
        msg.outlet_rejected_commands = self.outlet_valve.rejected_commands if o is not None else 0
        self.pub_state.publish(msg)
        self._report(k)

    # ---- diagnostics -------------------------------------------------------------------
    def _report(self, k: int, force: bool = False) -> None:
        total = self.held["ph"].total + self.held["outlet"].total
        period = self._diagnostics_period_s
        due = (self._last_report_k is None
               or (period > 0 and (k - self._last_report_k) * self.dt_s >= period))
        if not (force or due or total != self._reported_total):
            return
        array = DiagnosticArray()
        array.header.stamp = self.stamp(max(k, 0))
        for which, valve in (("ph", self.valve), ("outlet", self.outlet_valve)):
            if valve is None:
                continue
            held = self.held[which]
            new = held.total > 0 and total != self._reported_total
            status = DiagnosticStatus(
                level=DiagnosticStatus.WARN if new else DiagnosticStatus.OK,
                name=f"{self.get_name()}: {which} valve", hardware_id=f"{which}_valve",
                message=(f"{held.total} command(s) held so far ({held.not_finite} not finite, "
                         f"{held.out_of_range} out of range)" if held.total else "commands applied"),
                values=[KeyValue(key="commands_held", value=str(held.total)),
                        KeyValue(key="not_finite", value=str(held.not_finite)),
                        KeyValue(key="out_of_range", value=str(held.out_of_range)),
                        KeyValue(key="last_rejected_command_pct", value=repr(held.last_rejected)),
                        KeyValue(key="position_pct", value=repr(self.position[which])),
                        KeyValue(key="faults", value="; ".join(self.faults) if which == "ph" else "")])
            array.status.append(status)
        self.pub_diag.publish(array)
        self._last_report_k = k
        self._reported_total = total


def run() -> int:
    return main(ValveNode, "valve_actuator.node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
