"""Piecewise signals over time: an initial value followed by steps and ramps.

Used for setpoint profiles (:mod:`pi_controllers`) and feed-flow schedules
(disturbances, :mod:`ph_plant_sim.process`).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Change:
    """At ``at_s`` the value moves to ``value``: a step, or a ramp over ``ramp_s`` seconds."""

    at_s: float
    value: float
    ramp_s: float = 0.0


@dataclass
class Profile:
    """Piecewise signal: ``initial`` until the first change, then each change in turn.

    Changes must be in time order and must not overlap (a ramp ends before
    the next change starts).
    """

    initial: float
    changes: list[Change] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.changes = [c if isinstance(c, Change) else Change(**c) for c in self.changes]
        end = -math.inf
        for c in self.changes:
            if c.ramp_s < 0:
                raise ValueError(f"change at {c.at_s} s: ramp_s must be non-negative")
            if c.at_s < end:
                raise ValueError(f"change at {c.at_s} s starts before the previous one ends ({end} s)")
            end = c.at_s + c.ramp_s
        self._times = [c.at_s for c in self.changes]

    def value(self, t_s: float) -> float:
        k = bisect.bisect_right(self._times, t_s)
        if k == 0:
            return self.initial
        c = self.changes[k - 1]
        start = self.initial if k == 1 else self.changes[k - 2].value
        if c.ramp_s > 0.0 and t_s < c.at_s + c.ramp_s:
            return start + (c.value - start) * (t_s - c.at_s) / c.ramp_s
        return c.value

    def values(self) -> list[float]:
        """Every level the profile visits."""
        return [self.initial] + [c.value for c in self.changes]
