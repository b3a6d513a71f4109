"""One logistic model per oscillation state, against the shipped single model. Measured, not shipped.

    .venv/bin/python benchmarks/stiction_by_oscillation.py     # seconds, from benchmarks/results/stiction_dataset.json

The published stiction indicators were built for loops that oscillate (Jelali & Huang 2010 test for an
oscillation first, then for its shape), and the shipped model weighs them for every loop alike. This script fits
the shipped model's form (L2 logistic regression, the shipped L2 strength, each weight held to its paper's sign)
on the training loops twice, once for the loops the screen's oscillation test flags and once for the others, and
compares both with the single model on the calibration loops: rank AUC overall and within each state, and the
recall at the verdict's false-call rule on p alone (at most 2 % of the loops without stiction, and of the hard
negatives, reach the cut; no valve-model fit). Simulated loops only; prints figures, changes nothing.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from stiction_information_bound import false_call_cut, rank_auc

from phfdi.loopdiag.classifier import HARD_NEGATIVES, fit_logistic, load_model
from phfdi.loopdiag.features import FEATURE_NAMES, FEATURE_SIGNS

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"


def arrays(rows: list[dict], source: str):
    rs = [r for r in rows if r["source"] == source and not r.get("error")]
    return (np.array([r["features"] for r in rs], float), np.array([r["stiction"] for r in rs], bool),
            np.array([r["oscillating"] for r in rs], bool), np.array([r["loop_class"] in HARD_NEGATIVES for r in rs]))


def recall_at_rule(p: np.ndarray, y: np.ndarray, hard: np.ndarray) -> tuple[float, float]:
    """Recall and false calls at the lowest cut that at most 2 % of the negatives, and of the hard negatives,
    reach (the verdict's rule, ``false_call_cut``)."""
    cut = false_call_cut(p, [~y, ~y & hard])
    return float(np.mean(p[y] >= cut)), float(np.mean(p[~y] >= cut))


def main() -> int:
    if not DATASET.is_file():
        print(f"stiction_by_oscillation: {DATASET} not found; run benchmarks/stiction_dataset.py first", file=sys.stderr)
        return 2
    rows = json.loads(DATASET.read_text())["rows"]
    xt, yt, ot, _ = arrays(rows, "train")
    xc, yc, oc, hc = arrays(rows, "calibration")
    shipped = load_model()
    single = fit_logistic(xt, yt, np.ones(len(yt)), shipped.l2, FEATURE_NAMES, FEATURE_SIGNS)
    p_single = single.probability(xc)
    p_split = np.empty(len(yc))
    weights = {}
    for state in (True, False):
        m = fit_logistic(xt[ot == state], yt[ot == state], np.ones(int(np.sum(ot == state))), shipped.l2,
                         FEATURE_NAMES, FEATURE_SIGNS)
        p_split[oc == state] = m.probability(xc[oc == state])
        weights[state] = m.weights
    print(f"training loops: {len(yt)} ({int(ot.sum())} oscillating); calibration loops: {len(yc)} "
          f"({int(oc.sum())} oscillating; sticky among them {yc[oc].mean():.2f}, among the others {yc[~oc].mean():.2f})")
    print("| model | rank AUC | AUC, oscillating | AUC, not oscillating | recall at the 2 % rule | false calls |")
    print("|---|---|---|---|---|---|")
    for name, p in (("single (the shipped form)", p_single), ("one per oscillation state", p_split)):
        r, f = recall_at_rule(p, yc, hc)
        print(f"| {name} | {rank_auc(p, yc):.3f} | {rank_auc(p[oc], yc[oc]):.3f} | {rank_auc(p[~oc], yc[~oc]):.3f} | "
              f"{r:.3f} | {f:.1%} |")
    print("\nweights of the split models (log-odds per standard deviation):")
    print("| feature | oscillating | not oscillating | single |")
    print("|---|---|---|---|")
    for j, name in enumerate(FEATURE_NAMES):
        print(f"| {name} | {weights[True][j]:+.2f} | {weights[False][j]:+.2f} | {single.weights[j]:+.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
