"""What a simulation gets wrong: statistics of the residual measured - simulated.

* fit: RMSE, NRMSE = RMSE / std(measured) and fit % = 100 (1 - NRMSE);
* noise floor: the white measurement noise of a signal, from its finest
  wavelet details (median absolute deviation / 0.6745, Donoho & Johnstone
  1994), so a residual can be compared with what no model can remove;
* where: the share of the residual energy per stretch of time, and per
  wavelet scale (discrete wavelet transform, PyWavelets, ``db4``): detail
  level j holds periods of about 2^j to 2^(j+1) samples;
* what shape: a steady offset, a gain-like error (proportional to the
  simulated deviation from its mean), a pH-range-dependent error (a
  function of the simulated value that a line does not capture), a lag (a
  time shift of the simulation fits better), or coloured noise;
* tests: Ljung-Box whiteness, and cross-correlation with each input at lags
  0.. (a residual that an input can still predict means missing dynamics).
"""

from __future__ import annotations

import math

import numpy as np
import pywt
from scipy import stats

WAVELET = "db4"


def noise_floor(y: np.ndarray) -> float:
    """Standard deviation of the white noise on ``y`` (finest-scale wavelet MAD)."""
    y = np.asarray(y, dtype=float)
    _, detail = pywt.dwt(y, WAVELET, mode="symmetric")
    detail = detail[4:-4] if len(detail) > 16 else detail
    sigma = float(np.median(np.abs(detail - np.median(detail)))) / 0.6745
    if sigma <= 0.0:  # quantised, mostly flat signal: its quantisation noise
        steps = np.abs(np.diff(y))
        steps = steps[steps > 0]
        sigma = float(np.min(steps)) / math.sqrt(12.0) if len(steps) else 1e-6
    return max(sigma, 1e-9)


def fit_stats(measured: np.ndarray, simulated: np.ndarray) -> dict:
    e = measured - simulated
    rmse = float(np.sqrt(np.mean(e ** 2)))
    std = float(np.std(measured))
    nrmse = rmse / std if std > 0 else math.inf
    return {"rmse": rmse, "nrmse": nrmse, "fit_percent": 100.0 * (1.0 - nrmse), "mean_error": float(np.mean(e))}


