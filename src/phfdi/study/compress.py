"""Wavelet compression of a multisignal (MATLAB's mswcmp).

Same three steps as denoising, with a different step 2:

- :func:`compress_energy` keeps, in each row, the largest coefficients (by
  magnitude) until a stated fraction of the row's coefficient energy is
  retained (MATLAB's ``'L2_perf'`` method, one parameter for all rows);
- :func:`compress_threshold` zeroes the coefficients below a global
  threshold or below one threshold per detail level.

Each result reports, per row, the percentage of non-zero coefficients
(MATLAB's 100 - N0_perf) and the percentage of energy retained (L2_perf).
Energies are those of the coefficients, as MATLAB computes them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import pywt

from .multisignal import Decomposition


@dataclass
class Compressed:
    """Compressed rows, their decomposition, and the compression figures per row."""

    signals: np.ndarray
    decomposition: Decomposition
    #: threshold applied to each row (signal units); per level: (n_signals, level)
    thresholds: np.ndarray
    nonzero_pct: np.ndarray
    energy_retained_pct: np.ndarray


def _finish(dec: Decomposition, flat: np.ndarray, kept: np.ndarray, thresholds: np.ndarray) -> Compressed:
    energy = np.sum(dec.flat() ** 2, axis=1)
    kept_energy = np.sum(kept ** 2, axis=1)
    retained = 100.0 * np.divide(kept_energy, energy, out=np.full_like(energy, 100.0), where=energy > 0)
    nonzero = 100.0 * np.count_nonzero(kept, axis=1) / flat.shape[1]
    cdec = dec.unflat(kept)
    return Compressed(cdec.reconstruct(), cdec, thresholds, nonzero, retained)


def compress_energy(dec: Decomposition, retain: float = 0.99, keep_approx: bool = False) -> Compressed:
    """Keep the fewest largest coefficients of each row whose energy is at least ``retain`` of the row's.

    ``keep_approx=False`` (MATLAB's default) lets the approximation
    coefficients compete with the details; ``True`` keeps them all and adds
    the largest details until ``retain`` is reached. Hard thresholding: kept
    coefficients are unchanged. The reported threshold is the smallest kept
    magnitude.

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.study import compress_energy, decompose
    >>> dec = decompose(np.sin(np.linspace(0.0, 20.0, 1440))[None, :], "sym4", level=7)
    >>> c = compress_energy(dec, retain=0.99)
    >>> round(float(c.nonzero_pct[0]), 2), bool(c.energy_retained_pct[0] >= 99.0)
    (1.35, True)
    """
    if not 0.0 < retain <= 1.0:
        raise ValueError(f"retain must be in (0, 1], got {retain}")
    flat = dec.flat()
    n_rows, n_cfs = flat.shape
    n_a = dec.ca.shape[1]
    energy = flat ** 2
    total = energy.sum(axis=1)
    priority = energy.copy()
    if keep_approx:
        priority[:, :n_a] = np.inf
    order = np.argsort(-priority, axis=1, kind="stable")
    sorted_energy = np.take_along_axis(energy, order, axis=1)
    cum = np.cumsum(sorted_energy, axis=1)
    # fewest coefficients reaching the target (at least the approximation when it is kept)
    n_keep = np.argmax(cum >= retain * total[:, None] * (1.0 - 1e-12), axis=1) + 1
    if keep_approx:
        n_keep = np.maximum(n_keep, n_a)
    n_keep = np.where(total > 0, n_keep, 0)
    rank = np.empty_like(order)
    np.put_along_axis(rank, order, np.arange(n_cfs)[None, :].repeat(n_rows, axis=0), axis=1)
    mask = rank < n_keep[:, None]
    kept = np.where(mask, flat, 0.0)
    smallest_kept = np.where(mask, np.abs(flat), np.inf).min(axis=1)
    return _finish(dec, flat, kept, np.where(np.isfinite(smallest_kept), smallest_kept, 0.0))


def compress_threshold(dec: Decomposition, threshold: float | Sequence[float], shrink: str = "hard",
                       keep_approx: bool = True) -> Compressed:
    """Zero the coefficients below a threshold: one global value, or one per detail level (level 1 first).

    The approximation is kept untouched unless ``keep_approx`` is False (a
    global threshold then applies to it too).
    """
    if shrink not in ("soft", "hard"):
        raise ValueError(f"shrink must be 'soft' or 'hard', got {shrink!r}")
    per_level = np.atleast_1d(np.asarray(threshold, dtype=float))
    if per_level.size == 1:
        per_level = np.repeat(per_level, dec.level)
    elif per_level.size != dec.level:
        raise ValueError(f"give one threshold or {dec.level} (one per detail level), got {per_level.size}")
    if np.any(per_level < 0):
        raise ValueError("thresholds must be non-negative")
    cd = [pywt.threshold(d, per_level[j], mode=shrink) for j, d in enumerate(dec.cd)]
    ca = dec.ca if keep_approx else pywt.threshold(dec.ca, per_level.max(), mode=shrink)
    kept = Decomposition(ca, cd, dec.wavelet, dec.level, dec.mode, dec.n_samples).flat()
    return _finish(dec, dec.flat(), kept, np.repeat(per_level[None, :], dec.n_signals, axis=0))
