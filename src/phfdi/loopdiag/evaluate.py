"""Stiction detection measured against labelled loops, validated leave-one-loop-out.

Files of one loop are never split between training and test: each fold holds
out every file of one loop tag, tunes the decision threshold of each method on
the other loops only, and predicts the held-out loop's files. Methods:

* ``hammerstein_valve``: a valve nonlinearity (any actuator cause) beats the
  linear model by at least the threshold (held-out NRMSE gain, %);
* ``hammerstein_stiction``: the same, and the winning cause is stiction or
  backlash (Kano's model with J = 0 is a backlash; neither baseline can tell
  them apart either);
* ``horch_ccf`` and ``he_curve_fit`` (see :mod:`.baselines`), with their
  published thresholds and with a threshold tuned in the folds.

Thresholds are tuned for balanced accuracy with every loop weighted equally
(one loop has 23 of the 59 files); ties go to the threshold nearest the
published one.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from .vocabulary import FRICTION_CAUSES


@dataclass(frozen=True)
class Labelled:
    file: str
    stiction: bool
    loop_tag: str


def read_labels(path: str | Path) -> list[Labelled]:
    """labels.csv: file (relative to the csv's folder), label (stiction | no_stiction), loop_tag."""
    path = Path(path)
    out = []
    with open(path, encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            out.append(Labelled(str(path.parent / row["file"]), row["label"].strip() == "stiction",
                                row["loop_tag"].strip()))
    return out


#: a record repeats another when this share of its 20-sample windows of (OP, PV) appears there too
REPEAT_SHARE = 0.8
REPEAT_WINDOW = 20


def repeated_records(records: dict[str, tuple[np.ndarray, np.ndarray]], min_share: float = REPEAT_SHARE,
                     window: int = REPEAT_WINDOW) -> dict[str, tuple[str, float]]:
    """Records whose samples are (mostly) another record's: {name: (the record it repeats, shared share)}.

    Historian exports of one loop taken at different times can hold the same stretch of data under other
    time stamps (the refinery records do: several files of one loop share 88-94 % of their samples). Every
    ``window`` consecutive (OP, PV) pairs, rounded to 1e-5, is a key; a record repeats an earlier one (in
    name order) when at least ``min_share`` of its windows occur there too. Counting such files once keeps
    a metric from scoring one stretch twice.

    >>> a = (np.arange(100.0), np.sin(np.arange(100.0)))
    >>> b = (a[0][5:], a[1][5:])
    >>> repeated_records({"a": a, "b": b, "c": (np.zeros(50), np.ones(50))})
    {'b': ('a', 1.0)}
    """
    keys: dict[bytes, set[str]] = {}
    counts: dict[str, int] = {}
    for name, (op, pv) in records.items():
        op, pv = np.round(np.asarray(op, float), 5), np.round(np.asarray(pv, float), 5)
        n = max(len(op) - window + 1, 0)
        counts[name] = n
        for i in range(n):
            keys.setdefault(op[i:i + window].tobytes() + pv[i:i + window].tobytes(), set()).add(name)
    shared: dict[tuple[str, str], int] = {}
    for names in keys.values():
        for a in names:
            for b in names:
                if a < b:
                    shared[(a, b)] = shared.get((a, b), 0) + 1
    out: dict[str, tuple[str, float]] = {}
    for (a, b), c in sorted(shared.items()):
        share = c / max(min(counts[a], counts[b]), 1)
        if share >= min_share and b not in out:
            out[b] = (a, round(share, 3))
    return out


def record(report: dict, item: Labelled) -> dict:
    """What the evaluation needs from one report (small, JSON-friendly)."""
    base = report.get("baselines") or {}
    return {
        "file": item.file, "loop_tag": item.loop_tag, "stiction": item.stiction,
        "error": report.get("error"),
        "gain_percent": report.get("gain_percent"),
        "extended_cause": report.get("extended_cause"),
        "oscillating": (report.get("oscillation") or {}).get("oscillating"),
        "cause": report.get("cause"), "verdict": report.get("verdict"),
        "horch_index": (base.get("horch_ccf") or {}).get("index"),
        "horch_decision": (base.get("horch_ccf") or {}).get("decision"),
        "he_index": (base.get("he_curve_fit") or {}).get("index"),
        "he_decision": (base.get("he_curve_fit") or {}).get("decision"),
    }


# ---- methods: a score (higher = more like stiction; None = cannot say -> "no stiction") -----
def _gain(r: dict) -> float | None:
    g = r.get("gain_percent")
    return None if g is None or r.get("error") else float(g)


def _gain_friction(r: dict) -> float | None:
    g = _gain(r)
    return g if g is not None and r.get("extended_cause") in FRICTION_CAUSES else None


def _horch(r: dict) -> float | None:
    return r.get("horch_index") if r.get("horch_decision") in ("stiction", "no_stiction") else None


def _he(r: dict) -> float | None:
    return r.get("he_index")


@dataclass(frozen=True)
class Method:
    name: str
    score: Callable[[dict], float | None]
    published: float  # threshold: score >= threshold means stiction
    tune: bool
    description: str


METHODS = (
    Method("hammerstein_valve", _gain, 10.0, True, "valve nonlinearity (any actuator cause), gain >= threshold %"),
    Method("hammerstein_stiction", _gain_friction, 10.0, True, "stiction or backlash named, gain >= threshold %"),
    Method("horch_ccf", _horch, 0.5, False, "Horch (1999) CCF oddness > 0.5"),
    Method("horch_ccf_tuned", _horch, 0.5, True, "Horch (1999) CCF oddness, threshold tuned in folds"),
    Method("he_curve_fit", _he, 0.6, False, "He et al. (2007) SI >= 0.6"),
    Method("he_curve_fit_tuned", _he, 0.6, True, "He et al. (2007) SI, threshold tuned in folds"),
)
#: the default-threshold variants of the Hammerstein methods (10 %, chosen before the evaluation)
FIXED = (
    Method("hammerstein_valve_fixed10", _gain, 10.0, False, "valve nonlinearity, gain >= 10 % (fixed)"),
    Method("hammerstein_stiction_fixed10", _gain_friction, 10.0, False, "stiction or backlash, gain >= 10 % (fixed)"),
)


def predict(score: float | None, threshold: float) -> bool:
    return score is not None and math.isfinite(score) and score >= threshold


def weighted_balanced_accuracy(records: list[dict], scores: list[float | None], threshold: float) -> float:
    """Balanced accuracy with each loop's files sharing a weight of one."""
    per_loop: dict[str, int] = {}
    for r in records:
        per_loop[r["loop_tag"]] = per_loop.get(r["loop_tag"], 0) + 1
    hit = {True: 0.0, False: 0.0}
    tot = {True: 0.0, False: 0.0}
    for r, s in zip(records, scores):
        w = 1.0 / per_loop[r["loop_tag"]]
        tot[r["stiction"]] += w
        if predict(s, threshold) == r["stiction"]:
            hit[r["stiction"]] += w
    rates = [hit[k] / tot[k] for k in (True, False) if tot[k] > 0]
    return sum(rates) / len(rates) if rates else 0.0


def tune_threshold(records: list[dict], method: Method) -> float:
    scores = [method.score(r) for r in records]
    values = sorted({s for s in scores if s is not None and math.isfinite(s)})
    candidates = [method.published] + [v for v in values] + [values[-1] + 1.0 if values else method.published]
    best = max(candidates, key=lambda c: (weighted_balanced_accuracy(records, scores, c),
                                          -abs(c - method.published)))
    return best


def leave_one_loop_out(records: list[dict], method: Method) -> tuple[list[bool], dict[str, float]]:
    """Predictions for every record (in order) and the threshold used for each held-out loop."""
    preds = [False] * len(records)
    thresholds: dict[str, float] = {}
    for loop in sorted({r["loop_tag"] for r in records}):
        train = [r for r in records if r["loop_tag"] != loop]
        th = tune_threshold(train, method) if method.tune else method.published
        thresholds[loop] = th
        for i, r in enumerate(records):
            if r["loop_tag"] == loop:
                preds[i] = predict(method.score(r), th)
    return preds, thresholds


def metrics(records: list[dict], preds: list[bool]) -> dict:
    tp = sum(p and r["stiction"] for r, p in zip(records, preds))
    fp = sum(p and not r["stiction"] for r, p in zip(records, preds))
    fn = sum((not p) and r["stiction"] for r, p in zip(records, preds))
    tn = sum((not p) and not r["stiction"] for r, p in zip(records, preds))
    n = len(records)
    loops: dict[str, list] = {}
    for r, p in zip(records, preds):
        loops.setdefault(r["loop_tag"], []).append((r["stiction"], p))
    loops_right = sum(1 for v in loops.values() if (sum(p for _, p in v) * 2 > len(v)) == v[0][0])
    return {
        "files": n, "tp": tp, "fp": fp, "fn": fn, "tn": tn,
        "accuracy": (tp + tn) / n if n else math.nan,
        "precision": tp / (tp + fp) if tp + fp else math.nan,
        "recall": tp / (tp + fn) if tp + fn else math.nan,
        "balanced_accuracy": weighted_balanced_accuracy(records, [1.0 if p else None for p in preds], 0.5),
        "loops": len(loops), "loops_right": loops_right,
    }


def evaluate(records: list[dict]) -> dict:
    """Every method's leave-one-loop-out metrics (records with a read error count as predicted negative)."""
    out = {}
    for m in METHODS + FIXED:
        preds, th = leave_one_loop_out(records, m)
        res = metrics(records, preds)
        res["description"] = m.description
        ths = sorted(set(th.values()))
        res["thresholds"] = [float(f"{t:.4g}") for t in ths]
        out[m.name] = res
        out[m.name]["predictions"] = {r["file"]: p for r, p in zip(records, preds)}
    return out


def format_table(results: dict) -> str:
    """Markdown table: one row per method."""
    head = ("| method | accuracy | precision | recall | balanced acc. (loop-weighted) | TP | FP | FN | TN | "
            "loops right (majority) | thresholds used |")
    lines = [head, "|" + "---|" * 11]
    for name, r in results.items():
        prec = "n/a" if math.isnan(r["precision"]) else f"{r['precision']:.2f}"
        lines.append(f"| {name} | {r['accuracy']:.2f} | {prec} | {r['recall']:.2f} | "
                     f"{r['balanced_accuracy']:.2f} | {r['tp']} | {r['fp']} | {r['fn']} | {r['tn']} | "
                     f"{r['loops_right']}/{r['loops']} | {', '.join(map(str, r['thresholds']))} |")
    return "\n".join(lines)


# ---- the structure checks (phfdi.loopdiag.loopcheck) on labelled records -------------------------
def structure_checks(runs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]]) -> dict[str, str | None]:
    """{name: structure verdict} of (OP, PV, SP) records: None for a closed loop to score, else
    ``pv_frozen`` or ``not_a_closed_loop``."""
    from .loopcheck import check_loop

    return {name: check_loop(op, pv, sp).verdict for name, (op, pv, sp) in runs.items()}


def unrelated_pairs(runs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]],
                    loop_of: dict[str, str]) -> dict[str, int]:
    """Not-a-loop records made from real ones: OP of one record beside the PV of a record of another
    loop (both cut to the shorter length; no setpoint). Counts how many the structure check still
    takes for a closed loop (``coupled``: its false "closed loop" answers) out of ``pairs``."""
    from .loopcheck import check_loop

    coupled = pairs = 0
    for a, (op, _, _) in runs.items():
        for b, (_, pv, _) in runs.items():
            if loop_of[a] == loop_of[b]:
                continue
            n = min(len(op), len(pv))
            pairs += 1
            coupled += check_loop(op[:n], pv[:n], None).verdict is None
    return {"pairs": pairs, "coupled": coupled}


def frozen_copies(runs: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray | None]]) -> dict[str, int]:
    """Every record with PV held at its first value (a transmitter that froze, or a valve that never
    moved): how many the structure check calls ``pv_frozen``."""
    from .loopcheck import PV_FROZEN, check_loop

    found = sum(check_loop(op, np.full_like(pv, pv[0]), sp).verdict == PV_FROZEN for op, pv, sp in runs.values())
    return {"records": len(runs), "pv_frozen": found}
