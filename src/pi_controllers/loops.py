"""The loop's controllers: pH and (optionally) level, each with its setpoint profile.

:class:`ControllerBank` is what the controller node wraps and what the
in-process simulation steps once per sample.
"""

from __future__ import annotations

from dataclasses import dataclass

from phfdi_base.profiles import Profile

from .pi import PIController


@dataclass
class ControllerOutputs:
    """One sample's setpoints and controller outputs (%); NaN level setpoint without a level loop.

    Examples
    --------
    >>> from pi_controllers import ControllerOutputs
    >>> ControllerOutputs(0.0, 12.0, 24.6, 14.0, 42.7).ph_output_pct
    24.6
    """

    t_s: float
    ph_setpoint: float
    ph_output_pct: float
    level_setpoint_cm: float
    level_output_pct: float


@dataclass
class ControllerBank:
    """The loop's pH controller and (optionally) level controller, each with its setpoint profile.

    Step it once per sample with :meth:`compute`; :func:`pi_controllers.build.build_controllers` makes
    one from a scenario.

    Examples
    --------
    >>> from phfdi_base import Profile
    >>> from pi_controllers import ControllerBank, PIController
    >>> bank = ControllerBank(PIController(6.0, 10.0, action="direct"), Profile(12.0, [{"at_s": 5000.0, "value": 8.0}]))
    >>> bank.reset(24.6, 12.0, 100.0, float("nan"))
    >>> bank.compute(0.0, 12.0, float("nan")).ph_output_pct
    24.6
    >>> out = bank.compute(5000.0, 12.0, float("nan"))  # setpoint step to pH 8: more acid
    >>> out.ph_setpoint, out.ph_output_pct, out.level_output_pct
    (8.0, 48.6, 100.0)
    """

    ph: PIController
    ph_setpoint: Profile
    level: PIController | None = None
    level_setpoint: Profile | None = None
    # output held when there is no level controller (outlet valve position, %)
    fixed_level_output_pct: float = 100.0

    def reset(self, ph_output_pct: float, ph_meas: float, level_output_pct: float, level_meas: float) -> None:
        """Bumpless start: outputs at their given values for the t=0 setpoints."""
        self.ph.reset(ph_output_pct, self.ph_setpoint.value(0.0), ph_meas)
        if self.level is not None and self.level_setpoint is not None:
            self.level.reset(level_output_pct, self.level_setpoint.value(0.0), level_meas)

    def compute(self, t_s: float, ph_meas: float, level_meas: float) -> ControllerOutputs:
        sp_ph = self.ph_setpoint.value(t_s)
        u_ph = self.ph.step(sp_ph, ph_meas)
        if self.level is None or self.level_setpoint is None:  # built together (build_controllers)
            return ControllerOutputs(t_s, sp_ph, u_ph, float("nan"), self.fixed_level_output_pct)
        sp_level = self.level_setpoint.value(t_s)
        return ControllerOutputs(t_s, sp_ph, u_ph, sp_level, self.level.step(sp_level, level_meas))
