"""A control valve: command -> stem position -> flow.

    command (% span) --[position blocks]--> stem position (% span)
        --[inherent characteristic f]--> opening in [0, 1]
        --[x max flow]--> flow (mL/s) --[flow blocks]--> delivered flow

The position blocks carry the nonlinearities (backlash, stiction, ...), the
flow blocks the effects that act on flow (seat leakage).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from phfdi_base.blocks import Chain, Injected

Characteristic = Literal["linear", "equal_percentage"]


def inherent_characteristic(position_pct: float, kind: Characteristic, rangeability: float = 50.0) -> float:
    """Fraction of maximum flow at a stem position (constant pressure drop).

    linear: f = x. equal_percentage: f = R^(x - 1) for x > 0 (equal position
    increments give equal percentage flow changes), 0 when shut, with x the
    position as a fraction of span and R the rangeability.

    Parameters
    ----------
    position_pct : float
        Stem position (% of span), clipped to 0..100.
    kind : {"linear", "equal_percentage"}
    rangeability : float
        Largest over smallest controllable flow (equal percentage only).

    Examples
    --------
    >>> from valve_actuator import inherent_characteristic
    >>> inherent_characteristic(50.0, "linear"), round(inherent_characteristic(50.0, "equal_percentage"), 4)
    (0.5, 0.1414)
    """
    x = min(max(position_pct / 100.0, 0.0), 1.0)
    if kind == "linear":
        return x
    if kind == "equal_percentage":
        return rangeability ** (x - 1.0) if x > 0.0 else 0.0
    raise ValueError(f"unknown valve characteristic {kind!r}; use 'linear' or 'equal_percentage'")


@dataclass(slots=True)
class ValveOutput:
    """A valve's answer to one sample's command: stem position (% of span), opening (fraction of maximum
    flow), flow (mL/s) and the injected fault's severity (0 healthy .. 1 full).

    Examples
    --------
    >>> from valve_actuator import Valve
    >>> out = Valve(max_flow_ml_s=40.0).reset(25.0)
    >>> out.opening, out.flow_ml_s
    (0.25, 10.0)
    """

    position_pct: float
    opening: float  # fraction of maximum flow, 0..1
    flow_ml_s: float
    fault_severity: float


@dataclass
class ValveOutputs:
    """:class:`ValveOutput` of many samples (arrays)."""

    position_pct: np.ndarray
    opening: np.ndarray
    flow_ml_s: np.ndarray
    fault_severity: np.ndarray


@dataclass
class Valve:
    """One valve. ``step`` once per sample with the command in % of span.

    Non-finite commands are not applied: the valve holds its last position and
    counts them in ``rejected_commands``.

    Parameters
    ----------
    max_flow_ml_s : float
        Flow when fully open (mL/s).
    characteristic : {"linear", "equal_percentage"}
        Inherent characteristic (:func:`inherent_characteristic`).
    rangeability : float
        For the equal-percentage characteristic.
    position_blocks, flow_blocks : Chain
        Blocks between command and stem position (backlash, stiction, ...) and on the flow (leakage).

    Examples
    --------
    >>> import valve_actuator.blocks  # registers the valve blocks
    >>> from phfdi_base import Chain, make_block
    >>> from valve_actuator import Valve
    >>> valve = Valve(40.0, position_blocks=Chain([make_block("backlash", {"width_pct": 2.0})]))
    >>> valve.reset(50.0).flow_ml_s
    20.0
    >>> [valve.step(command, t).position_pct for t, command in enumerate([52.0, 51.0, 49.0])]
    [51.0, 51.0, 50.0]
    >>> valve.step(float("nan"), 3.0).position_pct, valve.rejected_commands  # holds on a bad command
    (50.0, 1)
    """

    max_flow_ml_s: float = 1.0
    characteristic: Characteristic = "linear"
    rangeability: float = 50.0
    position_blocks: Chain = field(default_factory=Chain)
    flow_blocks: Chain = field(default_factory=Chain)
    rejected_commands: int = 0
    _last: ValveOutput | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self._faults = [b for b in self.position_blocks.blocks + self.flow_blocks.blocks if isinstance(b, Injected)]

    def reset(self, command_pct: float) -> ValveOutput:
        self.position_blocks.reset(command_pct)
        pos = min(max(command_pct, 0.0), 100.0)
        opening = inherent_characteristic(pos, self.characteristic, self.rangeability)
        flow = opening * self.max_flow_ml_s
        self.flow_blocks.reset(flow)
        self._last = ValveOutput(pos, opening, flow, 0.0)
        return self._last

    def step(self, command_pct: float, t_s: float) -> ValveOutput:
        if not math.isfinite(command_pct):
            self.rejected_commands += 1
            if self._last is None:
                raise ValueError("first valve command is not finite and there is no position to hold")
            return self._last
        pos = self.position_blocks.step(command_pct, t_s)
        pos = min(max(pos, 0.0), 100.0)
        opening = inherent_characteristic(pos, self.characteristic, self.rangeability)
        flow = self.flow_blocks.step(opening * self.max_flow_ml_s, t_s)
        sev = max((b.severity_at(t_s) for b in self._faults), default=0.0) if self._faults else 0.0
        self._last = ValveOutput(pos, opening, flow, sev)
        return self._last

    def step_many(self, commands_pct: np.ndarray, t_s: np.ndarray) -> ValveOutputs:
        """Many samples at once; the same outputs as calling :meth:`step` for each in turn.

        Blocks are stepped per sample (they have state); clipping, the
        inherent characteristic and the hold on non-finite commands are
        applied to whole arrays, so a valve without blocks runs vectorised
        (the replaying detector's healthy reference valve).
        """
        cmd = np.asarray(commands_pct, dtype=float)
        t = np.asarray(t_s, dtype=float)
        n = len(cmd)
        fin = np.isfinite(cmd)
        if n and not fin[0] and self._last is None:
            raise ValueError("first valve command is not finite and there is no position to hold")
        self.rejected_commands += int(n - np.count_nonzero(fin))
        live = np.flatnonzero(fin)
        pos = np.where(fin, cmd, 0.0)
        if self.position_blocks.blocks:
            step = self.position_blocks.step
            for k in live.tolist():
                pos[k] = step(float(cmd[k]), float(t[k]))
        pos = np.clip(pos, 0.0, 100.0)
        x = np.clip(pos / 100.0, 0.0, 1.0)
        if self.characteristic == "linear":
            opening = x
        else:
            inherent_characteristic(50.0, self.characteristic, self.rangeability)  # validates the kind
            opening = np.where(x > 0.0, self.rangeability ** (x - 1.0), 0.0)
        flow = opening * self.max_flow_ml_s
        if self.flow_blocks.blocks:
            fstep = self.flow_blocks.step
            for k in live.tolist():
                flow[k] = fstep(float(flow[k]), float(t[k]))
        sev = np.zeros(n)
        if self._faults:
            for k in live.tolist():
                sev[k] = max(b.severity_at(float(t[k])) for b in self._faults)
        if len(live) < n:  # non-finite commands hold the last output
            src = np.maximum.accumulate(np.where(fin, np.arange(n), -1))
            held = src < 0
            src = np.maximum(src, 0)
            last = self._last
            out = []
            for arr, prev in ((pos, last.position_pct if last else 0.0), (opening, last.opening if last else 0.0),
                              (flow, last.flow_ml_s if last else 0.0), (sev, last.fault_severity if last else 0.0)):
                out.append(np.where(held, prev, arr[src]))
            pos, opening, flow, sev = out
        if n:
            self._last = ValveOutput(float(pos[-1]), float(opening[-1]), float(flow[-1]), float(sev[-1]))
        return ValveOutputs(pos, opening, flow, sev)

