"""The signals of a run: names, units and descriptions, one catalogue for every package.

A run is a uniform time base ``time_s`` plus named signals of the same length
(:class:`phfdi.records.Record`); names carry their unit as a suffix (``_pct``,
``_ml_s``, ``_cm``, ``_s``) and pH signals start with ``ph``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SIGNALS", "Signal", "label", "unit_of"]


@dataclass(frozen=True)
class Signal:
    """One signal of a run: its name (with the unit as a suffix), unit and description.

    Examples
    --------
    >>> from phfdi_base.signals import SIGNALS
    >>> [s.unit for s in SIGNALS if s.name == "valve_position_pct"]
    ['%']
    """

    name: str
    unit: str
    description: str


#: Signals of a closed-loop run, in file column order. Feed flows are added
#: per feed of the plant model as ``<feed>_flow_ml_s``.
SIGNALS: tuple[Signal, ...] = (
    Signal("time_s", "s", "simulated time of the sample"),
    Signal("ph_setpoint", "pH", "pH setpoint"),
    Signal("level_setpoint_cm", "cm", "level setpoint"),
    Signal("ph_controller_output_pct", "%", "pH controller output (the valve command)"),
    Signal("level_controller_output_pct", "%", "level controller output (outlet valve command)"),
    Signal("valve_command_pct", "%", "command received by the pH loop's valve"),
    Signal("valve_position_pct", "%", "stem position of the pH loop's valve"),
    Signal("outlet_valve_position_pct", "%", "stem position of the outlet valve"),
    Signal("outlet_flow_ml_s", "mL/s", "outlet flow"),
    Signal("ph_true", "pH", "true pH in the tank"),
    Signal("ph_measured", "pH", "pH probe reading"),
    Signal("level_true_cm", "cm", "true liquid level"),
    Signal("level_measured_cm", "cm", "level sensor reading"),
    Signal("fault_severity", "1", "injected fault's severity, 0 = healthy, 1 = full"),
)

_CATALOGUE = {s.name: s for s in SIGNALS}


def unit_of(name: str) -> str:
    """Unit of a signal from the catalogue, else from its name's suffix (``"1"`` when neither says).

    Examples
    --------
    >>> from phfdi_base import unit_of
    >>> unit_of("ph_measured"), unit_of("base_flow_ml_s"), unit_of("gain")
    ('pH', 'mL/s', '1')
    """
    if name in _CATALOGUE:
        return _CATALOGUE[name].unit
    for suffix, unit in (("_ml_s", "mL/s"), ("_pct", "%"), ("_cm", "cm"), ("_s", "s"), ("_ml", "mL")):
        if name.endswith(suffix):
            return unit
    if name.startswith("ph"):
        return "pH"
    return "1"


def label(name: str) -> str:
    """Axis label with unit, for figures.

    Examples
    --------
    >>> from phfdi_base import label
    >>> label("valve_position_pct"), label("ph_measured")
    ('valve position (%)', 'pH measured (pH)')
    """
    base = name
    for suffix in ("_ml_s", "_pct", "_cm", "_s"):
        if base.endswith(suffix):
            base = base[: -len(suffix)]
            break
    words = base.split("_")
    if words[0] == "ph":  # pH signals' names start with ph; a reader expects the quantity's own spelling
        words[0] = "pH"
    return f"{' '.join(words)} ({unit_of(name)})"
