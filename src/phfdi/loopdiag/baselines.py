"""Published stiction tests, implemented here as baselines for the Hammerstein diagnosis.

* :func:`horch_ccf` - Horch (1999), "A simple method for detection of stiction in
  control valves", Control Eng. Practice 7, 1221-1231. In an oscillating loop
  with a self-regulating process, the cross-correlation function (CCF) between
  controller output and process output is *odd* (zero at lag 0, a quarter
  period phase shift) when a sticky valve drives the oscillation, and *even*
  (extremum at lag 0, counter-phase) when the oscillation comes from tuning or
  an external disturbance. Not for integrating processes (Horch says so).
  Automated decision (ours): with tau_l < 0 <= tau_r the CCF's zero crossings
  nearest lag 0, the oddness index psi = |tau_r + tau_l| / (tau_r - tau_l)
  is 0 for an even CCF and 1 for an odd one (for a sinusoidal CCF it is the
  phase shift over 90 degrees); stiction when psi > 0.5.

* :func:`he_curve_fit` - He, Wang, Pottmann & Qin (2007), "A curve fitting method
  for detecting valve stiction in oscillating control loops", Ind. Eng. Chem.
  Res. 46, 4549-4560. Each half cycle of the output of the first integrator
  after the valve (OP for self-regulating processes, PV for integrating ones)
  is fitted with a triangle and with a sinusoid; the stiction index
  SI = MSE_sin / (MSE_sin + MSE_tri) is <= 0.4 for no stiction, >= 0.6 for
  stiction, undetermined between.

Both need an oscillating loop: a loop that does not oscillate gets no index
(``index`` None) and counts as "no stiction" in the evaluation, as it would in
a plant's monitoring system that runs them after an oscillation detector.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import correlate

from .oscillation import detect_oscillation, detrend, zero_crossings

HORCH_THRESHOLD = 0.5
HE_LOW, HE_HIGH = 0.4, 0.6


@dataclass
class BaselineResult:
    method: str
    index: float | None
    decision: str  # "stiction", "no_stiction", "undetermined", "not_applicable", "not_oscillating"
    detail: dict

    @property
    def stiction(self) -> bool:
        return self.decision == "stiction"

    def to_dict(self) -> dict:
        d = asdict(self)
        if isinstance(d["index"], float):
            d["index"] = float(f"{d['index']:.4g}") if math.isfinite(d["index"]) else None
        return d


# ---- Horch (1999) ------------------------------------------------------------------------
def cross_correlation(u: np.ndarray, y: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """r(tau) = corr(u(k), y(k + tau)) for tau = -max_lag..max_lag (biased, normalised).

    By FFT (:func:`scipy.signal.correlate`): ``np.correlate`` computes every lag directly, O(n^2), which
    took minutes on a long record; the FFT gives the same lags (to rounding) in O(n log n)."""
    u = np.asarray(u, float) - np.mean(u)
    y = np.asarray(y, float) - np.mean(y)
    n = len(u)
    full = correlate(y, u, mode="full", method="fft") / (n * np.std(u) * np.std(y))
    mid = n - 1
    lags = np.arange(-max_lag, max_lag + 1)
    return lags, full[mid - max_lag: mid + max_lag + 1]


def horch_oddness(r: np.ndarray, lags: np.ndarray) -> float:
    """psi = |tau_r + tau_l| / (tau_r - tau_l) from the zero crossings of r nearest lag 0."""
    z = zero_crossings(r) + lags[0]
    left, right = z[z < 0], z[z >= 0]
    if len(left) == 0 or len(right) == 0:
        return math.nan
    tau_l, tau_r = float(left[-1]), float(right[0])
    return abs(tau_r + tau_l) / (tau_r - tau_l)


def horch_ccf(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float,
              process_type: str) -> BaselineResult:
    osc = detect_oscillation(pv, sp, dt_s)
    if process_type == "integrating":
        return BaselineResult("horch_ccf", None, "not_applicable",
                              {"reason": "Horch's test is for self-regulating processes"})
    if not osc.oscillating or not osc.period_s:
        return BaselineResult("horch_ccf", None, "not_oscillating", {"regularity": osc.regularity})
    period = osc.period_s / dt_s
    max_lag = int(min(len(op) // 3, max(4, round(period))))
    lags, r = cross_correlation(detrend(op), detrend(pv), max_lag)
    psi = horch_oddness(r, lags)
    if not math.isfinite(psi):
        return BaselineResult("horch_ccf", None, "undetermined", {"reason": "no CCF zero crossing near lag 0"})
    decision = "stiction" if psi > HORCH_THRESHOLD else "no_stiction"
    return BaselineResult("horch_ccf", psi, decision, {"period_s": osc.period_s, "r0": float(r[max_lag])})


# ---- He et al. (2007) ---------------------------------------------------------------------
def _triangle_mse(y: np.ndarray) -> float:
    """Best continuous two-segment line (free knot inside the half cycle): every knot's least-squares
    fit at once (stacked QR factorisations, as accurate as one lstsq per knot)."""
    n = len(y)
    if n < 3:
        return math.inf
    t = np.arange(n, dtype=float)
    knots = np.arange(1, n - 1, dtype=float)
    design = np.empty((len(knots), n, 3))
    design[:, :, 0] = 1.0
    design[:, :, 1] = t
    design[:, :, 2] = np.maximum(t[None, :] - knots[:, None], 0.0)
    q, r = np.linalg.qr(design)
    coef = np.linalg.solve(r, np.einsum("kni,n->ki", q, y)[:, :, None])
    resid = y[None, :] - (design @ coef)[:, :, 0]
    return float(np.min(np.mean(resid * resid, axis=1)))


def _sine_mse(y: np.ndarray) -> float:
    """Best half sine A sin(pi (t - t0) / L) + c with t0, L on a small grid, A and c by least squares
    (the same fit as Rossi & Scali's sine, :func:`.indicators._fit_sine`)."""
    from .indicators import _fit_sine

    return _fit_sine(y)


def he_curve_fit(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float,
                 process_type: str, max_half_cycles: int = 40) -> BaselineResult:
    osc = detect_oscillation(pv, sp, dt_s)
    if not osc.oscillating or not osc.period_s:
        return BaselineResult("he_curve_fit", None, "not_oscillating", {"regularity": osc.regularity})
    signal_name = "pv" if process_type == "integrating" else "op"
    x = detrend(np.asarray(pv if signal_name == "pv" else op, float))
    period = osc.period_s / dt_s
    # zero crossings of a lightly smoothed copy, so that noise does not cut half cycles
    smooth = uniform_filter1d(x, size=max(1, int(round(period / 10))), mode="nearest")
    z = np.floor(zero_crossings(smooth)).astype(int) + 1
    mse_sin, mse_tri = [], []
    for a, b in zip(z[:-1], z[1:]):
        seg = x[a:b]
        if len(seg) < max(5, int(0.25 * period)):  # a noise crossing, not a half cycle
            continue
        mse_sin.append(_sine_mse(seg))
        mse_tri.append(_triangle_mse(seg))
        if len(mse_sin) >= max_half_cycles:
            break
    if not mse_sin:
        return BaselineResult("he_curve_fit", None, "undetermined", {"reason": "no complete half cycle"})
    ms, mt = float(np.mean(mse_sin)), float(np.mean(mse_tri))
    si = ms / (ms + mt) if ms + mt > 0 else 0.5
    decision = "stiction" if si >= HE_HIGH else ("no_stiction" if si <= HE_LOW else "undetermined")
    return BaselineResult("he_curve_fit", si, decision,
                          {"signal": signal_name, "half_cycles": len(mse_sin), "period_s": osc.period_s})


BASELINES = {"horch_ccf": horch_ccf, "he_curve_fit": he_curve_fit}


def run_baselines(op, pv, sp, dt_s, process_type) -> dict[str, BaselineResult]:
    return {name: f(op, pv, sp, dt_s, process_type) for name, f in BASELINES.items()}
