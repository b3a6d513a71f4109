"""Healthy reference model: the core plant and a healthy valve driven by measured inputs.

Analytical redundancy: the plant of the scenario (:class:`ph_plant_sim.plant.CstrPlant`,
built by the plant and valve cores' factories with the faults removed) is driven by

* the measured pH controller output through a *healthy* copy of the
  scenario's valve (:class:`valve_actuator.valve.Valve`, no fault blocks;
  non-finite commands hold the last position, as the core valve does);
* the measured level controller output through the outlet valve;
* the other feeds' flows: measured if given, else the scenario's schedules;

and predicts the pH and level the sensors should read. Residual = measured -
predicted. The model starts at the steady state of the first inputs, with the
volume taken from the measured level. Why the prediction stays trustworthy:
the open-loop tank forgets its initial state (composition with the dilution
time constant V/Q, about 110 s on the paper plant; level with about 320 s),
so a wrong start or an upset (a setpoint change, a fault that later clears)
fades out. A slow observer (:meth:`HealthyReference.correct`) removes
persistent model-plant mismatch; the detector applies it at fixed block
boundaries and freezes it while an alarm is active.

Samples are advanced in segments with :meth:`CstrPlant.simulate_flows` (the
same arithmetic as ``step``). Its pH solve starts from a guess; the detector
passes a guess fixed per block of samples, so each sample's prediction does
not depend on how the record was chunked.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ph_plant_sim.build import build_plant, build_process, load_plant_model, plant_start
from ph_plant_sim.plant import CstrPlant
from ph_plant_sim.process import PlantProcess
from phfdi_base.blocks import Chain
from phfdi_base.spec_tools import load_plugins
from valve_actuator.build import build_valves, check_reachable, start_commands
from valve_actuator.valve import Valve

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario
    from phfdi_base.spec import PlantModelSpec, ScenarioSpec

RESTART_LEVEL_CM = 1.0


@dataclass
class ReferenceState:
    """What isolation needs to re-run the reference from a past sample."""

    volume_ml: float
    amounts_mmol: tuple[float, ...]
    valve_command_pct: float  # last finite command (held on non-finite ones)
    outlet_command_pct: float


@dataclass
class Prediction:
    """Model outputs at each sample and the inputs that produced them."""

    ph: np.ndarray
    level_cm: np.ndarray
    flows: np.ndarray  # (N, n_feeds) mL/s
    openings: np.ndarray  # outlet opening, fraction of full flow


def healthy_spec(spec: ScenarioSpec) -> ScenarioSpec:
    """The scenario without its faults: what the reference model knows."""
    return spec.model_copy(update={"faults": []})


@dataclass
class StartPoint:
    """The loop's starting steady state (at the t=0 setpoints), as the in-process loop starts."""

    valve_command_pct: float
    outlet_command_pct: float
    outlet_opening: float
    flows_ml_s: list[float]


@dataclass
class KnownStart:
    """What the launcher already computed for this scenario (a node's :class:`phfdi_base.parts.NodePart`):
    the loop's starting steady state (at the t=0 setpoints, the same with or without the scenario's faults)
    and its plant model. With it the reference neither re-solves the steady state (nor imports the root
    finder that needs) nor reads the plant-model file: a detector node starts about 0.4 s of CPU sooner."""

    start: StartPoint  # or any object with the same four fields (phfdi_base.parts.LoopStart)
    plant_model: PlantModelSpec | None = None  # a validated plant model (or its view); None: the scenario's ``plant``


def _healthy_parts(spec: ScenarioSpec, known: KnownStart | None = None
                   ) -> tuple[PlantProcess, Valve | None, StartPoint]:
    """The plant (with its schedules) and the outlet valve of a scenario at its starting steady state, built by
    the plant and valve cores as the in-process loop builds them (same checks, same start)."""
    load_plugins(spec.plugins)
    model = load_plant_model(known.plant_model if known is not None and known.plant_model is not None
                             else spec.plant)
    plant = build_plant(model)
    if known is None:
        check_reachable(spec, lambda ph: plant_start(spec, plant, ph))
        rest = plant_start(spec, plant)
        level_controlled = spec.setpoints.level_cm is not None and not plant.tank.overflow
        cmd, outlet_cmd = start_commands(spec, rest, level_controlled)
        start = StartPoint(cmd, outlet_cmd, rest.outlet_opening, rest.flows_ml_s)
    else:  # checked and solved where the scenario was resolved
        k = known.start
        start = StartPoint(k.valve_command_pct, k.outlet_command_pct, k.outlet_opening, list(k.flows_ml_s))
    process = build_process(spec, plant, model, start.flows_ml_s, start.outlet_opening)
    _, outlet_valve = build_valves(spec, start.valve_command_pct, start.outlet_command_pct)
    return process, outlet_valve, start


