"""Thresholds for a false-alarm target, measured on healthy data: the tail fits every calibration uses.

A CUSUM's threshold for a target average run length to a false alarm (ARL0) is measured, not assumed:

1. cut each statistic's healthy increments into windows of L samples and run the CUSUM afresh in each window;
   M_w = the window's maximum (:func:`window_maxima`);
2. fit an exponential tail P(M > h) = exp(a - theta h) to the upper half of the M_w (CUSUM maxima have
   exponential tails) and solve P(M > h) = L / ARL0_stat for h (:func:`tail_threshold`): an alarm within a window
   of L samples has probability about L / ARL when ARL >> L;
3. ARL0 is the target for the whole detector, which alarms when any of its n statistics crosses: each statistic
   gets ARL0_stat = n ARL0 (Bonferroni; conservative since the statistics are correlated).

:func:`~wavelet_fdi.learned_detector.calibrate_bands` does this for the multichannel detector, and the same window
maxima and tail fit calibrate the peer detectors of the evaluation (:mod:`wavelet_fdi.peers`), so every detector is
held to the same false-alarm rate on the same residual streams. :func:`excess_tail_threshold` places a margin on
single values (the estimator's confirmation statistics, the spike level).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from phfdi_base.errors import UserError

#: the share of the window maxima, largest first, the exponential tail is fitted to
TAIL_FRACTION = 0.5


@dataclass
class TailFit:
    threshold: float
    a: float
    theta: float
    points: int
    windows: int
    window_max_observed: float

    def as_dict(self) -> dict[str, float]:
        return {"a": self.a, "theta": self.theta, "points": self.points, "windows": self.windows,
                "window_max_observed": self.window_max_observed}


def fit_tail(maxima: np.ndarray, tail_fraction: float = TAIL_FRACTION) -> tuple[float, float, int]:
    """(a, theta, points) of ln P(M > h) = a - theta h fitted to the upper tail of window maxima."""
    m = np.sort(np.asarray(maxima, dtype=float))[::-1]
    w = len(m)
    if w < 8:
        raise UserError(f"calibration needs at least 8 windows of healthy data, got {w}: add seeds or run longer")
    surv = (np.arange(w) + 0.5) / w
    top = max(4, int(tail_fraction * w))
    x, y = m[:top], np.log(surv[:top])
    if np.ptp(x) <= 0.0:
        return math.nan, math.nan, top
    slope, intercept = np.polyfit(x, y, 1)
    return float(intercept), float(-slope), top


def tail_threshold(maxima: np.ndarray, p_target: float, tail_fraction: float = TAIL_FRACTION) -> TailFit:
    """Threshold h with P(window maximum > h) = p_target from an exponential fit to the upper tail."""
    m = np.asarray(maxima, dtype=float)
    a, theta, top = fit_tail(m, tail_fraction)
    top_max = float(np.max(m))
    if not theta > 0.0:  # degenerate maxima (all equal, or no tail): stay above everything seen
        return TailFit(top_max * 2.0 + 1.0, a, theta, top, len(m), top_max)
    h = (a - math.log(p_target)) / theta
    return TailFit(float(max(h, 0.0)), a, theta, top, len(m), top_max)


#: the excess tail's start: exponential beyond this quantile (a generalised Pareto tail of shape 0)
EXCESS_TAIL_QUANTILE = 0.9


def excess_tail_threshold(values: Sequence[float], alpha: float, quantile: float = EXCESS_TAIL_QUANTILE) -> dict:
    """The value a healthy statistic exceeds with probability ``alpha``: the empirical ``quantile`` u, and beyond
    it an exponential tail with the mean excess over u as its scale (the generalised Pareto tail of shape 0,
    fitted by maximum likelihood): u + scale ln((1 - quantile) / alpha). For single values (the estimator's
    confirmation statistics, the spike level), where :func:`tail_threshold` fits window maxima."""
    v = np.sort(np.asarray([x for x in values if math.isfinite(x)], dtype=float))
    if len(v) < 20:
        raise ValueError(f"{len(v)} null values: too few to place a margin (20 at least)")
    u = float(np.quantile(v, quantile))
    excess = v[v > u] - u
    scale = float(excess.mean()) if len(excess) else 0.0
    scale = max(scale, 0.5)  # never below the chi-square(1)/2 tail's own scale, a well-specified model's
    return {"threshold": round(u + scale * math.log((1.0 - quantile) / alpha), 3), "u": round(u, 3),
            "scale": round(scale, 3), "n": int(len(v))}


def tail_probability(maxima: np.ndarray, threshold: float) -> float:
    """P(window maximum > threshold) from the tail fit (for held-out checks of a calibration)."""
    a, theta, _ = fit_tail(maxima)
    return math.exp(a - theta * threshold) if theta > 0.0 else math.nan


def window_maxima(z: np.ndarray, window: int) -> np.ndarray:
    """Maximum of a CUSUM started afresh in each full window of increments z (1-D)."""
    n = (len(z) // window) * window
    if n == 0:
        return np.empty(0)
    c = np.cumsum(z[:n].reshape(-1, window), axis=1)
    s = c - np.minimum(np.minimum.accumulate(c, axis=1), 0.0)
    return s.max(axis=1)
