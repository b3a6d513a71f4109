"""Fitting candidates to measured records: least squares on training samples, scored on held-out ones.

The residual is the open-loop simulation error of every measured output in
units of that output's noise floor (so a perfect model leaves unit-variance
white noise, and outputs weigh by how precisely they are measured). Each
candidate is started from the points of its catalogue grid; the best start
is refined by ``scipy.optimize.least_squares`` (trust-region reflective, in
[0, 1] coordinates of each parameter's bounds). Valve blocks, whose cost is
rough at the scale of the command's increments, are first zoomed in on by a
pattern search. Confidence intervals come from the Jacobian at the optimum,
widened for the residual's lag-one autocorrelation (an AR(1) effective
sample size), since a model error is never white. Nuisance parameters per
record: the tank pH at the first sample (``initial: fit``, records that
start mid-transient) and the rest point of a valve with a dead band.
"""

from __future__ import annotations

import copy
import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from phfdi_base.errors import UserError

from .catalogue import Candidate, Context, catalogue
from .data import Record
from .model import Evaluator, Prediction, Start
from .residual import ljung_box

Z95 = 1.959963984540054


@dataclass
class Problem:
    """Everything a fit needs, picklable (sent once to each worker process)."""

    records: list[Record]
    nominal: dict
    initial: str
    train: list[np.ndarray]  # per record, bool (N,)
    val: list[np.ndarray]
    noise: dict[str, float]  # output -> noise floor (its unit)
    scale: dict[str, float]  # output -> standard deviation of the measurement
    outputs: list[str]
    context: Context
    only: list[str] | None = None
    init_window: int = 20  # samples that set the start of a record used for validation only


@dataclass
class FitResult:
    """One fitted candidate (or pair): parameters, intervals, training fit and held-out scores."""

    label: str
    cause: str
    family: str
    variant: str
    params: dict[str, float]
    intervals: dict[str, list[float]]
    fixed: dict
    main: str
    n_params: int
    train_sse: float
    n_train: int
    aic: float
    bic: float
    val_rmse: dict[str, float]
    val_nrmse: dict[str, float]
    val_cost: float  # mean over outputs of (RMSE / noise floor)^2
    val_sq: np.ndarray  # per held-out sample: summed squared error in noise units
    val_lag1: float  # lag-one autocorrelation of the held-out error (main output)
    val_whiteness_p: float  # Ljung-Box p-value of the held-out error (main output)
    val_structure: float  # (Ljung-Box Q - lags) / n of the held-out error (main output): structure, any length
    starts: list  # per record: the fitted Start
    raw: dict  # the extended model mapping
    nfev: int = 0
    seconds: float = 0.0
    message: str = ""
    identified: dict[str, bool] = field(default_factory=dict)


