"""Linear process models from OP (or valve position) to PV, identified from historian data.

Structures (continuous-time gain K, time constant tau, input shift d samples;
the lag is discretised with a zero-order hold):

* ``foptd``: first order plus dead time ``K e^(-theta s) / (tau s + 1)``,
  the self-regulating loops (flow, pressure, temperature);
* ``integrating``: ``K e^(-theta s) / (s (tau s + 1))`` plus a constant
  drift (the unknown balance point), the level loops;
* ``arx``: ARX(2, 2, nk), ``A(q) y = B(q) u + c``, least squares on the
  equation error (the low-order black-box alternative).

**How a model is judged.** Historian data are closed-loop data with unmeasured
disturbances: a PV simulated from OP alone drifts away from the measured one
over two hours whatever the model. So every model is scored on its
predictions of how PV *changes* over the horizons h = 1, 2, 4, ... 32
samples, anchored on the measured PV h samples earlier:

    PV^(k | k-h) = PV(k-h) + x(k) - x(k-h),      x = the model's response to OP,

which is the output-error model with a random-walk disturbance (Ljung 1999,
ch. 3). ``prediction_nrmse`` pools the horizons (1, 2, 4, ... up to a third
of the held-out part): 0 is perfect, 1 is no better than "PV stays where it
was". Short horizons see the sample-to-sample response, long ones the slow
signature of a valve that does not follow OP for minutes. The same criterion is minimised on the training part
(FOPTD and integrating models by separable least squares: a grid over tau
and d, least squares for K) and reported on the held-out part.

**Closed loop.** Direct identification from closed-loop data can return the
controller's inverse instead of the process when disturbances dominate;
that solution has the gain sign that would make the loop a positive feedback
loop. ``gain_sign`` (from the identified controller action) rules it out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Literal, overload

import numpy as np
from scipy.signal import lfilter, lfilter_zi

#: fraction of the record (its end) held out for validation
VALIDATION_FRACTION = 1.0 / 3.0
#: input shifts tried, in samples: the model's output x[k - d]; d = -1 lets OP act within the
#: sample (historians sample fast flow loops at 10 s, slower than they respond); d >= 0 adds a
#: dead time of d samples
DELAYS = np.array([-1, 0, 1, 2, 3, 4, 5, 6, 8, 10, 13, 16, 20])
#: time constants tried, as multiples of the sample time (log-spaced), plus 0 (static)
TAU_FACTORS = np.concatenate(([0.0], np.geomspace(0.5, 120.0, 17)))
#: prediction horizons (samples) pooled in the criterion, those up to a third of the held-out part
HORIZONS = (1, 2, 4, 8, 16, 32, 64, 128)


@dataclass(frozen=True)
class Split:
    """Training part first, validation part last (a split in time)."""

    n: int
    n_train: int

    @classmethod
    def of(cls, n: int, validation_fraction: float = VALIDATION_FRACTION) -> "Split":
        n_val = max(1, int(round(n * validation_fraction)))
        return cls(n, n - n_val)

    @property
    def train(self) -> slice:
        return slice(0, self.n_train)

    @property
    def validation(self) -> slice:
        return slice(self.n_train, self.n)

    @property
    def horizons(self) -> tuple[int, ...]:
        """Prediction horizons (samples) for training and validation alike."""
        return tuple(h for h in HORIZONS if h <= max(1, (self.n - self.n_train) // 3))


def increments(x: np.ndarray, horizons: tuple[int, ...]) -> np.ndarray:
    """x[k] - x[k-h] for every horizon, stacked along the last axis (works on 1-D or rows)."""
    return np.concatenate([x[..., h:] - x[..., :-h] for h in horizons], axis=-1)


def prediction_nrmse(y: np.ndarray, y_model: np.ndarray, horizons: tuple[int, ...]) -> float:
    """Pooled NRMSE of the h-step PV predictions anchored on measured PV (see module docstring)."""
    if not np.all(np.isfinite(y_model)):
        return math.inf
    dy = increments(y, horizons)
    err = dy - increments(y_model, horizons)
    den = float(dy @ dy)
    return math.sqrt(float(err @ err) / den) if den > 0 else (0.0 if not err.any() else math.inf)


def nrmse(y: np.ndarray, y_hat: np.ndarray) -> float:
    """Plain simulation NRMSE: RMS error over the standard deviation of y (1 = predicting the mean)."""
    s = float(np.std(y))
    if not np.all(np.isfinite(y_hat)):
        return math.inf
    rmse = float(np.sqrt(np.mean((y - y_hat) ** 2)))
    return rmse / s if s > 0 else (0.0 if rmse == 0 else math.inf)


def information_criteria(sse: float, n: int, k: int) -> tuple[float, float]:
    """AIC and BIC of a least-squares fit with k parameters on n residuals (Gaussian errors)."""
    mse = max(sse / n, 1e-300)
    return n * math.log(mse) + 2 * k, n * math.log(mse) + k * math.log(n)


@dataclass
class LinearModel:
    """A fitted linear model, its response to the input and its scores."""

    structure: str
    dt_s: float
    params: dict
    n_params: int
    sse_train: float
    n_residuals: int
    nrmse_train: float = math.nan
    nrmse_validation: float = math.nan
    y_model: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict:
        out = {"structure": self.structure, **{k: _round(v) for k, v in self.params.items()}}
        aic, bic = information_criteria(self.sse_train, self.n_residuals, self.n_params)
        out.update(nrmse_train=_round(self.nrmse_train), nrmse_validation=_round(self.nrmse_validation),
                   aic=_round(aic), bic=_round(bic))
        return out


def _round(v, digits: int = 6):
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if not math.isfinite(v) else float(f"{v:.{digits}g}")
    if isinstance(v, list):
        return [_round(x, digits) for x in v]
    return v


def score(model: LinearModel, y: np.ndarray, split: Split) -> LinearModel:
    """Fill in the training and validation NRMSE of a model whose ``y_model`` is set."""
    tr, va = split.train, split.validation
    y_model = model.y_model
    if y_model is None:
        raise TypeError(f"score: the {model.structure} model has no y_model")
    model.nrmse_train = prediction_nrmse(y[tr], y_model[tr], split.horizons)
    model.nrmse_validation = prediction_nrmse(y[va], y_model[va], split.horizons)
    return model


# ---- separable least squares for FOPTD / integrating -----------------------------------
def _first_order(u: np.ndarray, a: float) -> np.ndarray:
    """x[k] = a x[k-1] + (1 - a) u[k-1], at rest on u[0] (unit-gain ZOH lag; a = 0: one-sample shift)."""
    if a <= 0.0:
        x = np.empty_like(u)
        x[0] = u[0]
        x[1:] = u[:-1]
        return x
    # the transposed direct form II state of this filter at rest on u[0] is u[0] itself
    x, _ = lfilter([0.0, 1.0 - a], [1.0, -a], u, zi=[u[0]])
    return x


def _response(du: np.ndarray, tau_s: float, dt_s: float, integrating: bool) -> np.ndarray:
    a = math.exp(-dt_s / tau_s) if tau_s > 0 else 0.0
    x = _first_order(du, a)
    return np.cumsum(x) * dt_s if integrating else x


@lru_cache(maxsize=16)
def _lag_spectra(poles: tuple[float, ...], n: int, nfft: int) -> np.ndarray:
    """Spectra of the unit-gain lags' impulse responses h[k] = (1 - a) a^(k-1), k >= 1, truncated at n."""
    k = np.arange(n, dtype=float)
    a = np.asarray(poles)[:, None]
    h = np.where(k[None, :] >= 1, (1.0 - a) * a ** np.maximum(k[None, :] - 1, 0), 0.0)
    return np.fft.rfft(h, nfft, axis=1)


