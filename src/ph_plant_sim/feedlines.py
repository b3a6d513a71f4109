"""Blocks of a feed line: what happens to a commanded flow before it reaches the vessel.

A feed's ``line`` in the plant model (``feeds.<name>.line``) is a chain of
these blocks, stepped once per sample on the flow the pump or valve is asked
to deliver (mL/s); its output is the flow that enters the vessel. They follow
the block protocol of :mod:`phfdi_base.blocks` (``reset``, ``step``), so a line
can also hold any user block.

* ``line_delay``: transport dead time of the tubing between pump and vessel;
* ``pump_curve``: a pump's delivery curve ``q = gain * max(0, q_cmd - threshold_ml_s)``
  (a diaphragm pump delivers less than its nominal rate, and nothing below a
  minimum stroke rate);
* ``pump_lag``: first-order start-up and stop dynamics of on/off dosing,
  with separate time constants for rising and falling flow.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from phfdi_base.blocks import register_block
from phfdi_base.faults import Fault, Injection, SizeRange, register_fault

from .sensors import TransportDelay, _check, lag_step


@register_block("line_delay")
@dataclass
class LineDelay(TransportDelay):
    """Transport dead time of a feed line: q_in(t) = q_cmd(t - delay_s) (interpolated between samples)."""


@register_block("pump_curve")
@dataclass
class PumpCurve:
    """Delivered flow q = gain * max(0, q_cmd - threshold_ml_s), mL/s; zero command delivers zero."""

    gain: float = 1.0
    threshold_ml_s: float = 0.0
    severity: float = 1.0

    def __post_init__(self) -> None:
        _check("gain", self.gain)
        _check("threshold_ml_s", self.threshold_ml_s)

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        g = 1.0 + self.severity * (self.gain - 1.0)
        return g * max(0.0, x - self.severity * self.threshold_ml_s)

    def step_many(self, x: np.ndarray, t_s: np.ndarray) -> np.ndarray:
        """:meth:`step` for each sample of ``x`` (the same arithmetic, vectorised)."""
        g = 1.0 + self.severity * (self.gain - 1.0)
        return g * np.maximum(0.0, np.asarray(x, dtype=float) - self.severity * self.threshold_ml_s)


#: A dosing pump that delivers other than its record says: the delivery curve with a gain of 1 - SIZE (pump_low),
#: 1 + SIZE (pump_high) or 0 (pump_stuck). Only ``phfdi inject`` (which writes the fault into a record's RECORDED
#: command and flow, since the measured pH is what the pump really delivered) and the rig estimator (which names it
#: by the pump's feed: its apparent strength) use them. The ranges: a pump can deliver nothing (pump_low's 1) but no
#: less; eleven times the recorded flow (pump_high's 10) and 1000 mL/s (a litre a second: no lab or pilot dosing
#: pump) are where a record stops being a pump's.
PUMP_CLASS = ("pump:{pump}_flow_ml_s",)
for _name, _what, _inject in (
        ("pump_low", "a dosing pump delivering less than recorded",
         Injection("fraction", "the pump delivers SIZE less than recorded: recorded = delivered / (1 - SIZE)",
                   SizeRange(0.0, 1.0, low_in=False, high_in=False), PUMP_CLASS)),
        ("pump_high", "a dosing pump delivering more than recorded",
         Injection("fraction", "the pump delivers SIZE more than recorded: recorded = delivered / (1 + SIZE)",
                   SizeRange(0.0, 10.0, low_in=False), PUMP_CLASS)),
        ("pump_stuck", "a dosing pump delivering nothing while its record says it runs",
         Injection("mL/s", "the pump delivers nothing while the record says SIZE mL/s "
                           "(only where the data's pump is off)", SizeRange(0.0, 1000.0, low_in=False), PUMP_CLASS))):
    register_fault(Fault(_name, site="pump", description=_what, isolate=False, preset=False, candidate=False,
                         inject=_inject), "pump_curve")


@register_block("pump_lag")
@dataclass
class PumpLag:
    """First-order approach of the delivered flow to its target: tau_start_s while rising, tau_stop_s while falling.

    Exact for a target held over each sample: y_k = y_k-1 + (1 - exp(-dt/tau)) (x_k - y_k-1).
    """

    tau_start_s: float = 0.0
    tau_stop_s: float = 0.0
    dt_s: float = 1.0
    severity: float = 1.0
    _y: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        _check("tau_start_s", self.tau_start_s)
        _check("tau_stop_s", self.tau_stop_s)
        _check("dt_s", self.dt_s, positive=True)

    def reset(self, x0: float) -> None:
        self._y = x0

    def step(self, x: float, t_s: float) -> float:
        rising = self._y is not None and x > self._y
        self._y = lag_step(self._y, x, self.severity * (self.tau_start_s if rising else self.tau_stop_s), self.dt_s)
        return self._y