class Fitter:
    """Fits candidates on a :class:`Problem` (one per process)."""

    def __init__(self, problem: Problem) -> None:
        self.p = problem
        self.evaluators = [Evaluator(r, problem.nominal, problem.initial) for r in problem.records]
        self.fit_init = problem.initial == "fit"
        self.train_records = [i for i, m in enumerate(problem.train) if m.any()]
        cands, self.skipped = catalogue(problem.context, problem.only)
        self.candidates = {c.label: c for c in cands}
        self._nominal: FitResult | None = None
        self._n_resid = sum(int(problem.train[i].sum()) * sum(o in problem.records[i].outputs
                                                              for o in problem.outputs) for i in self.train_records)

    # ---- residuals --------------------------------------------------------------
    def predict(self, i: int, raw: dict, start: Start) -> Prediction:
        return self.evaluators[i].predict(raw, start)

    def _errors(self, i: int, pred: Prediction) -> dict[str, np.ndarray]:
        rec = self.p.records[i]
        return {o: (pred.outputs[o] - rec.outputs[o]) / self.p.noise[o] for o in self.p.outputs if o in rec.outputs}

    def train_residual(self, raw: dict, starts: list[Start]) -> np.ndarray:
        parts = []
        for i in self.train_records:
            err = self._errors(i, self.predict(i, raw, starts[i]))
            m = self.p.train[i]
            parts.extend(e[m] for e in err.values())
        return np.concatenate(parts)

    def first_ph(self, i: int) -> float:
        y = self.p.records[i].outputs.get("ph_measured")
        return float(np.median(y[:5])) if y is not None else 7.0

    # ---- fitting ------------------------------------------------------------------
    def fit(self, cands: list[Candidate], starts: list[dict] | None = None) -> FitResult:
        """Least squares fit of one candidate, or of several together (a pair).

        ``starts``: parameter start points (default: the candidate's grid).
        Record nuisances start at the first measured pH and the valve resting
        at the first command.
        """
        t0 = time.perf_counter()
        params = [(c, q) for c in cands for q in c.params]
        n_par = len(params)
        banded = [c for c in cands if c.band is not None]
        # nuisances per training record: start pH (initial: fit), valve rest offset (valve with memory)
        nuis: list[tuple[int, str]] = []
        for i in self.train_records:
            if self.fit_init:
                nuis.append((i, "ph"))
            if banded:
                nuis.append((i, "offset"))

        def values(x: np.ndarray) -> list[dict]:
            vals = [dict() for _ in cands]
            for j, (c, q) in enumerate(params):
                vals[cands.index(c)][q.name] = q.from_unit(float(x[j]))
            return vals

        def half_band(vals: list[dict]) -> float:
            return max((c.band(vals[cands.index(c)]) for c in banded), default=0.0)

        def starts_of(x: np.ndarray, vals: list[dict]) -> list[Start]:
            out = [Start(self.first_ph(i) if self.fit_init else None) for i in range(len(self.p.records))]
            band = half_band(vals)
            for j, (i, kind) in enumerate(nuis):
                v = float(x[n_par + j])
                if kind == "ph":
                    out[i] = Start(v, out[i].valve_offset_pct)
                else:
                    out[i] = Start(out[i].ph, v * band)
            return out

        def model(vals: list[dict]) -> dict:
            raw = copy.deepcopy(self.p.nominal)
            for c, v in zip(cands, vals):
                c.apply(raw, v)
            return raw

        def resid(x: np.ndarray) -> np.ndarray:
            vals = values(x)
            try:
                r = self.train_residual(model(vals), starts_of(x, vals))
            except (UserError, ValueError, FloatingPointError):
                return np.full(self._n_resid, 1e3)
            return np.where(np.isfinite(r), r, 1e3)

        nuis0 = [self.first_ph(i) if kind == "ph" else 0.0 for i, kind in nuis]
        grid = starts if starts is not None else list(cands[0].starts)
        x_starts = [np.array([q.to_unit(q.clip(s[q.name])) for c, q in params] + nuis0, dtype=float) for s in grid]
        lower = np.r_[np.zeros(n_par), [0.0 if k == "ph" else -1.0 for _, k in nuis]]
        upper = np.r_[np.ones(n_par), [14.0 if k == "ph" else 1.0 for _, k in nuis]]
        nfev = 0
        scored = []
        for x in x_starts:
            r = resid(x)
            scored.append((float(np.sum(r ** 2)), x, r))
            nfev += 1
        scored.sort(key=lambda t: t[0])
        best_cost, x_best, r_best = scored[0]
        jac = np.zeros((len(r_best), len(x_best)))
        message = "start point only"
        nonsmooth = any(c.nonsmooth for c in cands)
        if len(x_best) > 0:
            n_x = len(x_best)
            if nonsmooth and 0 < n_par <= 2:
                # a valve block's cost is rough at the scale of the command's increments (a threshold 1 % off
                # moves one slip): zoom in on the best grid point by pattern search, then polish
                x_best, best_cost, r_best, used = _zoom(resid, x_best, best_cost, r_best, n_par, lower, upper)
                nfev += used
                stages = ((0.002, 6),)
                refine = [(best_cost, x_best, r_best)]
            else:
                # refine the best start point (and the runner-up when nearly as good)
                stages = ((0.02, 10), (0.002, 8)) if nonsmooth else ((1e-4, 20),)
                refine = [scored[0]] + [t for t in scored[1:2] if t[0] < 1.5 * scored[0][0]]
            for i_start, (cost0, x0, _) in enumerate(refine):
                for step, evals in (stages if i_start == 0 else stages[:1]):
                    res = least_squares(resid, np.clip(x0, lower, upper), bounds=(lower, upper), method="trf",
                                        diff_step=step, max_nfev=evals * (n_x + 1), x_scale=1.0)
                    nfev += res.nfev + (res.njev or 0) * n_x
                    cost = float(np.sum(res.fun ** 2))
                    if cost < best_cost:
                        best_cost, x_best, r_best, jac, message = cost, res.x, res.fun, res.jac, res.message
                    x0 = res.x
            if not np.any(jac):
                jac = _jacobian(resid, x_best, r_best, lower, upper, 0.02 if nonsmooth else 1e-4)
                nfev += len(x_best)
        vals = values(x_best)
        start_list = starts_of(x_best, vals)
        raw = model(vals)
        sse = float(np.sum(r_best ** 2))
        n = len(r_best)
        k = n_par + len(nuis)
        intervals, identified = self._intervals(params, x_best[:n_par], jac[:, :n_par], r_best, n, k)
        flat = {}
        for c, v in zip(cands, vals):
            for name, value in v.items():
                flat[name if len(cands) == 1 else f"{c.cause}.{name}"] = value
        res_val = self.validate(raw, start_list, banded_half=half_band(vals))
        fixed = {}
        for c in cands:
            fixed.update({(k_ if len(cands) == 1 else f"{c.cause}.{k_}"): v for k_, v in c.fixed.items()})
            if c.variant:
                fixed["feed" if len(cands) == 1 else f"{c.cause}.feed"] = c.variant
        aic = n * math.log(max(sse, 1e-300) / n) + 2 * k
        bic = n * math.log(max(sse, 1e-300) / n) + k * math.log(n)
        return FitResult(
            label="+".join(c.label for c in cands), cause="+".join(c.cause for c in cands),
            family="+".join(dict.fromkeys(c.family for c in cands)),
            variant="+".join(c.variant for c in cands if c.variant), params=flat,
            intervals=intervals, fixed=fixed, main=cands[0].main if len(cands) == 1 else "",
            n_params=n_par, train_sse=sse, n_train=n, aic=aic, bic=bic, val_rmse=res_val["rmse"],
            val_nrmse=res_val["nrmse"], val_cost=res_val["cost"], val_sq=res_val["sq"], val_lag1=res_val["lag1"],
            val_whiteness_p=res_val["whiteness_p"],
            val_structure=res_val["structure"], starts=res_val["starts"],
            raw=raw, nfev=nfev, seconds=time.perf_counter() - t0, message=str(message), identified=identified)

    def _intervals(self, params, u, jac, r, n, k) -> tuple[dict, dict]:
        out, ident = {}, {}
        if not params:
            return out, ident
        s2 = float(np.sum(r ** 2)) / max(n - k, 1)
        rho = lag1(r)
        inflate = min((1 + rho) / (1 - rho), 1e4) if rho > 0 else 1.0
        cov = np.linalg.pinv(jac.T @ jac) * s2 * inflate
        multi = len({id(c) for c, _ in params}) > 1
        for j, (c, q) in enumerate(params):
            name = f"{c.cause}.{q.name}" if multi else q.name
            var = cov[j, j]
            if float(np.linalg.norm(jac[:, j])) < 1e-12 or not np.isfinite(var):
                out[name] = [q.low, q.high]
                ident[name] = False
                continue
            sd = math.sqrt(max(var, 0.0))
            out[name] = [q.from_unit(u[j] - Z95 * sd), q.from_unit(u[j] + Z95 * sd)]
            ident[name] = bool((u[j] - Z95 * sd) > 0.0 or (u[j] + Z95 * sd) < 1.0)
        return out, ident

    # ---- held-out scoring ---------------------------------------------------------
    def validate(self, raw: dict, starts: list[Start], banded_half: float = 0.0) -> dict:
        """Held-out errors of a model: RMSE and NRMSE per output, and per-sample squared errors (noise units).

        A record used for validation only gets its unknown start (pH, valve rest point) from its first
        ``init_window`` samples, which are then left out of the score.
        """
        starts = list(starts)
        sq_parts, acc = [], {o: [0.0, 0] for o in self.p.outputs}
        main_parts = []
        for i, rec in enumerate(self.p.records):
            mask = self.p.val[i].copy()
            if not mask.any():
                continue
            if i not in self.train_records and (self.fit_init or banded_half > 0):
                starts[i] = self._start_of(i, raw, banded_half)
                mask[: self.p.init_window] = False
            try:
                err = self._errors(i, self.predict(i, raw, starts[i]))
            except (UserError, ValueError, FloatingPointError):
                err = {o: np.full(len(rec), 1e3) for o in self.p.outputs if o in rec.outputs}
            sq = np.zeros(int(mask.sum()))
            if self.p.outputs[0] in err:
                main_parts.append(err[self.p.outputs[0]][mask])
            for o, e in err.items():
                ev = e[mask]
                sq += ev ** 2
                acc[o][0] += float(np.sum((ev * self.p.noise[o]) ** 2))
                acc[o][1] += len(ev)
            sq_parts.append(sq)
        rmse = {o: math.sqrt(s / c) if c else math.nan for o, (s, c) in acc.items()}
        nrmse = {o: rmse[o] / self.p.scale[o] for o in rmse}
        cost = float(np.mean([(rmse[o] / self.p.noise[o]) ** 2 for o in rmse if math.isfinite(rmse[o])]))
        return {"rmse": rmse, "nrmse": nrmse, "cost": cost,
                "sq": np.concatenate(sq_parts) if sq_parts else np.zeros(0), "starts": starts,
                "lag1": float(np.mean([lag1(e) for e in main_parts])) if main_parts else 0.0,
                **_whiteness(main_parts)}

    def _start_of(self, i: int, raw: dict, half_band: float) -> Start:
        """Unknown start of a validation-only record, fitted on its first samples."""
        window = np.zeros(len(self.p.records[i]), bool)
        window[: self.p.init_window] = True
        x0, lo, hi = [], [], []
        if self.fit_init:
            x0.append(self.first_ph(i)), lo.append(0.0), hi.append(14.0)
        if half_band > 0:
            x0.append(0.0), lo.append(-1.0), hi.append(1.0)

        def start(x) -> Start:
            ph = float(x[0]) if self.fit_init else None
            off = float(x[-1]) * half_band if half_band > 0 else 0.0
            return Start(ph, off)

        def r(x):
            err = self._errors(i, self.predict(i, raw, start(x)))
            return np.concatenate([e[window] for e in err.values()])

        return start(least_squares(r, x0, bounds=(lo, hi), diff_step=1e-3, max_nfev=40).x)

    def nominal(self) -> FitResult:
        if self._nominal is None:
            self._nominal = self.fit([_nominal_candidate()], starts=[{}])
        return self._nominal