def _responses(du: np.ndarray, taus_s: np.ndarray, dt_s: float, integrating: bool) -> np.ndarray:
    """:func:`_response` of each row of ``du`` (m, n) for many time constants at once: (m, n_tau, n)
    (one FFT convolution, exact for the record)."""
    n = du.shape[-1]
    nfft = 1 << (2 * n - 1).bit_length()
    poles = tuple(math.exp(-dt_s / t) if t > 0 else 0.0 for t in taus_s)
    spectra = np.fft.rfft(du - du[:, :1], nfft, axis=-1)[:, None, :] * _lag_spectra(poles, n, nfft)
    x = np.fft.irfft(spectra, nfft, axis=-1)[..., :n]
    x += du[:, :1, None]
    return np.cumsum(x, axis=-1) * dt_s if integrating else x


def _shift(x: np.ndarray, d: int) -> np.ndarray:
    idx = np.clip(np.arange(len(x)) - d, 0, len(x) - 1)
    return x[idx]


@dataclass(frozen=True)
class LagTargets:
    """The PV side of the lag-model search (:func:`fit_lag_model`): the h-step increments of the
    training part and what depends on them alone, computed once for every input tried against
    the same PV (the valve-model search tries hundreds)."""

    y: np.ndarray
    dt_s: float
    split: Split
    integrating: bool
    delays: np.ndarray
    starts: np.ndarray
    n_off: int
    dys: tuple
    weights: tuple
    shifted: tuple
    syy: float

    @classmethod
    def of(cls, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
           delays: np.ndarray = DELAYS) -> "LagTargets":
        n_tr = split.n_train
        hs = split.horizons
        delays = np.asarray(delays)[np.asarray(delays) < n_tr // 4]
        d_max = max(int(delays.max()), 0)
        starts = d_max - delays  # where delay d's window starts in the response's increments
        # targets: dy_h[k] for k in [h + d_max, n_tr)
        dys = [y[h + d_max:n_tr] - y[d_max:n_tr - h] for h in hs]
        w = [0.0] * len(hs)
        if integrating:
            # project the drift column (h dt in horizon h's block) out of targets and regressors
            norm = math.sqrt(sum(len(d) * (h * dt_s) ** 2 for d, h in zip(dys, hs)))
            w = [h * dt_s / norm for h in hs]
            c_y = sum(wi * float(d.sum()) for wi, d in zip(w, dys))
            dys = [d - c_y * wi for d, wi in zip(dys, w)]
        syy = float(sum(d @ d for d in dys))
        n_off = int(starts.max()) + 1
        # contiguous copies: the same products bit for bit as the strided views (tested), faster
        return cls(y, dt_s, split, integrating, delays, starts, n_off, tuple(dys), tuple(w),
                   tuple(np.ascontiguousarray(_shifted(dy, n_off).T) for dy in dys), syy)

    @property
    def n_residuals(self) -> int:
        return sum(len(d) for d in self.dys)


def _lag_grid(u: np.ndarray, t: LagTargets, gain_sign: int, tau_factors: np.ndarray):
    """Criterion and gain on the (tau, delay) grid for each input row of ``u`` (m, n): arrays
    (m, n_tau, n_delay), and the time constants and centred inputs. Row by row the same arithmetic
    as for one input, so a batch gives bit for bit the values of its rows one at a time."""
    n_tr = t.split.n_train
    du = u - np.mean(u[:, :n_tr], axis=1, keepdims=True)
    taus = np.asarray(tau_factors, float) * t.dt_s
    resp = _responses(du, taus, t.dt_s, t.integrating)  # (m, n_tau, n)
    starts, n_off = t.starts, t.n_off
    shape = (len(u), len(taus), len(t.delays))
    sxx = np.zeros(shape)
    sxy = np.zeros(shape)
    sdr = np.zeros(shape)
    # window [s, s + n_dy) of a cumulative sum c: c[s + n_dy - 1] - c[s - 1], with c[-1] = 0
    first = starts == 0
    before = np.where(first, 0, starts - 1)
    for h, dy, wi, shifted in zip(t.split.horizons, t.dys, t.weights, t.shifted):
        # target i (sample k = i + h + d_max) meets, for delay d, the response increment
        # D[i + s_d] with D[j] = r[j + h] - r[j] and s_d = d_max - d
        n_dy = len(dy)
        span = n_dy + n_off - 1
        inc = resp[..., h:h + span] - resp[..., :span]
        sxy += (inc @ shifted)[..., starts]  # stacked matmul: one BLAS call per row, as for one input
        if t.integrating:
            c1 = np.cumsum(inc, axis=-1)
            sdr += wi * (c1[..., starts + n_dy - 1] - np.where(first, 0.0, c1[..., before]))
        np.multiply(inc, inc, out=inc)
        c2 = np.cumsum(inc, axis=-1, out=inc)
        sxx += c2[..., starts + n_dy - 1] - np.where(first, 0.0, c2[..., before])
    if t.integrating:
        sxx = sxx - sdr ** 2
    ok = sxx > 1e-12 * np.maximum(1e-300, sxx.max(axis=(1, 2), keepdims=True))
    gain = np.where(ok, sxy / np.where(ok, sxx, 1.0), 0.0)
    if gain_sign:
        gain = np.where(gain * gain_sign > 0, gain, 0.0)
    sse = t.syy - 2 * gain * sxy + gain ** 2 * sxx
    return sse, gain, taus, du


def lag_criteria(u: np.ndarray, targets: LagTargets, gain_sign: int = 0,
                 tau_factors: np.ndarray = TAU_FACTORS) -> np.ndarray:
    """The training criterion of :func:`fit_lag_model` (``sse_only``) for each row of ``u`` (m, n)
    at once, equal bit for bit to calling it on each row."""
    sse, *_ = _lag_grid(np.atleast_2d(u), targets, gain_sign, tau_factors)
    best = sse.reshape(len(sse), -1).min(axis=1)
    return np.where(best > targets.syy, targets.syy, best)


@overload
def fit_lag_model(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
                  gain_sign: int = 0, delays: np.ndarray = DELAYS,
                  tau_factors: np.ndarray = TAU_FACTORS, sse_only: Literal[False] = False,
                  targets: LagTargets | None = None) -> LinearModel: ...
@overload
def fit_lag_model(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
                  gain_sign: int = 0, delays: np.ndarray = DELAYS,
                  tau_factors: np.ndarray = TAU_FACTORS, *, sse_only: Literal[True],
                  targets: LagTargets | None = None) -> float: ...
@overload
def fit_lag_model(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
                  gain_sign: int = 0, delays: np.ndarray = DELAYS,
                  tau_factors: np.ndarray = TAU_FACTORS, sse_only: bool = False,
                  targets: LagTargets | None = None) -> LinearModel | float: ...
def fit_lag_model(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
                  gain_sign: int = 0, delays: np.ndarray = DELAYS,
                  tau_factors: np.ndarray = TAU_FACTORS, sse_only: bool = False,
                  targets: LagTargets | None = None) -> LinearModel | float:
    """FOPTD (or integrating with lag) from u to y, minimising the pooled h-step prediction error.

    Self-regulating: dy_h = K dx_h.  Integrating: dy_h = K dz_h + b h dt (z = dt cumsum x).
    ``gain_sign`` +1 / -1 admits only gains of that sign (0: either). ``sse_only``: return the
    training criterion alone. ``targets``: the PV side computed beforehand (:class:`LagTargets`
    of this y, split and delays); many inputs at once: :func:`lag_criteria`.

    The increments of the training part from sample ``max(delays)`` on are the residuals for
    every delay alike; for each horizon the cross products with all delays come from one
    correlation and one cumulative sum.
    """
    t = targets or LagTargets.of(y, dt_s, split, integrating, delays)
    sse, gain, taus, du = _lag_grid(u[None, :], t, gain_sign, tau_factors)
    sse, gain, du = sse[0], gain[0], du[0]
    it, idl = np.unravel_index(int(np.argmin(sse)), sse.shape)
    best = (float(sse[it, idl]), float(taus[it]), int(t.delays[idl]), float(gain[it, idl]))
    if best[0] > t.syy:
        best = (t.syy, 0.0, 0, 0.0)
    if sse_only:
        return best[0]
    return _finish_lag_model(du, y, dt_s, split, integrating, best, t.n_residuals)


def _shifted(dy: np.ndarray, n_off: int) -> np.ndarray:
    """Rows m[o] = dy placed at offset o in a vector of length len(dy) + n_off - 1 (zeros elsewhere)."""
    pad = np.zeros(n_off - 1)
    zp = np.concatenate((pad, dy, pad))
    return np.lib.stride_tricks.sliding_window_view(zp, len(dy) + n_off - 1)[::-1]


def _finish_lag_model(du: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
                      best: tuple, n_residuals: int) -> LinearModel:
    sse, tau_s, d, gain = best
    tr = split.train
    x = gain * _shift(_response(du, tau_s, dt_s, integrating), d)
    t = np.arange(len(y)) * dt_s
    if integrating:
        # drift and offset for the simulated output (they cancel in the increments except the drift)
        design = np.column_stack([np.ones(split.n_train), t[tr]])
        (offset, drift), *_ = np.linalg.lstsq(design, y[tr] - x[tr], rcond=None)
        y_model = x + offset + drift * t
    else:
        offset, drift = float(np.mean(y[tr] - x[tr])), 0.0
        y_model = x + offset
    params = {"gain": gain, "time_constant_s": tau_s, "dead_time_s": max(d, 0) * dt_s,
              "same_sample_response": d < 0, "offset": float(offset)}
    if integrating:
        params["drift_per_s"] = float(drift)
    model = LinearModel("integrating" if integrating else "foptd", dt_s, params, 4 if integrating else 3,
                        sse, n_residuals, y_model=y_model)
    return score(model, y, split)


# ---- ARX(2, 2, nk) ---------------------------------------------------------------------------
def fit_arx(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, gain_sign: int = 0,
            na: int = 2, nb: int = 2, delays: np.ndarray = DELAYS[2:]) -> LinearModel:
    """ARX by least squares on the equation error, then simulated from u alone and scored.

    No direct feedthrough (nk >= 1): with b0 free, the equation error of closed-loop data is
    minimised exactly by the PI controller's inverse (PV(k) - PV(k-1) = -(OP(k) - OP(k-1)) / Kc
    + ...), whatever the process. On refinery loop 2111FIC46005 the free fit put a same-sample
    "response" b0 = -19 beside a static gain of +4.7: the controller's proportional kick.
    """
    tr = split.train
    um, ym = float(np.mean(u[tr])), float(np.mean(y[tr]))
    du, dy = u - um, y - ym
    delays = delays[delays < max(1, split.n_train // 10)]
    start = na + int(delays.max()) + nb
    rows = np.arange(start, split.n_train)
    best: tuple[float, int, np.ndarray] | None = None
    for nk in delays:
        cols = [-dy[rows - i] for i in range(1, na + 1)] + [du[rows - nk - j] for j in range(nb)]
        cols.append(np.ones(len(rows)))
        design = np.column_stack(cols)
        theta, *_ = np.linalg.lstsq(design, dy[rows], rcond=None)
        sse = float(np.sum((dy[rows] - design @ theta) ** 2))
        if best is None or sse < best[0]:
            best = (sse, int(nk), theta)
    assert best is not None
    _, nk, theta = best
    a = np.concatenate(([1.0], theta[:na]))
    b = np.concatenate((np.zeros(nk), theta[na:na + nb]))
    stable = bool(np.all(np.abs(np.roots(a)) < 1.0))
    static = float(np.sum(theta[na:na + nb]) / a.sum()) if abs(a.sum()) > 1e-9 else math.nan
    admissible = stable and not (gain_sign and math.isfinite(static) and static * gain_sign < 0)
    y_model = _simulate_arx(a, b, float(theta[-1]), du) + ym if admissible else np.full(len(y), np.nan)
    params = {"a": [float(v) for v in a[1:]], "b": [float(v) for v in theta[na:na + nb]],
              "dead_time_s": nk * dt_s, "offset": float(theta[-1]), "gain": static, "stable": stable,
              "admissible": admissible}
    hs = split.horizons
    n_res = sum(split.n_train - h for h in hs)
    if admissible:
        err = increments(y[tr], hs) - increments(y_model[tr], hs)
        sse_pred = float(err @ err)
    else:
        sse_pred = math.inf
    model = LinearModel("arx", dt_s, params, na + nb + 2, sse_pred, n_res, y_model=y_model)
    return score(model, y, split)


def _simulate_arx(a: np.ndarray, b: np.ndarray, c: float, du: np.ndarray) -> np.ndarray:
    """Simulate A(q) y = B(q) u + c from rest, the input held at u[0] before k = 0 (A stable)."""
    m = max(len(a), len(b))
    aa, bb = np.pad(a, (0, m - len(a))), np.pad(b, (0, m - len(b)))
    y, _ = lfilter(bb, aa, du, zi=lfilter_zi(bb, aa) * du[0])
    return y + c / float(aa.sum())


def fit_linear(u: np.ndarray, y: np.ndarray, dt_s: float, split: Split, integrating: bool,
               gain_sign: int = 0) -> list[LinearModel]:
    """The linear candidates for OP -> PV, best (lowest validation NRMSE) first."""
    models = [fit_lag_model(u, y, dt_s, split, integrating, gain_sign), fit_arx(u, y, dt_s, split, gain_sign)]
    return sorted(models, key=lambda m: (m.nrmse_validation, m.n_params))
