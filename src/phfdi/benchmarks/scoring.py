"""Scores of anomaly and change-point detection benchmarks, from their published definitions.

Outlier detection (:func:`binary_scores`): a 0/1 prediction per row against
a 0/1 label, all rows of all files pooled into one confusion matrix;
F1 = TP / (TP + (FP + FN) / 2), FAR = FP / (FP + TN) (% of normal rows
flagged), MAR = FN / (FN + TP) (% of anomalous rows missed).

Change-point detection (:func:`nab_scores`), the NAB score of Lavin and
Ahmad (2015) as SKAB applies it:

* every true change point at time t gets a detection window [t, t + w]
  (to its right, both ends included); where a window reaches the next one's
  start, the next window starts where this one ends (SKAB's "cut right
  window");
* the first predicted change point inside a window earns
  (A_TP - A_FP)/2 * (1 - tanh(x)/tanh(pi/2)) + A_FP, with x running
  linearly from -pi/2 at the window's start to pi/2 at its end (A_TP at the
  start, A_FP at the end); later ones in the same window count nothing;
* each predicted change point outside every window adds A_FP; each window
  without one adds A_FN;
* the sum over all files is normalised to
  100 (score - null) / (perfect - null), where the null detector scores
  A_FN and the perfect one A_TP per window.

SKAB's own code evaluates the tanh curve on a grid of 1000 points across the
window; here x is continuous (the difference is below 0.002 per window).

Predicted change points of a 0/1 prediction are the rows where it switches
(:func:`switches`); the first row counts as a switch when it is 1 (the
prediction before the scored rows is taken as 0).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np

#: NAB application profiles (A_TP, A_FP, A_FN) as SKAB uses them
NAB_PROFILES: dict[str, tuple[float, float, float]] = {
    "standard": (1.0, -0.11, -1.0),
    "low_fp": (1.0, -0.22, -1.0),
    "low_fn": (1.0, -0.11, -2.0),
}


@dataclass
class BinaryScores:
    """Pooled outlier-detection scores; rates in %."""

    f1: float
    far_pct: float
    mar_pct: float
    tp: int
    fp: int
    fn: int
    tn: int

    def as_dict(self) -> dict:
        return asdict(self)


def _as_binary(x, what: str) -> np.ndarray:
    a = np.asarray(x)
    if a.ndim != 1:
        raise ValueError(f"{what} must be one-dimensional, got shape {a.shape}")
    if a.size and not np.isin(a, (0, 1)).all():
        raise ValueError(f"{what} must hold only 0 and 1")
    return a.astype(bool)


def binary_scores(labels: Sequence, predictions: Sequence) -> BinaryScores:
    """F1, FAR, MAR over all rows of all files pooled (one label and one prediction array per file)."""
    if len(labels) != len(predictions):
        raise ValueError(f"{len(labels)} label arrays but {len(predictions)} prediction arrays")
    tp = fp = fn = tn = 0
    for i, (y, p) in enumerate(zip(labels, predictions)):
        y = _as_binary(y, f"labels[{i}]")
        p = _as_binary(p, f"predictions[{i}]")
        if len(y) != len(p):
            raise ValueError(f"file {i}: {len(y)} labels but {len(p)} predictions")
        tp += int(np.sum(y & p))
        fp += int(np.sum(~y & p))
        fn += int(np.sum(y & ~p))
        tn += int(np.sum(~y & ~p))
    f1 = tp / (tp + (fp + fn) / 2.0) if tp + fp + fn else 1.0
    far = 100.0 * fp / (fp + tn) if fp + tn else 0.0
    mar = 100.0 * fn / (fn + tp) if fn + tp else 0.0
    return BinaryScores(f1, far, mar, tp, fp, fn, tn)


def switches(prediction) -> np.ndarray:
    """0/1 change points of a 0/1 prediction: 1 where it differs from the row before (row 0: itself)."""
    p = _as_binary(prediction, "prediction").astype(np.int8)
    out = np.zeros(len(p), dtype=np.int8)
    if len(p):
        out[0] = p[0]
        out[1:] = np.abs(np.diff(p))
    return out


def detection_windows(time_s, changepoints, width_s: float) -> list[tuple[float, float]]:
    """[t, t + width] after each true change point; overlapping windows cut at the earlier one's end."""
    t = np.asarray(time_s, dtype=float)
    cp = _as_binary(changepoints, "changepoints")
    if len(t) != len(cp):
        raise ValueError(f"{len(t)} times but {len(cp)} change-point flags")
    windows = [[float(x), float(x) + width_s] for x in t[cp]]
    for i in range(len(windows) - 1):
        if windows[i][1] >= windows[i + 1][0]:
            windows[i + 1][0] = windows[i][1]
    return [(a, b) for a, b in windows]


