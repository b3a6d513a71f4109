"""Causal, incremental stationary wavelet transform (a trous filter bank).

Level j filters the previous level's approximation with PyWavelets' analysis
filters ``dec_lo`` / ``dec_hi`` upsampled by 2^(j-1) (zeros between taps):

    a_j[n] = sum_k dec_lo[k] a_(j-1)[n - k 2^(j-1)],   a_0 = x
    d_j[n] = sum_k dec_hi[k] a_(j-1)[n - k 2^(j-1)]

This is ``pywt.swt(x, wavelet, level, norm=False)`` delayed by
(len(filter) / 2) (2^j - 1) samples so that it only uses the past (tests
check the equality against pywt.swt). The filters have unit energy, so white
noise of standard deviation sigma gives coefficients of standard deviation
sigma at every level; the approximation's DC gain is 2^(J/2).

Every output sample is computed with the same arithmetic whatever the chunk
it arrives in (taps summed in a fixed order over element-wise numpy
operations), so chunked and whole-record processing agree bit for bit. The
state is the last (len(filter) - 1) 2^(j-1) inputs of each level.

:func:`coefficient_residuals` is the paper's offline variant (Section 7): the
decimated level-J DWT (``pywt.wavedec``) of a measured and a predicted signal
and their differences per level, Res1D..ResJD and ResJA.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pywt


def wavelet_filters(name: str) -> tuple[np.ndarray, np.ndarray]:
    """(dec_lo, dec_hi) of an orthogonal PyWavelets wavelet, e.g. 'sym4', 'db8'."""
    try:
        w = pywt.Wavelet(name)
    except ValueError:
        raise ValueError(f"unknown wavelet {name!r}; use a discrete PyWavelets name such as sym4 or db8") from None
    if not w.orthogonal:
        raise ValueError(f"wavelet {name!r} is not orthogonal; use an orthogonal family (db, sym, coif)")
    return np.asarray(w.dec_lo, dtype=float), np.asarray(w.dec_hi, dtype=float)


def _fir(history: np.ndarray, x: np.ndarray, taps: np.ndarray, stride: int) -> np.ndarray:
    """y[n] = sum_k taps[k] xe[n - k stride] over history + x, taps summed in order."""
    xe = np.concatenate((history, x))
    m = len(history)
    n = len(x)
    y = taps[0] * xe[m:m + n]
    for k in range(1, len(taps)):
        start = m - k * stride
        y = y + taps[k] * xe[start:start + n]
    return y


@dataclass
class LevelOutputs:
    """Coefficients of a chunk: details[j-1] is D_j (shape (J, N) or (J, N, m)), approx is A_J ((N,) or (N, m))."""

    details: np.ndarray
    approx: np.ndarray


class CausalSwt:
    """Streaming level-J stationary wavelet transform of one signal (or of m signals at once).

    Causal (each coefficient uses past samples only) and chunk-invariant: feeding a record in any
    pieces gives the same coefficients. Filters from PyWavelets.

    Parameters
    ----------
    wavelet : str
        A PyWavelets wavelet name.
    level : int
        J, 1..10.
    channels : int, optional
        None for one signal (inputs of shape (N,)), or m for m signals at once ((N, m)).

    Examples
    --------
    >>> import numpy as np
    >>> from wavelet_fdi import CausalSwt
    >>> swt = CausalSwt("sym4", level=3)
    >>> out = swt.process(np.ones(100))
    >>> swt.band_names(), out.details.shape, swt.fill_samples
    (['D1', 'D2', 'D3', 'A3'], (3, 100), 50)
    >>> bool(np.all(np.abs(out.details[:, swt.fill_samples:]) < 1e-9))  # a constant has no detail
    True
    """

    def __init__(self, wavelet: str = "sym4", level: int = 3, channels: int | None = None) -> None:
        """``channels``: None for one signal (inputs of shape (N,)), or m for m signals at once ((N, m))."""
        if not 1 <= int(level) <= 10:
            raise ValueError(f"wavelet level must be between 1 and 10, got {level}")
        self.wavelet = wavelet
        self.level = int(level)
        self.lo, self.hi = wavelet_filters(wavelet)
        self.taps = len(self.lo)
        tail = () if channels is None else (int(channels),)
        self._hist = [np.zeros(((self.taps - 1) * 2 ** j,) + tail) for j in range(self.level)]
        self.samples_seen = 0

    @property
    def fill_samples(self) -> int:
        """Samples after which every output depends on real inputs only (no start-up zeros)."""
        return (self.taps - 1) * (2 ** self.level - 1) + 1

    def reset(self) -> None:
        for h in self._hist:
            h[:] = 0.0
        self.samples_seen = 0

    def process(self, x: np.ndarray) -> LevelOutputs:
        """Coefficients for the next samples ``x`` (any length, including 1)."""
        a = np.asarray(x, dtype=float)
        details = np.empty((self.level,) + a.shape)
        for j in range(self.level):
            stride = 2 ** j
            hist = self._hist[j]
            details[j] = _fir(hist, a, self.hi, stride)
            a_next = _fir(hist, a, self.lo, stride)
            keep = len(hist)
            if keep:
                self._hist[j] = np.concatenate((hist, a))[-keep:]
            a = a_next
        self.samples_seen += len(x)
        return LevelOutputs(details, a)

    def band_names(self) -> list[str]:
        return [f"D{j + 1}" for j in range(self.level)] + [f"A{self.level}"]


def coefficient_residuals(measured: np.ndarray, predicted: np.ndarray, wavelet: str = "sym4",
                          level: int = 3) -> dict[str, dict[str, np.ndarray]]:
    """The paper's Section 7 offline analysis with ``pywt.wavedec`` (decimated, like MATLAB's wavedec).

    Returns {"measured": {...}, "predicted": {...}, "residual": {...}}, each
    mapping 'D1'..'DJ' and 'AJ' to coefficient arrays; residual = measured -
    predicted per level (Res1D..ResJD, ResJA). The transform is linear, so
    the residual's coefficients equal the coefficients of the time-domain
    residual.
    """
    out = {}
    for key, sig in (("measured", measured), ("predicted", predicted)):
        coeffs = pywt.wavedec(np.asarray(sig, dtype=float), wavelet, level=level)
        bands = {f"A{level}": coeffs[0]}
        for j in range(1, level + 1):
            bands[f"D{j}"] = coeffs[level + 1 - j]
        out[key] = bands
    out["residual"] = {k: out["measured"][k] - out["predicted"][k] for k in out["measured"]}
    return out
