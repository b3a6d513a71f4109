"""Valve nonlinearity between OP and the process, fitted jointly with the linear part.

Hammerstein structure: OP -> valve block (from :mod:`valve_actuator.blocks`,
the same code the simulator runs) -> stem position -> linear lag model -> PV.
For each cause, a global grid search over the block's parameters
(:func:`scipy.optimize.brute`, then a finer grid around the best point), and
for each grid point the linear part by separable least squares
(:func:`phfdi.loopdiag.identify.fit_lag_model`): the same scheme as Jelali
(2008) and Choudhury et al. (2008) for the Kano stiction model. Parameters are
fitted on the training part; causes are ranked on the held-out part.

Each grid is evaluated as one batch (:meth:`Problem.sse_many`): every block of the
grid runs over OP together (:func:`valve_actuator.batch.positions`) and the linear
part is searched for all of them at once (:func:`phfdi.loopdiag.identify.lag_criteria`),
with the PV side computed once per loop. Row by row this is the same arithmetic as
one grid point at a time, so the criterion values, the grid's choice and every
answer are the same bit for bit (tests/loops/test_fast_paths.py); it is several
times faster because the Python work is per grid, not per point and sample.

Parameters are in OP units, i.e. % of span when OP is in % (stiction ``S``
and ``J`` as in Kano et al. 2004: S = dead-band + stick-band, J = slip jump).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy.optimize import brute

from valve_actuator.batch import positions
from valve_actuator.blocks import Backlash, DeadZone, Quantization, Saturation, Stiction

from .identify import (
    DELAYS,
    TAU_FACTORS,
    LagTargets,
    LinearModel,
    Split,
    fit_lag_model,
    information_criteria,
    lag_criteria,
    score,
)
from .vocabulary import ACTUATOR_CAUSES, WIDTH_SEARCH_SPAN

#: grid points whose linear part is searched in one batch (bounds the (points, tau, samples) arrays)
BATCH_ROWS = 32



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
        """While scanning a nonlinearity, search the linear part only up to the nominal lag
        model's dead time + 2 samples and twice its time constant: a valve nonlinearity explains
        part of the apparent lag, never adds to it. The winner is re-fitted on the full grid."""
        d0 = -1 if lag.params.get("same_sample_response") else int(round(lag.params["dead_time_s"] / self.dt_s))
        self.delays = DELAYS[DELAYS <= d0 + 2]
        f0 = lag.params["time_constant_s"] / self.dt_s
        self.tau_factors = TAU_FACTORS[TAU_FACTORS <= max(2.0 * f0, 2.0)]
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
        """Training criterion of the block with the linear part searched on the scan grid."""
        return float(self.sse_many([block])[0])

    def sse_many(self, blocks: list) -> np.ndarray:
        """:meth:`sse` of each block, as one batch (equal to calling it on each, bit for bit)."""
        v = positions(blocks, self.op)
        n_tr = self.split.n_train
        still = np.ptp(v[:, :n_tr], axis=1) <= 1e-12 * np.maximum(1.0, np.abs(v[:, 0]))
        out = np.empty(len(blocks))
        if still.any():
            out[still] = _no_motion(self, v[np.argmax(still)]).sse_train  # the same for every still stem
        moving = np.flatnonzero(~still)
        targets = self._scan_targets()
        for k in range(0, len(moving), BATCH_ROWS):
            rows = moving[k:k + BATCH_ROWS]
            out[rows] = lag_criteria(v[rows], targets, self.gain_sign, self.tau_factors)
        return out

    def _scan_targets(self) -> LagTargets:
        key = tuple(int(d) for d in self.delays)
        cached = getattr(self, "_targets", None)
        if cached is None or cached[0] != key:
            cached = (key, LagTargets.of(self.pv, self.dt_s, self.split, self.integrating, self.delays))
            self._targets = cached
        return cached[1]


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
    """Widths from 1 % to 80 % of the training OP span (:data:`.vocabulary.WIDTH_SEARCH_SPAN`), log-spaced
    (log10 values)."""
    lo, hi = WIDTH_SEARCH_SPAN
    return np.linspace(math.log10(lo * p.span), math.log10(hi * p.span), n)


def _grid(p: Problem, block_at: Callable[[np.ndarray], object], ranges: tuple, full_output: bool = False):
    """:func:`scipy.optimize.brute` (no finishing step) over ``ranges`` of the block's parameters,
    its grid evaluated as one batch: brute hands the whole grid to its ``workers`` map at once,
    and this map runs :meth:`Problem.sse_many` on it (the values brute's point-by-point calls of
    ``p.sse(block_at(z))`` would give, bit for bit). ``block_at`` takes the point as a 1-D array."""
    def one(z):
        return p.sse(block_at(np.atleast_1d(z)))

    def batch(_one, points):
        return p.sse_many([block_at(np.atleast_1d(z)) for z in points]).tolist()

    return brute(one, ranges, finish=None, full_output=full_output, workers=batch)


def _grid_1d(p: Problem, make: Callable[[float], object], log_widths: np.ndarray) -> float:
    """Best log10 width on a grid, then on a finer grid around it."""
    at = lambda z: make(10.0 ** float(z[0]))  # noqa: E731
    step = float(log_widths[1] - log_widths[0])
    best = _grid(p, at, (slice(log_widths[0], log_widths[-1] + 0.5 * step, step),))
    best = float(np.atleast_1d(best)[0])
    fine = _grid(p, at, (slice(best - step, best + step * 1.01, step / 4),))
    return float(np.atleast_1d(fine)[0])


def fit_backlash(p: Problem) -> CauseFit:
    z = _grid_1d(p, lambda w: Backlash(width_pct=w), _widths(p, 16))
    params = {"width_pct": 10.0 ** z}
    model, v = p.fit(Backlash(**params))
    return CauseFit("backlash", params, model, v, 1)


def fit_stiction(p: Problem, backlash: CauseFit | None = None) -> CauseFit:
    """Kano S on a log grid and J as a fraction of S in [0, 1.2]; the two best grid points
    are refined on finer local grids (the error surface is rugged: a slip one sample earlier
    or later changes the fit).

    Kano's model with J = 0 is a dead-band of width S, like a backlash, except at the start of
    the record: the Kano block starts stuck and needs a full S to move either way, the backlash
    block starts centred and needs half its width. The backlash optimum, when given, is a
    starting point of the refinement too.
    """
    at = lambda z: Stiction(s_pct=10.0 ** z[0], j_pct=10.0 ** z[0] * z[1])  # noqa: E731
    lw = _widths(p, 16)
    step = float(lw[1] - lw[0])
    _, _, grid, values = _grid(p, at, (slice(lw[0], lw[-1] + 0.5 * step, step), slice(0.0, 1.21, 0.2)),
                               full_output=True)
    flat = np.argsort(values, axis=None)[:2]
    starts = [grid[:, *np.unravel_index(i, values.shape)] for i in flat]
    if backlash is not None:
        starts.append(np.array([math.log10(backlash.parameters["width_pct"]), 0.0]))
    best_z, best_f = starts[0], math.inf
    for z0 in starts:
        z, fz, *_ = _grid(p, at, (slice(z0[0] - step / 2, z0[0] + step * 0.51, step / 4),
                                  slice(max(0.0, z0[1] - 0.1), z0[1] + 0.101, 0.05)), full_output=True)
        if fz < best_f:
            best_z, best_f = z, fz
    s = 10.0 ** float(best_z[0])
    params = {"s_pct": s, "j_pct": s * float(best_z[1])}
    model, v = p.fit(Stiction(**params))
    return CauseFit("stiction", params, model, v, 2)


def fit_deadzone(p: Problem) -> CauseFit | None:
    """Dead-zone around a centre: OP at the start (where the block comes to rest), the training
    median or quartiles of OP. Only widths OP crosses on both sides (between its 5 % and 95 %
    quantiles) are tried: a zone OP stays on one side of is indistinguishable from an offset
    and a saturation."""
    q05, q95 = np.quantile(p.op_train, [0.05, 0.95])
    best: tuple[float, float, float] | None = None
    centres = [float(p.op[0])] + [float(np.quantile(p.op_train, q)) for q in (0.5, 0.25, 0.75)]
    for c in centres:
        w_max = 2.0 * min(c - q05, q95 - c)
        lw = _widths(p, 8)
        lw = lw[lw <= math.log10(w_max)] if w_max > 0 else lw[:0]
        if len(lw) < 2:
            continue
        def dead_zone(w: float, c: float = c) -> DeadZone:
            return DeadZone(width_pct=w, center_pct=c)

        z = _grid_1d(p, dead_zone, lw)
        z = min(z, math.log10(w_max))
        sse = p.sse(DeadZone(width_pct=10.0 ** z, center_pct=c))
        if best is None or sse < best[0]:
            best = (sse, z, c)
    if best is None:
        return None
    params = {"width_pct": 10.0 ** best[1], "center_pct": best[2]}
    model, v = p.fit(DeadZone(**params))
    return CauseFit("deadzone", params, model, v, 2)


def fit_saturation(p: Problem) -> CauseFit | None:
    """The stem cannot pass a limit inside the OP range (flat tops or bottoms): a high or a low
    limit on OP's quantiles, then a finer grid around the best. None for OP not in %."""
    if not p.op_in_percent:
        return None
    lo_op, hi_op = float(np.min(p.op_train)), float(np.max(p.op_train))
    if not (0.0 <= lo_op and hi_op <= 100.0):
        return None
    best: tuple[float, str, float] | None = None
    tried = [(side, limit) for q in np.linspace(0.3, 0.97, 12)
             for side, limit in (("high", float(np.quantile(p.op_train, q))),
                                 ("low", float(np.quantile(p.op_train, 1 - q))))]
    for sse, (side, limit) in zip(p.sse_many([_saturation(s, lim) for s, lim in tried]).tolist(), tried):
        if best is None or sse < best[0]:
            best = (sse, side, limit)
    assert best is not None
    _, side, limit = best
    step = (hi_op - lo_op) / 24.0
    at = lambda z: _saturation(side, float(z[0]))  # noqa: E731
    limit = float(np.atleast_1d(_grid(p, at, (slice(limit - step, limit + step * 1.01, step / 4),)))[0])
    block = _saturation(side, limit)
    params = {"low_pct": block.low_pct, "high_pct": block.high_pct}
    model, v = p.fit(block)
    return CauseFit("saturation", params, model, v, 1)


