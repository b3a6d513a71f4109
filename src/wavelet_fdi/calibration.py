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
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from phfdi_base.spec import ScenarioSpec

from .config import Calibration, DetectorSettings

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


def front_end_trace(spec: ScenarioSpec, run, settings: DetectorSettings) -> dict[str, np.ndarray]:
    """Residuals and coefficients of one healthy run through the detector's front end (no alarms)."""
    from .detector import StreamingDetector
    from .replay import run_chunks

    both = DetectorSettings(**{**settings.__dict__, "channels": ("ph", "level")})
    det = StreamingDetector(spec, provisional(both, spec.name, spec.sample_time_s), both, isolate=False,
                            record_trace=True)
    run_chunks(det, run)
    return det.trace()


def healthy_traces(spec_for_seed: Callable[[int], ScenarioSpec], seeds: Sequence[int], settings: DetectorSettings,
                   progress: Callable[[float], None] | None = None) -> list[dict[str, np.ndarray]]:
    """Front-end traces (residuals, coefficients) of simulated healthy runs, one per seed."""
    from phfdi.loop import simulate

    out = []
    for i, seed in enumerate(seeds):
        spec = spec_for_seed(seed)
        out.append(front_end_trace(spec, simulate(spec), settings))
        if progress:
            progress((i + 1) / len(seeds))
    return out


def calibrate_from_runs(paths: Sequence[str], spec: ScenarioSpec, settings: DetectorSettings | None = None,
                        progress: Callable[[float], None] | None = None, runs: Sequence | None = None) -> Calibration:
    """Calibrate on recorded healthy runs of a plant (its model: ``spec``) instead of simulations.

    ``runs``: the runs of ``paths`` already read (e.g. with a column map); read here when None."""
    from .replay import load_any

    settings = settings or DetectorSettings()
    traces = []
    for i, path in enumerate(paths):
        traces.append(front_end_trace(spec, runs[i] if runs is not None else load_any(path), settings))
        if progress:
            progress((i + 1) / len(paths))
    cal = calibrate_from_traces(traces, settings, spec.name, spec.sample_time_s, [])
    cal.sources = [str(p) for p in paths]
    return cal


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
    from .statistics import increments

    ch, band, kind = name.split(".")
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
        # up and down mean CUSUMs share one threshold: the healthy residual is symmetric, and
        # pooling their window maxima halves the fit's scatter
        group = [name]
        if name.endswith(".mean_up") or name.endswith(".mean_down"):
            base = name.rsplit(".", 1)[0]
            group = [n for n in (f"{base}.mean_up", f"{base}.mean_down") if n in names]
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


def scenario_for_seed(scenario: str, overrides: Sequence[str] = ()) -> Callable[[int], ScenarioSpec]:
    def spec(seed: int) -> ScenarioSpec:
        return load_scenario(scenario, fault="healthy", overrides=list(overrides) + [f"seed={seed}"])

    return spec


def calibrate(scenario: str = "paper", settings: DetectorSettings | None = None,
              seeds: Sequence[int] = DEFAULT_CALIBRATION_SEEDS, overrides: Sequence[str] = (),
              progress: Callable[[float], None] | None = None) -> Calibration:
    """Calibrate the detector on healthy runs of a scenario (see the module docstring)."""
    settings = settings or DetectorSettings()
    make = scenario_for_seed(scenario, overrides)
    traces = healthy_traces(make, seeds, settings, progress)
    dt = make(seeds[0]).sample_time_s
    return calibrate_from_traces(traces, settings, scenario, dt, seeds)
