"""The controllers' part of a scenario: both PI loops and their setpoint profiles.

A factory from the validated scenario (:class:`phfdi_base.spec.ScenarioSpec`)
used alike by the in-process loop and the controllers node.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from phfdi_base.spec_tools import profile

from .loops import ControllerBank
from .pi import PIController

if TYPE_CHECKING:  # the schema (pydantic) is not needed to read a validated scenario (a node's start-up)
    from phfdi_base.spec import PISpec, ScenarioSpec

__all__ = ["build_controllers", "pi_controller"]


def pi_controller(p: PISpec, dt_s: float) -> PIController:
    """A PI controller from its spec (a scenario's ``controllers.ph`` or ``controllers.level``).

    Parameters
    ----------
    p : PISpec
        Tuning, action, anti-windup and limits.
    dt_s : float
        Sample time (s).

    Examples
    --------
    >>> from phfdi_base.spec import PISpec
    >>> from pi_controllers import pi_controller
    >>> pi = pi_controller(PISpec(kp=2.0, ti_s=60.0, action="direct"), 1.0)
    >>> pi.kp, pi.action
    (2.0, 'direct')
    """
    return PIController(p.kp, p.ti_s, dt_s, p.u_min, p.u_max, p.action, p.antiwindup, p.tt_s, p.setpoint_weight)


def build_controllers(spec: ScenarioSpec, valve_command_pct: float, outlet_command_pct: float,
                      ph: float, level_cm: float) -> ControllerBank:
    """Both loops, bumpless at the starting steady state (outputs = these commands, at this pH and level).

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario (tunings and setpoint profiles).
    valve_command_pct, outlet_command_pct : float
        The outputs at the start (% of span).
    ph, level_cm : float
        The measurements at the start.

    Returns
    -------
    ControllerBank

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> from pi_controllers import build_controllers
    >>> bank = build_controllers(load_scenario("paper"), 24.6, 42.7, 12.0, 14.0)
    >>> out = bank.compute(0.0, 12.0, 14.0)
    >>> out.ph_output_pct, out.level_output_pct
    (24.6, 42.7)
    """
    dt = spec.sample_time_s
    c = spec.controllers
    bank = ControllerBank(pi_controller(c.ph, dt), profile(spec.setpoints.ph),
                          pi_controller(c.level, dt) if c.level else None,
                          profile(spec.setpoints.level_cm) if spec.setpoints.level_cm else None,
                          fixed_level_output_pct=outlet_command_pct)
    bank.reset(valve_command_pct, ph, outlet_command_pct, level_cm)
    return bank
