"""The whole offline analysis of the paper's Sections 6 and 7 as numbers (no figures, no files).

:func:`analyze_multisignal` runs Section 6 on a multisignal: row
decomposition, approximations, denoising (every rule, levels 5 and 7),
compression, clustering, variance change points and the severity read from
level-3 residuals. :func:`analyze_pair` runs Section 7 on one healthy and
one faulty run. :mod:`phfdi.study.report` turns the results into figures and
REPORT.md; ``benchmarks/analysis.py`` times :func:`analyze_multisignal`.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import changepoint, cluster, compress, denoise, residuals
from .multisignal import Decomposition, Multisignal, decompose, reconstruction_error


@dataclass
class Options:
    """Settings of the analysis (defaults: the paper's)."""

    wavelet: str = "sym4"
    level: int = 7
    mode: str = "symmetric"
    #: denoising levels compared (the paper's Figures 30 to 32)
    denoise_levels: tuple[int, ...] = (5, 7)
    denoise_rule: str = "universal"
    shrink: str = "soft"
    noise: str = "level"
    retain: float = 0.99
    #: None: chosen by silhouette
    n_clusters: int | None = 3
    cluster_seed: int = 0
    max_changes: int = 6
    min_distance: int = 10
    #: fraction of the record at each end where "bumps" are measured
    edge_fraction: float = 0.05
    #: Section 7
    residual_level: int = 3
    residual_wavelets: tuple[str, ...] = ("sym4", "db8")
    #: trailing window (coefficients) of the realistic residual detector, and its threshold margin
    detect_window: int = 8
    detect_margin: float = 1.2
    #: a variance change point this close to the fault onset (s) counts as finding it
    onset_tolerance_s: float = 200.0


def _rms(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    return np.sqrt(np.mean(np.square(x), axis=axis))


def edge_errors(approx: np.ndarray, reference: np.ndarray, fraction: float) -> dict[str, float]:
    """RMS error (signal units) over the whole record, over its first and last ``fraction``, mean over rows."""
    n = reference.shape[1]
    m = max(1, int(round(fraction * n)))
    err = approx - reference
    return {
        "rms_all": float(np.mean(_rms(err, axis=1))),
        "rms_start": float(np.mean(_rms(err[:, :m], axis=1))),
        "rms_end": float(np.mean(_rms(err[:, -m:], axis=1))),
        "max_abs_edges": float(np.max(np.abs(np.hstack([err[:, :m], err[:, -m:]])))),
    }


def residual_noise_stats(residual: np.ndarray, sigma: np.ndarray) -> dict[str, float]:
    """Does a denoising residual look like noise: its std over the estimated noise sigma, and its
    lag-1 autocorrelation (0 for white noise), mean over rows; the largest |residual| / sigma."""
    r = residual - residual.mean(axis=1, keepdims=True)
    var = np.sum(r * r, axis=1)
    lag1 = np.sum(r[:, 1:] * r[:, :-1], axis=1) / np.where(var > 0, var, 1.0)
    s = np.where(sigma > 0, sigma, np.nan)
    return {
        "std_over_sigma": float(np.nanmean(r.std(axis=1) / s)),
        "lag1_autocorrelation": float(np.mean(lag1)),
        "max_abs_over_sigma": float(np.nanmax(np.max(np.abs(r), axis=1) / s)),
    }


def _by_class(ms: Multisignal, fn) -> dict[str, Any]:
    """``fn(row_indices)`` over all rows ("all") and over each class's rows."""
    out = {"all": fn(np.arange(ms.shape[0]))}
    out.update({label: fn(ms.rows(label)) for label in ms.classes})
    return out


def _cluster_runs(features: dict[str, np.ndarray], ms: Multisignal, opts: Options,
                  paper_grouping: dict[str, int] | None) -> dict[str, Any]:
    true_codes = ms.label_codes()
    paper_codes = None
    if paper_grouping and all(lab in paper_grouping for lab in ms.labels):
        paper_codes = np.array([paper_grouping[lab] for lab in ms.labels])
    out: dict[str, Any] = {"runs": [], "silhouette": {}}
    n_rows = ms.shape[0]
    if n_rows < 3:
        return out
    for fname, feats in features.items():
        chosen, scores = cluster.choose_n_clusters(feats, range(2, min(9, n_rows)), "hierarchical")
        out["silhouette"][fname] = {int(k): float(v) for k, v in scores.items()}
        for method in cluster.METHODS:
            for k_source, k in (("given", opts.n_clusters), ("silhouette", chosen)):
                if k is None or not 1 <= k <= n_rows:
                    continue
                labels = cluster.cluster(feats, k, method, opts.cluster_seed)
                classes, table = cluster.contingency(labels, ms.labels)
                out["runs"].append({
                    "features": fname, "method": method, "k_source": k_source, "k": int(k),
                    "labels": labels.tolist(),
                    "ari_paper": None if paper_codes is None else cluster.adjusted_rand_index(labels, paper_codes),
                    "ari_classes": cluster.adjusted_rand_index(labels, true_codes),
                    "classes": classes, "table": table.tolist(),
                })
    return out


def analyze_multisignal(ms: Multisignal, opts: Options | None = None,
                        paper_grouping: dict[str, int] | None = None) -> dict[str, Any]:
    """Section 6 on a multisignal; returns plain numbers and arrays (for the report and the tests)."""
    opts = opts or Options()
    x = ms.data
    reference = ms.truth if ms.truth is not None else None
    out: dict[str, Any] = {"shape": list(ms.shape), "labels": list(ms.labels), "names": list(ms.names)}

    # -- decomposition (Figure 29's structure) and approximations (Figures 30, 31)
    dec = decompose(x, opts.wavelet, opts.level, opts.mode)
    out["decomposition"] = {
        "wavelet": dec.wavelet, "level": dec.level, "mode": dec.mode,
        "ca_shape": list(dec.ca.shape), "cd_shapes": [list(d.shape) for d in dec.cd],
        "lengths": dec.lengths(), "reconstruction_error": reconstruction_error(dec, x),
    }
    approx = {lev: dec.approximation(lev) for lev in sorted({opts.level, *opts.denoise_levels})}
    out["approximations"] = approx

    # -- denoising: the paper's setting at each level, then every rule and shrinkage
    decs = {lev: dec if lev == opts.level else decompose(x, opts.wavelet, lev, opts.mode)
            for lev in opts.denoise_levels}
    den = {lev: denoise.denoise(d_lev, opts.denoise_rule, opts.shrink, opts.noise) for lev, d_lev in decs.items()}
    out["denoised"] = {lev: d.signals for lev, d in den.items()}
    noise_sigma = {lev: d.sigma[:, 0] for lev, d in den.items()}
    out["denoise_residual"] = {
        lev: _by_class(ms, lambda idx, d=d, lev=lev: residual_noise_stats((x - d.signals)[idx], noise_sigma[lev][idx]))
        for lev, d in den.items()}
    if reference is not None:
        candidates = {f"approximation level {lev}": a for lev, a in approx.items()}
        candidates.update({f"denoised level {lev}": d.signals for lev, d in den.items()})
        candidates["measured (no processing)"] = x
        out["edges"] = {name: _by_class(ms, lambda idx, a=a: edge_errors(a[idx], reference[idx], opts.edge_fraction))
                        for name, a in candidates.items()}
        rules = {}
        for lev, d_lev in decs.items():
            for rule in denoise.RULES:
                for shrink in ("soft", "hard"):
                    sig = denoise.denoise(d_lev, rule, shrink, opts.noise).signals
                    rules[f"{rule}/{shrink}/level {lev}"] = float(np.mean(_rms(sig - reference, axis=1)))
        out["denoise_rules_rms"] = rules

    # -- compression (Figures 33, 34): as recorded, and each row about its mean
    cmp_raw = compress.compress_energy(dec, opts.retain)
    centred = x - x.mean(axis=1, keepdims=True)
    dec_c = decompose(centred, opts.wavelet, opts.level, opts.mode)
    cmp_c = compress.compress_energy(dec_c, opts.retain)
    out["compression"] = {
        "retain": opts.retain, "n_coefficients": int(dec.flat().shape[1]),
        "raw_nonzero_pct": cmp_raw.nonzero_pct, "raw_energy_pct": cmp_raw.energy_retained_pct,
        "centred_nonzero_pct": cmp_c.nonzero_pct, "centred_energy_pct": cmp_c.energy_retained_pct,
    }
    out["compressed"] = cmp_raw.signals
    out["compressed_centred"] = cmp_c.signals + x.mean(axis=1, keepdims=True)

    # -- clustering (Figures 35, 36) from wavelet representations
    feats = {
        f"ca{opts.level} (compressed)": cmp_raw.decomposition.ca,
        "compressed coefficients": cmp_raw.decomposition.flat(),
        f"denoised signal (level {opts.denoise_levels[0]})": den[opts.denoise_levels[0]].signals,
        f"detail energies D1..D{opts.level} + ca{opts.level}": _energy_features(dec),
    }
    out["clustering"] = _cluster_runs(feats, ms, opts, paper_grouping)
    out["linkage"] = {name: cluster.hierarchical(f, 1)[1] for name, f in feats.items()} if ms.shape[0] >= 2 else {}

    # -- severity from level-3 residuals against the healthy row with the same noise seed
    out["severity"] = _severity(ms, opts)
    return out


def _energy_features(dec: Decomposition) -> np.ndarray:
    """log10 of the energy per band of each row: a scale signature, blind to when things happen."""
    bands = [dec.ca] + dec.cd
    e = np.column_stack([np.sum(b * b, axis=1) for b in bands])
    return np.log10(np.maximum(e, 1e-300))


def _ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 0..n-1, ties sharing their mean rank."""
    order = np.argsort(x, kind="mergesort")
    r = np.empty(len(x))
    r[order] = np.arange(len(x))
    _, inverse = np.unique(x, return_inverse=True)
    return (np.bincount(inverse, r) / np.bincount(inverse))[inverse]


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    """Spearman rank correlation: Pearson correlation of the ranks. (Written out because importing
    scipy.stats for it costs about a second, more than the rest of the analysis.)"""
    return float(np.corrcoef(_ranks(np.asarray(x, float)), _ranks(np.asarray(y, float)))[0, 1])


def _severity(ms: Multisignal, opts: Options) -> dict[str, Any]:
    """RMS of the level-3 approximation residual (fault row - healthy row of the same seed) vs severity."""
    healthy = {info.get("seed"): i for i, (lab, info) in enumerate(zip(ms.labels, ms.info)) if lab == "healthy"}
    out: dict[str, Any] = {}
    for label in ms.classes:
        if label == "healthy":
            continue
        pts = []
        for i in ms.rows(label):
            info = ms.info[i]
            j = healthy.get(info.get("seed"))
            if j is None or "severity_factor" not in info:
                continue
            ca_f = residuals.band_coefficients(ms.data[i], opts.wavelet, opts.residual_level, opts.mode)
            ca_h = residuals.band_coefficients(ms.data[j], opts.wavelet, opts.residual_level, opts.mode)
            key = f"A{opts.residual_level}"
            pts.append((float(info["severity_factor"]), float(_rms(ca_f[key] - ca_h[key]))))
        if len(pts) >= 3:
            f, r = np.array(pts).T
            rho = spearman(f, r) if np.ptp(f) > 0 and np.ptp(r) > 0 else float("nan")
            out[label] = {"factors": f.tolist(), "res_a_rms": r.tolist(), "spearman": float(rho)}
    return out


# ---- Section 7 ----------------------------------------------------------------------------------
@dataclass
class ChangePoints:
    """Variance change points (s) found in one input of the faulty run and of a healthy counterpart."""

    input: str
    faulty_s: list[float]
    healthy_s: list[float]
    #: change nearest the onset and its error (s), None when nothing lies within the tolerance
    nearest_s: float | None = None
    error_s: float | None = None


@dataclass
class PairResult:
    """Section 7 on one fault: residual sets per wavelet, detections, change points."""

    fault: str
    onset_s: float | None
    signal: str
    time_s: np.ndarray
    faulty: np.ndarray
    healthy: np.ndarray
    twin: dict[str, residuals.ResidualSet] = field(default_factory=dict)
    twin_detection: dict[str, dict[str, residuals.Detection]] = field(default_factory=dict)
    realistic: dict[str, residuals.ResidualSet] = field(default_factory=dict)
    realistic_detection: dict[str, dict[str, residuals.Detection]] = field(default_factory=dict)
    change_points: list[ChangePoints] = field(default_factory=list)


def change_points_in_band(x: np.ndarray, time_s: np.ndarray, band: str = "D1", wavelet: str = "db3",
                          opts: Options | None = None, trim: float = 0.02) -> list[float]:
    """wvarchg on one band's coefficients of ``x`` (the largest ``trim`` replaced by the mean); times in s.

    ``band='D1'`` with db3 is MATLAB's recipe (level-1 details)."""
    opts = opts or Options()
    x = np.ascontiguousarray(x, dtype=float)
    # the healthy counterparts recur for every fault: remember results by content
    key = (hashlib.sha1(x.tobytes()).hexdigest(), float(time_s[0]), float(time_s[1]), band, wavelet, opts.mode,
           opts.max_changes, opts.min_distance, trim)
    if key in _CP_CACHE:
        return list(_CP_CACHE[key])
    level = int(band[1:])
    coeffs = residuals.band_coefficients(x, wavelet, level, opts.mode)[band]
    c = changepoint.trim_largest(coeffs - coeffs.mean(), trim)
    r = changepoint.variance_change_points(c, opts.max_changes, opts.min_distance)
    dt = float(time_s[1] - time_s[0])
    t = residuals.coefficient_times(len(x), wavelet, level, opts.mode, dt, float(time_s[0]))[band]
    _CP_CACHE[key] = [float(t[p]) for p in r.points]
    return list(_CP_CACHE[key])


_CP_CACHE: dict[tuple, list[float]] = {}


def _score(cp: ChangePoints, onset_s: float | None, tolerance_s: float) -> ChangePoints:
    if onset_s is not None and cp.faulty_s:
        nearest = min(cp.faulty_s, key=lambda t: abs(t - onset_s))
        if abs(nearest - onset_s) <= tolerance_s:
            cp.nearest_s, cp.error_s = nearest, nearest - onset_s
    return cp


def analyze_pair(fault: str, healthy: Any, faulty: Any, onset_s: float | None = None,
                 reference: Any = None, calibration: Any = None, signal: str = "ph_measured",
                 opts: Options | None = None) -> PairResult:
    """Section 7 on one fault, from runs (anything with ``time_s`` and ``run[name]``).

    ``healthy`` is the faulty run's twin (same noise) for the paper's
    residuals; ``reference`` (a healthy run with its own noise) and
    ``calibration`` (another healthy run) give the realistic detector, whose
    thresholds come from ``calibration - reference``. Variance change points
    are sought in the MATLAB recipe's input (level-1 details of the pH), in
    the valve stem position's level-1 details (when recorded), and in the
    level-3 approximation of the residual against the reference.
    """
    opts = opts or Options()
    t = np.asarray(faulty.time_s, dtype=float)
    dt, t0 = float(t[1] - t[0]), float(t[0])
    xf, xh = np.asarray(faulty[signal], dtype=float), np.asarray(healthy[signal], dtype=float)
    out = PairResult(fault, onset_s, signal, t, xf, xh)
    for w in opts.residual_wavelets:
        rs = residuals.residuals(xh, xf, w, opts.residual_level, opts.mode, dt, t0)
        out.twin[w] = rs
        out.twin_detection[w] = residuals.detect(rs, {b: 1e-9 for b in rs.residual}, 1, onset_s)
        if reference is not None and calibration is not None:
            xr, xc = np.asarray(reference[signal], dtype=float), np.asarray(calibration[signal], dtype=float)
            real = residuals.residuals(xr, xf, w, opts.residual_level, opts.mode, dt, t0)
            cal = residuals.residuals(xr, xc, w, opts.residual_level, opts.mode, dt, t0)
            thr = residuals.calibrate(cal, opts.detect_window, opts.detect_margin)
            out.realistic[w] = real
            out.realistic_detection[w] = residuals.detect(real, thr, opts.detect_window, onset_s)
    cps = [ChangePoints(f"{signal}: level-1 details (db3, MATLAB's recipe)",
                        change_points_in_band(xf, t, "D1", "db3", opts),
                        change_points_in_band(xh, t, "D1", "db3", opts))]
    position = "valve_position_pct"
    if position in faulty and position in healthy and np.all(np.isfinite(faulty[position])):
        cps.append(ChangePoints(f"{position}: level-1 details (db3)",
                                change_points_in_band(np.asarray(faulty[position], float), t, "D1", "db3", opts),
                                change_points_in_band(np.asarray(healthy[position], float), t, "D1", "db3", opts)))
    if reference is not None and calibration is not None:
        xr, xc = np.asarray(reference[signal], dtype=float), np.asarray(calibration[signal], dtype=float)
        band = f"A{opts.residual_level}"
        cps.append(ChangePoints(f"{signal} residual vs healthy reference: {band} ({opts.wavelet})",
                                change_points_in_band(xf - xr, t, band, opts.wavelet, opts, trim=0.0),
                                change_points_in_band(xc - xr, t, band, opts.wavelet, opts, trim=0.0)))
    out.change_points = [_score(cp, onset_s, opts.onset_tolerance_s) for cp in cps]
    return out
