"""Statistics of a pH record that say whether a simulated run looks like the recorded ones: the reading's
noise after a detrend, the shape of that noise (its autocorrelation two samples apart, the period of its
spectral hump: the stroke ripple), the meter's quantisation and how often a reading repeats.

The same functions measure the recorded runs (``benchmarks/rigsim_real_vs_sim.py``) and the simulated ones
(tests/rigsim), so the stated ranges compare like with like.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

#: the detrend: a local quadratic over this many samples (about 6 s at the rig's 0.35 s)
DETREND_SAMPLES = 17
#: the band searched for the ripple's spectral peak (Hz); the rig's Nyquist frequency is 1.44 Hz
RIPPLE_BAND_HZ = (0.3, 1.3)
#: samples whose local slope exceeds this (pH/s) are left out, with DETREND_SAMPLES either side: at a
#: titration's knee the detrend leaves the curve's shape in the residual, which is not noise
QUIET_SLOPE_PH_S = 0.03
#: the shortest quiet stretch that enters the spectrum (samples; Welch segments of this length)
SEGMENT_SAMPLES = 64


@dataclass(frozen=True)
class RunStatistics:
    """What :func:`run_statistics` measures (units in the names).

    Examples
    --------
    >>> from phfdi.rigsim import run_statistics, simulate_run
    >>> run = simulate_run("add_base_new_setting", seed=3, duration_s=300.0)
    >>> s = run_statistics(run.time_s, run.ph)
    >>> s.on_grid, round(s.quantum_ph, 2), sorted(s.to_dict())[:2]
    (True, 0.01, ['lag1_autocorrelation', 'lag2_autocorrelation'])
    """

    samples: int
    quiet_samples: int  # samples away from steep parts, on which the noise statistics are measured
    mean_dt_s: float
    noise_ph: float  # robust standard deviation (1.4826 MAD) of the detrended reading
    lag1_autocorrelation: float
    lag2_autocorrelation: float
    ripple_period_s: float  # period of the detrended reading's spectral peak within RIPPLE_BAND_HZ
    quantum_ph: float  # the finest step between readings
    on_grid: bool  # every reading a multiple of 0.01 pH
    repeat_share: float  # share of readings equal to the previous one
    longest_repeat: int  # most identical readings in a row

    def to_dict(self) -> dict:
        return asdict(self)


def detrended(time_s: np.ndarray, ph: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reading minus a local quadratic (Savitzky-Golay over :data:`DETREND_SAMPLES` samples), and the
    mask of quiet samples (local slope below :data:`QUIET_SLOPE_PH_S`, away from steep parts)."""
    from scipy.ndimage import binary_dilation
    from scipy.signal import savgol_filter

    ph = np.asarray(ph, dtype=float)
    dt = float(np.mean(np.diff(time_s)))
    residual = ph - savgol_filter(ph, DETREND_SAMPLES, 2, mode="interp")
    slope = savgol_filter(ph, DETREND_SAMPLES, 2, deriv=1, delta=dt, mode="interp")
    steep = binary_dilation(np.abs(slope) > QUIET_SLOPE_PH_S, iterations=DETREND_SAMPLES)
    return residual, ~steep


def _autocorrelation(e: np.ndarray, quiet: np.ndarray, lag: int) -> float:
    """Autocorrelation at ``lag`` over the pairs of quiet samples."""
    both = quiet[:-lag] & quiet[lag:]
    if both.sum() < 10:
        return float("nan")
    m = e[quiet].mean()
    den = float(np.mean((e[quiet] - m) ** 2))
    return float(np.mean((e[:-lag][both] - m) * (e[lag:][both] - m)) / den) if den > 0 else float("nan")


def _segments(quiet: np.ndarray, least: int) -> list[slice]:
    edges = np.flatnonzero(np.diff(np.r_[0, quiet.astype(int), 0]))
    return [slice(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a >= least]


def ripple_period_s(time_s: np.ndarray, residual: np.ndarray, quiet: np.ndarray) -> float:
    """The period (s) of the largest peak of the residual's spectrum within :data:`RIPPLE_BAND_HZ`: Welch
    periodograms of the quiet stretches (:data:`SEGMENT_SAMPLES`-sample segments, 0.045 Hz per bin at the
    rig's interval) averaged with their lengths as weights."""
    from scipy.signal import welch

    dt = float(np.mean(np.diff(time_s)))
    total, weight, f = None, 0, None
    for seg in _segments(quiet, SEGMENT_SAMPLES):
        e = residual[seg]
        f, p = welch(e - e.mean(), fs=1.0 / dt, nperseg=SEGMENT_SAMPLES)
        total = p * len(e) if total is None else total + p * len(e)
        weight += len(e)
    if total is None or f is None:
        return float("nan")
    band = (f >= RIPPLE_BAND_HZ[0]) & (f <= RIPPLE_BAND_HZ[1])
    return float(1.0 / f[band][int(np.argmax(total[band]))])


def run_statistics(time_s: np.ndarray, ph: np.ndarray) -> RunStatistics:
    """The statistics of one record's reading (time in s, pH as recorded).

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.rigsim import run_statistics
    >>> t = np.arange(2000) * 0.35
    >>> ph = np.round(7.0 + 0.001 * t + np.random.default_rng(0).normal(0, 0.03, 2000), 2)
    >>> s = run_statistics(t, ph)  # white noise: the detrend alone makes lags 1 and 2 read about -0.16
    >>> 0.025 < s.noise_ph < 0.035, s.on_grid, round(s.lag1_autocorrelation, 2), round(s.lag2_autocorrelation, 2)
    (True, True, -0.16, -0.16)
    """
    t = np.asarray(time_s, dtype=float)
    ph = np.asarray(ph, dtype=float)
    e, quiet = detrended(t, ph)
    q = e[quiet] if quiet.sum() >= 10 else e
    mad = float(np.median(np.abs(q - np.median(q))))
    steps = np.abs(np.diff(ph))
    steps = steps[steps > 1e-9]
    same = np.diff(ph) == 0.0
    longest, run = 0, 0
    for s in same.tolist():
        run = run + 1 if s else 0
        longest = max(longest, run)
    return RunStatistics(
        samples=len(ph), quiet_samples=int(quiet.sum()), mean_dt_s=float(np.mean(np.diff(t))),
        noise_ph=1.4826 * mad, lag1_autocorrelation=_autocorrelation(e, quiet, 1),
        lag2_autocorrelation=_autocorrelation(e, quiet, 2), ripple_period_s=ripple_period_s(t, e, quiet),
        quantum_ph=float(steps.min()) if len(steps) else float("nan"),
        on_grid=bool(np.all(np.abs(ph * 100.0 - np.round(ph * 100.0)) < 1e-6)),
        repeat_share=float(same.mean()), longest_repeat=longest + 1 if longest else 1)
