"""Rows of the classifier's data sets: one per loop record, simulated (labelled by construction) or real.

A row holds the feature vector of the screen (:func:`.features.screen_evidence`), the label and the group the
record belongs to. The classifier is trained and calibrated on simulated rows only (:mod:`.domain`); rows of
the labelled refinery records are for testing (benchmarks/stiction_real_test.py), never for fitting.
"""

from __future__ import annotations

from phfdi.run import Run

from .domain import slips
from .features import FEATURE_NAMES, screen_evidence
from .synthetic import simulate_loop
from .training import DrawnLoop


def screen_row(run: Run, process_type: str) -> dict:
    """The screen's features of one run (and which were measured)."""
    sp = run["sp"] if "sp" in run else None
    scr = screen_evidence(run["op_pct"], run["pv"], sp, run.dt_s, process_type)
    return {"features": [float(v) for v in scr.features], "measured": [scr.measured[n] for n in FEATURE_NAMES],
            "oscillating": bool(scr.oscillation.oscillating)}


def simulated_row(loop: DrawnLoop, source: str) -> dict:
    """Row of one simulated loop (``source``: which set it belongs to, e.g. "train" or "calibration"): its
    features, label, class, conditions, valve and how often its stem broke away."""
    run = simulate_loop(loop.spec)
    run.metadata["process_type"] = loop.process_type
    row = {"name": loop.group, "group": loop.group, "source": source, "stiction": bool(loop.stiction),
           "loop_class": loop.loop_class, "process_type": loop.process_type, "conditions": list(loop.conditions),
           "valve": loop.spec.valve, "slips": slips(run["stem_pct"], run["op_pct"])}
    row.update(screen_row(run, loop.process_type))
    return row
