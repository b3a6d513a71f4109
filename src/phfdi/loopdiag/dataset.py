"""Rows of the classifier's data sets: one per loop record, simulated (labelled by construction) or real.

A row holds the feature vector of the screen (:func:`.features.screen_evidence`), the label and the group the
record belongs to. The classifier is trained and calibrated on simulated rows only (:mod:`.domain`); rows of
the labelled refinery records are for testing (benchmarks/stiction_real_test.py), never for fitting.
"""

from __future__ import annotations

import numpy as np

from phfdi.records.record import Record

from .classifier import HARD_NEGATIVES, Data, LogisticModel, train_simulated
from .domain import slips
from .features import FEATURE_NAMES, FEATURE_SIGNS, screen_evidence
from .synthetic import simulate_loop
from .training import DrawnLoop


def screen_row(run: Record, process_type: str) -> dict:
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


def simulated_data(rows: list[dict]) -> Data:
    """Data of simulated rows (:func:`phfdi.loopdiag.dataset.simulated_row`): features, labels, each loop its own
    group, the features' published signs."""
    return Data(np.array([r["features"] for r in rows], float), np.array([r["stiction"] for r in rows], bool),
                [r["group"] for r in rows], np.zeros(len(rows), bool), list(FEATURE_NAMES), list(FEATURE_SIGNS))


def train_from_rows(rows: list[dict]) -> LogisticModel:
    """:func:`train_simulated` on the ``train`` and ``calibration`` rows of a data set
    (benchmarks/stiction_dataset.py), the calibration set's hard negatives marked by their class."""
    train_rows = [r for r in rows if r["source"] == "train" and not r.get("error")]
    cal_rows = [r for r in rows if r["source"] == "calibration" and not r.get("error")]
    hard = np.array([r["loop_class"] in HARD_NEGATIVES for r in cal_rows])
    fitted = ["valve_fit" in r for r in cal_rows]
    if any(fitted) and not all(fitted):
        raise ValueError("some calibration rows have the valve-model fit's outcome and some do not: run "
                         "benchmarks/stiction_dataset.py --add-valve-fits on the data set")
    decides = takes_back = None
    if cal_rows and all(fitted):
        decides = np.array([r["valve_fit"]["decides"] for r in cal_rows], bool)
        takes_back = np.array([r["valve_fit"]["takes_back"] for r in cal_rows], bool)
    return train_simulated(simulated_data(train_rows), simulated_data(cal_rows), hard, decides, takes_back)


def valve_fit_row(loop: DrawnLoop) -> dict:
    """What the valve-model fit says of one simulated loop, run whatever the screen's call (``fits="all"``):
    whether it would decide an undetermined screen for stiction, and whether it would take a stiction call back
    (:func:`.verdict.friction_decides`, :func:`.verdict.contradiction`). The operating point is set on the
    final calls with these (:func:`.classifier.operating_point`)."""
    from .diagnose import Settings
    from .single import diagnose_run
    from .verdict import contradiction, friction_decides

    run = simulate_loop(loop.spec)
    run.metadata["process_type"] = loop.process_type
    rep = diagnose_run(run, Settings(baselines=False, fits="all"))
    if rep.get("error") or rep.get("stiction") is None:  # not diagnosed, or not a closed loop: never called
        return {"name": loop.group, "decides": False, "takes_back": True, "cause": None,
                "why": rep.get("error") or "not scored as a closed loop"}
    return {"name": loop.group, "decides": friction_decides(rep) is not None,
            "takes_back": contradiction(rep) is not None, "cause": rep.get("cause"),
            "gain_percent": rep.get("gain_percent")}
