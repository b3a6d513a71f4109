"""A practitioner's black-box baseline beside the physical model: a Wiener model of the pH.

Linear dynamics on the acid/base imbalance followed by a fitted static
titration curve, the textbook black-box model of a neutralisation
(Kalafatis, Wang and Cluett; Pearson):

* imbalance u_k = sum_j w_j q_j,k (mL/s): w = +1 for the first basic feed,
  a fitted weight for every other feed (negative for an acid: the ratio of
  its strength to the base's);
* dynamics: a dead time and a first-order lag, x_k = a x_k-1 + (1 - a) u_k-d,
  a = exp(-dt / tau), started at a per-record level x_0 (records start
  mid-transient, like the physical model's starting pH);
* titration curve: pH = c + a1 asinh((x - m) / b1), the shape of a strong
  acid-strong base titration (exactly asinh in the excess), softened by b1.

Fitted by ``scipy.optimize.least_squares`` on the same training samples as the
physical model; a validation record gets x_0 from its first ``init_window``
samples, and a record of a group the fit has not seen, with ``adapt``, gets its
x_0 and the base weight of its group (the reagent strengths) from its first
fraction; both are then left out of the score.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import lfilter

from phfdi.records import Record


@dataclass
class WienerFit:
    feeds: list[str]
    weights: dict[str, float]  # per feed (the basic reference feed: 1)
    tau_s: float
    delay_s: float
    curve: tuple[float, float, float, float]  # c, a1, m, b1
    x0: list[float]  # per training record
    group_weights: dict[str, float] = field(default_factory=dict)  # reference feed's weight per group
    nrmse_by_record: dict[str, float] = field(default_factory=dict)  # held-out, per validation record
    adapted: dict[str, dict] = field(default_factory=dict)
    predictions: dict[str, np.ndarray] = field(default_factory=dict)  # per validation record, every sample (pH)


def _flows(rec: Record, feeds: list[str]) -> np.ndarray:
    return np.column_stack([rec.inputs.get(f"{f}_flow_ml_s", np.zeros(len(rec))) for f in feeds])


def _simulate(q: np.ndarray, w: np.ndarray, tau: float, delay: float, curve, x0: float, dt: float) -> np.ndarray:
    u = q @ w
    d = int(round(delay / dt))
    if d > 0:
        u = np.r_[np.full(d, u[0]), u[:-d]]
    a = math.exp(-dt / max(tau, 1e-6))
    # lfilter from rest at x0: y_k = a y_k-1 + (1 - a) u_k with y_-1 = x0
    x = lfilter([1.0 - a], [1.0, -a], u, zi=[a * x0])[0]
    c, a1, m, b1 = curve
    return c + a1 * np.arcsinh((x - m) / max(b1, 1e-9))


def fit_wiener(records: list[Record], train: list[np.ndarray], val: list[np.ndarray], feeds: list[str],
               basic_feed: str, groups: list[str] | None = None, adapt: float = 0.0,
               init_window: int = 20) -> WienerFit:
    """Fit on the training samples of the training records; score every record's validation samples."""
    dt = records[0].dt_s
    others = [f for f in feeds if f != basic_feed]
    tr = [i for i, m in enumerate(train) if m.any()]
    groups = groups or ["all"] * len(records)
    tr_groups = sorted({groups[i] for i in tr})
    flows = [_flows(r, feeds) for r in records]
    ys = [r.outputs["ph_measured"] for r in records]
    all_q = np.concatenate([flows[i] for i in tr])
    scale_u = float(np.mean(all_q.sum(axis=1))) or 1.0
    n_o, n_g = len(others), len(tr_groups)

    def unpack(p):
        w_other = p[:n_o]
        g_w = dict(zip(tr_groups, np.exp(p[n_o:n_o + n_g])))
        tau, delay = math.exp(p[n_o + n_g]), p[n_o + n_g + 1]
        curve = (p[n_o + n_g + 2], p[n_o + n_g + 3], p[n_o + n_g + 4] * scale_u, math.exp(p[n_o + n_g + 5]) * scale_u)
        x0 = p[n_o + n_g + 6:]
        return w_other, g_w, tau, delay, curve, x0

    def weights(w_other, w_base) -> np.ndarray:
        return np.array([w_base if f == basic_feed else w_other[others.index(f)] for f in feeds])

    def resid(p):
        w_other, g_w, tau, delay, curve, x0 = unpack(p)
        parts = []
        for j, i in enumerate(tr):
            pred = _simulate(flows[i], weights(w_other, g_w[groups[i]]), tau, delay, curve, x0[j] * scale_u, dt)
            parts.append((pred - ys[i])[train[i]])
        return np.concatenate(parts)

    p0 = np.r_[[-1.0] * n_o, [0.0] * n_g, [math.log(60.0)], [2.0], [7.0], [1.5], [0.0], [math.log(0.05)],
               [0.0] * len(tr)]
    lo = np.r_[[-50.0] * n_o, [-5.0] * n_g, [math.log(dt)], [0.0], [0.0], [0.05], [-20.0], [math.log(1e-4)],
               [-20.0] * len(tr)]
    hi = np.r_[[0.0] * n_o, [5.0] * n_g, [math.log(5000.0)], [60.0], [14.0], [5.0], [20.0], [math.log(20.0)],
               [20.0] * len(tr)]
    best = None
    for tau0 in (20.0, 100.0, 400.0):  # a few starts: the cost has local minima in the time constant
        p = p0.copy()
        p[n_o + n_g] = math.log(tau0)
        sol = least_squares(resid, p, bounds=(lo, hi), diff_step=1e-3, max_nfev=300)
        if best is None or sol.cost < best.cost:
            best = sol
    w_other, g_w, tau, delay, curve, x0 = unpack(best.x)
    fit = WienerFit(feeds, {f: float(v) for f, v in zip(others, w_other)}, tau, float(delay), tuple(map(float, curve)),
                    [float(v) * scale_u for v in x0], {g: float(v) for g, v in g_w.items()})
    mean_w = float(np.exp(np.mean(np.log(list(g_w.values())))))
    for i, rec in enumerate(records):
        mask = val[i].copy()
        if not mask.any():
            continue
        unseen = groups[i] not in g_w
        n_fit = max(init_window, int(round(adapt * len(rec)))) if unseen and adapt > 0 else init_window
        window = np.zeros(len(rec), bool)
        window[:n_fit] = True
        free_w = unseen and adapt > 0
        w_fixed = g_w.get(groups[i], mean_w)

        def r_start(z, i=i, window=window, free_w=free_w, w_fixed=w_fixed):
            w_b = math.exp(z[1]) if free_w else w_fixed
            pred = _simulate(flows[i], weights(w_other, w_b), tau, delay, curve, z[0] * scale_u, dt)
            return (pred - ys[i])[window]

        z0 = [0.0, math.log(w_fixed)] if free_w else [0.0]
        starts = [np.array(z0, float) + np.r_[[s], [0.0] * (len(z0) - 1)] for s in (-2.0, 0.0, 2.0)]
        sol = min((least_squares(r_start, z, diff_step=1e-3, max_nfev=200) for z in starts), key=lambda s: s.cost)
        w_b = math.exp(sol.x[1]) if free_w else w_fixed
        pred = _simulate(flows[i], weights(w_other, w_b), tau, delay, curve, sol.x[0] * scale_u, dt)
        mask[:n_fit] = False
        fit.predictions[rec.name] = pred
        err = (pred - ys[i])[mask]
        fit.nrmse_by_record[rec.name] = float(np.sqrt(np.mean(err ** 2)) / (np.std(ys[i][mask]) or 1.0))
        if free_w:
            fit.adapted[rec.name] = {"samples": n_fit, "base_weight": w_b}
    return fit
