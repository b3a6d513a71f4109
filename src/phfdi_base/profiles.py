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
    """At ``at_s`` (s) the value moves to ``value``: a step, or a ramp over ``ramp_s`` seconds.

    Examples
    --------
    >>> from phfdi_base import Change, Profile
    >>> Profile(12.0, [Change(at_s=100.0, value=8.0, ramp_s=40.0)]).value(120.0)
    10.0
    """

    at_s: float
    value: float
    ramp_s: float = 0.0


@dataclass
class Profile:
    """Piecewise signal: ``initial`` until the first change, then each change in turn.

    Parameters
    ----------
    initial : float
        The value before the first change (in the signal's unit).
    changes : list of Change (or of dicts with its fields)
        In time order, not overlapping (a ramp ends before the next change starts); a ``ValueError``
        names the change otherwise.

    Examples
    --------
    >>> from phfdi_base import Profile
    >>> setpoint = Profile(12.0, [{"at_s": 5000.0, "value": 8.0}])
    >>> setpoint.value(4999.0), setpoint.value(5000.0)
    (12.0, 8.0)
    >>> setpoint.values()
    [12.0, 8.0]
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
