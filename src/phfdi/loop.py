"""The closed loop in one process, composed from the four cores.

One tick k (time t_k = k * dt), the same order the ROS node graph follows:

1. the plant's sensors measure the state at t_k;
2. the controllers compute their outputs for t_k from the measurements;
3. the valves move for the commands of t_k;
4. the plant integrates from t_k to t_k+1 with those flows held.

:func:`build_parts` makes each part from a scenario; the plant, valve and
controller nodes each call it and keep their own part, so the node graph and
:func:`simulate` run the same code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import itemgetter
from typing import Callable, Iterable, Mapping

import numpy as np

from ph_plant_sim.build import build_plant, build_process, load_plant_model, plant_start
from ph_plant_sim.plant import CstrPlant
from ph_plant_sim.process import PlantProcess, advance_plant
from phfdi_base.errors import UserError
from phfdi_base.signals import SIGNALS
from phfdi_base.spec import ScenarioSpec, load_plugins
from pi_controllers.build import build_controllers
from pi_controllers.loops import ControllerBank
from valve_actuator.build import build_valves, check_reachable, start_commands, step_valves
from valve_actuator.valve import Valve

from . import __version__
from .records.record import Record


class RunRecorder:
    """Rows collected one sample at a time, turned into columns at the end."""

    def __init__(self, names: Iterable[str], n_samples: int = 0) -> None:
        self.names = list(names)
        self.rows: list[Mapping[str, float]] = []

    def append(self, row: Mapping[str, float]) -> None:
        self.rows.append(row)

    @property
    def n(self) -> int:
        return len(self.rows)

    def run(self, metadata: dict) -> Record:
        rows = self.rows
        if not rows:
            return Record.of({n: np.zeros(0) for n in self.names}, metadata)
        try:  # every row has every signal (the usual case): one C-level pass
            table = np.array(list(map(itemgetter(*self.names), rows)), dtype=float).reshape(len(rows), -1)
        except KeyError:  # some rows lack a signal: NaN there
            table = np.array([[r.get(n, math.nan) for n in self.names] for r in rows], dtype=float)
        return Record.of({n: table[:, i].copy() for i, n in enumerate(self.names)}, metadata)


# ---- construction -----------------------------------------------------------------
@dataclass
class OperatingPoint:
    """Steady state the loop starts from (at the t=0 setpoints)."""

    valve_command_pct: float
    outlet_command_pct: float
    outlet_opening: float
    flows_ml_s: list[float]


def operating_point(spec: ScenarioSpec, plant: CstrPlant, ph_target: float | None = None) -> OperatingPoint:
    """Valve positions that hold the plant at the pH (default: initial setpoint) and level setpoint."""
    rest = plant_start(spec, plant, ph_target)
    level_controlled = spec.setpoints.level_cm is not None and not plant.tank.overflow
    cmd, outlet_cmd = start_commands(spec, rest, level_controlled)
    return OperatingPoint(cmd, outlet_cmd, rest.outlet_opening, rest.flows_ml_s)


@dataclass
class LoopParts:
    spec: ScenarioSpec
    process: PlantProcess
    valve: Valve
    outlet_valve: Valve | None
    controllers: ControllerBank
    start: OperatingPoint

    @property
    def dt_s(self) -> float:
        return self.spec.sample_time_s

    @property
    def n_samples(self) -> int:
        return int(math.floor(self.spec.duration_s / self.spec.sample_time_s + 1e-9)) + 1


def build_parts(spec: ScenarioSpec) -> LoopParts:
    """Plant, valves and controllers for a scenario, at its initial steady state (each core builds its part)."""
    load_plugins(spec.plugins)
    model = load_plant_model(spec.plant)
    plant = build_plant(model)
    check_reachable(spec, lambda ph: plant_start(spec, plant, ph))
    start = operating_point(spec, plant)
    process = build_process(spec, plant, model, start.flows_ml_s, start.outlet_opening)
    valve, outlet_valve = build_valves(spec, start.valve_command_pct, start.outlet_command_pct)
    bank = build_controllers(spec, start.valve_command_pct, start.outlet_command_pct, plant.ph, plant.level_cm)
    return LoopParts(spec, process, valve, outlet_valve, bank, start)


# ---- running ----------------------------------------------------------------------
def signal_names(parts: LoopParts) -> list[str]:
    names = [s.name for s in SIGNALS]
    i = names.index("outlet_valve_position_pct")
    feeds = [f"{f.name}_flow_ml_s" for f in parts.process.plant.feeds]
    return names[:i] + feeds + names[i:]


def tick(parts: LoopParts, k: int) -> dict[str, float]:
    """One sample of the closed loop; returns the run's row for t_k."""
    t = k * parts.dt_s
    proc = parts.process
    m = proc.measure(t)
    c = parts.controllers.compute(t, m.ph_measured, m.level_measured_cm)
    vs = step_valves(parts.valve, parts.outlet_valve, parts.start.outlet_opening, t,
                     c.ph_output_pct, c.level_output_pct)
    v = vs.valve
    flows, outlet_flow = advance_plant(proc, parts.spec.valves.ph.feed, t, v.flow_ml_s, vs.outlet_opening)
    row = {
        "time_s": t,
        "ph_setpoint": c.ph_setpoint,
        "level_setpoint_cm": c.level_setpoint_cm,
        "ph_controller_output_pct": c.ph_output_pct,
        "level_controller_output_pct": c.level_output_pct,
        "valve_command_pct": c.ph_output_pct,
        "valve_position_pct": v.position_pct,
        "outlet_valve_position_pct": vs.outlet_position_pct,
        "outlet_flow_ml_s": outlet_flow,
        "ph_true": m.ph_true,
        "ph_measured": m.ph_measured,
        "level_true_cm": m.level_true_cm,
        "level_measured_cm": m.level_measured_cm,
        "fault_severity": max(v.fault_severity, m.sensor_fault_severity),
    }
    for f, q in zip(proc.plant.feeds, flows):
        row[f"{f.name}_flow_ml_s"] = q
    return row


