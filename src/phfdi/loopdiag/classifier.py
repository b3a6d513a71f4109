"""A small interpretable stiction classifier: L2-regularised logistic regression on the indicators.

p(stiction) = 1 / (1 + exp(-(b + sum_i w_i z_i))),  z_i = (x_i - mean_i) / scale_i

x the features of :mod:`.features` (each a published indicator), standardised with the training
set's weighted mean and standard deviation, so each weight says how much one standard deviation of
that indicator moves the log-odds, and w_i z_i is that indicator's contribution to one verdict.
Fitted by :func:`scipy.optimize.minimize` (L-BFGS-B, analytic gradient) on the weighted mean
log-loss plus (l2 / 2) |w|^2 (the intercept is not penalised). With ``signs`` each weight is bounded
to the sign its paper reads as stiction (:data:`phfdi.loopdiag.features.FEATURE_SIGNS`): with 3
stiction loops among the real records, an unconstrained fit learns weights against the published
reading of an indicator (a better Kano fit counting against stiction, say), which no next plant
would share; bounded, such an indicator gets weight 0.

Training data: the labelled real records (every loop's files share a weight of one, so a loop with
23 files counts as much as a loop with one) and synthetic loops of :mod:`.training` (their total
weight ``synthetic_ratio`` times the real loops'). The L2 strength, the synthetic ratio and the
decision threshold are chosen inside the training data (:func:`choose_hyperparameters`): by
leave-one-loop-out on its real records, averaged with a 5-fold cross-validation of its synthetic
loops (criterion "real+synthetic", the default) or alone ("real"); :func:`nested_lolo` evaluates
that whole procedure with one more loop level outside it, so no choice ever sees the loop it is
scored on.

**One verdict with an undetermined band** (:func:`choose_band`): the inner leave-one-loop-out
probabilities of the real records (at the chosen hyper-parameters) calibrate the model (Platt 1999:
p = sigmoid(a logit(p_model) + b), fitted with Platt's smoothed targets) and fix two cut points on the
calibrated p: "stiction" at or above ``high``, "no stiction" below ``low``, "undetermined" between. The
band is the one whose confident calls on those inner probabilities meet :data:`TARGET_PRECISION`,
:data:`MAX_FALSE_STICTION` and :data:`MAX_UNDETERMINED` with the most correct calls; so under
:func:`nested_lolo` the band, like every other choice, never sees the loop it is scored on.

The shipped model is ``models/stiction_classifier.json`` (package data), written by
``benchmarks/train_stiction_classifier.py`` from ``benchmarks/results/stiction_dataset.json``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from phfdi_base.outputs import write_text

L2_GRID = (0.01, 0.1, 1.0)
SYNTHETIC_RATIO_GRID = (0.5, 1.0, 2.0, 4.0)
#: folds of the synthetic loops' cross-validation inside the hyper-parameter choice
SYNTHETIC_FOLDS = 5
#: what the hyper-parameters and the threshold are chosen for: the real records' leave-one-loop-out
#: alone ("real"), or its mean with the synthetic loops' cross-validation ("real+synthetic")
CRITERIA = ("real", "real+synthetic")
MODEL_RESOURCE = "models/stiction_classifier.json"
#: confident calls must be at least this often right: "stiction" calls sticky, "no stiction" calls not
TARGET_PRECISION = 0.9
#: at most this share of the no-stiction records may be called "stiction"
MAX_FALSE_STICTION = 0.10
#: at most this share of the records may be left "undetermined"
MAX_UNDETERMINED = 0.25
#: the three answers of the band
STICTION, NO_STICTION, UNDETERMINED = "stiction", "no_stiction", "undetermined"


@dataclass
class LogisticModel:
    features: list[str]
    mean: np.ndarray
    scale: np.ndarray
    weights: np.ndarray
    bias: float
    threshold: float = 0.5
    l2: float = 0.1
    synthetic_ratio: float = 1.0
    info: dict = field(default_factory=dict)
    signs: list[int] | None = None
    #: Platt scaling (a, b) of the logit; None: the model's own probability
    calibration: tuple[float, float] | None = None
    #: (low, high) on the calibrated probability; None: one cut at ``threshold``
    band: tuple[float, float] | None = None

    def z(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, float) - self.mean) / self.scale

    def probability(self, x: np.ndarray) -> np.ndarray:
        s = self.z(x) @ self.weights + self.bias
        return 1.0 / (1.0 + np.exp(-s))

    def calibrated(self, x: np.ndarray) -> np.ndarray:
        """p(stiction) after Platt scaling (the model's own probability when not calibrated)."""
        return platt(self.probability(x), self.calibration)

    def cuts(self) -> tuple[float, float]:
        """(low, high) on the calibrated probability: the band, or the calibrated ``threshold`` twice."""
        if self.band is not None:
            return self.band
        cut = float(platt(np.array(self.threshold), self.calibration))
        return cut, cut

    def call(self, p_calibrated: np.ndarray) -> np.ndarray:
        """"stiction", "no_stiction" or "undetermined" for calibrated probabilities."""
        low, high = self.cuts()
        return band_calls(np.asarray(p_calibrated, float), low, high)

    def contributions(self, x: np.ndarray) -> np.ndarray:
        """Each feature's term w_i z_i of the log-odds (the intercept is ``bias``)."""
        return self.z(x) * self.weights

    def to_dict(self) -> dict:
        return {"kind": "logistic_regression_l2", "features": list(self.features),
                "mean": [float(v) for v in self.mean], "scale": [float(v) for v in self.scale],
                "weights": [float(v) for v in self.weights], "bias": float(self.bias),
                "threshold": float(self.threshold), "l2": self.l2, "synthetic_ratio": self.synthetic_ratio,
                "signs": self.signs, "info": self.info,
                "calibration": None if self.calibration is None else [float(v) for v in self.calibration],
                "band": None if self.band is None else [float(v) for v in self.band]}

    @classmethod
    def from_dict(cls, d: dict) -> "LogisticModel":
        return cls(list(d["features"]), np.array(d["mean"], float), np.array(d["scale"], float),
                   np.array(d["weights"], float), float(d["bias"]), float(d["threshold"]),
                   float(d.get("l2", 0.1)), float(d.get("synthetic_ratio", 1.0)), dict(d.get("info", {})),
                   d.get("signs"), _pair(d.get("calibration")), _pair(d.get("band")))

    def save(self, path: str | Path) -> None:
        write_text(path, json.dumps(self.to_dict(), indent=1) + "\n", overwrite=True)


def _pair(v) -> tuple[float, float] | None:
    return None if v is None else (float(v[0]), float(v[1]))


def load_model(path: str | Path | None = None) -> LogisticModel:
    """The shipped model (package data) or one from ``path``."""
    if path is None:
        text = resources.files("phfdi.loopdiag").joinpath(MODEL_RESOURCE).read_text()
    else:
        text = Path(path).read_text()
    return LogisticModel.from_dict(json.loads(text))


# ---- fitting --------------------------------------------------------------------------------
def fit_logistic(x: np.ndarray, y: np.ndarray, w: np.ndarray, l2: float, features: list[str],
                 signs: list[int] | None = None) -> LogisticModel:
    """Weighted L2 logistic regression on standardised features (deterministic: zero start); with
    ``signs`` (+1, -1, or 0 for free, per feature) each weight is bounded to its sign."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.asarray(w, float) / np.sum(w)
    mean = w @ x
    scale = np.sqrt(w @ (x - mean) ** 2)
    scale = np.where(scale > 1e-12, scale, 1.0)
    z = (x - mean) / scale

    def objective(theta: np.ndarray) -> tuple[float, np.ndarray]:
        beta, b = theta[:-1], theta[-1]
        s = z @ beta + b
        # log(1 + exp(-s)) for y = 1, log(1 + exp(s)) for y = 0, stably
        loss = np.logaddexp(0.0, s) - y * s
        p = 1.0 / (1.0 + np.exp(-s))
        g = w * (p - y)
        f = float(w @ loss) + 0.5 * l2 * float(beta @ beta)
        grad = np.concatenate([z.T @ g + l2 * beta, [float(np.sum(g))]])
        return f, grad

    bounds = None
    if signs is not None:
        bounds = [(0.0, None) if sg > 0 else (None, 0.0) if sg < 0 else (None, None) for sg in signs]
        bounds.append((None, None))
    res = minimize(objective, np.zeros(z.shape[1] + 1), jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": 2000, "gtol": 1e-9})
    return LogisticModel(list(features), mean, scale, res.x[:-1].copy(), float(res.x[-1]), 0.5, l2,
                         signs=None if signs is None else [int(v) for v in signs])


def training_weights(groups: list[str], real: np.ndarray, synthetic_ratio: float) -> np.ndarray:
    """Real records: every group's records share a weight of one. Synthetic records: together
    ``synthetic_ratio`` times the real groups' total."""
    groups = list(groups)
    real = np.asarray(real, bool)
    count: dict[str, int] = {}
    for g, r in zip(groups, real):
        if r:
            count[g] = count.get(g, 0) + 1
    n_real_groups = max(len(count), 1)
    n_syn = int(np.sum(~real))
    w = np.empty(len(groups))
    for i, (g, r) in enumerate(zip(groups, real)):
        w[i] = 1.0 / count[g] if r else synthetic_ratio * n_real_groups / max(n_syn, 1)
    return w


# ---- scoring --------------------------------------------------------------------------------
def loop_balanced_accuracy(y: np.ndarray, pred: np.ndarray, groups: list[str]) -> float:
    """Balanced accuracy with every group's records sharing a weight of one."""
    count: dict[str, int] = {}
    for g in groups:
        count[g] = count.get(g, 0) + 1
    hit = {True: 0.0, False: 0.0}
    tot = {True: 0.0, False: 0.0}
    for yi, pi, g in zip(y, pred, groups):
        wt = 1.0 / count[g]
        tot[bool(yi)] += wt
        hit[bool(yi)] += wt * (bool(pi) == bool(yi))
    rates = [hit[k] / tot[k] for k in (True, False) if tot[k] > 0]
    return sum(rates) / len(rates) if rates else 0.0


def best_threshold(prob: np.ndarray, y: np.ndarray, groups: list[str]) -> tuple[float, float]:
    """(threshold, loop-balanced accuracy) maximising the latter; ties: nearest 0.5."""
    return best_threshold_multi([(prob, y, groups)])


def best_threshold_multi(sets: list[tuple[np.ndarray, np.ndarray, list[str]]]) -> tuple[float, float]:
    """(threshold, mean over the sets of their loop-balanced accuracy) maximising the latter;
    ties: nearest 0.5."""
    p = np.sort(np.unique(np.concatenate([s[0] for s in sets])))
    cands = [0.5] + list((p[1:] + p[:-1]) / 2) + [float(p[0]) - 1e-9, float(p[-1]) + 1e-9]
    scored = [(float(np.mean([loop_balanced_accuracy(y, prob >= c, g) for prob, y, g in sets])), -abs(c - 0.5), c)
              for c in cands]
    acc, _, th = max(scored)
    return float(th), float(acc)


# ---- calibration and the undetermined band --------------------------------------------------
def platt(prob: np.ndarray, calibration: tuple[float, float] | None) -> np.ndarray:
    """sigmoid(a logit(p) + b); p itself when ``calibration`` is None."""
    prob = np.asarray(prob, float)
    if calibration is None:
        return prob
    a, b = calibration
    logit = np.log(np.clip(prob, 1e-12, 1 - 1e-12) / np.clip(1 - prob, 1e-12, 1.0))
    return 1.0 / (1.0 + np.exp(-(a * logit + b)))


def fit_platt(prob: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Platt's (1999) scaling of out-of-fold probabilities: (a, b) minimising the log-loss against his
    smoothed targets (N+ + 1) / (N+ + 2) and 1 / (N- + 2), which keep a separable set from driving a to
    infinity; a is held >= 0 (a calibration never reverses the ranking)."""
    prob, y = np.asarray(prob, float), np.asarray(y, bool)
    n_pos, n_neg = int(y.sum()), int((~y).sum())
    t = np.where(y, (n_pos + 1.0) / (n_pos + 2.0), 1.0 / (n_neg + 2.0))
    logit = np.log(np.clip(prob, 1e-12, 1 - 1e-12) / np.clip(1 - prob, 1e-12, 1.0))

    def objective(theta: np.ndarray) -> tuple[float, np.ndarray]:
        s = theta[0] * logit + theta[1]
        q = 1.0 / (1.0 + np.exp(-s))
        loss = float(np.mean(np.logaddexp(0.0, s) - t * s))
        g = (q - t) / len(t)
        return loss, np.array([float(g @ logit), float(np.sum(g))])

    res = minimize(objective, np.array([1.0, 0.0]), jac=True, method="L-BFGS-B", bounds=[(0.0, None), (None, None)])
    return float(res.x[0]), float(res.x[1])


def band_calls(p_calibrated: np.ndarray, low: float, high: float) -> np.ndarray:
    """"stiction" at or above ``high``, "no_stiction" below ``low``, "undetermined" between."""
    p = np.asarray(p_calibrated, float)
    return np.where(p >= high, STICTION, np.where(p < low, NO_STICTION, UNDETERMINED))


def call_rates(calls: np.ndarray, y: np.ndarray) -> dict:
    """Counts and rates of banded calls against labels: precision of the confident "stiction" calls,
    recall (sticky records called "stiction"), the share of no-stiction records called "stiction",
    the precision of the "no stiction" calls and the share left undetermined."""
    calls, y = np.asarray(calls), np.asarray(y, bool)
    st, no, und = calls == STICTION, calls == NO_STICTION, calls == UNDETERMINED
    tp, fp = int(np.sum(st & y)), int(np.sum(st & ~y))
    tn, fn = int(np.sum(no & ~y)), int(np.sum(no & y))
    n, n_pos, n_neg = len(y), int(y.sum()), int((~y).sum())
    return {"files": n, "stiction_records": n_pos, "no_stiction_records": n_neg,
            "tp": tp, "fp": fp, "tn": tn, "fn": fn, "undetermined": int(und.sum()),
            "undetermined_stiction": int(np.sum(und & y)), "undetermined_no_stiction": int(np.sum(und & ~y)),
            "precision": tp / (tp + fp) if tp + fp else math.nan,
            "recall": tp / n_pos if n_pos else math.nan,
            "false_stiction_rate": fp / n_neg if n_neg else math.nan,
            "no_stiction_precision": tn / (tn + fn) if tn + fn else math.nan,
            "undetermined_share": float(und.sum()) / n if n else math.nan}


def _band_violation(r: dict) -> float:
    """How far banded calls fall short of the targets (0: all met); no "stiction" call at all counts as
    precision 0, so a band that never says stiction is not a way out."""
    prec = 0.0 if math.isnan(r["precision"]) else r["precision"]
    npv = 1.0 if math.isnan(r["no_stiction_precision"]) else r["no_stiction_precision"]
    fsr = 0.0 if math.isnan(r["false_stiction_rate"]) else r["false_stiction_rate"]
    return (max(0.0, TARGET_PRECISION - prec) + max(0.0, TARGET_PRECISION - npv)
            + max(0.0, fsr - MAX_FALSE_STICTION) + max(0.0, r["undetermined_share"] - MAX_UNDETERMINED))


def choose_band(p_calibrated: np.ndarray, y: np.ndarray) -> dict:
    """(low, high) on calibrated probabilities: among the cut points between neighbouring values, the
    band whose calls meet the targets (:data:`TARGET_PRECISION` for both confident answers,
    :data:`MAX_FALSE_STICTION`, :data:`MAX_UNDETERMINED`) with the most correct confident calls;
    ties: fewer undetermined, then centred nearest 0.5. When no band meets them all, the one that
    falls least short (``met`` False)."""
    p = np.sort(np.unique(np.asarray(p_calibrated, float)))
    cuts = [float(p[0]) - 1e-9] + list((p[1:] + p[:-1]) / 2) + [float(p[-1]) + 1e-9]
    best = None
    for i, low in enumerate(cuts):
        for high in cuts[i:]:
            r = call_rates(band_calls(p_calibrated, low, high), y)
            key = (_band_violation(r), -(r["tp"] + r["tn"]), r["undetermined"], abs((low + high) / 2 - 0.5))
            if best is None or key < best[0]:
                best = (key, low, high, r)
    assert best is not None
    key, low, high, r = best
    return {"low": float(low), "high": float(high), "met": key[0] == 0.0, "inner": r}


@dataclass
class Data:
    x: np.ndarray
    y: np.ndarray
    groups: list[str]
    real: np.ndarray  # bool: a real record (False: synthetic)
    features: list[str]
    signs: list[int] | None = None  # weight signs (see fit_logistic); None: unconstrained

    def take(self, mask: np.ndarray) -> "Data":
        idx = np.flatnonzero(mask)
        return Data(self.x[idx], self.y[idx], [self.groups[i] for i in idx], self.real[idx], self.features,
                    self.signs)


def _fit(d: Data, l2: float, ratio: float) -> LogisticModel:
    m = fit_logistic(d.x, d.y, training_weights(d.groups, d.real, ratio), l2, d.features, d.signs)
    m.synthetic_ratio = ratio
    return m


def lolo_probabilities(d: Data, l2: float, ratio: float) -> np.ndarray:
    """Out-of-fold p(stiction) of every real record, holding out one real group at a time
    (synthetic records always train)."""
    prob = np.full(len(d.y), np.nan)
    for g in sorted({g for g, r in zip(d.groups, d.real) if r}):
        held = np.array([gg == g for gg in d.groups]) & d.real
        model = _fit(d.take(~held), l2, ratio)
        prob[held] = model.probability(d.x[held])
    return prob


def synthetic_cv_probabilities(d: Data, l2: float, ratio: float, folds: int = SYNTHETIC_FOLDS) -> np.ndarray:
    """Out-of-fold p(stiction) of every synthetic record: its loops in ``folds`` folds (by sorted
    group name), each predicted by a model trained on the real records and the other folds."""
    prob = np.full(len(d.y), np.nan)
    syn_groups = sorted({g for g, r in zip(d.groups, d.real) if not r})
    fold_of = {g: k % folds for k, g in enumerate(syn_groups)}
    for k in range(folds):
        held = np.array([(not r) and fold_of[g] == k for g, r in zip(d.groups, d.real)])
        if held.any():
            prob[held] = _fit(d.take(~held), l2, ratio).probability(d.x[held])
    return prob


def choose_hyperparameters(d: Data, criterion: str = "real+synthetic") -> dict:
    """L2 strength, synthetic ratio and threshold maximising the loop-balanced accuracy of the
    leave-one-loop-out predictions on the real records of ``d`` (``criterion`` "real"), or its mean
    with the balanced accuracy of the synthetic loops' cross-validation ("real+synthetic": a model
    for the next plant should hold on the simulator's breadth of loops too). Ties: stronger L2,
    ratio nearest 1."""
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    best = None
    real_idx = np.flatnonzero(d.real)
    syn_idx = np.flatnonzero(~d.real)
    groups = [d.groups[i] for i in real_idx]
    syn_groups = [d.groups[i] for i in syn_idx]
    for l2 in L2_GRID:
        for ratio in SYNTHETIC_RATIO_GRID:
            prob = lolo_probabilities(d, l2, ratio)[real_idx]
            sets = [(prob, d.y[real_idx], groups)]
            if criterion == "real+synthetic" and len(syn_idx):
                sets.append((synthetic_cv_probabilities(d, l2, ratio)[syn_idx], d.y[syn_idx], syn_groups))
            th, acc = best_threshold_multi(sets)
            key = (round(acc, 9), l2, -abs(math.log(ratio)))
            if best is None or key > best[0]:
                best = (key, {"l2": l2, "synthetic_ratio": ratio, "threshold": th, "inner_balanced_accuracy": acc})
    assert best is not None
    return best[1]


def train(d: Data, criterion: str = "real+synthetic") -> LogisticModel:
    """Hyper-parameters by :func:`choose_hyperparameters` on ``d``, then one fit on all of ``d``; the
    calibration and the undetermined band from the leave-one-loop-out probabilities of ``d``'s real
    records at those hyper-parameters (:func:`fit_platt`, :func:`choose_band`)."""
    hp = choose_hyperparameters(d, criterion)
    model = _fit(d, hp["l2"], hp["synthetic_ratio"])
    model.threshold = hp["threshold"]
    model.info["inner_balanced_accuracy"] = hp["inner_balanced_accuracy"]
    model.info["criterion"] = criterion
    real = np.flatnonzero(d.real)
    if len({bool(v) for v in d.y[real]}) == 2:
        inner = lolo_probabilities(d, hp["l2"], hp["synthetic_ratio"])[real]
        model.calibration = fit_platt(inner, d.y[real])
        band = choose_band(platt(inner, model.calibration), d.y[real])
        model.band = (band["low"], band["high"])
        model.info["band_inner"] = {"met": band["met"], **{k: (None if isinstance(v, float) and math.isnan(v) else v)
                                                           for k, v in band["inner"].items()}}
    return model


@dataclass
class Nested:
    """Out-of-fold answers of :func:`nested_lolo_calls` for every record of the data (NaN, False and ""
    where not real): the model's probability and its single-threshold prediction, the calibrated
    probability and the banded call; the choices of each fold."""

    prob: np.ndarray
    pred: np.ndarray
    calibrated: np.ndarray
    calls: np.ndarray
    choices: dict


def nested_lolo_calls(d: Data, progress=None, criterion: str = "real+synthetic") -> Nested:
    """Nested leave-one-loop-out: for each real group, :func:`train` on everything else (which
    chooses its hyper-parameters, calibration and band by an inner leave-one-loop-out) and predict the
    group."""
    prob = np.full(len(d.y), np.nan)
    cal = np.full(len(d.y), np.nan)
    pred = np.zeros(len(d.y), bool)
    calls = np.full(len(d.y), "", dtype=object)
    choices = {}
    real_groups = sorted({g for g, r in zip(d.groups, d.real) if r})
    for k, g in enumerate(real_groups):
        held = np.array([gg == g for gg in d.groups]) & d.real
        model = train(d.take(~held), criterion)
        prob[held] = model.probability(d.x[held])
        pred[held] = prob[held] >= model.threshold
        cal[held] = model.calibrated(d.x[held])
        calls[held] = model.call(cal[held])
        choices[g] = {"l2": model.l2, "synthetic_ratio": model.synthetic_ratio, "threshold": model.threshold,
                      "calibration": model.calibration, "band": model.band,
                      "band_met_inner": (model.info.get("band_inner") or {}).get("met")}
        if progress:
            progress(k + 1, len(real_groups))
    return Nested(prob, pred, cal, calls, choices)


def nested_lolo(d: Data, progress=None, criterion: str = "real+synthetic") -> tuple[np.ndarray, np.ndarray, dict]:
    """(prob, prediction at the fold's threshold, choices per fold) of :func:`nested_lolo_calls`."""
    n = nested_lolo_calls(d, progress, criterion)
    return n.prob, n.pred, n.choices


# ---- trained on simulation only: the shipped model ----------------------------------------------
#: the verdict's operating point: at most this share of the simulated calibration loops without stiction, and
#: of its hard negatives (loops tuned too tight, loops cycling with an external oscillation), called "stiction"
SIM_FALSE_CALL = 0.02
#: the classes of :mod:`.domain` whose false calls the operating point also bounds on their own
HARD_NEGATIVES = ("tight_tuning", "external_oscillation")
#: below this calibrated p (even odds at the calibration set's half-sticky mix) the answer is "no stiction"
NO_STICTION_BELOW = 0.5


def cv_log_loss(d: Data, l2: float, folds: int = SYNTHETIC_FOLDS) -> float:
    """Mean log-loss of ``folds``-fold cross-validation (records in folds by position, every loop its own
    group), each fold predicted by a model fitted on the others."""
    k = np.arange(len(d.y)) % folds
    loss = 0.0
    for f in range(folds):
        held = k == f
        m = fit_logistic(d.x[~held], d.y[~held], np.ones(int((~held).sum())), l2, d.features, d.signs)
        p = np.clip(m.probability(d.x[held]), 1e-12, 1 - 1e-12)
        loss += float(-np.sum(np.where(d.y[held], np.log(p), np.log(1 - p))))
    return loss / len(d.y)


def final_calls(p_calibrated: np.ndarray, cut: float, decides: np.ndarray | None = None,
                takes_back: np.ndarray | None = None, low: float = NO_STICTION_BELOW) -> np.ndarray:
    """Which loops the verdict calls "stiction" at ``cut``: the calibrated p reaches it and the valve-model fit does
    not take the call back, or p is in the undetermined band and the fit decides for stiction
    (:mod:`.verdict`). Without the fit's outcomes, p reaching the cut."""
    p = np.asarray(p_calibrated, float)
    n = len(p)
    back = np.zeros(n, bool) if takes_back is None else np.asarray(takes_back, bool)
    dec = np.zeros(n, bool) if decides is None else np.asarray(decides, bool)
    return ((p >= cut) & ~back) | ((p >= low) & (p < cut) & dec)


def operating_point(p_calibrated: np.ndarray, y: np.ndarray, hard: np.ndarray,
                    max_false: float = SIM_FALSE_CALL, decides: np.ndarray | None = None,
                    takes_back: np.ndarray | None = None) -> dict:
    """The lowest cut on the calibrated p at which at most ``max_false`` of the loops without stiction, and of the
    hard negatives among them, are called stiction (:func:`final_calls`: with the valve-model fit's outcomes when
    given, so that the rate is that of the verdict's final calls); with the recall it keeps. A loop the fit decides
    for stiction is called whatever the cut, so the rate falls as the cut rises, and the search is over the
    negatives' own p values."""
    p, y, hard = np.asarray(p_calibrated, float), np.asarray(y, bool), np.asarray(hard, bool)
    groups = [g for g in (~y, ~y & hard) if g.any()]

    def within(cut: float) -> bool:
        called = final_calls(p, cut, decides, takes_back)
        return all(int(np.sum(called[g])) <= int(math.floor(max_false * int(g.sum()))) for g in groups)

    candidates = [0.5] + sorted({float(np.nextafter(v, 1.0)) for v in p[~y] if v >= 0.5})
    cut = next((c for c in candidates if within(c)), float(np.nextafter(1.0, 2.0)))
    called = final_calls(p, cut, decides, takes_back)
    return {"cut": cut, "false_call_rate": float(np.mean(called[~y])) if (~y).any() else math.nan,
            "hard_false_call_rate": float(np.mean(called[~y & hard])) if (~y & hard).any() else math.nan,
            "recall": float(np.mean(called[y])) if y.any() else math.nan,
            "with_valve_model_fit": decides is not None or takes_back is not None}


def train_simulated(train_set: Data, calibration_set: Data, hard: np.ndarray, decides: np.ndarray | None = None,
                    takes_back: np.ndarray | None = None) -> LogisticModel:
    """The shipped model, from simulated loops only: the L2 strength of :data:`L2_GRID` with the least
    cross-validated log-loss on ``train_set``, weights fitted on all of it; Platt's calibration on
    ``calibration_set`` (:func:`fit_platt`), and the undetermined band from it: "no stiction" below
    :data:`NO_STICTION_BELOW`, "stiction" from the operating point of :func:`operating_point` (``hard`` marks
    the calibration set's hard negatives; ``decides`` and ``takes_back``: the valve-model fit's outcomes on the
    calibration loops, so that the rate holds for the final calls)."""
    losses = {l2: cv_log_loss(train_set, l2) for l2 in L2_GRID}
    l2 = min(losses, key=lambda v: (round(losses[v], 9), -v))
    model = fit_logistic(train_set.x, train_set.y, np.ones(len(train_set.y)), l2, train_set.features,
                         train_set.signs)
    model.synthetic_ratio = 1.0
    model.calibration = fit_platt(model.probability(calibration_set.x), calibration_set.y)
    p_cal = model.calibrated(calibration_set.x)
    op = operating_point(p_cal, calibration_set.y, hard, decides=decides, takes_back=takes_back)
    model.band = (NO_STICTION_BELOW, max(op["cut"], NO_STICTION_BELOW))
    model.threshold = 0.5
    model.info.update({"trained_on": "simulated loops only (phfdi.loopdiag.domain)", "cv_log_loss": losses,
                       "operating_point": op, "max_false_call": SIM_FALSE_CALL,
                       "calibration_calls": call_rates(model.call(p_cal), calibration_set.y)})
    return model

