"""Learned healthy reference: each channel predicted from its own past and the other channels (ARX, ridge).

For plants without a first-principles model. Fitted on healthy rows (the first
N rows of a record, or a separate healthy file), it predicts every channel one
step ahead,

    x_c(t) = b_c + sum_{l=1..p} a_{c,l} x_c(t - l) + sum_{j != c} g_{c,j} x_j(t)

on standardised data (training mean and standard deviation per channel), fitted
by ridge regression with separate penalties on the own lags and on the other
channels. The residual r_c(t) = x_c(t) - prediction, in units of its healthy
(in-sample) standard deviation, is what the wavelet bands and CUSUMs of
:mod:`wavelet_fdi.learned_detector` watch.

Why ARX with ridge and not a PCA subspace: measured at the SKAB rig (docs/detector.md,
benchmarks/skab.py) the healthy channels drift slowly (pump temperature by degrees in
minutes, the relation between the two accelerometers by several of their noise
widths) well inside a record. A static subspace fitted on a few hundred rows
(T^2 + Q, the benchmark's PCA baseline) calls every such drift a fault. Each
channel's own lags absorb its slow dynamics: a slowly wandering channel (the AR
coefficients near 1) becomes its innovations, while a channel that is noise around a
set point (flow, vibration; coefficients near 0) keeps a level shift in its residual
for as long as the shift lasts, which is what makes a fault alarm hold. The other
channels enter with a heavier penalty, so a relation learned from a short healthy
stretch cannot dominate a channel's prediction. Ridge (closed form with numpy) is
linear, fast (the whole record in a few vectorised passes) and needs no tuning loop.

Missing samples (NaN) are replaced by the channel's training mean as an input to
the other channels' predictions and by its previous value in its own lags; the
residual of a missing sample is NaN (the detector treats it as healthy and says so).
The predictions are computed term by term in a fixed order, so any chunking of a
record gives bit-identical residuals.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.outputs import write_text

FORMAT = "phfdi-learned-reference/1"


@dataclass
class LearnedReference:
    """ARX predictor of every channel (standardised units inside; measured units at the interface)."""

    channels: tuple[str, ...]
    lags: int
    mean: np.ndarray  # (m,) training mean, measured units
    scale: np.ndarray  # (m,) training standard deviation, measured units
    intercept: np.ndarray  # (m,)
    own: np.ndarray  # (m, lags): coefficient of x_c(t - l), l = 1..lags
    cross: np.ndarray  # (m, m): coefficient of x_j(t) in channel c's prediction; zero diagonal
    residual_sigma: np.ndarray  # (m,) in-sample residual standard deviation, standardised units
    fit_rows: int
    ridge_own: float
    ridge_cross: float

    kind = "arx"

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def residual_channels(self) -> tuple[str, ...]:
        """Every channel gets a residual (the reference protocol, :mod:`wavelet_fdi.references`)."""
        return self.channels

    # ---- fitting -------------------------------------------------------------------
    @classmethod
    def fit(cls, x: np.ndarray, channels: Sequence[str], lags: int = 2, ridge_own: float = 1.0,
            ridge_cross: float = 10.0) -> "LearnedReference":
        """Fit on healthy rows x (n, m). Rows with a missing value are left out of the fit."""
        x = np.asarray(x, dtype=float)
        channels = tuple(channels)
        if x.ndim != 2 or x.shape[1] != len(channels):
            raise UserError(f"healthy data must be rows x {len(channels)} channels, got shape {x.shape}")
        if lags < 0:
            raise UserError(f"lags must be 0 or more, got {lags}")
        if ridge_own < 0 or ridge_cross < 0:
            raise UserError("ridge penalties must be 0 or more")
        m = len(channels)
        finite = np.isfinite(x)
        for c in range(m):
            if finite[:, c].sum() < 2:
                raise UserError(f"channel {channels[c]!r} has fewer than 2 finite healthy samples")
        mean = np.array([np.mean(x[finite[:, c], c]) for c in range(m)])
        scale = np.array([np.std(x[finite[:, c], c]) for c in range(m)])
        scale = np.where(scale > 1e-12 * np.maximum(np.abs(mean), 1.0), scale, 1.0)  # constant channel: unit scale
        z = (x - mean) / scale
        n = len(z)
        rows = np.arange(lags, n)
        ok = finite[rows].all(axis=1)
        for lag in range(1, lags + 1):
            ok &= finite[rows - lag].all(axis=1)
        rows = rows[ok]
        if len(rows) < 2 * (m + lags + 1):
            raise UserError(f"the healthy part has {len(rows)} complete rows; the reference needs at least "
                            f"{2 * (m + lags + 1)} (more rows or fewer lags)")
        intercept = np.zeros(m)
        own = np.zeros((m, lags))
        cross = np.zeros((m, m))
        sigma = np.ones(m)
        for c in range(m):
            others = [j for j in range(m) if j != c]
            cols = [np.ones(len(rows))] + [z[rows - lag, c] for lag in range(1, lags + 1)] + [z[rows, j] for j in others]
            a = np.column_stack(cols)
            penalty = np.diag([0.0] + [ridge_own] * lags + [ridge_cross] * len(others))
            y = z[rows, c]
            coef = np.linalg.solve(a.T @ a + penalty, a.T @ y)
            intercept[c] = coef[0]
            own[c] = coef[1:1 + lags]
            cross[c, others] = coef[1 + lags:]
            s = float(np.std(y - a @ coef))
            sigma[c] = s if s > 1e-9 else 1.0
        return cls(channels, lags, mean, scale, intercept, own, cross, sigma, int(n), float(ridge_own),
                   float(ridge_cross))

    # ---- prediction -----------------------------------------------------------------
    def new_state(self) -> "ReferenceStream":
        return ReferenceStream(self)

    def residuals(self, t_s: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        """Residuals of a whole record (n, m) in healthy-sigma units (a fresh stream; times not used)."""
        return self.new_state().residuals(t_s, x)

    # ---- file ---------------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {"kind": self.kind, "channels": list(self.channels), "lags": self.lags, "mean": self.mean.tolist(),
                "scale": self.scale.tolist(), "intercept": self.intercept.tolist(), "own": self.own.tolist(),
                "cross": self.cross.tolist(), "residual_sigma": self.residual_sigma.tolist(),
                "fit_rows": self.fit_rows, "ridge_own": self.ridge_own, "ridge_cross": self.ridge_cross}

    @classmethod
    def from_dict(cls, d: dict, where: str = "reference") -> "LearnedReference":
        try:
            channels, lags, arr, own, cross = linear_arrays(d)
            return cls(channels, lags, arr["mean"], arr["scale"], arr["intercept"], own, cross,
                       arr["residual_sigma"], int(d["fit_rows"]), float(d["ridge_own"]), float(d["ridge_cross"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: not a learned reference ({exc})") from None


def linear_arrays(d: dict) -> tuple[tuple[str, ...], int, dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """The linear predictor in a reference file's entry (the arx and oe kinds share it): channels, lags, the
    per-channel arrays (mean, scale, intercept, residual_sigma), own (m, lags) and cross (m, m). Raises
    KeyError, TypeError or ValueError when the entry is malformed (the caller names the file)."""
    channels = tuple(str(c) for c in d["channels"])
    m, lags = len(channels), int(d["lags"])
    arr = {k: np.asarray(d[k], dtype=float) for k in ("mean", "scale", "intercept", "residual_sigma")}
    own = np.asarray(d["own"], dtype=float).reshape(m, lags)
    cross = np.asarray(d["cross"], dtype=float).reshape(m, m)
    if any(v.shape != (m,) for v in arr.values()):
        raise ValueError("a per-channel array has the wrong length")
    return channels, lags, arr, own, cross


class ReferenceStream:
    """One-step-ahead residuals of a stream; keeps the last ``lags`` standardised rows."""

    def __init__(self, ref: LearnedReference) -> None:
        self.ref = ref
        self._hist: np.ndarray | None = None  # (lags, m), oldest first

    def residuals(self, t_s: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        """Residuals of the next rows x (n, m), in healthy-sigma units; NaN where x is missing. The ARX
        predictor works in samples: ``t_s`` is accepted for the reference protocol and not used."""
        r = self.ref
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != r.n_channels:
            raise ValueError(f"expected rows x {r.n_channels} channels, got shape {x.shape}")
        n, m = x.shape
        z = (x - r.mean) / r.scale
        missing = ~np.isfinite(z)
        zin = np.where(missing, 0.0, z)  # the training mean as an input to the other channels
        if self._hist is None:
            first = zin[0] if n else np.zeros(m)
            self._hist = np.tile(first, (r.lags, 1))
        # own lags: previous finite value of the channel itself
        zown = z.copy()
        if missing.any():
            prev = self._hist[-1] if r.lags else np.zeros(m)
            for c in np.flatnonzero(missing.any(axis=0)):
                col = zown[:, c]
                idx = np.where(np.isfinite(col), np.arange(n), -1)
                np.maximum.accumulate(idx, out=idx)
                zown[:, c] = np.where(idx >= 0, col[np.maximum(idx, 0)], prev[c])
        ext = np.vstack((self._hist, zown)) if r.lags else zown
        pred = np.tile(r.intercept, (n, 1))
        for lag in range(1, r.lags + 1):
            pred = pred + r.own[:, lag - 1] * ext[r.lags - lag:r.lags - lag + n]
        for j in range(m):
            pred = pred + np.outer(zin[:, j], r.cross[:, j])
        if r.lags:
            self._hist = ext[-r.lags:].copy()
        res = (z - pred) / r.residual_sigma
        return np.where(missing, np.nan, res)


def save_json(path: str | Path, payload: dict, overwrite: bool = True) -> None:
    """A model file, atomically (phfdi_base.outputs)."""
    write_text(path, json.dumps(payload, indent=1, allow_nan=False), overwrite)


def load_json(path: str | Path, fmt: str) -> dict:
    p = Path(path)
    try:
        d = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise UserError(f"{p}: cannot read ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise UserError(f"{p}: not a JSON file ({exc})") from None
    if not isinstance(d, dict) or d.get("format") != fmt:
        raise UserError(f"{p}: not a {fmt} file (format field {d.get('format') if isinstance(d, dict) else None!r})")
    return d

