"""Wavelet denoising of a multisignal in three steps (MATLAB's wden / mswden).

1. decompose every row at level N (:func:`phfdi.study.multisignal.decompose`);
2. for each level 1..N and each row, pick a threshold from a rule and the
   noise level of that row and level, and shrink the detail coefficients
   (:func:`pywt.threshold`, soft or hard);
3. reconstruct from the untouched approximation and the shrunk details.

Threshold rules return thresholds for unit-variance noise (MATLAB's
``thselect``); they are scaled by the noise estimate sigma, the median
absolute deviation of the detail coefficients over 0.6745 (``wnoisest``):

- ``universal`` (``'sqtwolog'``, VisuShrink): sqrt(2 ln n);
- ``sure`` (``'rigrsure'``): the threshold minimising Stein's unbiased risk
  estimate of soft thresholding, computed on each level's coefficients;
- ``heursure``: ``universal`` when the coefficients look like pure noise,
  else the smaller of ``sure`` and ``universal``;
- ``minimax`` (``'minimaxi'``): 0.3936 + 0.1829 log2 n (0 for n <= 32),
  Donoho and Johnstone's fit of the minimax threshold.

As in MATLAB's wden, n for ``universal`` and ``minimax`` is the number of
coefficients of the whole decomposition of a row, and ``sure``/``heursure``
use each level's own coefficients. Noise scaling: ``level`` (MATLAB
``'mln'``, one sigma per level, for coloured noise), ``first`` (``'sln'``,
sigma of level 1 for all levels) or ``none`` (``'one'``). Shrinkage is
:func:`pywt.threshold`: hard thresholding keeps a coefficient equal to the
threshold (MATLAB's wthresh zeroes it; it matters for the one coefficient a
SURE threshold is taken from).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pywt

from .multisignal import Decomposition

#: MAD of a standard normal: sigma = median(|d|) / 0.6745
MAD_TO_SIGMA = 0.6745
RULES = ("universal", "sure", "heursure", "minimax")
NOISE_SCALINGS = ("level", "first", "none")


# ---- threshold rules (for unit noise) ----------------------------------------------------
def universal_threshold(n: int) -> float:
    """sqrt(2 ln n) (VisuShrink; MATLAB 'sqtwolog')."""
    if n < 1:
        raise ValueError("n must be positive")
    return float(np.sqrt(2.0 * np.log(n)))


def minimax_threshold(n: int) -> float:
    """0.3936 + 0.1829 log2(n), or 0 when n <= 32 (MATLAB 'minimaxi')."""
    if n < 1:
        raise ValueError("n must be positive")
    return 0.0 if n <= 32 else float(0.3936 + 0.1829 * np.log2(n))


def sure_threshold(x: np.ndarray) -> np.ndarray:
    """Threshold minimising Stein's unbiased risk estimate of soft thresholding (MATLAB 'rigrsure').

    For a threshold equal to the k-th smallest |x| (k = 1..n) the risk is
    ``(n - 2k + sum_{i<=k} x_(i)^2 + (n - k) x_(k)^2) / n``; the threshold is
    the |x| of least risk. Works along the last axis (one threshold per row).
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    sx2 = np.sort(x * x, axis=-1)
    k = np.arange(1, n + 1)
    risks = (n - 2 * k + np.cumsum(sx2, axis=-1) + (n - k) * sx2) / n
    best = np.argmin(risks, axis=-1)
    return np.sqrt(np.take_along_axis(sx2, best[..., None], axis=-1)[..., 0])


def heursure_threshold(x: np.ndarray) -> np.ndarray:
    """Universal threshold when the signal is too weak for SURE to be reliable, else min(SURE, universal)."""
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    universal = universal_threshold(n)
    eta = (np.sum(x * x, axis=-1) - n) / n
    crit = np.log2(n) ** 1.5 / np.sqrt(n)
    return np.where(eta < crit, universal, np.minimum(sure_threshold(x), universal))


def noise_sigma(d: np.ndarray) -> np.ndarray:
    """Robust noise standard deviation of each row: median(|d|) / 0.6745."""
    return np.median(np.abs(np.atleast_2d(d)), axis=-1) / MAD_TO_SIGMA


# ---- multisignal denoising ------------------------------------------------------------------
@dataclass
class Denoised:
    """Denoised rows, their thresholded decomposition, and the thresholds used.

    ``thresholds[i, j-1]`` and ``sigma[i, j-1]`` are row i's threshold and noise
    estimate at level j (signal units).
    """

    signals: np.ndarray
    decomposition: Decomposition
    thresholds: np.ndarray
    sigma: np.ndarray
    rule: str
    shrink: str
    noise: str


def level_thresholds(dec: Decomposition, rule: str = "universal", noise: str = "level") -> tuple[np.ndarray, np.ndarray]:
    """Threshold and noise sigma of every row and detail level, (n_signals, level) each."""
    if rule not in RULES:
        raise ValueError(f"unknown threshold rule {rule!r}; use one of {', '.join(RULES)}")
    if noise not in NOISE_SCALINGS:
        raise ValueError(f"unknown noise scaling {noise!r}; use one of {', '.join(NOISE_SCALINGS)}")
    n_rows = dec.n_signals
    if noise == "level":
        sigma = np.column_stack([noise_sigma(d) for d in dec.cd])
    elif noise == "first":
        sigma = np.repeat(noise_sigma(dec.cd[0])[:, None], dec.level, axis=1)
    else:
        sigma = np.ones((n_rows, dec.level))
    n_all = sum(dec.lengths()[:-1])
    thresholds = np.zeros_like(sigma)
    for j, d in enumerate(dec.cd):
        s = sigma[:, j]
        # a level without noise (constant or exactly smooth rows) is left alone, as MATLAB does
        quiet = s < np.sqrt(np.finfo(float).eps) * np.max(np.abs(d), axis=1, initial=0.0)
        quiet |= s <= 0
        if rule == "universal":
            t = np.full(n_rows, universal_threshold(n_all))
        elif rule == "minimax":
            t = np.full(n_rows, minimax_threshold(n_all))
        else:
            scaled = d / np.where(quiet, 1.0, s)[:, None]
            t = sure_threshold(scaled) if rule == "sure" else heursure_threshold(scaled)
        thresholds[:, j] = np.where(quiet, 0.0, t * s)
    return thresholds, sigma


def denoise(dec: Decomposition, rule: str = "universal", shrink: str = "soft", noise: str = "level") -> Denoised:
    """Threshold every detail level of every row and reconstruct (MATLAB's ``mswden('den', ...)``)."""
    if shrink not in ("soft", "hard"):
        raise ValueError(f"shrink must be 'soft' or 'hard', got {shrink!r}")
    thresholds, sigma = level_thresholds(dec, rule, noise)
    cd = [pywt.threshold(d, thresholds[:, j][:, None], mode=shrink) for j, d in enumerate(dec.cd)]
    den = dec.with_details(cd)
    return Denoised(den.reconstruct(), den, thresholds, sigma, rule, shrink, noise)
