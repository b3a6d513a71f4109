"""Choudhury's higher-order statistics test and the PV-OP ellipse for the apparent stiction.

* :func:`ngi_nli` - Choudhury, Shah & Thornhill (2004), "Diagnosis of poor control-loop performance
  using higher-order statistics", Automatica 40, 1719-1728. The squared bicoherence

      bic^2(f1, f2) = |E[X(f1) X(f2) X*(f1 + f2)]|^2 / (E|X(f1) X(f2)|^2 E|X(f1 + f2)|^2)

  is estimated from K Hanning-windowed, half-overlapping segments of the control error over the
  principal domain (0 < f2 <= f1, f1 + f2 <= 1/2; segments of 64 samples for records under 2000
  samples, else 128). A Gaussian linear signal has bic^2 = 0; the estimate of a zero bicoherence is
  chi^2(2) / (2K) distributed (mean 1/K, alpha = 0.05 quantile bic^2_crit = chi^2_alpha(2) / (2K)).
  Non-Gaussianity index: Choudhury et al. subtract bic^2_crit from an average of the bicoherence;
  on records of 751 samples (K = 22) the averages of significant or robust values do not separate
  a limit cycle from noise, so here NGI = mean(bic^2) - 1/K, the excess over the Gaussian
  expectation (their decision NGI > 0.001 kept; the classifier uses the value). Nonlinearity index, only for a
  non-Gaussian signal, NLI = |max bic^2 - (robust mean + 2 robust std of bic^2)| (> 0.01:
  nonlinear), the robust statistics over the middle 80 % of the values. Choudhury names a valve
  nonlinearity when both are positive and the loop oscillates. NLI is reported as 0 for a Gaussian
  signal (Choudhury does not compute it then).

* :func:`apparent_stiction` - Choudhury, Shah, Thornhill & Shook (2006), "Automatic detection and
  quantification of stiction in control valves", Control Eng. Practice 14, 1395-1412. OP and PV
  are band-pass filtered (frequency-domain, keeping 0.5 to 4 times the loop's frequency: the
  oscillation and its first harmonics), an ellipse is fitted to the PV-OP plot (direct least
  squares, Fitzgibbon, Pilu & Fisher 1999), and its width along the OP axis through its centre is
  the apparent stiction in OP units. Meaningful only for a nonlinear loop (NLI > 0): a linear
  oscillation also draws an ellipse, of width 2 |sin(phase)| times OP's amplitude.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.stats import chi2

from .indicators import Indicator, loop_period_s, not_applicable
from .oscillation import detrend

BIC_REF = ("Choudhury, Shah & Thornhill (2004), Automatica 40, 1719-1728: NGI > 0.001 non-Gaussian, "
           "NLI > 0.01 nonlinear")
ELLIPSE_REF = ("Choudhury, Shah, Thornhill & Shook (2006), Control Eng. Practice 14, 1395-1412: PV-OP "
               "ellipse width along OP = apparent stiction")
NGI_THRESHOLD = 0.001
NLI_THRESHOLD = 0.01
ALPHA = 0.05


def squared_bicoherence(x: np.ndarray, segment: int | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """(bic^2 over the principal domain, the (f1, f2) bin pairs, number of segments K)."""
    x = np.asarray(x, float)
    n = len(x)
    if segment is None:
        segment = 128 if n >= 2000 else 64
    step = segment // 2
    starts = range(0, n - segment + 1, step)
    win = np.hanning(segment)
    segs = np.array([detrend(x[s:s + segment]) * win for s in starts])
    k = len(segs)
    spec = np.fft.fft(segs, axis=1)
    half = segment // 2
    f1, f2 = np.meshgrid(np.arange(1, half), np.arange(1, half), indexing="ij")
    mask = (f2 <= f1) & (f1 + f2 < half)
    f1, f2 = f1[mask], f2[mask]
    x1, x2, x12 = spec[:, f1], spec[:, f2], spec[:, f1 + f2]
    num = np.abs(np.mean(x1 * x2 * np.conj(x12), axis=0)) ** 2
    den = np.mean(np.abs(x1 * x2) ** 2, axis=0) * np.mean(np.abs(x12) ** 2, axis=0)
    bic2 = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    return bic2, np.column_stack([f1, f2]), k


def ngi_nli(pv: np.ndarray, sp: np.ndarray | None, dt_s: float) -> tuple[Indicator, Indicator]:
    """NGI and NLI of the control error SP - PV (PV about its mean without SP)."""
    e = (np.asarray(sp, float) if sp is not None else np.mean(pv)) - np.asarray(pv, float)
    e = detrend(e)
    if len(e) < 256 or float(np.std(e)) <= 0:
        na = "record shorter than 256 samples" if len(e) < 256 else "control error constant"
        return not_applicable("bicoherence_ngi", na, BIC_REF), not_applicable("bicoherence_nli", na, BIC_REF)
    bic2, pairs, k = squared_bicoherence(e / np.std(e))
    thr = float(chi2.ppf(1 - ALPHA, 2)) / (2 * k)
    lo, hi = np.quantile(bic2, [0.1, 0.9])
    robust = bic2[(bic2 >= lo) & (bic2 <= hi)]
    ngi = float(np.mean(bic2)) - 1.0 / k
    nli_raw = abs(float(np.max(bic2)) - (float(np.mean(robust)) + 2 * float(np.std(robust))))
    nli = nli_raw if ngi > NGI_THRESHOLD else 0.0
    sig = bic2[bic2 > thr]
    imax = int(np.argmax(bic2))
    seg = 128 if len(e) >= 2000 else 64
    detail = {"segments": k, "critical_bic2": thr, "nli_ungated": nli_raw, "significant_share": len(sig) / len(bic2),
              "max_bic2": float(bic2[imax]),
              "max_at_f1_cycles_per_sample": pairs[imax, 0] / seg, "max_at_f2_cycles_per_sample": pairs[imax, 1] / seg}
    ngi_ind = Indicator("bicoherence_ngi", ngi, "stiction" if ngi > NGI_THRESHOLD else "no_stiction", detail,
                        BIC_REF)
    nl = ngi > NGI_THRESHOLD and nli > NLI_THRESHOLD
    nli_ind = Indicator("bicoherence_nli", nli, "stiction" if nl else "no_stiction",
                        {"non_gaussian": ngi > NGI_THRESHOLD}, BIC_REF)
    return ngi_ind, nli_ind


# ---- the PV-OP ellipse ----------------------------------------------------------------------
def band_pass(x: np.ndarray, low_cycles: float, high_cycles: float) -> np.ndarray:
    """Keep the frequencies between low and high (cycles per sample) of detrended x (FFT mask)."""
    y = detrend(np.asarray(x, float))
    spec = np.fft.rfft(y)
    f = np.fft.rfftfreq(len(y))
    spec[(f < low_cycles) | (f > high_cycles)] = 0.0
    return np.fft.irfft(spec, len(y))


def fit_ellipse(x: np.ndarray, y: np.ndarray) -> np.ndarray | None:
    """Conic coefficients (a, b, c, d, e, f) of a x^2 + b xy + c y^2 + d x + e y + f = 0 by
    Fitzgibbon, Pilu & Fisher's (1999) direct least-squares ellipse fit (Halir & Flusser's
    numerically stable form); None when the points do not make an ellipse."""
    d1 = np.column_stack([x * x, x * y, y * y])
    d2 = np.column_stack([x, y, np.ones_like(x)])
    s1, s2, s3 = d1.T @ d1, d1.T @ d2, d2.T @ d2
    try:
        t = -np.linalg.solve(s3, s2.T)
    except np.linalg.LinAlgError:
        return None
    m = s1 + s2 @ t
    m = np.array([m[2] / 2, -m[1], m[0] / 2])
    try:
        w, v = np.linalg.eig(m)
    except np.linalg.LinAlgError:
        return None
    v = np.real(v)
    cond = 4 * v[0] * v[2] - v[1] ** 2
    ok = np.flatnonzero(cond > 0)
    if len(ok) == 0:
        return None
    a1 = v[:, ok[0]]
    return np.concatenate([a1, t @ a1])


def ellipse_geometry(coef: np.ndarray) -> tuple[float, float, float]:
    """(centre x, centre y, chord length along x through the centre) of an ellipse conic."""
    a, b, c, d, e, f = coef
    den = 4 * a * c - b * b
    xc = (b * e - 2 * c * d) / den
    yc = (b * d - 2 * a * e) / den
    # a x^2 + (b yc + d) x + (c yc^2 + e yc + f) = 0
    p, q = b * yc + d, c * yc * yc + e * yc + f
    disc = p * p - 4 * a * q
    width = math.sqrt(disc) / abs(a) if disc > 0 and a != 0 else 0.0
    return float(xc), float(yc), float(width)


def ellipse_points(coef: np.ndarray, n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """Points on the ellipse (for figures)."""
    a, b, c, d, e, f = coef
    xc, yc, _ = ellipse_geometry(coef)
    th = np.linspace(0, 2 * math.pi, n)
    ux, uy = np.cos(th), np.sin(th)
    # r^2 (a ux^2 + b ux uy + c uy^2) = -(value of the conic at the centre)
    f0 = a * xc * xc + b * xc * yc + c * yc * yc + d * xc + e * yc + f
    quad = a * ux * ux + b * ux * uy + c * uy * uy
    r = np.sqrt(np.maximum(-f0 / np.where(quad != 0, quad, np.nan), 0.0))
    return xc + r * ux, yc + r * uy


def apparent_stiction(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float) -> Indicator:
    """Width of the fitted PV-OP ellipse along OP (OP units) and its share of the filtered OP's
    peak-to-peak (``value``, 0..1). ``detail`` keeps the conic (in the original units) for figures."""
    name = "ellipse_apparent_stiction"
    period_s, oscillating = loop_period_s(pv, sp, dt_s)
    if not math.isfinite(period_s):
        return not_applicable(name, "no dominant period", ELLIPSE_REF)
    fp = dt_s / period_s
    opf = band_pass(op, 0.5 * fp, min(4 * fp, 0.5))
    pvf = band_pass(pv, 0.5 * fp, min(4 * fp, 0.5))
    so, sv = float(np.std(opf)), float(np.std(pvf))
    if so <= 0 or sv <= 0:
        return not_applicable(name, "no movement in the loop's band", ELLIPSE_REF)
    coef = fit_ellipse(opf / so, pvf / sv)
    if coef is None:
        return not_applicable(name, "the PV-OP plot does not make an ellipse", ELLIPSE_REF)
    xc, yc, width = ellipse_geometry(coef)
    width_op = width * so
    span = float(np.ptp(opf))
    share = min(width_op / span, 1.0) if span > 0 else 0.0
    # conic in original (filtered, centred) units: x = OP / so, y = PV / sv
    a, b, c, d, e, f = coef
    conic = [a / so ** 2, b / (so * sv), c / sv ** 2, d / so, e / sv, f]
    return Indicator(name, share, "undetermined",
                     {"apparent_stiction_op": width_op, "filtered_op_span": span, "period_s": period_s,
                      "oscillating": oscillating, "op_mean": float(np.mean(op)), "pv_mean": float(np.mean(pv)),
                      **{f"conic_{k}": v for k, v in zip("abcdef", conic)}}, ELLIPSE_REF)
