"""Multisignals and their row-wise wavelet decomposition (MATLAB's mdwtdec / mdwtrec on PyWavelets).

A *multisignal* is a matrix whose rows are signals of equal length (the
paper's Section 6, after MATLAB's Wavelet Toolbox). Rows come from runs
(:class:`phfdi.records.Record` or anything with ``time_s`` and ``__getitem__``)
resampled onto a common grid, each with a class label ("healthy",
"backlash", ...) and a name.

:func:`decompose` is ``mdwtdec('r', X, level, wname)``: one
:func:`pywt.wavedec` over the rows. PyWavelets' ``symmetric`` mode is
MATLAB's default ``'sym'`` extension (half-point symmetric) and gives the
same coefficient counts, ``floor((n + filter_length - 1) / 2)`` per level,
and the same coefficients (PyWavelets checks itself against MATLAB R2012a
output, see ``pywt/tests/test_matlab_compatibility.py``): 1440 samples with
sym4 at level 7 give approximation coefficients of length 18, as the
paper's ``ca: [35x18 double]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Sequence

import numpy as np
import pywt

from phfdi_base.signals import unit_of

#: MATLAB's extension-mode names (dwtmode) -> PyWavelets' names
MATLAB_MODES = {
    "sym": "symmetric", "symh": "symmetric", "symw": "reflect", "zpd": "zero", "sp0": "constant",
    "sp1": "smooth", "ppd": "periodic", "per": "periodization", "asym": "antisymmetric",
    "asymh": "antisymmetric", "asymw": "antireflect",
}


def pywt_mode(mode: str) -> str:
    """PyWavelets extension mode from a PyWavelets or MATLAB name ('sym' -> 'symmetric')."""
    name = MATLAB_MODES.get(mode, mode)
    if name not in pywt.Modes.modes:
        raise ValueError(f"unknown extension mode {mode!r}; use one of {', '.join(pywt.Modes.modes)} "
                         f"or a MATLAB name ({', '.join(MATLAB_MODES)})")
    return name


# ---- the multisignal ------------------------------------------------------------------
@dataclass
class Multisignal:
    """Rows of equal length with their labels.

    ``data[i]`` is signal i sampled at ``time_s``; ``labels[i]`` its class;
    ``names[i]`` a unique name; ``truth`` (optional) the same rows without
    measurement noise when known (simulated ``ph_true``), used only to score
    denoising; ``info[i]`` what produced the row (severity, seed, file).

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.study import Multisignal
    >>> ms = Multisignal(np.zeros((3, 1440)), ["healthy", "backlash", "backlash"], ["h1", "b1", "b2"],
    ...                  np.arange(1440.0))
    >>> ms.shape, ms.classes, ms.rows("backlash").tolist()
    ((3, 1440), ['healthy', 'backlash'], [1, 2])
    """

    data: np.ndarray
    labels: list[str]
    names: list[str]
    time_s: np.ndarray
    signal: str = "ph_measured"
    unit: str = "pH"
    truth: np.ndarray | None = None
    info: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.data = np.atleast_2d(np.asarray(self.data, dtype=float))
        n, m = self.data.shape
        if len(self.labels) != n or len(self.names) != n:
            raise ValueError(f"{n} rows but {len(self.labels)} labels and {len(self.names)} names")
        if len(self.time_s) != m:
            raise ValueError(f"rows have {m} samples but time_s has {len(self.time_s)}")
        if self.truth is not None and np.shape(self.truth) != self.data.shape:
            raise ValueError(f"truth has shape {np.shape(self.truth)}, data {self.data.shape}")
        if not self.info:
            self.info = [{} for _ in range(n)]

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape  # type: ignore[return-value]

    @property
    def classes(self) -> list[str]:
        """Distinct labels in order of first appearance."""
        return list(dict.fromkeys(self.labels))

    def label_codes(self) -> np.ndarray:
        """Integer class of each row (index into :attr:`classes`)."""
        classes = self.classes
        return np.array([classes.index(lab) for lab in self.labels])

    def rows(self, label: str) -> np.ndarray:
        return np.array([i for i, lab in enumerate(self.labels) if lab == label], dtype=int)

    def subset(self, index: Sequence[int]) -> "Multisignal":
        index = list(index)
        return replace(self, data=self.data[index], labels=[self.labels[i] for i in index],
                       names=[self.names[i] for i in index],
                       truth=None if self.truth is None else self.truth[index],
                       info=[self.info[i] for i in index])


def resample_mean(t_s: np.ndarray, x: np.ndarray, edges_s: np.ndarray) -> np.ndarray:
    """Mean of the linear interpolant of ``x(t)`` over each bin ``[edges[k], edges[k+1]]``.

    An anti-aliasing (boxcar) downsampler for any ratio and for non-uniform
    time stamps (bags): the exact bin average of the piecewise-linear signal,
    from its cumulative trapezoid integral. Upsampling tends to linear
    interpolation. Non-finite samples are dropped first.
    """
    t_s = np.asarray(t_s, dtype=float)
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(t_s) & np.isfinite(x)
    if ok.sum() < 2:
        raise ValueError("fewer than two finite samples to resample")
    t_s, x = t_s[ok], x[ok]
    order = np.argsort(t_s, kind="stable")
    t_s, x = t_s[order], x[order]
    edges_s = np.asarray(edges_s, dtype=float)
    # cumulative integral of the linear interpolant, extended flat (constant x) beyond the ends
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t_s))))
    e = np.clip(edges_s, t_s[0], t_s[-1])
    k = np.clip(np.searchsorted(t_s, e, side="right") - 1, 0, len(t_s) - 2)
    frac = e - t_s[k]
    slope = (x[k + 1] - x[k]) / np.where(t_s[k + 1] > t_s[k], t_s[k + 1] - t_s[k], 1.0)
    integral = cum[k] + frac * (x[k] + 0.5 * slope * frac)
    integral = integral + (edges_s - e) * np.where(edges_s > t_s[-1], x[-1], x[0])
    width = np.diff(edges_s)
    if np.any(width <= 0):
        raise ValueError("resampling bin edges must increase")
    return np.diff(integral) / width


def common_window(runs: Sequence[Any]) -> tuple[float, float]:
    """The time span all runs cover (s)."""
    t0 = max(float(np.nanmin(r.time_s)) for r in runs)
    t1 = min(float(np.nanmax(r.time_s)) for r in runs)
    if not t1 > t0:
        raise ValueError("the runs share no common time span")
    return t0, t1


def from_runs(runs: Sequence[Any], labels: Sequence[str], signal: str = "ph_measured",
              n_samples: int = 1440, names: Sequence[str] | None = None,
              window_s: tuple[float, float] | None = None, truth_signal: str | None = "ph_true",
              info: Sequence[dict] | None = None) -> Multisignal:
    """One row per run: ``signal`` bin-averaged onto ``n_samples`` bins of the common window.

    Runs of different lengths or sample times are cut to the span they all
    cover (``window_s`` overrides it); each row is then the mean of the
    signal over ``n_samples`` equal bins (:func:`resample_mean`), so 10001
    samples at 1 s become 1440 bins of 6.94 s. The time axis is the bin
    centres relative to the window start.
    """
    if not runs:
        raise ValueError("no runs to build a multisignal from")
    if n_samples < 2:
        raise ValueError(f"n_samples must be at least 2, got {n_samples}")
    t0, t1 = window_s if window_s is not None else common_window(runs)
    edges = np.linspace(t0, t1, n_samples + 1)
    data = np.vstack([resample_mean(r.time_s, r[signal], edges) for r in runs])
    truth = None
    if truth_signal and all(truth_signal in r for r in runs):
        truth = np.vstack([resample_mean(r.time_s, r[truth_signal], edges) for r in runs])
    names = list(names) if names is not None else [f"{lab}-{i}" for i, lab in enumerate(labels)]

    return Multisignal(data, list(labels), names, 0.5 * (edges[1:] + edges[:-1]) - t0, signal,
                       unit_of(signal), truth, [dict(d) for d in info] if info else [])


# ---- decomposition (mdwtdec / mdwtrec) ------------------------------------------------------
@dataclass
class Decomposition:
    """Row-wise DWT of a multisignal, laid out like MATLAB's mdwtdec structure.

    ``ca`` is (n_signals, len_a) at level ``level``; ``cd[j-1]`` holds the
    detail coefficients of level j (MATLAB's ``cd{j}``), finest first.
    """

    ca: np.ndarray
    cd: list[np.ndarray]
    wavelet: str
    level: int
    mode: str
    n_samples: int

    @property
    def n_signals(self) -> int:
        return self.ca.shape[0]

    def coeffs(self) -> list[np.ndarray]:
        """PyWavelets order: [cA_L, cD_L, ..., cD_1]."""
        return [self.ca] + self.cd[::-1]

    def lengths(self) -> list[int]:
        """MATLAB's bookkeeping vector L: [len cA_L, len cD_L, ..., len cD_1, n_samples]."""
        return [self.ca.shape[1]] + [d.shape[1] for d in self.cd[::-1]] + [self.n_samples]

    def flat(self) -> np.ndarray:
        """All coefficients of each row side by side, (n_signals, n_coefficients): [ca, cd_L, ..., cd_1]."""
        return np.hstack(self.coeffs())

    def unflat(self, flat: np.ndarray) -> "Decomposition":
        """A decomposition of the same layout holding ``flat`` (as returned by :meth:`flat`)."""
        flat = np.atleast_2d(flat)
        parts, start = [], 0
        for n in self.lengths()[:-1]:
            parts.append(flat[:, start:start + n])
            start += n
        return replace(self, ca=parts[0], cd=parts[1:][::-1])

    def with_details(self, cd: list[np.ndarray]) -> "Decomposition":
        return replace(self, cd=list(cd))

    def _waverec(self, coeffs: list[np.ndarray]) -> np.ndarray:
        x = pywt.waverec(coeffs, self.wavelet, mode=self.mode, axis=1)
        return x[:, : self.n_samples]

    def reconstruct(self) -> np.ndarray:
        """The multisignal back from all coefficients (inverse DWT of every row)."""
        return self._waverec(self.coeffs())

    def approximation(self, level: int | None = None) -> np.ndarray:
        """Reconstructed approximation at ``level`` (1..L; MATLAB's ``mdwtrec(dec, 'a', level)``).

        The approximation at level k keeps cA_L and the details of levels
        k+1..L and zeroes the details of levels 1..k.
        """
        level = self.level if level is None else level
        if not 0 <= level <= self.level:
            raise ValueError(f"approximation level must be in 0..{self.level}, got {level}")
        cd = [np.zeros_like(d) if j < level else d for j, d in enumerate(self.cd)]
        return self._waverec([self.ca] + cd[::-1])

    def detail(self, level: int) -> np.ndarray:
        """Reconstructed detail of ``level`` (MATLAB's ``mdwtrec(dec, 'd', level)``)."""
        if not 1 <= level <= self.level:
            raise ValueError(f"detail level must be in 1..{self.level}, got {level}")
        cd = [d if j == level - 1 else np.zeros_like(d) for j, d in enumerate(self.cd)]
        return self._waverec([np.zeros_like(self.ca)] + cd[::-1])


def decompose(data: np.ndarray | Multisignal, wavelet: str = "sym4", level: int = 7,
              mode: str = "symmetric") -> Decomposition:
    """Row decomposition of a multisignal at ``level`` (MATLAB's ``mdwtdec('r', X, level, wname)``).

    Parameters
    ----------
    data : ndarray (n_signals, n_samples) or Multisignal
    wavelet : str
        A PyWavelets wavelet name.
    level : int
        1 .. the largest level the row length allows (a ``ValueError`` says the range otherwise).
    mode : str
        Signal extension, PyWavelets' or MATLAB's name (``"sym"`` is ``"symmetric"``).

    Returns
    -------
    Decomposition
        ``ca`` (n_signals, len_a) and ``cd[j-1]`` the level-j details, finest first.

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.study import decompose
    >>> dec = decompose(np.sin(np.linspace(0.0, 20.0, 1440))[None, :].repeat(35, axis=0), "sym4", level=7)
    >>> dec.ca.shape, len(dec.cd)
    ((35, 18), 7)
    """
    x = data.data if isinstance(data, Multisignal) else np.atleast_2d(np.asarray(data, dtype=float))
    mode = pywt_mode(mode)
    w = pywt.Wavelet(wavelet)
    max_level = pywt.dwt_max_level(x.shape[1], w.dec_len)
    if not 1 <= level <= max(max_level, 1):
        raise ValueError(f"level {level} is out of range for {x.shape[1]} samples and {wavelet} "
                         f"(1..{max_level})")
    coeffs = pywt.wavedec(x, w, mode=mode, level=level, axis=1)
    return Decomposition(coeffs[0], coeffs[1:][::-1], w.name, level, mode, x.shape[1])


def reconstruction_error(dec: Decomposition, data: np.ndarray) -> float:
    """Largest absolute difference between the rows and their inverse DWT (perfect reconstruction check)."""
    return float(np.max(np.abs(dec.reconstruct() - np.atleast_2d(data))))
