"""The faults :mod:`phfdi.inject` hides in measured records: names, families, units (no numpy: read by --help)."""

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
class FaultKind:
    """One injectable fault: its family (sensor or actuator), the unit of its size and what it does."""

    name: str
    family: str
    unit: str
    what: str


KINDS: dict[str, FaultKind] = {k.name: k for k in (
    FaultKind("probe_bias", "sensor", "pH", "a step of SIZE pH added to pH"),
    FaultKind("probe_drift", "sensor", "pH/min", "a ramp of SIZE pH per minute added to pH"),
    FaultKind("probe_frozen", "sensor", "none", "pH held at its value at the onset (SIZE ignored)"),
    FaultKind("probe_noise", "sensor", "pH (std)", "seeded Gaussian noise of standard deviation SIZE pH added"),
    FaultKind("probe_lag", "sensor", "s", "a first-order lag of time constant SIZE s added to the probe"),
    FaultKind("probe_gain", "sensor", "fraction", "slope error about pH 7: pH' = 7 + (1 + SIZE)(pH - 7)"),
    FaultKind("pump_low", "actuator", "fraction", "the pump delivers SIZE less than recorded: "
                                                  "recorded = delivered / (1 - SIZE)"),
    FaultKind("pump_high", "actuator", "fraction", "the pump delivers SIZE more than recorded: "
                                                   "recorded = delivered / (1 + SIZE)"),
    FaultKind("pump_stuck", "actuator", "mL/s", "the pump delivers nothing while the record says SIZE mL/s "
                                                "(only where the data's pump is off)"),
)}
