"""Helpers shared by the detector tests."""

from __future__ import annotations

from phfdi.scenario import load_scenario

PAPER_FAULTS = ("backlash", "friction", "deadzone", "saturation", "stiction", "probe_delay")


def short_spec(fault: str = "backlash", onset_s: float = 1000.0, duration_s: float = 1600.0, **over):
    """The paper loop shortened: pH 8 from 200 s, a fault at ``onset_s``."""
    overrides = [f"duration_s={duration_s}", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]
    overrides += [f"{k}={v}" for k, v in over.items()]
    if fault == "healthy":
        return load_scenario("paper", fault="healthy", overrides=overrides)
    return load_scenario("paper", fault=fault, overrides=overrides, onset_s=onset_s)
