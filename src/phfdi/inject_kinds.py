"""The faults :mod:`phfdi.inject` hides in measured records: names, families, units (no numpy: read by --help).

A probe fault's name is its name in the fault catalogue (:mod:`phfdi_base.faults`: ``probe_bias`` is the entry whose
block ``sensor_bias`` simulates it, in that block's own units, a drift per second there and per minute here) and
the rig estimator's class for it (``probe_bias``, ``probe_drift``, ``probe_noise``); ``isolated_as`` below lists
every class a right name may give. The pump faults have no catalogue entry: no block models a rig pump's fault.
"""

from __future__ import annotations

from dataclasses import dataclass

#: the pH meter's resolution (pH): an injected pH is rounded to it
PH_RESOLUTION = 0.01
PH_MIN, PH_MAX = 0.0, 14.0
#: the calibration point a probe_gain turns about (pH)
PH_CAL_POINT = 7.0
PUMPS = ("acid", "base")
TRUTH_FORMAT = "phfdi-fault/1"


@dataclass(frozen=True)
class SizeRange:
    """The sizes a fault kind takes: from ``low`` to ``high`` in its unit, each end in or out of the range.

    >>> SizeRange(0.0, 1.0, low_in=False, high_in=False).says("fraction")
    'above 0 and below 1 (a fraction)'
    >>> 1e308 in SizeRange(-14.0, 14.0)
    False
    """

    low: float
    high: float
    low_in: bool = True
    high_in: bool = True

    def __contains__(self, size: float) -> bool:
        above = size >= self.low if self.low_in else size > self.low
        below = size <= self.high if self.high_in else size < self.high
        return above and below

    def says(self, unit: str) -> str:
        """The range in words, with its unit."""
        unit = "(a fraction)" if unit == "fraction" else unit
        if self.low_in and self.high_in:
            return f"from {self.low:g} to {self.high:g} {unit}"
        low = f"at least {self.low:g}" if self.low_in else f"above {self.low:g}"
        high = f"at most {self.high:g}" if self.high_in else f"below {self.high:g}"
        return f"{low} and {high} {unit}"


@dataclass(frozen=True)
class FaultKind:
    """One injectable fault: its family (sensor or actuator), the unit of its size, what it does and the sizes
    it takes (None: it takes no size).

    The ranges are where a size still means the fault: beyond the probe's 0..14 pH span a bias, a drift per
    minute or a noise's standard deviation only clips to the span's ends; a lag longer than a day is a frozen
    probe in any record; a gain at or below -1 turns the slope over; a pump can deliver nothing (pump_low's 1)
    but no less; eleven times the recorded flow (pump_high's 10) and 1000 mL/s (a litre a second: no lab or pilot
    dosing pump) are where a record stops being a pump's.
    """

    name: str
    family: str
    unit: str
    what: str
    sizes: SizeRange | None
    #: the classes the rig estimator's isolation (wavelet_fdi.estimator_isolation) names it by when it names it
    #: right, the exact one first; ``{pump}`` stands for the pump the fault is on (``pump:acid_flow_ml_s``)
    isolated_as: tuple[str, ...] = ()

    def isolation_classes(self, pump: str | None = None) -> list[str]:
        """The classes a right name gives this fault (on ``pump``'s flow for a pump fault)."""
        return [c.format(pump=pump) for c in self.isolated_as]

    def size_text(self) -> str:
        """'from -14 to 14 pH' (--help): the range and its unit."""
        return "none" if self.sizes is None else self.sizes.says(self.unit)


#: Isolation classes: a slope error is locally an offset or a drift, a drift over a short window an offset; a frozen
#: or sluggish reading loses its noise (s < 1); a pump's error is its feed's apparent strength.
PUMP_CLASS = ("pump:{pump}_flow_ml_s",)
KINDS: dict[str, FaultKind] = {k.name: k for k in (
    FaultKind("probe_bias", "sensor", "pH", "a step of SIZE pH added to pH", SizeRange(-PH_MAX, PH_MAX),
              ("probe_bias",)),
    FaultKind("probe_drift", "sensor", "pH/min", "a ramp of SIZE pH per minute added to pH",
              SizeRange(-PH_MAX, PH_MAX), ("probe_drift", "probe_bias")),
    FaultKind("probe_frozen", "sensor", "none", "pH held at its value at the onset (SIZE ignored)", None,
              ("probe_noise",)),
    FaultKind("probe_noise", "sensor", "pH (std)", "seeded Gaussian noise of standard deviation SIZE pH added",
              SizeRange(0.0, PH_MAX, low_in=False), ("probe_noise",)),
    FaultKind("probe_lag", "sensor", "s", "a first-order lag of time constant SIZE s added to the probe",
              SizeRange(0.0, 86400.0, low_in=False), ("probe_noise",)),
    FaultKind("probe_gain", "sensor", "fraction", "slope error about pH 7: pH' = 7 + (1 + SIZE)(pH - 7)",
              SizeRange(-1.0, 10.0, low_in=False), ("probe_bias", "probe_drift")),
    FaultKind("pump_low", "actuator", "fraction", "the pump delivers SIZE less than recorded: "
                                                  "recorded = delivered / (1 - SIZE)",
              SizeRange(0.0, 1.0, low_in=False, high_in=False), PUMP_CLASS),
    FaultKind("pump_high", "actuator", "fraction", "the pump delivers SIZE more than recorded: "
                                                   "recorded = delivered / (1 + SIZE)",
              SizeRange(0.0, 10.0, low_in=False), PUMP_CLASS),
    FaultKind("pump_stuck", "actuator", "mL/s", "the pump delivers nothing while the record says SIZE mL/s "
                                                "(only where the data's pump is off)",
              SizeRange(0.0, 1000.0, low_in=False), PUMP_CLASS),
)}
