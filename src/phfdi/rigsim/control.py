"""What commands the pumps in a run: a replayed profile, an open-loop setting or ramp, an on/off controller
with hysteresis, or a PI controller (:class:`pi_controllers.PIController`) on one pump.

Every policy answers :meth:`Policy.command` once per sample with the reading of that sample (the rig logs a
row's command beside the pH it was decided on, as the recorded closed loop shows: the base pump comes on in
the row whose pH first falls below its threshold) and the commands then hold until the next sample.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from pi_controllers import PIController

from .operations import Operation, quantise_command

#: the controllers' assumed sample time (s): the rig's nominal logging interval
CONTROL_DT_S = 0.35


class Policy(Protocol):
    def start(self, ph: float) -> tuple[float, float]:
        """Come to rest at the run's start pH; returns the (acid, base) commands (%) in effect before it."""

    def command(self, t_s: float, reading_ph: float) -> tuple[float, float]:
        """(acid, base) commands (%) for the sample at ``t_s`` s from the start, given its reading."""

    def setpoint(self, t_s: float) -> float:
        """The setpoint at ``t_s`` (pH; NaN without a controller)."""


class _Setpoints:
    def __init__(self, changes: list[tuple[float, float]]) -> None:
        self.times = np.array([c[0] for c in changes]) if changes else np.array([0.0])
        self.values = [c[1] for c in changes] if changes else [math.nan]

    def setpoint(self, t_s: float) -> float:
        return self.values[max(0, int(np.searchsorted(self.times, t_s, side="right")) - 1)]


class ProfilePolicy(_Setpoints):
    """Piecewise-constant commands at change points (s from the start, acid %, base %)."""

    def __init__(self, profile: list[tuple[float, float, float]]) -> None:
        super().__init__([])
        self.change_s = np.array([p[0] for p in profile])
        self.acid = [quantise_command(p[1]) for p in profile]
        self.base = [quantise_command(p[2]) for p in profile]

    def start(self, ph: float) -> tuple[float, float]:
        return self.acid[0], self.base[0]

    def command(self, t_s: float, reading_ph: float) -> tuple[float, float]:
        i = max(0, int(np.searchsorted(self.change_s, t_s, side="right")) - 1)
        return self.acid[i], self.base[i]


class OpenLoopPolicy(_Setpoints):
    """Steady commands, or ramps from the start setting to the end one over the run (a slow titration)."""

    def __init__(self, acid_pct: float, base_pct: float, duration_s: float, acid_end_pct: float | None = None,
                 base_end_pct: float | None = None) -> None:
        super().__init__([])
        self.acid0, self.base0 = acid_pct, base_pct
        self.acid1 = acid_pct if acid_end_pct is None else acid_end_pct
        self.base1 = base_pct if base_end_pct is None else base_end_pct
        self.duration_s = duration_s

    def start(self, ph: float) -> tuple[float, float]:
        return self.acid0, self.base0

    def command(self, t_s: float, reading_ph: float) -> tuple[float, float]:
        f = min(1.0, max(0.0, t_s / self.duration_s))
        return (quantise_command(self.acid0 + f * (self.acid1 - self.acid0)),
                quantise_command(self.base0 + f * (self.base1 - self.base0)))