def _zoom(resid, x, cost, r, n_par, lower, upper, half: float = 0.12, shrink: float = 2.5, stages: int = 6):
    """Pattern search on the first ``n_par`` coordinates: a 5 (x 5) grid about the best point, shrinking.

    Returns (x, cost, residual, evaluations). Each stage spans +-``half`` of the
    [0, 1] coordinate, then ``half / shrink``: six stages reach about 1/400 of
    the range (0.2 % of a log decade's worth of a valve parameter).
    """
    used = 0
    offsets = np.linspace(-1.0, 1.0, 5)
    for _ in range(stages):
        grid = itertools.product(*([offsets] * n_par))
        best = (cost, x, r)
        for d in grid:
            if not any(d):
                continue
            xt = x.copy()
            xt[:n_par] = np.clip(x[:n_par] + half * np.asarray(d), lower[:n_par], upper[:n_par])
            rt = resid(xt)
            used += 1
            ct = float(np.sum(rt ** 2))
            if ct < best[0]:
                best = (ct, xt, rt)
        cost, x, r = best
        half /= shrink
    return x, cost, r, used


def _jacobian(fun, x, f0, lower, upper, step) -> np.ndarray:
    """Forward differences (backward at an upper bound), for intervals when no least-squares step ran."""
    jac = np.zeros((len(f0), len(x)))
    for j in range(len(x)):
        h = step * max(1.0, abs(x[j]))
        xj = x.copy()
        xj[j] = x[j] + h if x[j] + h <= upper[j] else x[j] - h
        jac[:, j] = (fun(xj) - f0) / (xj[j] - x[j])
    return jac


