"""Thresholds for a false-alarm target, measured on healthy runs.

Procedure (reproducible: the seeds are stored in the file):

1. simulate the scenario healthy with each calibration seed (seeds distinct
   from the evaluation's) and run the detector's front end on it: residuals
   and their wavelet coefficients after the warm-up;
2. sigma per channel and band = RMS of the coefficients (healthy mean 0);
3. cut the monitored stream of each statistic into windows of L samples and
   run the CUSUM afresh in each window; M_w = the window's maximum;
4. fit an exponential tail P(M > h) = exp(a - theta h) to the upper half of
   the M_w (CUSUM maxima have exponential tails; the up and down mean CUSUMs
   of a band are pooled, the healthy residual being symmetric) and solve
   P(M > h) = L / ARL0_stat for h: an alarm within a window of L samples
   has probability about L / ARL when ARL >> L;
5. ARL0 is the target for the whole detector, which alarms when any of its
   n statistics crosses: each statistic gets ARL0_stat = n ARL0 (Bonferroni;
   conservative since the statistics are correlated).

The same window maxima and tail fit calibrate the peer detectors of the
evaluation (:mod:`wavelet_fdi.peers`), so every detector is held to the same
false-alarm rate on the same residual streams.

This module holds the statistics (steps 2-5, :func:`calibrate_from_traces`);
simulating the healthy runs and running the front end on them (step 1) is the
application's (:mod:`phfdi.calibration`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from phfdi_base.errors import UserError

from .config import Calibration, DetectorSettings
from .statistics import CusumBank, increments, parse_statistic

#: seeds of the calibration runs: disjoint from the evaluation's (1..99)
DEFAULT_CALIBRATION_SEEDS = tuple(range(1001, 1017))
WINDOW_SAMPLES = 1000
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


def provisional(settings: DetectorSettings, scenario: str, dt_s: float) -> Calibration:
    """Unit sigmas and infinite thresholds: runs the detector's front end without alarms."""
    bands = settings.bands() + ["raw"]
    names = [n for rb in (True, False) for n in
             DetectorSettings(**{**settings.__dict__, "channels": ("ph", "level"), "raw_band": rb}).statistic_names()]
    return Calibration(scenario, settings.wavelet, settings.level, dt_s, settings.arl0_samples,
                       {ch: {b: 1.0 for b in bands} for ch in ("ph", "level")},
                       {n: math.inf for n in names})


def measure_sigma(traces: list[dict[str, np.ndarray]], bands: list[str]) -> dict[str, dict[str, float]]:
    sigma: dict[str, dict[str, float]] = {}
    for ch, key in (("ph", "ph_residual"), ("level", "level_residual_cm")):
        mask = np.concatenate([t[f"{ch}_monitored"] for t in traces])
        coef = np.concatenate([t[f"{ch}_coefficients"] for t in traces])[mask]
        raw = np.concatenate([t[key] for t in traces])[mask]
        if len(raw) == 0:
            raise UserError(f"calibration runs have no usable {ch} samples after the warm-up")
        sigma[ch] = {b: float(np.sqrt(np.mean(coef[:, j] ** 2))) for j, b in enumerate(bands)}
        sigma[ch]["raw"] = float(np.sqrt(np.mean(raw**2)))
    return sigma


def statistic_increments(trace: dict[str, np.ndarray], name: str, sigma: dict[str, dict[str, float]],
                         settings: DetectorSettings) -> np.ndarray:
    """Increments of one detector statistic on the monitored samples of a trace."""

    ch, band, kind = parse_statistic(name)
    j = settings.rows().index(band)
    mask = trace[f"{ch}_monitored"]
    u = trace[f"{ch}_coefficients"][mask, j] / sigma[ch]["raw" if band == "R" else band]
    return increments(kind, u, settings.reference_value(name))


def calibrate_from_traces(traces: list[dict[str, np.ndarray]], settings: DetectorSettings, scenario: str,
                          dt_s: float, seeds: Sequence[int], window: int = WINDOW_SAMPLES) -> Calibration:
    sigma = measure_sigma(traces, settings.bands())
    names = settings.statistic_names()
    p_target = window / (settings.arl0_samples * len(names))
    thresholds, fits = {}, {}
    for name in names:
        if name in thresholds:
            continue
        # statistics of one group share one threshold (up and down mean CUSUMs: the healthy residual is
        # symmetric, and pooling their window maxima halves the fit's scatter)
        group = settings.threshold_group(name)
        maxima = np.concatenate([window_maxima(statistic_increments(t, g, sigma, settings), window)
                                 for t in traces for g in group])
        fit = tail_threshold(maxima, p_target)
        for g in group:
            thresholds[g] = fit.threshold
            fits[g] = fit.as_dict()
    n_samples = int(sum(int(np.count_nonzero(t["ph_monitored"])) for t in traces))
    return Calibration(
        scenario=scenario, wavelet=settings.wavelet, level=settings.level, sample_time_s=dt_s,
        arl0_samples=settings.arl0_samples, sigma=sigma, thresholds=thresholds,
        design={"mean_shift_sigma": settings.mean_shift_sigma, "variance_ratio": settings.variance_ratio,
                "arl0_samples": settings.arl0_samples, "warmup_s": settings.warmup_s,
                "channels": list(settings.channels), "raw_band": settings.raw_band},
        seeds=[int(s) for s in seeds], healthy_samples=n_samples, window_samples=window,
        method=(f"window maxima of CUSUMs restarted every {window} samples, exponential fit to the upper "
                f"{int(100 * TAIL_FRACTION)} %, P(max > h) = {window} / (ARL0 x {len(names)} statistics)"),
        tail_fits=fits)


def alarm_positions(z: np.ndarray, h: np.ndarray, clear_samples: int, quiet_samples: int | None = None,
                    clear_fraction: float = 0.5) -> list[int]:
    """Alarms of a union of CUSUMs on increments z (n, N): the physics detector's raise/confirm/clear logic, offline
    (for checking a calibration's false-alarm rate on long records)
    (a crossing within clear_samples of the previous one confirms the alarm instead of raising one, unless the
    alarm cleared before it: every statistic below clear_fraction of its threshold for quiet_samples)."""

    out: list[int] = []
    pos, last, active, loud_last = 0, -1, False, -1
    n = z.shape[1]
    bank = CusumBank(z.shape[0])
    while pos < n:
        end = min(n, pos + 65536)
        s = bank.update(z[:, pos:end], pos)
        over = np.flatnonzero((s > h[:, None]).any(axis=0))
        stop = end if not len(over) else pos + int(over[0]) + 1  # values after a crossing are restarted
        if quiet_samples is not None:
            gi = np.arange(pos, stop)
            loud = (s[:, :stop - pos] >= clear_fraction * h[:, None]).any(axis=0)
            last_loud = np.maximum.accumulate(np.where(loud, gi, loud_last))
            if active and ((gi - last_loud >= quiet_samples) & (gi > last)).any():
                active = False
            loud_last = int(last_loud[-1])
        if not len(over):
            pos = end
            continue
        x = stop - 1
        if not active or x - last > clear_samples:
            out.append(x)
        last, active = x, True
        bank.restart(x)
        pos = x + 1
    return out
