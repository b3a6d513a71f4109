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

from phfdi.blocks import Chain, Injected

Characteristic = Literal["linear", "equal_percentage"]


def inherent_characteristic(position_pct: float, kind: Characteristic, rangeability: float = 50.0) -> float:
    """Fraction of maximum flow at a stem position (constant pressure drop).

    linear: f = x. equal_percentage: f = R^(x - 1) for x > 0 (equal position
    increments give equal percentage flow changes), 0 when shut, with x the
    position as a fraction of span and R the rangeability.
    """
    x = min(max(position_pct / 100.0, 0.0), 1.0)
    if kind == "linear":
        return x
    if kind == "equal_percentage":
        return rangeability ** (x - 1.0) if x > 0.0 else 0.0
    raise ValueError(f"unknown valve characteristic {kind!r}; use 'linear' or 'equal_percentage'")


@dataclass(slots=True)
class ValveOutput:
    position_pct: float
    opening: float  # fraction of maximum flow, 0..1
    flow_ml_s: float
    fault_severity: float


@dataclass
class Valve:
    """One valve. ``step`` once per sample with the command in % of span.

    Non-finite commands are not applied: the valve holds its last position and
    counts them in ``rejected_commands``.
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