def _saturation(side: str, limit: float) -> Saturation:
    limit = min(max(limit, 1e-6), 100.0 - 1e-6)
    return Saturation(high_pct=limit) if side == "high" else Saturation(low_pct=limit)


def fit_quantization(p: Problem) -> CauseFit:
    """Resolution step q and the place b of one boundary between levels (levels at b +- q/2, ...).

    Parametrised by the boundary, not by the levels' offset: a loop hunts across one boundary,
    so with b right the error changes smoothly with q, while with the offset as parameter the
    optimum is a needle no grid finds. b runs over OP's quantiles, q over a log grid; the two
    best points are refined locally.
    """
    qs = _widths(p, 8)
    step = float(qs[1] - qs[0])
    bs = np.quantile(p.op_train, np.linspace(0.05, 0.95, 13))
    b_step = float(np.median(np.diff(bs))) if len(bs) > 1 else 0.1
    # OP held at one value most of the time (a compressed record) makes the step zero, or a rounding error of the
    # quantiles (1e-15): either makes a grid whose points all round to one value, which brute cannot search
    if not b_step > 1e-9 * max(1.0, float(np.max(np.abs(bs)))):
        b_step = max(float(np.ptp(p.op_train)) / 12.0, 1e-6)
    at = lambda z: _quantizer(z[0], z[1])  # noqa: E731
    points = [(lq, b) for lq in qs for b in bs]
    scores = [(v, lq, b) for v, (lq, b) in zip(p.sse_many([at(z) for z in points]).tolist(), points)]
    best = min(scores)
    for _, lq0, b0 in sorted(scores)[:2]:
        z, fz, *_ = _grid(p, at, (slice(lq0 - step / 2, lq0 + step * 0.51, step / 4),
                                  slice(b0 - b_step / 2, b0 + b_step * 0.51, b_step / 4)), full_output=True)
        if fz < best[0]:
            best = (fz, float(z[0]), float(z[1]))
    block = _quantizer(best[1], best[2])
    params = {"step_pct": block.step_pct, "offset_pct": block.offset_pct}
    model, v = p.fit(block)
    return CauseFit("quantization", params, model, v, 2)


def _quantizer(log_q: float, boundary: float) -> Quantization:
    q = 10.0 ** float(log_q)
    return Quantization(step_pct=q, offset_pct=(float(boundary) + 0.5 * q) % q)


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
