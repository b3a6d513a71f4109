"""The plant as the rest of the loop sees it: tank, feeds and sensors.

:class:`PlantProcess` is what the plant node wraps and what the in-process
simulation steps: ``measure`` the sample at t_k, then ``advance`` to t_k+1
with the valve flows of sample k.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Mapping

from phfdi_base.blocks import Chain, Injected
from phfdi_base.profiles import Profile

from .contents import InitialContents, add_contents
from .plant import CstrPlant


@dataclass
class Measurement:
    t_s: float
    ph_true: float
    ph_measured: float
    level_true_cm: float
    level_measured_cm: float
    sensor_fault_severity: float = 0.0


@dataclass
class PlantProcess:
    """Tank plus sensors plus the schedule of the feeds no valve manipulates.

    ``feed_schedules`` maps a feed name to its flow profile (mL/s); feeds
    driven by a valve get their flow from :meth:`advance`. Build one from a scenario with
    :func:`ph_plant_sim.build.build_process`.

    Examples
    --------
    >>> from ph_plant_sim import PlantProcess, build_plant, load_plant_model
    >>> plant = build_plant(load_plant_model("paper"))
    >>> plant.set_steady_state([9.82, 2.0, 15.6], 0.427)
    >>> process = PlantProcess(plant, dt_s=1.0)
    >>> m = process.measure(0.0)
    >>> round(m.ph_measured, 1), round(m.level_measured_cm, 1)
    (12.0, 14.0)
    """

    plant: CstrPlant
    ph_sensor: Chain = field(default_factory=Chain)
    level_sensor: Chain = field(default_factory=Chain)
    feed_schedules: dict[str, Profile] = field(default_factory=dict)
    dt_s: float = 1.0
    #: per feed, the blocks between the commanded flow and the vessel (dead time, pump curve, pump lag)
    feed_lines: dict[str, Chain] = field(default_factory=dict)
    #: what the vessel holds at the start besides the steady mix of its feeds (ph_plant_sim.contents)
    contents: InitialContents | None = None

    def rest(self, flows_ml_s: list[float], outlet_opening: float = 1.0) -> None:
        """Put the process at rest at these commanded flows: the vessel at the steady state of what the lines
        deliver, plus its own initial contents; then the sensors and the feed lines at rest."""
        self.plant.set_steady_state(self.steady_delivery(flows_ml_s), outlet_opening)
        if self.contents is not None:
            add_contents(self.plant, self.contents)
        self.reset_sensors()
        self.reset_lines(flows_ml_s)

    def feed_flows(self, t_s: float, valve_flows: Mapping[str, float]) -> list[float]:
        flows = []
        for feed in self.plant.feeds:
            if feed.name in valve_flows:
                flows.append(valve_flows[feed.name])
            elif feed.name in self.feed_schedules:
                flows.append(self.feed_schedules[feed.name].value(t_s))
            else:
                flows.append(feed.flow_ml_s)
        return flows

    def reset_lines(self, flows_ml_s: list[float]) -> None:
        """Put every feed line at rest, passing the given commanded flows."""
        for feed, q in zip(self.plant.feeds, flows_ml_s):
            if feed.name in self.feed_lines:
                self.feed_lines[feed.name].reset(q)

    def steady_delivery(self, flows_ml_s: list[float]) -> list[float]:
        """Flows a line delivers after resting at constant commanded flows (its static map: the pump curve)."""
        if not self.feed_lines:
            return list(flows_ml_s)
        out = []
        for feed, q in zip(self.plant.feeds, flows_ml_s):
            line = self.feed_lines.get(feed.name)
            if line is None:
                out.append(q)
                continue
            probe = copy.deepcopy(line)
            probe.reset(q)
            out.append(max(0.0, probe.step(q, 0.0)))
        return out

    def deliver(self, flows_ml_s: list[float], t_s: float) -> list[float]:
        """Commanded flows -> flows entering the vessel, through each feed's line (call once per sample)."""
        if not self.feed_lines:
            return list(flows_ml_s)
        out = []
        for feed, q in zip(self.plant.feeds, flows_ml_s):
            line = self.feed_lines.get(feed.name)
            out.append(max(0.0, line.step(q, t_s)) if line is not None else q)
        return out

    def __post_init__(self) -> None:
        self._sensor_faults = [b for b in self.ph_sensor.blocks + self.level_sensor.blocks if isinstance(b, Injected)]

    def reset_sensors(self) -> None:
        self.ph_sensor.reset(self.plant.ph)
        self.level_sensor.reset(self.plant.level_cm)

    def measure(self, t_s: float) -> Measurement:
        """Sample the sensors at t_s (call exactly once per sample)."""
        ph = self.plant.ph
        level = self.plant.level_cm
        sev = max(b.severity_at(t_s) for b in self._sensor_faults) if self._sensor_faults else 0.0
        return Measurement(t_s, ph, self.ph_sensor.step(ph, t_s), level,
                           self.level_sensor.step(level, t_s), sev)

    def advance(self, t_s: float, valve_flows: Mapping[str, float], outlet_opening: float) -> list[float]:
        """Integrate from t_s to t_s + dt_s; returns the commanded feed flows (mL/s)."""
        flows = self.feed_flows(t_s, valve_flows)
        self.plant.step(self.deliver(flows, t_s), outlet_opening, self.dt_s)
        return flows


def advance_plant(process: PlantProcess, valve_feed: str, t_s: float, valve_flow_ml_s: float,
                  outlet_opening: float) -> tuple[list[float], float]:
    """Plant side of a tick: feed flows and outlet flow of t_s, then integrate to t_s + dt.

    Returns (commanded feed flows in plant feed order, outlet flow), both mL/s,
    as they were during the sample: the feeds' line blocks (dead time, pump
    curve) lie between the commanded flow and the vessel, and a run records
    the commanded flow, as a pump's historian does. The in-process loop and the plant node call this.

    Parameters
    ----------
    process : PlantProcess
        The plant with its sensors and feed schedules.
    valve_feed : str
        The feed the pH valve drives.
    t_s : float
        Time of the sample (s).
    valve_flow_ml_s : float
        The valve's flow during the sample (mL/s).
    outlet_opening : float
        Fraction of full outlet flow during the sample.

    Examples
    --------
    >>> from ph_plant_sim import PlantProcess, advance_plant, build_plant, load_plant_model
    >>> plant = build_plant(load_plant_model("paper"))
    >>> plant.set_steady_state([9.82, 2.0, 15.6], 0.427)
    >>> flows, outlet_ml_s = advance_plant(PlantProcess(plant), "acid", 0.0, 11.8, 0.427)
    >>> flows, round(outlet_ml_s, 1)
    ([11.8, 2.0, 15.6], 27.4)
    """
    flows = process.feed_flows(t_s, {valve_feed: valve_flow_ml_s})
    delivered = process.deliver(flows, t_s)
    outlet_flow = process.plant.outlet_flow(delivered, outlet_opening)
    process.plant.step(delivered, outlet_opening, process.dt_s)
    return flows, outlet_flow
