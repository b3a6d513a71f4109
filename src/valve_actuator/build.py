"""The valves' part of a scenario: the pH loop's valve and the outlet valve with their injected faults.

A factory from the validated scenario (:class:`phfdi_base.spec.ScenarioSpec`)
used alike by the in-process loop, the valve node and the detector's
reference model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

from phfdi_base.blocks import Chain
from phfdi_base.errors import UserError
from phfdi_base.spec_tools import injected_faults, profile

from .blocks import flow_blocks
from .valve import Valve, ValveOutput

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario (a node's start-up)
    from phfdi_base.spec import ScenarioSpec, ValveSpec

__all__ = ["ValveStep", "build_valve", "build_valves", "check_reachable", "position_for_opening", "start_commands",
           "step_valves"]


def position_for_opening(opening: float, valve: ValveSpec) -> float:
    """Inverse inherent characteristic: stem position (%) giving a flow fraction.

    Parameters
    ----------
    opening : float
        Fraction of maximum flow, in (0, 1].
    valve : ValveSpec
        The valve's characteristic and rangeability.

    Examples
    --------
    >>> from phfdi_base.spec import ValveSpec
    >>> from valve_actuator import position_for_opening
    >>> position_for_opening(0.5, ValveSpec(characteristic="linear"))
    50.0
    >>> position_for_opening(1.0, ValveSpec(characteristic="equal_percentage"))
    100.0
    """
    if valve.characteristic == "linear":
        return 100.0 * opening
    return 100.0 * (1.0 + math.log(opening) / math.log(valve.rangeability))


class FlowsAtRest(Protocol):
    """What the plant says about a steady state (:class:`ph_plant_sim.build.PlantStart`); read only."""

    @property
    def flows_ml_s(self) -> Sequence[float]: ...  # every feed, plant feed order
    @property
    def valve_feed_index(self) -> int: ...  # the feed the pH valve drives
    @property
    def outlet_opening(self) -> float: ...  # fraction of full outlet flow at rest


def start_commands(spec: ScenarioSpec, rest: FlowsAtRest, level_controlled: bool) -> tuple[float, float]:
    """Stem commands (%) of the pH valve and the outlet valve that give the plant's flows at rest.

    ``level_controlled``: the outlet valve holds a level (else it stays fully open, 100 %).
    """
    max_flow = spec.valves.ph.max_flow_ml_s
    assert max_flow is not None  # the scenario schema requires it for the pH valve
    cmd = position_for_opening(rest.flows_ml_s[rest.valve_feed_index] / max_flow, spec.valves.ph)
    outlet = spec.valves.outlet
    outlet_cmd = position_for_opening(rest.outlet_opening, outlet) if level_controlled and outlet else 100.0
    return cmd, outlet_cmd


def check_reachable(spec: ScenarioSpec, rest_at: Callable[[float], FlowsAtRest]) -> None:
    """Every pH setpoint must be reachable by the healthy valve within the scenario's margin.

    ``rest_at(ph)``: the plant's steady state at that pH (:func:`ph_plant_sim.build.plant_start`).
    """
    margin = spec.min_actuator_margin_pct
    for value in profile(spec.setpoints.ph).values():
        cmd, _ = start_commands(spec, rest_at(value), False)
        if not margin <= cmd <= 100.0 - margin:
            raise UserError(f"setpoints.ph: pH {value} needs the valve at {cmd:.1f} %, "
                            f"outside the reachable range {margin:.0f}..{100 - margin:.0f} %")


def build_valve(vspec: ValveSpec, spec: ScenarioSpec, site: str, command_pct: float | None = None) -> Valve:
    """One valve with the scenario's faults at ``site`` (stem) and ``site_flow`` (flow), at rest at a command
    (if one is given).

    Parameters
    ----------
    vspec : ValveSpec
        The valve (maximum flow, characteristic).
    spec : ScenarioSpec
        The scenario whose faults at ``site`` the valve gets.
    site : str
        ``"valve"`` (the pH loop's valve) or ``"outlet_valve"``.
    command_pct : float, optional
        Put the valve at rest at this command (% of span).

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> from valve_actuator import build_valve
    >>> spec = load_scenario("paper", fault="backlash")
    >>> valve = build_valve(spec.valves.ph, spec, "valve", 25.0)
    >>> valve.max_flow_ml_s, type(valve.position_blocks.blocks[0].block).__name__
    (40.0, 'Backlash')
    """
    max_flow = vspec.max_flow_ml_s or 1.0
    valve = Valve(max_flow, vspec.characteristic, vspec.rangeability,
                  Chain(injected_faults(spec, site, max_flow, flow_blocks())),
                  Chain(injected_faults(spec, site + "_flow", max_flow, flow_blocks())))
    if command_pct is not None:
        valve.reset(command_pct)
    return valve


def build_valves(spec: ScenarioSpec, valve_command_pct: float,
                 outlet_command_pct: float) -> tuple[Valve, Valve | None]:
    """The pH loop's valve and the outlet valve (None when the scenario has none), at rest at these commands.

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario (valves and their faults).
    valve_command_pct, outlet_command_pct : float
        The commands to be at rest at (% of span), e.g. from :func:`start_commands`.

    Returns
    -------
    valve, outlet_valve : Valve, Valve or None

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> from valve_actuator import build_valves
    >>> valve, outlet = build_valves(load_scenario("paper"), 24.6, 42.7)
    >>> valve.reset(24.6).position_pct, outlet.characteristic
    (24.6, 'linear')
    """
    valve = build_valve(spec.valves.ph, spec, "valve", valve_command_pct)
    outlet = None
    if spec.valves.outlet is not None:
        outlet = build_valve(spec.valves.outlet, spec, "outlet_valve", outlet_command_pct)
    return valve, outlet


@dataclass(slots=True)
class ValveStep:
    """The valves' answer to one sample's controller outputs (from :func:`step_valves`).

    Examples
    --------
    >>> from valve_actuator import Valve, step_valves
    >>> answer = step_valves(Valve(40.0), None, 0.43, 0.0, 30.0, 55.0)
    >>> answer.valve.flow_ml_s, answer.outlet_opening, answer.outlet is None
    (12.0, 0.43, True)
    """

    valve: ValveOutput  # the pH loop's valve
    outlet_position_pct: float  # outlet stem position (the level output itself when there is no outlet valve)
    outlet_opening: float  # fraction of full outlet flow
    outlet: ValveOutput | None  # the outlet valve's full output, if there is one


def step_valves(valve: Valve, outlet_valve: Valve | None, fixed_outlet_opening: float, t_s: float,
                ph_command_pct: float, level_command_pct: float) -> ValveStep:
    """Valve side of a tick: both valves move for the commands of t_s (the in-process loop and the valve node).

    Parameters
    ----------
    valve : Valve
        The pH loop's valve.
    outlet_valve : Valve or None
        The outlet valve; without one the outlet stays at ``fixed_outlet_opening``.
    fixed_outlet_opening : float
        Fraction of full outlet flow when there is no outlet valve.
    t_s : float
        Time of the sample (s).
    ph_command_pct, level_command_pct : float
        The controllers' outputs (% of span).

    Returns
    -------
    ValveStep

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> from valve_actuator import build_valves, step_valves
    >>> valve, outlet = build_valves(load_scenario("paper", fault="backlash"), 24.6, 42.7)
    >>> answer = step_valves(valve, outlet, 1.0, 8000.0, 30.0, 42.7)  # backlash acts from 7000 s
    >>> round(answer.valve.position_pct, 2), answer.valve.fault_severity
    (29.65, 1.0)
    """
    v = valve.step(ph_command_pct, t_s)
    if outlet_valve is None:
        return ValveStep(v, level_command_pct, fixed_outlet_opening, None)
    o = outlet_valve.step(level_command_pct, t_s)
    return ValveStep(v, o.position_pct, o.opening, o)
