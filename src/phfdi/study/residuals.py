"""Wavelet-coefficient residuals between a healthy and a faulty run (the paper's Section 7).

Both runs' pH is decomposed at level 3 (sym4 in the paper's text, db8 in
the filter-bank scheme it cites); each coefficient vector of the faulty run
minus the healthy one is a residual: Res1D, Res2D, Res3D (details of levels
1 to 3) and Res3A (approximation of level 3). A residual that leaves its
healthy band marks the fault.

Two references are compared:

- the paper's: the healthy run is the faulty run's twin (same noise
  realisation), so every residual is exactly zero until the fault acts;
- a realistic one: the healthy reference has its own noise (another seed,
  as a model or a recorded healthy run would), and the alarm threshold of
  each residual is set on a *separate* healthy-vs-healthy pair, so the
  fault onset is never used to tune the detector.

Coefficient k of level j stands for the time where its synthesis function
is centred (:func:`coefficient_times`), so residuals are plotted and
detections reported in seconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pywt

from .multisignal import pywt_mode

BANDS = ("D1", "D2", "D3", "A3")


def _band_geometry(n_samples: int, wavelet: str, level: int, mode: str) -> dict[str, tuple[float, int, int, int]]:
    """Per band: (energy centre, first and last sample of the support) of coefficient 0, and the band length.

    Measured from the reconstruction of a unit coefficient in the middle of
    the band; coefficient k sits 2**j k samples further.
    """
    coeffs = pywt.wavedec(np.zeros(n_samples), wavelet, mode=mode, level=level)
    names = [f"A{level}"] + [f"D{j}" for j in range(level, 0, -1)]
    samples = np.arange(n_samples)
    out = {}
    for b, name in enumerate(names):
        j = level if name.startswith("A") else int(name[1:])
        k0 = len(coeffs[b]) // 2
        unit = [np.zeros_like(c) for c in coeffs]
        unit[b][k0] = 1.0
        r = pywt.waverec(unit, wavelet, mode=mode)[:n_samples]
        support = np.nonzero(np.abs(r) > 1e-12 * np.max(np.abs(r)))[0]
        shift = k0 * 2 ** j
        centre = float(np.sum(samples * r * r) / np.sum(r * r))
        out[name] = (centre - shift, int(support[0]) - shift, int(support[-1]) - shift, len(coeffs[b]))
    return out


def coefficient_times(n_samples: int, wavelet: str, level: int, mode: str = "symmetric",
                      dt_s: float = 1.0, t0_s: float = 0.0, anchor: str = "centre") -> dict[str, np.ndarray]:
    """Time (s) each coefficient stands for, per band ('D1'.. 'Dlevel', 'Alevel').

    ``anchor='centre'``: the centre of energy of its synthesis function
    (where the coefficient looks; for plots); ``'end'``: the last sample it
    depends on (when it can first be computed; for alarm times).
    Consecutive coefficients are 2**j samples apart.
    """
    if anchor not in ("centre", "end"):
        raise ValueError(f"anchor must be 'centre' or 'end', got {anchor!r}")
    out = {}
    for name, (centre, _, last, n_c) in _band_geometry(n_samples, wavelet, level, pywt_mode(mode)).items():
        j = level if name.startswith("A") else int(name[1:])
        at = centre if anchor == "centre" else last
        out[name] = t0_s + dt_s * (at + 2 ** j * np.arange(n_c))
    return out


def interior(n_samples: int, wavelet: str, level: int, mode: str = "symmetric") -> dict[str, np.ndarray]:
    """Per band, which coefficients depend on recorded samples only (not on the boundary extension)."""
    out = {}
    for name, (_, first, last, n_c) in _band_geometry(n_samples, wavelet, level, pywt_mode(mode)).items():
        j = level if name.startswith("A") else int(name[1:])
        k = 2 ** j * np.arange(n_c)
        out[name] = (k + first >= 0) & (k + last <= n_samples - 1)
    return out


def band_coefficients(x: np.ndarray, wavelet: str = "sym4", level: int = 3,
                      mode: str = "symmetric") -> dict[str, np.ndarray]:
    """{'A3': cA3, 'D3': cD3, 'D2': cD2, 'D1': cD1} of one signal (MATLAB wavedec + appcoef/detcoef)."""
    coeffs = pywt.wavedec(np.asarray(x, dtype=float), wavelet, mode=pywt_mode(mode), level=level)
    names = [f"A{level}"] + [f"D{j}" for j in range(level, 0, -1)]
    return dict(zip(names, coeffs))


def moving_rms(x: np.ndarray, window: int) -> np.ndarray:
    """Trailing root-mean-square over ``window`` values (causal; shorter at the start)."""
    x2 = np.concatenate(([0.0], np.cumsum(np.asarray(x, dtype=float) ** 2)))
    k = np.arange(1, len(x) + 1)
    lo = np.maximum(k - window, 0)
    return np.sqrt((x2[k] - x2[lo]) / (k - lo))


@dataclass
class ResidualSet:
    """Coefficients of both runs and their residuals, per band, with the coefficient times."""

    wavelet: str
    level: int
    mode: str
    #: centre of each coefficient (plots) and when it can first be computed (alarms), s
    times_s: dict[str, np.ndarray]
    available_s: dict[str, np.ndarray]
    #: coefficients that do not lean on the boundary extension (the only ones alarms use)
    interior: dict[str, np.ndarray]
    healthy: dict[str, np.ndarray]
    faulty: dict[str, np.ndarray]
    residual: dict[str, np.ndarray]
    lengths: list[int] = field(default_factory=list)
    reconstruction_error: float = 0.0


def residuals(healthy: np.ndarray, faulty: np.ndarray, wavelet: str = "sym4", level: int = 3,
              mode: str = "symmetric", dt_s: float = 1.0, t0_s: float = 0.0) -> ResidualSet:
    """Res1D .. Res{level}D and Res{level}A of ``faulty - healthy`` (same length and time base)."""
    healthy = np.asarray(healthy, dtype=float)
    faulty = np.asarray(faulty, dtype=float)
    if healthy.shape != faulty.shape:
        raise ValueError(f"healthy has {healthy.shape} samples, faulty {faulty.shape}")
    h = band_coefficients(healthy, wavelet, level, mode)
    f = band_coefficients(faulty, wavelet, level, mode)
    times = coefficient_times(len(faulty), wavelet, level, mode, dt_s, t0_s)
    available = coefficient_times(len(faulty), wavelet, level, mode, dt_s, t0_s, anchor="end")
    inside = interior(len(faulty), wavelet, level, mode)
    res = {b: f[b] - h[b] for b in f}
    coeffs = [f[f"A{level}"]] + [f[f"D{j}"] for j in range(level, 0, -1)]
    rec = pywt.waverec(coeffs, wavelet, mode=pywt_mode(mode))[: len(faulty)]
    return ResidualSet(pywt.Wavelet(wavelet).name, level, pywt_mode(mode), times, available, inside, h, f, res,
                       [len(c) for c in coeffs] + [len(faulty)], float(np.max(np.abs(rec - faulty))))


@dataclass
class Detection:
    """Alarms of one residual band against its threshold."""

    band: str
    threshold: float
    #: time (s) of the first alarm, None if the statistic never exceeds the threshold
    first_alarm_s: float | None
    #: when the onset is known: alarms before it (false alarms) and the first alarm at or after it
    false_alarms: int = 0
    first_after_onset_s: float | None = None


def detect(res: ResidualSet, thresholds: dict[str, float], window: int = 1,
           onset_s: float | None = None) -> dict[str, Detection]:
    """Alarms where the |residual| (or its trailing RMS over ``window`` coefficients) exceeds the threshold.

    An alarm is dated when its coefficient can first be computed (the last
    sample it depends on). ``onset_s`` is used only to score the alarms
    (false alarms before it, delay after it), never to place them.
    """
    out = {}
    for band, r in res.residual.items():
        stat = np.abs(r) if window <= 1 else moving_rms(r, window)
        t = res.available_s[band]
        alarm = (stat > thresholds[band]) & res.interior[band]
        first = float(t[np.argmax(alarm)]) if alarm.any() else None
        det = Detection(band, thresholds[band], first)
        if onset_s is not None:
            det.false_alarms = int(np.sum(alarm & (t < onset_s)))
            after = alarm & (t >= onset_s)
            det.first_after_onset_s = float(t[np.argmax(after)]) if after.any() else None
        out[band] = det
    return out


def calibrate(res: ResidualSet, window: int = 1, margin: float = 1.2) -> dict[str, float]:
    """Thresholds from a healthy-vs-healthy residual set: ``margin`` times the largest statistic seen."""
    out = {}
    for band, r in res.residual.items():
        stat = np.abs(r) if window <= 1 else moving_rms(r, window)
        out[band] = float(margin * np.max(stat[res.interior[band]]))
    return out
