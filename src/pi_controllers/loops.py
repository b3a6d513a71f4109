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
    t_s: float
    ph_setpoint: float
    ph_output_pct: float
    level_setpoint_cm: float
    level_output_pct: float


@dataclass
class ControllerBank:
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