def run_metadata(spec: ScenarioSpec, mode: str) -> dict:
    return {
        "scenario": spec.name,
        "mode": mode,
        "seed": spec.seed,
        "sample_time_s": spec.sample_time_s,
        "valve_feed": spec.valves.ph.feed,
        "faults": [f.model_dump() for f in spec.faults],
        "spec": spec.model_dump(mode="json"),
        "producer": f"phfdi {__version__}",
    }


def simulate(spec: ScenarioSpec, progress: Callable[[float], None] | None = None) -> Record:
    """Run a scenario's closed loop in this process."""
    parts = build_parts(spec)
    n = parts.n_samples
    rec = RunRecorder(signal_names(parts), n)
    report_every = max(1, n // 20)
    try:
        for k in range(n):
            rec.append(tick(parts, k))
            if progress is not None and k % report_every == 0:
                progress(k / n)
    except FloatingPointError as exc:
        raise UserError(f"scenario {spec.name}: simulation stopped at t = {k * parts.dt_s:g} s: {exc}") from None
    if progress is not None:
        progress(1.0)
    return rec.run(run_metadata(spec, "closed_loop"))


def _uniform_step(t) -> float:
    """The sample time of a uniform, increasing time base (s); a :class:`UserError` otherwise."""
    if len(t) < 2:
        raise UserError("open-loop inputs need at least two samples")
    dt = float(t[1] - t[0])
    if dt <= 0 or not all(abs(d - dt) <= 1e-6 * dt for d in (t[1:] - t[:-1])):
        raise UserError("open-loop inputs must be uniformly sampled with increasing time_s (resample first)")
    return dt


def _rest_at_first_inputs(parts: LoopParts, valve_cmd: float | None, outlet_cmd: float | None,
                          flows_at: Callable[[int, float], list[float]]) -> None:
    """Valves, plant, sensors and feed lines at rest at the first sample's inputs (None: not recorded)."""
    v0 = parts.valve.reset(valve_cmd) if valve_cmd is not None else None
    o_cmd0 = outlet_cmd if outlet_cmd is not None else parts.start.outlet_command_pct
    o0 = parts.outlet_valve.reset(o_cmd0) if parts.outlet_valve is not None else None
    opening0 = o0.opening if o0 is not None else parts.start.outlet_opening
    q0 = flows_at(0, v0.flow_ml_s if v0 else 0.0)
    parts.process.rest(q0, opening0)


def simulate_open_loop(spec: ScenarioSpec, inputs: Record, start: str = "first_inputs") -> Record:
    """Plant, valves and sensors driven by recorded inputs instead of the controllers.

    ``inputs`` needs ``time_s`` (uniform) and, for the manipulated feed, either
    ``valve_command_pct`` (through the scenario's valve and its faults) or
    ``<feed>_flow_ml_s``. Other feeds take ``<feed>_flow_ml_s`` if present,
    else their schedule. The outlet takes ``level_controller_output_pct`` if
    present, else holds its initial position. The plant starts at the steady
    state of the first sample's inputs (``start="first_inputs"``) or at the
    scenario's own operating point, as the closed loop does (``"scenario"``).
    """
    if start not in ("first_inputs", "scenario"):
        raise UserError(f"open-loop start must be 'first_inputs' or 'scenario', got {start!r}")
    t = inputs.time_s
    dt = _uniform_step(t)
    spec = spec.model_copy(update={"sample_time_s": dt, "duration_s": float(t[-1] - t[0]) or dt})
    parts = build_parts(spec)
    plant = parts.process.plant
    feed = spec.valves.ph.feed
    names = [f.name for f in plant.feeds]
    has_cmd = "valve_command_pct" in inputs
    if not has_cmd and f"{feed}_flow_ml_s" not in inputs:
        raise UserError(f"open-loop inputs need valve_command_pct or {feed}_flow_ml_s")
    outlet_cmd = inputs["level_controller_output_pct"] if "level_controller_output_pct" in inputs else None

    def flows_at(k: int, valve_flow: float) -> list[float]:
        out = []
        for name in names:
            col = f"{name}_flow_ml_s"
            if name == feed and has_cmd:
                out.append(valve_flow)
            elif col in inputs:
                out.append(float(inputs[col][k]))
            else:
                out.append(parts.process.feed_flows(float(t[k] - t[0]), {})[names.index(name)])
        return out

    if start == "first_inputs":
        _rest_at_first_inputs(parts, float(inputs["valve_command_pct"][0]) if has_cmd else None,
                              float(outlet_cmd[0]) if outlet_cmd is not None else None, flows_at)

    rec = RunRecorder(signal_names(parts), len(t))
    for k in range(len(t)):
        tk = float(t[k] - t[0])
        m = parts.process.measure(tk)
        if has_cmd:
            cmd = float(inputs["valve_command_pct"][k])
            v = parts.valve.step(cmd, tk)
            pos, vflow, sev = v.position_pct, v.flow_ml_s, v.fault_severity
        else:
            cmd, pos, vflow, sev = math.nan, math.nan, float(inputs[f"{feed}_flow_ml_s"][k]), 0.0
        if parts.outlet_valve is not None:
            oc = float(outlet_cmd[k]) if outlet_cmd is not None else parts.start.outlet_command_pct
            o = parts.outlet_valve.step(oc, tk)
            opos, opening = o.position_pct, o.opening
        else:
            oc, opos, opening = math.nan, math.nan, parts.start.outlet_opening
        flows = flows_at(k, vflow)
        delivered = parts.process.deliver(flows, tk)
        row = {
            "time_s": float(t[k]), "ph_setpoint": math.nan, "level_setpoint_cm": math.nan,
            "ph_controller_output_pct": cmd, "level_controller_output_pct": oc,
            "valve_command_pct": cmd, "valve_position_pct": pos, "outlet_valve_position_pct": opos,
            "outlet_flow_ml_s": plant.outlet_flow(delivered, opening),
            "ph_true": m.ph_true, "ph_measured": m.ph_measured,
            "level_true_cm": m.level_true_cm, "level_measured_cm": m.level_measured_cm,
            "fault_severity": max(sev, m.sensor_fault_severity),
        }
        for name, q in zip(names, flows):
            row[f"{name}_flow_ml_s"] = q
        rec.append(row)
        try:
            plant.step(delivered, opening, dt)
        except FloatingPointError as exc:
            raise UserError(f"open-loop simulation stopped at t = {t[k]:g} s: {exc}") from None
    return rec.run(run_metadata(spec, "open_loop"))
