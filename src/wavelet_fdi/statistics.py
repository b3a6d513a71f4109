"""Page's CUSUM for several statistics at once, vectorised over a chunk.

Each statistic accumulates increments z_n (log-likelihood-ratio-like:
positive drift after a change, negative before) as

    S_n = max(0, S_(n-1) + z_n)

computed in the equivalent form S_n = C_n - min(M_(n-1), C_n), with C the
running sum of z and M its running minimum, so a whole chunk is two numpy
accumulations. Both are exact left-to-right recursions, so chunked and
whole-record processing agree bit for bit. :meth:`CusumBank.renormalise`
(C := S, M := 0) keeps the state bounded; it leaves S unchanged and is called
at fixed sample indices so that it too is independent of chunking.

The reference values of the energy CUSUMs (:func:`energy_reference`,
:func:`energy_decrease_reference`) are here; each statistic's increments are
its class's in :mod:`wavelet_fdi.learned_statistics`.
"""

from __future__ import annotations

import math

import numpy as np


def parse_statistic(name: str) -> tuple[str, str, str]:
    """(channel, band, kind) of a statistic's name ``CHANNEL.BAND.KIND``, e.g. ``ph.A3.mean_up``; the one place
    names are taken apart (a channel's own name may hold dots: the last two fields are band and kind).

    >>> parse_statistic("ph.R.mean_down")
    ('ph', 'R', 'mean_down')
    >>> parse_statistic("Pressure.v2.D1.energy_down")
    ('Pressure.v2', 'D1', 'energy_down')
    """
    parts = name.rsplit(".", 2)
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"not a statistic name (CHANNEL.BAND.KIND): {name!r}")
    return parts[0], parts[1], parts[2]


def energy_reference(variance_ratio: float) -> float:
    """Reference value k of the variance CUSUM designed for a variance ratio rho > 1."""
    if not variance_ratio > 1.0:
        raise ValueError(f"variance ratio must exceed 1, got {variance_ratio}")
    return math.log(variance_ratio) / (1.0 - 1.0 / variance_ratio)


def energy_decrease_reference(variance_ratio: float) -> float:
    """Reference value k of the variance-decrease CUSUM (increments k - u^2) for a variance ratio 0 < rho < 1: the
    Gaussian log-likelihood ratio ln(1/rho) / (1/rho - 1), scaled like :func:`energy_reference`."""
    if not 0.0 < variance_ratio < 1.0:
        raise ValueError(f"variance ratio of a decrease must be between 0 and 1, got {variance_ratio}")
    return math.log(1.0 / variance_ratio) / (1.0 / variance_ratio - 1.0)


class CusumBank:
    """n one-sided CUSUMs with a global sample counter for change-time estimates.

    ``update`` takes the increments of a chunk of samples (already minus their reference value) and
    returns each statistic S = max(0, S + z) per sample; ``last_zero`` is where each last was 0 (the
    change-time estimate of an alarm).

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import CusumBank
    >>> bank = CusumBank(2)
    >>> bank.update(np.array([[0.5, 0.5, -2.0, 1.0], [-1.0, -1.0, -1.0, -1.0]]), first_index=0)
    array([[0.5, 1. , 0. , 1. ],
           [0. , 0. , 0. , 0. ]])
    >>> bank.last_zero
    array([2, 3])
    """

    def __init__(self, n: int) -> None:
        self.n = n
        self.c = np.zeros(n)
        self.m = np.zeros(n)
        self.last_zero = np.zeros(n, dtype=np.int64)  # last sample index where S was 0

    @property
    def value(self) -> np.ndarray:
        return self.c - self.m

    def restart(self, index: int) -> None:
        """All statistics to zero, as after sample ``index``."""
        self.c[:] = 0.0
        self.m[:] = 0.0
        self.last_zero[:] = index

    def renormalise(self) -> None:
        s = self.c - self.m
        self.c = s
        self.m = np.zeros(self.n)

    def update(self, z: np.ndarray, first_index: int) -> np.ndarray:
        """Consume increments z (n, N) of samples first_index..first_index+N-1; return S (n, N)."""
        if z.shape[1] == 0:
            return np.empty((self.n, 0))
        self._call = (first_index, self.last_zero.copy())  # for last_zero_at: the call's start and what was before
        c = np.cumsum(np.concatenate((self.c[:, None], z), axis=1), axis=1)[:, 1:]
        m = np.minimum.accumulate(np.concatenate((self.m[:, None], c), axis=1), axis=1)[:, 1:]
        s = c - m
        zero = s <= 0.0
        any_zero = zero.any(axis=1)
        if any_zero.any():
            last = z.shape[1] - 1 - np.argmax(zero[:, ::-1], axis=1)
            self.last_zero = np.where(any_zero, first_index + last, self.last_zero)
        self.c = c[:, -1].copy()
        self.m = m[:, -1].copy()
        self._call_s = s
        return s

    def last_zero_at(self, row: int, index: int) -> int:
        """The last sample up to ``index`` (inside the last :meth:`update` call) where statistic ``row`` was 0.
        ``last_zero`` is the call's end, which can lie after ``index``: an onset taken from it would depend on
        how the samples were split into calls."""
        first, before = self._call
        zero = np.flatnonzero(self._call_s[row, :index - first + 1] <= 0.0)
        return int(first + zero[-1]) if zero.size else int(before[row])