def ljung_box(e: np.ndarray, lags: int = 20) -> dict:
    """Ljung-Box Q over ``lags`` autocorrelations and its p-value (H0: white)."""
    e = np.asarray(e, dtype=float) - np.mean(e)
    n = len(e)
    lags = min(lags, n // 4)
    den = float(np.dot(e, e))
    if den <= 0 or lags < 1:
        return {"q": 0.0, "p_value": 1.0, "lags": lags, "white": True, "structure": 0.0}
    acf = np.array([np.dot(e[:-k], e[k:]) / den for k in range(1, lags + 1)])
    q = float(n * (n + 2) * np.sum(acf ** 2 / (n - np.arange(1, lags + 1))))
    p = float(stats.chi2.sf(q, lags))
    # how much structure, whatever the record length: (Q - lags) / n ~ sum of squared autocorrelations beyond
    # what white noise of this length shows (about 0 when white; 20 f^2 for a slow error holding a share f of
    # the variance)
    return {"q": q, "p_value": p, "lags": lags, "white": p > 0.01, "structure": max(0.0, (q - lags) / n)}


def input_correlation(e: np.ndarray, inputs: dict[str, np.ndarray], dt_s: float, max_lag: int = 50) -> dict:
    """Largest |cross-correlation| of the residual with each input's changes at lags 0..max_lag.

    Input changes (first differences) rather than levels: levels of a slow
    input correlate with any slow residual. Significant above 2.58 / sqrt(n)
    (99 %, for a white residual; a coloured one exceeds it more often).
    """
    e = np.asarray(e, dtype=float)
    e = e - e.mean()
    n = len(e)
    bound = 2.58 / math.sqrt(n)
    out = {}
    for name, u in inputs.items():
        du = np.diff(np.asarray(u, dtype=float), prepend=u[0])
        du = du - du.mean()
        den = math.sqrt(float(np.dot(e, e)) * float(np.dot(du, du)))
        if den <= 0:
            out[name] = {"max_abs_corr": 0.0, "lag_s": 0.0, "significant": False, "bound": bound}
            continue
        best, best_lag = 0.0, 0
        for k in range(0, min(max_lag, n // 4) + 1):
            c = float(np.dot(du[: n - k], e[k:])) / den
            if abs(c) > abs(best):
                best, best_lag = c, k
        out[name] = {"max_abs_corr": abs(best), "lag_s": best_lag * dt_s, "significant": abs(best) > bound,
                     "bound": bound}
    return out


def scale_energy(e: np.ndarray, dt_s: float) -> list[dict]:
    """Share of residual energy per wavelet scale (detail levels, then the approximation)."""
    e = np.asarray(e, dtype=float)
    level = max(1, min(pywt.dwt_max_level(len(e), WAVELET), 12))
    coeffs = pywt.wavedec(e, WAVELET, level=level, mode="periodization")
    energies = [float(np.sum(c ** 2)) for c in coeffs]
    total = sum(energies) or 1.0
    out = []
    for j in range(1, level + 1):  # coeffs[-j] is detail level j
        out.append({"level": j, "period_s": [dt_s * 2 ** j, dt_s * 2 ** (j + 1)],
                    "share": energies[-j] / total})
    out.append({"level": "approximation", "period_s": [dt_s * 2 ** (level + 1), math.inf],
                "share": energies[0] / total})
    return out


def time_energy(e: np.ndarray, time_s: np.ndarray, windows: int = 10) -> list[dict]:
    """Share of residual energy per stretch of the record."""
    edges = np.linspace(0, len(e), windows + 1).astype(int)
    total = float(np.sum(e ** 2)) or 1.0
    return [{"start_s": float(time_s[a]), "end_s": float(time_s[b - 1]), "share": float(np.sum(e[a:b] ** 2)) / total}
            for a, b in zip(edges[:-1], edges[1:]) if b > a]


def best_shift(measured: np.ndarray, simulated: np.ndarray, max_shift: int) -> tuple[int, float]:
    """Shift (samples, + = measurement later) of the simulation that minimises the RMSE, and that RMSE."""
    n = len(measured)
    best = (0, float(np.sqrt(np.mean((measured - simulated) ** 2))))
    for s in range(-max_shift, max_shift + 1):
        if s == 0 or abs(s) >= n // 2:
            continue
        if s > 0:
            r = measured[s:] - simulated[:-s]
        else:
            r = measured[:s] - simulated[-s:]
        rmse = float(np.sqrt(np.mean(r ** 2)))
        if rmse < best[1]:
            best = (s, rmse)
    return best


def characterise(measured: np.ndarray, simulated: np.ndarray, time_s: np.ndarray, noise: float,
                 unit: str) -> dict:
    """Shape of the misfit: shares of its energy explained by an offset, a gain, a range function, a lag."""
    e = measured - simulated
    dt = float(time_s[1] - time_s[0])
    mse = float(np.mean(e ** 2))
    structured = max(mse - noise ** 2, 0.0)
    out: dict = {"rmse": math.sqrt(mse), "noise_floor": noise, "rmse_over_noise": math.sqrt(mse) / noise,
                 "findings": []}
    if structured <= 0.25 * noise ** 2 or mse <= 0:
        out["findings"].append({"kind": "white", "share": 1.0,
                                "text": f"the residual is at the noise floor ({math.sqrt(mse):.3g} {unit} RMS, "
                                        f"noise {noise:.3g} {unit})"})
        return out
    mean = float(np.mean(e))
    offset_share = mean ** 2 / mse
    x = simulated - np.mean(simulated)
    sxx = float(np.dot(x, x))
    beta = float(np.dot(x, e - mean)) / sxx if sxx > 0 else 0.0
    gain_share = (beta ** 2 * sxx / len(e)) / mse
    # range dependence: mean residual per bin of the simulated value, beyond the line
    lin = e - mean - beta * x
    bins = np.unique(np.quantile(simulated, np.linspace(0, 1, 9)))
    if len(bins) > 2:
        idx = np.clip(np.digitize(simulated, bins[1:-1]), 0, len(bins) - 2)
        means = np.array([lin[idx == b].mean() if np.any(idx == b) else 0.0 for b in range(len(bins) - 1)])
        range_share = float(np.mean(means[idx] ** 2)) / mse
        worst = int(np.argmax(np.abs(means)))
        worst_band = (float(bins[worst]), float(bins[worst + 1]))
    else:
        range_share, worst_band = 0.0, (float(simulated.min()), float(simulated.max()))
    shift, shift_rmse = best_shift(measured, simulated, max(1, min(len(e) // 10, int(round(600.0 / dt)))))
    lag_share = max(0.0, 1.0 - shift_rmse ** 2 / mse) if shift != 0 else 0.0
    lb = ljung_box(e)
    share_struct = structured / mse
    findings = []
    if offset_share > 0.3:
        findings.append({"kind": "offset", "share": offset_share,
                         "text": f"a steady offset of {mean:+.3g} {unit} ({100 * offset_share:.0f} % of the misfit "
                                 f"energy)"})
    if gain_share > 0.2:
        findings.append({"kind": "gain", "share": gain_share,
                         "text": f"gain-like: the measurement moves {1 + beta:.3g} times as far as the simulation "
                                 f"about its mean ({100 * gain_share:.0f} %)"})
    if range_share > 0.2:
        findings.append({"kind": "range", "share": range_share,
                         "text": f"depends on the operating range: largest where the simulation reads "
                                 f"{worst_band[0]:.3g} to {worst_band[1]:.3g} {unit} ({100 * range_share:.0f} % "
                                 f"beyond offset and gain)"})
    if lag_share > 0.2:
        findings.append({"kind": "lag", "share": lag_share,
                         "text": f"a lag: the measurement {'trails' if shift > 0 else 'leads'} the simulation by "
                                 f"about {abs(shift) * dt:.3g} s (shifting removes {100 * lag_share:.0f} % of the "
                                 f"misfit energy)"})
    if not findings:
        findings.append({"kind": "coloured", "share": share_struct,
                         "text": f"coloured: structured error above the noise floor without a simple shape "
                                 f"(Ljung-Box p = {lb['p_value']:.2g})"})
    out.update({"offset": mean, "offset_share": offset_share, "gain_error": beta, "gain_share": gain_share,
                "range_share": range_share, "lag_s": shift * dt, "lag_share": lag_share,
                "structured_share": share_struct, "findings": sorted(findings, key=lambda f: -f["share"])})
    return out


def analyse(measured: np.ndarray, simulated: np.ndarray, time_s: np.ndarray, inputs: dict[str, np.ndarray],
            noise: float, unit: str) -> dict:
    """Everything about one output's residual, as a JSON-ready dict."""
    e = measured - simulated
    dt = float(time_s[1] - time_s[0])
    out = fit_stats(measured, simulated)
    out["shape"] = characterise(measured, simulated, time_s, noise, unit)
    out["scales"] = scale_energy(e, dt)
    out["time"] = time_energy(e, time_s)
    out["whiteness"] = ljung_box(e)
    out["input_correlation"] = input_correlation(e, inputs, dt)
    return out


def significance(sq_nominal: np.ndarray, sq_candidate: np.ndarray, batches: int = 20,
                 margin: float = 0.0) -> float:
    """One-sided p-value that the candidate's held-out squared error is not below the nominal's.

    ``sq_*``: per-sample squared errors. Batch means (``batches`` contiguous
    blocks) make the test robust to autocorrelated errors. With
    ``margin`` > 0 the null is "the candidate removes less than that fraction
    of the nominal's squared error".
    """
    d = np.asarray(sq_nominal) * (1.0 - margin) - np.asarray(sq_candidate)
    n = len(d)
    if n < 2 * batches:
        batches = max(2, n // 2)
    means = np.array([b.mean() for b in np.array_split(d, batches)])
    sd = float(np.std(means, ddof=1))
    if sd <= 0:
        return 0.0 if means.mean() > 0 else 1.0
    t = float(means.mean()) / (sd / math.sqrt(len(means)))
    return float(stats.t.sf(t, len(means) - 1))


def significance_f(sq_nominal: np.ndarray, sq_candidate: np.ndarray, lag1: float, k: int) -> float:
    """p-value of an F test that the candidate's held-out squared error is below the nominal's.

    The candidate's own error is the noise model: (SSE_nom - SSE_cand) / k over
    SSE_cand / n_eff, with n_eff the number of held-out samples shrunk for the
    error's lag-one autocorrelation rho by (1 - rho) / (1 + rho). Strong when a
    candidate leaves white noise (a fix that works everywhere it matters,
    however few stretches carry the misfit), weak when it leaves structure.
    """
    n = len(sq_candidate)
    sse_c = float(np.sum(sq_candidate))
    sse_n = float(np.sum(sq_nominal))
    if n < 3 or sse_c <= 0:
        return 0.0 if sse_n > sse_c else 1.0
    rho = min(max(lag1, 0.0), 0.999)
    n_eff = max(2.0, n * (1.0 - rho) / (1.0 + rho))
    k = max(k, 1)
    f = ((sse_n - sse_c) / k) / (sse_c / n_eff)
    return float(stats.f.sf(f, k, n_eff)) if f > 0 else 1.0
