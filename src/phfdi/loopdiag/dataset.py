"""Rows of the classifier's data set: one per loop record, real (labelled) or synthetic.

A row holds the feature vector (:mod:`.features`), the label, the group the record belongs to (the
loop tag: leave-one-loop-out holds out every record of one group), and the decisions of the
methods the classifier is compared with (Horch's CCF, He et al.'s curve fit, the Hammerstein
diagnosis at its default 10 % gain).
"""

from __future__ import annotations

from pathlib import Path

from phfdi.run import Run
from phfdi_base.errors import UserError

from .diagnose import Settings
from .evaluate import Labelled
from .features import FEATURE_NAMES, loop_evidence
from .readers import read_loop
from .synthetic import simulate_loop
from .training import DrawnLoop
from .vocabulary import FRICTION_CAUSES


def row_for_run(run: Run, stiction: bool, group: str, source: str, name: str,
                settings: Settings | None = None) -> dict:
    le = loop_evidence(run, settings)
    ind = le.indicators
    gain = le.evidence.gain_percent() if le.evidence.identifiable else None
    return {
        "name": name, "group": group, "source": source, "stiction": bool(stiction),
        "process_type": run.metadata.get("process_type"),
        "features": [float(v) for v in le.features],
        "measured": [le.measured[n] for n in FEATURE_NAMES],
        "horch_decision": ind["horch_ccf"].decision, "horch_index": ind["horch_ccf"].value,
        "he_decision": ind["he_curve_fit"].decision, "he_index": ind["he_curve_fit"].value,
        "hammerstein_gain_percent": gain,  # best of the valve models fitted (all five for real records)
        "oscillating": bool(le.evidence.oscillation.oscillating),
    }


def real_row(item: Labelled, root: str | None = None) -> dict:
    """Row of a labelled file (``error`` set when it cannot be read)."""
    name = str(Path(item.file).relative_to(root)) if root and Path(item.file).is_relative_to(root) else item.file
    try:
        run = read_loop(item.file)
    except UserError as exc:
        return {"name": name, "group": item.loop_tag, "source": "real", "stiction": item.stiction,
                "error": str(exc)}
    return row_for_run(run, item.stiction, item.loop_tag, "real", name)


def synthetic_row(loop: DrawnLoop) -> dict:
    run = simulate_loop(loop.spec)
    run.metadata["process_type"] = loop.process_type
    # the features need the friction models only (the Hammerstein comparison runs on real records)
    row = row_for_run(run, loop.stiction, loop.group, "synthetic", loop.group,
                      Settings(causes=FRICTION_CAUSES, baselines=False))
    row["conditions"] = list(loop.conditions)
    if loop.loop_class:
        row["loop_class"] = loop.loop_class
    row["valve"] = loop.spec.valve
    return row