def nab_reward(t_s: float, window: tuple[float, float], a_tp: float, a_fp: float) -> float:
    """Reward of a first detection at t_s inside window: A_TP at its start falling to A_FP at its end."""
    start, end = window
    frac = 0.0 if end <= start else min(max((t_s - start) / (end - start), 0.0), 1.0)
    x = -math.pi / 2 + math.pi * frac
    return (a_tp - a_fp) / 2.0 * (1.0 - math.tanh(x) / math.tanh(math.pi / 2)) + a_fp


@dataclass
class FileChangepoints:
    """Where one file's predicted change points fell: first detection time per window (None: missed)."""

    windows: list[tuple[float, float]]
    first_detection_s: list[float | None]
    false_positive_times_s: list[float]

    @property
    def missed(self) -> int:
        return sum(d is None for d in self.first_detection_s)

    @property
    def false_positives(self) -> int:
        return len(self.false_positive_times_s)


def match_changepoints(time_s, true_changepoints, predicted_changepoints, width_s: float) -> FileChangepoints:
    """Assign one file's predicted change points to the true change points' detection windows."""
    t = np.asarray(time_s, dtype=float)
    pred = _as_binary(predicted_changepoints, "predicted change points")
    if len(pred) != len(t):
        raise ValueError(f"{len(t)} times but {len(pred)} predicted change-point flags")
    windows = detection_windows(t, true_changepoints, width_s)
    times = np.sort(t[pred])
    inside = np.zeros(len(times), dtype=bool)
    first: list[float | None] = []
    for a, b in windows:
        hit = (times >= a) & (times <= b)
        inside |= hit
        first.append(float(times[hit][0]) if hit.any() else None)
    return FileChangepoints(windows, first, [float(x) for x in times[~inside]])


@dataclass
class NabResult:
    """Normalised NAB score per profile (0 = null detector, 100 = perfect) and the counts behind it."""

    scores: dict[str, float]
    raw: dict[str, float]
    windows: int
    missed: int
    false_positives: int
    mean_delay_s: float

    def as_dict(self) -> dict:
        return asdict(self)


def nab_scores(files: Sequence[FileChangepoints], profiles: dict[str, tuple[float, float, float]] | None = None
               ) -> NabResult:
    """NAB scores of matched files (:func:`match_changepoints`), summed over files, then normalised."""
    profiles = profiles or NAB_PROFILES
    n_windows = sum(len(f.windows) for f in files)
    raw, scores = {}, {}
    for name, (a_tp, a_fp, a_fn) in profiles.items():
        s = 0.0
        for f in files:
            s += a_fp * f.false_positives
            for w, d in zip(f.windows, f.first_detection_s):
                s += a_fn if d is None else nab_reward(d, w, a_tp, a_fp)
        null, perfect = a_fn * n_windows, a_tp * n_windows
        raw[name] = s
        scores[name] = 100.0 * (s - null) / (perfect - null) if perfect != null else math.nan
    delays = [d - w[0] for f in files for w, d in zip(f.windows, f.first_detection_s) if d is not None]
    return NabResult(scores, raw, n_windows, sum(f.missed for f in files), sum(f.false_positives for f in files),
                     float(np.mean(delays)) if delays else math.nan)
