"""Discrete PI controller with anti-windup (Astrom & Hagglund, Advanced PID Control, ch. 3).

Positional form, sampled every ``dt_s``, forward-Euler integral:

    e   = sp - pv            (reverse action: output rises when PV falls)
    e   = pv - sp            (direct action: output rises when PV rises)
    v   = Kp (b*sp - pv) * sign + I          b: setpoint weight (1: plain PI)
    u   = clip(v, u_min, u_max)
    I  += Kp dt/Ti e + dt/Tt (u - v)         back-calculation anti-windup

With ``antiwindup="conditional"`` the integral is frozen while the output is
saturated and the error would drive it further into saturation. Changing the
tuning or the setpoint weight, and switching from manual to automatic, is
bumpless: the integral is re-initialised so the output does not jump.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

Action = Literal["direct", "reverse"]
AntiWindup = Literal["back_calculation", "conditional", "none"]


@dataclass
class PIController:
    """PI controller in engineering units: Kp in % of output per unit of PV.

    Parameters
    ----------
    kp : float
        Proportional gain (% / PV unit), positive.
    ti_s : float
        Integral time (s), positive.
    dt_s : float
        Sample time (s).
    u_min, u_max : float
        Output limits (%).
    action : {"reverse", "direct"}
        "reverse" (heating-type: u up when PV below SP) or "direct".
    antiwindup : {"back_calculation", "conditional", "none"}
    tt_s : float, optional
        Tracking time for back-calculation; default Ti (Astrom & Hagglund suggest Ti for PI: fast enough
        to stop windup, slow enough not to reset on noise).
    setpoint_weight : float
        b in the proportional term; b < 1 softens setpoint steps.

    Examples
    --------
    >>> from pi_controllers import PIController
    >>> pi = PIController(kp=2.0, ti_s=60.0, dt_s=1.0)
    >>> pi.reset(50.0, 8.0, 8.0)  # bumpless: output 50 % at SP = PV = 8
    >>> pi.step(8.0, 7.5), round(pi.step(8.0, 7.5), 4)
    (51.0, 51.0167)
    """

    kp: float
    ti_s: float
    dt_s: float = 1.0
    u_min: float = 0.0
    u_max: float = 100.0
    action: Action = "reverse"
    antiwindup: AntiWindup = "back_calculation"
    tt_s: float | None = None
    setpoint_weight: float = 1.0
    manual: bool = False
    _i: float = field(default=0.0, repr=False)
    _u: float = field(default=0.0, repr=False)
    _last_sp: float = field(default=0.0, repr=False)
    _last_pv: float = field(default=0.0, repr=False)

    def __post_init__(self) -> None:
        for name in ("kp", "ti_s", "dt_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be positive and finite, got {v}")
        if not self.u_min < self.u_max:
            raise ValueError(f"u_min must be below u_max, got {self.u_min}, {self.u_max}")
        if self.action not in ("direct", "reverse"):
            raise ValueError(f"action must be 'direct' or 'reverse', got {self.action!r}")
        if self.antiwindup not in ("back_calculation", "conditional", "none"):
            raise ValueError(f"antiwindup must be back_calculation, conditional or none, got {self.antiwindup!r}")
        if self.tt_s is not None and not (self.tt_s > 0):
            raise ValueError(f"tt_s must be positive, got {self.tt_s}")
        if not 0.0 <= self.setpoint_weight <= 1.0:
            raise ValueError(f"setpoint_weight must be within [0, 1], got {self.setpoint_weight}")

    @property
    def sign(self) -> float:
        return 1.0 if self.action == "reverse" else -1.0

    @property
    def output(self) -> float:
        return self._u

    def _proportional(self, sp: float, pv: float) -> float:
        return self.kp * self.sign * (self.setpoint_weight * sp - pv)

    def reset(self, u0: float, sp: float, pv: float) -> None:
        """Start bumplessly at output u0 for the given setpoint and measurement."""
        self._last_sp, self._last_pv = sp, pv
        self._u = min(max(u0, self.u_min), self.u_max)
        self._i = self._u - self._proportional(sp, pv)

    def set_tuning(self, kp: float | None = None, ti_s: float | None = None,
                   setpoint_weight: float | None = None) -> None:
        """Change tuning without a bump in the output."""
        self.kp = self.kp if kp is None else kp
        self.ti_s = self.ti_s if ti_s is None else ti_s
        self.setpoint_weight = self.setpoint_weight if setpoint_weight is None else setpoint_weight
        self.__post_init__()
        self._i = self._u - self._proportional(self._last_sp, self._last_pv)

    def set_manual(self, u: float) -> None:
        """Manual mode: the output is held at u (clipped); the integral tracks it."""
        self.manual = True
        self._u = min(max(u, self.u_min), self.u_max)

    def set_auto(self) -> None:
        """Back to automatic, bumpless from the current manual output."""
        self.manual = False
        self._i = self._u - self._proportional(self._last_sp, self._last_pv)

    def step(self, sp: float, pv: float) -> float:
        """Controller output (%) for this sample."""
        self._last_sp, self._last_pv = sp, pv
        p = self._proportional(sp, pv)
        if self.manual:
            self._i = self._u - p
            return self._u
        v = p + self._i
        u = min(max(v, self.u_min), self.u_max)
        e = self.sign * (sp - pv)
        di = self.kp * self.dt_s / self.ti_s * e
        if self.antiwindup == "back_calculation":
            tt = self.ti_s if self.tt_s is None else self.tt_s
            di += self.dt_s / tt * (u - v)
        elif self.antiwindup == "conditional":
            if (v > self.u_max and di > 0) or (v < self.u_min and di < 0):
                di = 0.0
        self._i += di
        self._u = u
        return u
