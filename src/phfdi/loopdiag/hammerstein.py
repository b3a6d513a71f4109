"""Valve nonlinearity between OP and the process, fitted jointly with the linear part.

Hammerstein structure: OP -> valve block (from :mod:`valve_actuator.blocks`,
the same code the simulator runs) -> stem position -> linear lag model -> PV.
For each cause, a global grid search over the block's parameters
(:func:`scipy.optimize.brute`, then a finer grid around the best point), and
for each grid point the linear part by separable least squares
(:func:`phfdi.loopdiag.identify.fit_lag_model`): the same scheme as Jelali
(2008) and Choudhury et al. (2008) for the Kano stiction model. Parameters are
fitted on the training part; causes are ranked on the held-out part.

Parameters are in OP units, i.e. % of span when OP is in % (stiction ``S``
and ``J`` as in Kano et al. 2004: S = dead-band + stick-band, J = slip jump).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brute

from valve_actuator.blocks import Backlash, DeadZone, Quantization, Saturation, Stiction

from .identify import DELAYS, TAU_FACTORS, LinearModel, Split, fit_lag_model, information_criteria, score

#: causes of the actuator family, in catalogue order (simplest first breaks ties)
ACTUATOR_CAUSES = ("backlash", "deadzone", "saturation", "quantization", "stiction")


def through_block(block, u: np.ndarray) -> np.ndarray:
    """Run a position block over the command sequence u (starting at rest on u[0])."""
    block.reset(float(u[0]))
    step = block.step
    out = np.empty(len(u))
    for k, x in enumerate(u.tolist()):
        out[k] = step(x, 0.0)
    return out


@dataclass
class CauseFit:
    """Best parameters of one cause and the model they give."""

    cause: str
    parameters: dict
    model: LinearModel
    position: np.ndarray = field(repr=False)
    n_block_params: int = 1
    family: str = "actuator"

    @property
    def n_params(self) -> int:
        return self.model.n_params + self.n_block_params

    def entry(self) -> dict:
        aic, bic = information_criteria(self.model.sse_train, self.model.n_residuals, self.n_params)
        return {"cause": self.cause, "family": self.family,
                "parameters": {k: _r(v) for k, v in self.parameters.items()},
                "nrmse_validation": _r(self.model.nrmse_validation), "nrmse_train": _r(self.model.nrmse_train),
                "aic": _r(aic), "bic": _r(bic), "n_params": self.n_params,
                "linear_part": {k: _r(v) for k, v in self.model.params.items()}}


def _r(v):
    return float(f"{v:.6g}") if isinstance(v, float) and math.isfinite(v) else v


@dataclass
class Problem:
    """One loop's data for the Hammerstein search."""

    op: np.ndarray
    pv: np.ndarray
    dt_s: float
    split: Split
    integrating: bool
    op_in_percent: bool
    gain_sign: int = 0
    #: the linear grid searched for each nonlinearity candidate (see :meth:`centre_on`)
    delays: np.ndarray = field(default_factory=lambda: DELAYS)
    tau_factors: np.ndarray = field(default_factory=lambda: TAU_FACTORS)

    def centre_on(self, lag: LinearModel) -> "Problem":
        """Search the linear part near the nominal lag model (dead time +-2 samples, time
        constant within a factor 4) while scanning the nonlinearity; the winner is re-fitted
        on the full grid. Cuts the work five-fold."""
        d0 = -1 if lag.params.get("same_sample_response") else int(round(lag.params["dead_time_s"] / self.dt_s))
        self.delays = DELAYS[np.abs(DELAYS - d0) <= 2]
        f0 = lag.params["time_constant_s"] / self.dt_s
        if f0 > 0:
            keep = (TAU_FACTORS == 0) | ((TAU_FACTORS >= f0 / 4) & (TAU_FACTORS <= f0 * 4))
        else:
            keep = TAU_FACTORS <= 2.0
        self.tau_factors = TAU_FACTORS[keep]
        return self

    @property
    def op_train(self) -> np.ndarray:
        return self.op[self.split.train]

    @property
    def span(self) -> float:
        """Peak-to-peak OP over the training part (the scale of every width searched)."""
        return max(float(np.ptp(self.op_train)), 1e-9)

    def fit(self, block, full_grid: bool = True) -> tuple[LinearModel, np.ndarray]:
        v = through_block(block, self.op)
        if np.ptp(v[self.split.train]) <= 1e-12 * max(1.0, abs(float(v[0]))):
            return _no_motion(self, v), v
        grid = (DELAYS, TAU_FACTORS) if full_grid else (self.delays, self.tau_factors)
        return fit_lag_model(v, self.pv, self.dt_s, self.split, self.integrating, self.gain_sign, *grid), v

    def sse(self, block) -> float:
        return self.fit(block, full_grid=False)[0].sse_train


def _no_motion(p: Problem, v: np.ndarray) -> LinearModel:
    """A stem that never moves on the training part explains nothing: PV predicted to stay."""
    y = p.pv
    y_model = np.full(len(y), float(np.mean(y[p.split.train])))
    hs = p.split.horizons
    dy = np.concatenate([y[h:p.split.n_train] - y[:p.split.n_train - h] for h in hs])
    m = LinearModel("integrating" if p.integrating else "foptd", p.dt_s, {"gain": 0.0}, 3, float(dy @ dy),
                    len(dy), y_model=y_model)
    return score(m, y, p.split)


