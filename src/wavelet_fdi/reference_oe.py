"""Learned output-error reference: each channel's own lags taken from the model's own past predictions.

The ARX reference (:mod:`wavelet_fdi.reference_learned`) predicts a channel from its own last *measured*
samples, so a sensor fault is gone from its residual one sample after it happens: a probe that jumps and
stays there is one innovation spike, a frozen probe is perfectly predictable. This kind is the
output-error (simulation) form of the same linear model (Ljung, *System Identification: Theory for the
User*, 2nd ed. 1999, section 4.2, "output-error model structure"): the own lags are the model's own past
outputs ``s_c``, the other channels enter as inputs,

    y_c(t) = b_c + sum_{l=1..p} a_{c,l} s_c(t - l) + sum_{j != c} g_{c,j} x_j(t)
    r_c(t) = x_c(t) - y_c(t)                          (in healthy sigmas: r_c / residual_sigma_c)
    s_c(t) = y_c(t) + kappa * r_c(t)                  (kappa = 1 / correction_samples)

on standardised data. ``kappa = 0`` is the pure simulation (it drifts away on any slow change the other
channels do not explain); ``kappa = 1`` is the ARX predictor. In between, the simulation is pulled toward
the measurement with a time constant of ``correction_samples``: a sensor step that stays keeps a residual
that decays over about that many samples instead of one, and a frozen channel leaves a residual wherever
the other channels say it should have moved. With one own coefficient near 1 the residual of a step of
size d decays as roughly d (1 - kappa)^k.

Fitting (:meth:`OutputErrorReference.fit`): the ARX ridge fit first, then, channel by channel, the
prediction-error method on this very predictor (Ljung 1999, section 7.3): nonlinear least squares
(scipy ``least_squares``) of the corrected simulation's residual on the healthy rows, the ridge penalties
kept as extra residuals. (Pseudo-linear regression, regressing on the simulated lags, diverged on a plain
test plant: residual standard deviations of 4 to 15 sigmas.) The own polynomial is kept stable (its
roots shrunk inside the unit circle). ``residual_sigma`` is the standard deviation of the final simulated
residual on the healthy rows.

Missing samples (NaN): the training mean as an input to the others, no correction of the channel's own
simulation (``s = y``) and a NaN residual. The recursion runs sample by sample, left to right, so any
chunking of a record gives bit-identical residuals.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from phfdi_base.errors import UserError

from .reference_learned import LearnedReference, linear_arrays

#: stability margin: roots of the own-lag polynomial are kept within this radius
MAX_ROOT = 0.999


@dataclass
class OutputErrorReference:
    """Output-error predictor of every channel with a slow correction toward the measurement."""

    channels: tuple[str, ...]
    lags: int
    mean: np.ndarray  # (m,) training mean, measured units
    scale: np.ndarray  # (m,) training standard deviation, measured units
    intercept: np.ndarray  # (m,)
    own: np.ndarray  # (m, lags): coefficient of s_c(t - l)
    cross: np.ndarray  # (m, m): coefficient of x_j(t); zero diagonal
    residual_sigma: np.ndarray  # (m,) healthy simulated-residual standard deviation, standardised units
    correction_samples: float  # 1 / kappa; 0 means no correction (pure simulation)
    fit_rows: int
    ridge_own: float
    ridge_cross: float
    iterations: int

    kind = "oe"

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def residual_channels(self) -> tuple[str, ...]:
        return self.channels

    @property
    def kappa(self) -> float:
        return 0.0 if self.correction_samples <= 0 else min(1.0, 1.0 / self.correction_samples)

    # ---- fitting -------------------------------------------------------------------
    @classmethod
    def fit(cls, x: np.ndarray, channels: Sequence[str], lags: int = 2, ridge_own: float = 1.0,
            ridge_cross: float = 10.0, correction_samples: float = 100.0,
            iterations: int = 20) -> "OutputErrorReference":
        """Fit on healthy rows x (n, m): ARX first, then the prediction-error method on the corrected simulation."""
        if correction_samples < 0 or (0 < correction_samples < 1):
            raise UserError(f"correction_samples must be 0 (pure simulation) or at least 1, got {correction_samples}")
        if iterations < 0:
            raise UserError(f"iterations must be 0 or more, got {iterations}")
        arx = LearnedReference.fit(x, channels, lags, ridge_own, ridge_cross)
        x = np.asarray(x, dtype=float)
        ref = cls(arx.channels, lags, arx.mean, arx.scale, arx.intercept.copy(), _stable(arx.own),
                  arx.cross.copy(), np.ones(len(arx.channels)), float(correction_samples), arx.fit_rows,
                  float(ridge_own), float(ridge_cross), int(iterations))
        m = ref.n_channels
        z = (x - ref.mean) / ref.scale
        finite = np.isfinite(z)
        zin = np.where(finite, z, 0.0)
        if iterations:
            for c in range(m):
                _fit_channel(ref, c, z, zin, finite, iterations)
        res = ref.new_state().residuals(None, x) * ref.residual_sigma  # standardised units
        sigma = np.nanstd(res[lags:], axis=0)
        ref.residual_sigma = np.where(np.isfinite(sigma) & (sigma > 1e-9), sigma, 1.0)
        return ref

    # ---- prediction -----------------------------------------------------------------
    def new_state(self) -> "OutputErrorStream":
        return OutputErrorStream(self)

    def residuals(self, t_s: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        return self.new_state().residuals(t_s, x)

    # ---- file ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"kind": self.kind, "channels": list(self.channels), "lags": self.lags, "mean": self.mean.tolist(),
                "scale": self.scale.tolist(), "intercept": self.intercept.tolist(), "own": self.own.tolist(),
                "cross": self.cross.tolist(), "residual_sigma": self.residual_sigma.tolist(),
                "correction_samples": self.correction_samples, "fit_rows": self.fit_rows,
                "ridge_own": self.ridge_own, "ridge_cross": self.ridge_cross, "iterations": self.iterations}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "OutputErrorReference":
        try:
            channels, lags, arr, own, cross = linear_arrays(d)
            corr = float(d["correction_samples"])
            if corr < 0 or 0 < corr < 1:
                raise ValueError("correction_samples must be 0 or at least 1")
            return cls(channels, lags, arr["mean"], arr["scale"], arr["intercept"], own, cross,
                       arr["residual_sigma"], corr, int(d["fit_rows"]), float(d["ridge_own"]),
                       float(d["ridge_cross"]), int(d.get("iterations", 0)))
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: not an output-error reference ({exc})") from None


def _fit_channel(ref: "OutputErrorReference", c: int, z: np.ndarray, zin: np.ndarray, finite: np.ndarray,
                 iterations: int) -> None:
    """Channel c's coefficients by nonlinear least squares on the corrected simulation's residual (the
    prediction-error method for the output-error structure, Ljung 1999 section 7.3), started at the ARX fit,
    with the ridge penalties as extra residuals; at most ``iterations`` * (parameters + 1) evaluations."""
    from scipy.optimize import least_squares
    from scipy.signal import lfilter, lfiltic

    p, m, kappa = ref.lags, ref.n_channels, ref.kappa
    others = [j for j in range(m) if j != c]
    ok = finite[:, c].copy()
    ok[:p] = False
    # for the fit only, a missing sample of the channel is bridged linearly (the stream does not correct there)
    idx = np.arange(len(z))
    target = np.interp(idx, idx[finite[:, c]], z[finite[:, c], c])
    xo = zin[:, others]
    w = np.sqrt(np.r_[[ref.ridge_own] * p, [ref.ridge_cross] * len(others)])

    def split(theta):
        return theta[0], theta[1:1 + p], theta[1 + p:]

    def err(theta):
        b, a, g = split(theta)
        drive = b + xo @ g
        # s(t) = (1 - kappa) (drive(t) + sum a_l s(t - l)) + kappa x_c(t); started at s = x_c(0)
        den = np.r_[1.0, -(1.0 - kappa) * a]
        first = np.full(p, target[0])
        s = lfilter([1.0], den, (1.0 - kappa) * drive + kappa * target, zi=lfiltic([1.0], den, first[::-1]))[0]
        lagged = np.vstack([np.r_[first[:lag], s[:len(s) - lag]] for lag in range(1, p + 1)]).T if p else 0.0
        y = drive + (lagged @ a if p else 0.0)
        e = np.where(ok, target - y, 0.0)
        e = np.where(np.isfinite(e), np.clip(e, -1e6, 1e6), 1e6)
        return np.r_[e, w * theta[1:]]

    theta0 = np.r_[ref.intercept[c], ref.own[c], ref.cross[c, others]]
    with np.errstate(over="ignore", invalid="ignore"):  # a trial step into an unstable filter is refused
        sol = least_squares(err, theta0, max_nfev=iterations * (len(theta0) + 1), x_scale="jac")
        theta = sol.x if np.sum(err(sol.x) ** 2) < np.sum(err(theta0) ** 2) else theta0
    b, a, g = split(theta)
    ref.intercept[c] = b
    ref.own[c] = _stable(a[None, :])[0] if p else a
    ref.cross[c, others] = g


def _stable(own: np.ndarray) -> np.ndarray:
    """Own-lag coefficients (m, p) with the roots of z^p - a_1 z^(p-1) - ... - a_p inside MAX_ROOT."""
    out = np.array(own, dtype=float, copy=True)
    for c in range(out.shape[0]):
        a = out[c]
        if not len(a):
            continue
        roots = np.roots(np.concatenate(([1.0], -a)))
        big = np.abs(roots) > MAX_ROOT
        if big.any():
            roots = np.where(big, roots / np.abs(roots) * MAX_ROOT, roots)
            out[c] = -np.real(np.poly(roots))[1:]
    return out


class OutputErrorStream:
    """Residuals of a stream; keeps the last ``lags`` simulated outputs per channel."""

    def __init__(self, ref: OutputErrorReference) -> None:
        self.ref = ref
        self._hist: np.ndarray | None = None  # (lags, m) simulated outputs, oldest first

    def residuals(self, t_s: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        """Residuals of the next rows x (n, m) in healthy-sigma units; NaN where x is missing. Works in
        samples: ``t_s`` is accepted for the reference protocol and not used."""
        r = self.ref
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != r.n_channels:
            raise ValueError(f"expected rows x {r.n_channels} channels, got shape {x.shape}")
        n, m = x.shape
        p = r.lags
        z = (x - r.mean) / r.scale
        missing = ~np.isfinite(z)
        zin = np.where(missing, 0.0, z)
        if self._hist is None:
            self._hist = np.tile(zin[0] if n else np.zeros(m), (p, 1))
        # the part of each prediction that does not depend on the recursion, in the ARX's term order
        exo = np.tile(r.intercept, (n, 1))
        for j in range(m):
            exo = exo + np.outer(zin[:, j], r.cross[:, j])
        kappa = r.kappa
        gain = np.where(missing, 0.0, kappa)
        own = r.own
        hist = np.vstack((self._hist, np.zeros((n, m))))  # rows p.. are this chunk's simulated outputs
        res = np.empty((n, m))
        for i in range(n):
            y = exo[i].copy()
            for lag in range(1, p + 1):
                y = y + own[:, lag - 1] * hist[p + i - lag]
            e = zin[i] - y
            res[i] = e
            hist[p + i] = y + gain[i] * e
        if p:
            self._hist = hist[-p:].copy()
        return np.where(missing, np.nan, res / r.residual_sigma)