def _nominal_candidate() -> Candidate:
    return Candidate("none", [], [{}], lambda raw, p: None, "")


def lag1(r: np.ndarray) -> float:
    r = np.asarray(r, dtype=float)
    if len(r) < 3:
        return 0.0
    r = r - r.mean()
    den = float(np.dot(r, r))
    return float(np.dot(r[:-1], r[1:]) / den) if den > 0 else 0.0


# ---- worker processes -----------------------------------------------------------------
_WORKER: Fitter | None = None


def init_worker(problem: Problem) -> None:
    global _WORKER
    import os

    os.environ.setdefault("OMP_NUM_THREADS", "1")
    _WORKER = Fitter(problem)


def fit_task(labels: list[str], starts: list[dict] | None = None) -> FitResult:
    """Fit the named candidate (or pair) in a worker process."""
    fitter = _WORKER
    cands = [fitter.candidates[label] for label in labels]
    return fitter.fit(cands, starts)


def _whiteness(main_parts: list[np.ndarray]) -> dict[str, float]:
    """Ljung-Box p-value and structure index of the held-out error of the main output."""
    if not main_parts:
        return {"whiteness_p": 1.0, "structure": 0.0}
    lb = ljung_box(np.concatenate(main_parts))
    return {"whiteness_p": lb["p_value"], "structure": lb["structure"]}