class HealthyReference:
    """The healthy loop's plant and valves, stepped on measured inputs."""

    def __init__(self, spec: ScenarioSpec, known: KnownStart | None = None) -> None:
        """``known``: the starting point and plant model already computed for ``spec`` (a node's part)."""
        self.spec = healthy_spec(spec)
        self.process, self.outlet_valve, self.start = _healthy_parts(self.spec, known)
        self.plant: CstrPlant = self.process.plant
        self.dt_s = self.spec.sample_time_s
        vspec = self.spec.valves.ph
        # the scenario schema requires both for the pH valve (phfdi_base.spec.ScenarioSpec)
        assert vspec.feed is not None and vspec.max_flow_ml_s is not None
        self.valve_feed = vspec.feed
        self.feed_names = [f.name for f in self.plant.feeds]
        self.valve_index = self.feed_names.index(vspec.feed)
        self.valve = Valve(vspec.max_flow_ml_s, vspec.characteristic, vspec.rangeability)
        self.valve_spec = vspec
        self.has_level = not self.plant.tank.overflow
        self._last_cmd = self.start.valve_command_pct
        self._last_outlet_cmd = self.start.outlet_command_pct
        self._correction_index = self._strong_component()
        self.resets = 0

    # ---- construction helpers ----------------------------------------------------
    def _strong_component(self) -> int | None:
        """Strong (non-buffering) component carried by the valve's feed: where the observer corrects."""
        comps = self.plant.chemistry.components
        conc = self.plant.feed_conc[self.valve_index]
        best, best_c = None, 0.0
        for i, c in enumerate(comps):
            if not c.pka and c.charge != 0 and conc[i] > best_c:
                best, best_c = i, conc[i]
        if best is None:
            for i, c in enumerate(comps):
                if not c.pka and c.charge != 0:
                    return i
        return best

    def new_valve(self, position_blocks=None) -> Valve:
        """A valve like the reference's, optionally with position blocks (isolation hypotheses)."""
        v = self.valve_spec
        assert v.max_flow_ml_s is not None  # checked in __init__
        return Valve(v.max_flow_ml_s, v.characteristic, v.rangeability, position_blocks or Chain())

    # ---- state -------------------------------------------------------------------
    def initialize(self, t_s: float, valve_command_pct: float, outlet_command_pct: float,
                   level_cm: float, other_flows: dict[str, float] | None = None, ph: float = math.nan) -> None:
        """Steady state of these inputs, then re-aligned on the measured pH and level (:meth:`realign`)."""
        cmd = valve_command_pct if math.isfinite(valve_command_pct) else self._last_cmd
        self._last_cmd = cmd
        q = self.valve.reset(cmd).flow_ml_s
        ocmd = outlet_command_pct if math.isfinite(outlet_command_pct) else self._last_outlet_cmd
        self._last_outlet_cmd = ocmd
        opening = self.outlet_valve.reset(ocmd).opening if self.outlet_valve is not None else self.start.outlet_opening
        flows = self._flows_at(t_s, q, other_flows)
        if sum(flows) <= 0.0:
            flows = list(self.start.flows_ml_s)
        self._restart_low(np.asarray(flows, dtype=float), opening)
        self.realign(ph, level_cm)

    def realign(self, ph: float, level_cm: float) -> None:
        """Put the state on the measured pH (strong-ion balance) and level (volume), where they are usable.

        Used when the model's state cannot be trusted: at a start (the plant
        need not be at the steady state of its first inputs) and, through
        :meth:`initialize`, after the valve command was missing (the valve
        moved unseen). The third direction of the composition (the buffer's
        total) is left to fade with the dilution time constant during the
        warm-up, which is why a restart starts from the steady state of the
        returned command rather than from the held command's state.
        """
        if self.has_level and math.isfinite(level_cm) and level_cm > 0.0:
            self.correct(0.0, level_cm - self.plant.level_cm)
        if math.isfinite(ph) and 0.0 <= ph <= 14.0:
            self.correct(ph - self.ph, 0.0)

    def _flows_at(self, t_s: float, valve_flow: float, other: dict[str, float] | None) -> list[float]:
        flows = self.process.feed_flows(t_s, {self.valve_feed: valve_flow})
        if other:
            for i, name in enumerate(self.feed_names):
                v = other.get(name)
                if i != self.valve_index and v is not None and math.isfinite(v) and v >= 0.0:
                    flows[i] = v
        return flows

    def snapshot(self) -> ReferenceState:
        s = self.plant.state
        return ReferenceState(s.volume_ml, tuple(s.amounts_mmol), self._last_cmd, self._last_outlet_cmd)

    def restore(self, snap: ReferenceState) -> None:
        s = self.plant.state
        s.volume_ml = snap.volume_ml
        s.amounts_mmol = list(snap.amounts_mmol)
        self._last_cmd = snap.valve_command_pct
        self._last_outlet_cmd = snap.outlet_command_pct
        self.valve.reset(snap.valve_command_pct)
        if self.outlet_valve is not None:
            self.outlet_valve.reset(snap.outlet_command_pct)

    # ---- inputs -> flows ----------------------------------------------------------
    def feed_matrix(self, t_s: np.ndarray, valve_flow: np.ndarray,
                    other_flows: dict[str, np.ndarray] | None = None) -> np.ndarray:
        """(N, n_feeds) feed flows: the valve's flow plus the other feeds (measured or scheduled)."""
        n = len(t_s)
        flows = np.empty((n, len(self.feed_names)))
        for i, name in enumerate(self.feed_names):
            if i == self.valve_index:
                flows[:, i] = valve_flow
                continue
            sched = self.process.feed_schedules.get(name)
            if sched is None:
                col = np.full(n, self.plant.feeds[i].flow_ml_s)
            elif not sched.changes:
                col = np.full(n, sched.initial)
            else:
                col = np.array([sched.value(float(t)) for t in t_s])
            meas = None if other_flows is None else other_flows.get(name)
            if meas is not None:
                ok = np.isfinite(meas) & (meas >= 0.0)
                col = np.where(ok, meas, col)
            flows[:, i] = col
        return flows

    def valve_flows(self, valve: Valve, commands: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        return valve.step_many(commands, t_s).flow_ml_s

    def openings(self, outlet_commands: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        if self.outlet_valve is None:
            return np.full(len(t_s), self.start.outlet_opening)
        return self.outlet_valve.step_many(outlet_commands, t_s).opening

    # ---- prediction -----------------------------------------------------------------
    def advance(self, t_s: np.ndarray, commands: np.ndarray, outlet_commands: np.ndarray,
                ph_guess: float, other_flows: dict[str, np.ndarray] | None = None) -> Prediction:
        """Predicted pH and level at each sample's time, then move the state past the samples.

        The prediction of sample k is the model state at t_k (the sensors read
        the tank before sample k's inputs act), so it depends only on inputs
        before k.
        """
        valve_flow = self.valve_flows(self.valve, commands, t_s)
        fin = np.isfinite(commands)
        if fin.any():
            self._last_cmd = float(commands[fin][-1])
        ofin = np.isfinite(outlet_commands)
        if ofin.any():
            self._last_outlet_cmd = float(outlet_commands[ofin][-1])
        flows = self.feed_matrix(t_s, valve_flow, other_flows)
        openings = np.maximum(self.openings(outlet_commands, t_s), 0.0)
        return self.run_flows(flows, openings, ph_guess)

    def run_flows(self, flows: np.ndarray, openings: np.ndarray, ph_guess: float) -> Prediction:
        """Advance the plant through held flows; NaN predictions if the tank runs dry (then restarted)."""
        plant = self.plant
        plant.state.ph = ph_guess  # the pH solve's starting point, fixed per block by the caller
        n = len(flows)
        try:
            out = plant.simulate_flows(flows, openings, self.dt_s)
        except (FloatingPointError, ValueError, OverflowError, ZeroDivisionError):
            # the tank ran dry (or inputs drove the state out of range): the model cannot follow;
            # restart it near empty
            self.resets += 1
            self._restart_low(flows[-1], float(openings[-1]))
            return Prediction(np.full(n, np.nan), np.full(n, np.nan), flows, openings)
        return Prediction(out["ph"][:n], out["level_cm"][:n], flows, openings)

    def _restart_low(self, flows: np.ndarray, opening: float) -> None:
        q = flows if flows.sum() > 0.0 else np.asarray(self.start.flows_ml_s)
        try:
            self.plant.set_steady_state(list(q), max(opening, 1e-6))
        except ValueError:  # its steady level would be below the outlet: keep a little liquid
            self.plant.set_state(self.plant.mixed_inflow(list(q)), RESTART_LEVEL_CM)

    @property
    def ph(self) -> float:
        return self.plant.balance.ph(self.plant.concentrations, guess=7.0)

    # ---- observer ---------------------------------------------------------------------
    def correct(self, ph_error: float, level_error_cm: float) -> None:
        """Move the state so its pH rises by ``ph_error`` and its level by ``level_error_cm``.

        The pH correction shifts the strong-ion balance through the valve
        feed's strong component by -(df/dpH) dpH (f: the charge balance), the
        level correction scales the volume at constant composition.
        """
        plant = self.plant
        s = plant.state
        if self.has_level and math.isfinite(level_error_cm) and level_error_cm != 0.0:
            new_v = max(s.volume_ml + level_error_cm * plant.tank.area_cm2, 1e-3 * s.volume_ml)
            scale = new_v / s.volume_ml
            s.amounts_mmol = [n * scale for n in s.amounts_mmol]
            s.volume_ml = new_v
        i = self._correction_index
        if i is None or not math.isfinite(ph_error) or ph_error == 0.0:
            return
        conc = plant.concentrations
        ph_now = plant.balance.ph(conc, guess=7.0)
        _, dfdph = plant.balance.residual(ph_now, conc)
        d_strong = -dfdph * ph_error  # mol/L of charge
        z = plant.chemistry.components[i].charge
        dn = d_strong / z * s.volume_ml
        s.amounts_mmol[i] = max(s.amounts_mmol[i] + dn, 0.0)