class OnOffPolicy(_Setpoints):
    """Bang-bang with hysteresis about the setpoint: ``base`` switched (on below sp - band, off above
    sp + band) against a steady acid, ``acid`` switched (on above sp + band, off below sp - band) against a
    steady base, or ``both`` (base on below sp - band until it reaches sp, acid on above sp + band until it
    reaches sp). A band of 0 switches at the setpoint itself: noise makes the pump chatter there."""

    def __init__(self, mode: str, on_pct: float, other_pct: float, band_ph: float,
                 setpoints: list[tuple[float, float]]) -> None:
        super().__init__(setpoints)
        self.mode, self.on_pct, self.other_pct, self.band = mode, on_pct, other_pct, band_ph
        self.acid_on = self.base_on = False

    def start(self, ph: float) -> tuple[float, float]:
        sp = self.setpoint(0.0)
        self.base_on = self.mode in ("base", "both") and ph < sp - (self.band if self.mode == "both" else 0.0)
        self.acid_on = self.mode in ("acid", "both") and ph > sp + (self.band if self.mode == "both" else 0.0)
        return self._commands()

    def _commands(self) -> tuple[float, float]:
        if self.mode == "base":
            return self.other_pct, self.on_pct if self.base_on else 0.0
        if self.mode == "acid":
            return self.on_pct if self.acid_on else 0.0, self.other_pct
        return self.on_pct if self.acid_on else 0.0, self.on_pct if self.base_on else 0.0

    def command(self, t_s: float, reading_ph: float) -> tuple[float, float]:
        sp, band, y = self.setpoint(t_s), self.band, reading_ph
        if self.mode == "base":
            if y < sp - band:
                self.base_on = True
            elif y > sp + band:
                self.base_on = False
        elif self.mode == "acid":
            if y > sp + band:
                self.acid_on = True
            elif y < sp - band:
                self.acid_on = False
        else:
            if y < sp - band:
                self.base_on = True
            elif y >= sp:
                self.base_on = False
            if y > sp + band:
                self.acid_on = True
            elif y <= sp:
                self.acid_on = False
        return self._commands()


class PIPolicy(_Setpoints):
    """A PI controller (:class:`pi_controllers.PIController`, back-calculation anti-windup, 0..100 %) on one
    pump's command, the other pump steady. More base raises the pH, so a PI on the base pump is reverse acting
    (output up when the pH is below the setpoint), one on the acid pump direct acting."""

    def __init__(self, pump: str, kp_pct_per_ph: float, ti_s: float, other_pct: float,
                 setpoints: list[tuple[float, float]]) -> None:
        super().__init__(setpoints)
        self.pump, self.other_pct = pump, other_pct
        self.pi = PIController(kp=kp_pct_per_ph, ti_s=ti_s, dt_s=CONTROL_DT_S, u_min=0.0, u_max=100.0,
                               action="reverse" if pump == "base" else "direct")

    def _commands(self, u: float) -> tuple[float, float]:
        return (u, self.other_pct) if self.pump == "acid" else (self.other_pct, u)

    def start(self, ph: float) -> tuple[float, float]:
        self.pi.reset(0.0, self.setpoint(0.0), ph)  # the pump off, the integral bumpless from there
        return self._commands(0.0)

    def command(self, t_s: float, reading_ph: float) -> tuple[float, float]:
        return self._commands(quantise_command(self.pi.step(self.setpoint(t_s), reading_ph)))


def build_policy(op: Operation) -> Policy:
    """The policy that runs a drawn :class:`~phfdi.rigsim.operations.Operation`."""
    v = op.values
    if op.kind == "profile":
        return ProfilePolicy(op.profile)
    if op.kind == "open_loop":
        return OpenLoopPolicy(float(v["acid_pct"]), float(v["base_pct"]), op.duration_s,  # type: ignore[arg-type]
                              v.get("acid_end_pct"), v.get("base_end_pct"))  # type: ignore[arg-type]
    if op.kind == "on_off":
        return OnOffPolicy(str(v["switched"]), float(v["on_pct"]), float(v.get("other_pct", 0.0)),  # type: ignore
                           float(v["band_ph"]), op.setpoints)  # type: ignore[arg-type]
    if op.kind == "pi":
        return PIPolicy(str(v["pump"]), float(v["kp_pct_per_ph"]), float(v["ti_s"]),  # type: ignore[arg-type]
                        float(v["other_pct"]), op.setpoints)  # type: ignore[arg-type]
    raise ValueError(f"unknown operation kind {op.kind!r}")