# ---- the search per cause ---------------------------------------------------------------
def _widths(p: Problem, n: int = 12) -> np.ndarray:
    """Widths from 1 % to 80 % of the training OP span, log-spaced (log10 values)."""
    return np.linspace(math.log10(0.01 * p.span), math.log10(0.8 * p.span), n)


def _grid_1d(p: Problem, make: Callable[[float], object], log_widths: np.ndarray) -> float:
    """Best log10 width on a grid, then on a finer grid around it."""
    f = lambda z: p.sse(make(10.0 ** float(np.atleast_1d(z)[0])))  # noqa: E731
    step = float(log_widths[1] - log_widths[0])
    best = brute(f, (slice(log_widths[0], log_widths[-1] + 0.5 * step, step),), finish=None)
    best = float(np.atleast_1d(best)[0])
    fine = brute(f, (slice(best - step, best + step * 1.01, step / 4),), finish=None)
    return float(np.atleast_1d(fine)[0])


def fit_backlash(p: Problem) -> CauseFit:
    z = _grid_1d(p, lambda w: Backlash(width_pct=w), _widths(p))
    params = {"width_pct": 10.0 ** z}
    model, v = p.fit(Backlash(**params))
    return CauseFit("backlash", params, model, v, 1)


def fit_stiction(p: Problem, backlash: CauseFit | None = None) -> CauseFit:
    """Kano S on a log grid and J as a fraction of S in [0, 1.2], then a finer grid around the best.

    Kano's model with J = 0 is a backlash of width S: the backlash optimum, when given, is a
    candidate too, so the two-parameter model never fits the training data worse than its special
    case.
    """
    f = lambda z: p.sse(Stiction(s_pct=10.0 ** z[0], j_pct=10.0 ** z[0] * z[1]))  # noqa: E731
    lw = _widths(p)
    step = float(lw[1] - lw[0])
    best, f_best, *_ = brute(f, (slice(lw[0], lw[-1] + 0.5 * step, step), slice(0.0, 1.21, 0.2)),
                             finish=None, full_output=True)
    if backlash is not None:
        z_b = np.array([math.log10(backlash.parameters["width_pct"]), 0.0])
        if f(z_b) < f_best:
            best = z_b
    fine = brute(f, (slice(best[0] - step / 2, best[0] + step * 0.51, step / 4),
                     slice(max(0.0, best[1] - 0.1), best[1] + 0.101, 0.05)), finish=None)
    s = 10.0 ** float(fine[0])
    params = {"s_pct": s, "j_pct": s * float(fine[1])}
    model, v = p.fit(Stiction(**params))
    return CauseFit("stiction", params, model, v, 2)


def fit_deadzone(p: Problem) -> CauseFit:
    """Dead-zone around the operating point: the training median of OP, or its quartiles."""
    best: tuple[float, float, float] | None = None
    for q in (0.5, 0.25, 0.75):
        c = float(np.quantile(p.op_train, q))
        z = _grid_1d(p, lambda w, c=c: DeadZone(width_pct=w, center_pct=c), _widths(p, 8))
        sse = p.sse(DeadZone(width_pct=10.0 ** z, center_pct=c))
        if best is None or sse < best[0]:
            best = (sse, z, c)
    assert best is not None
    params = {"width_pct": 10.0 ** best[1], "center_pct": best[2]}
    model, v = p.fit(DeadZone(**params))
    return CauseFit("deadzone", params, model, v, 2)


def fit_saturation(p: Problem) -> CauseFit | None:
    """The stem cannot pass a limit inside the OP range (flat tops or bottoms); None for OP not in %."""
    if not p.op_in_percent:
        return None
    lo_op, hi_op = float(np.min(p.op_train)), float(np.max(p.op_train))
    if not (0.0 <= lo_op and hi_op <= 100.0):
        return None
    best: tuple[float, dict] | None = None
    for q in np.linspace(0.3, 0.97, 12):
        hi = float(np.quantile(p.op_train, q))
        lo = float(np.quantile(p.op_train, 1.0 - q))
        for params in ({"low_pct": 0.0, "high_pct": max(hi, 1e-6)}, {"low_pct": min(lo, 99.999), "high_pct": 100.0}):
            if not params["low_pct"] < params["high_pct"]:
                continue
            sse = p.sse(Saturation(**params))
            if best is None or sse < best[0]:
                best = (sse, params)
    if best is None:
        return None
    model, v = p.fit(Saturation(**best[1]))
    return CauseFit("saturation", best[1], model, v, 1)


def fit_quantization(p: Problem) -> CauseFit:
    z = _grid_1d(p, lambda w: Quantization(step_pct=w), _widths(p, 10))
    params = {"step_pct": 10.0 ** z}
    model, v = p.fit(Quantization(**params))
    return CauseFit("quantization", params, model, v, 1)


FITTERS: dict[str, Callable[[Problem], CauseFit | None]] = {
    "backlash": fit_backlash,
    "deadzone": fit_deadzone,
    "saturation": fit_saturation,
    "quantization": fit_quantization,
    "stiction": fit_stiction,
}


def fit_causes(p: Problem, causes: tuple[str, ...] = ACTUATOR_CAUSES) -> list[CauseFit]:
    """Every actuator cause fitted, best on the validation part first (ties: fewer parameters)."""
    fits: dict[str, CauseFit] = {}
    for c in causes:
        fit = fit_stiction(p, fits.get("backlash")) if c == "stiction" else FITTERS[c](p)
        if fit is not None:
            fits[c] = fit
    return sorted(fits.values(), key=lambda f: (f.model.nrmse_validation, f.n_params))
