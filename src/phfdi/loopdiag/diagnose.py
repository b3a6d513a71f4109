"""Diagnose one loop from OP, PV and SP: oscillation, linear model, what it misses, the cause.

Order of work (docs/loop_diagnosis.md has the reasoning and the measured results):

1. oscillation test on the control error (:mod:`.oscillation`);
2. the loop's PI law from the data (:mod:`.controller`): its action fixes the
   sign of the process gain, which keeps the identification away from the
   controller's inverse;
3. linear OP -> PV models, FOPTD (integrating for level loops) and ARX,
   fitted on the first two thirds of the record and scored on the last third
   (:mod:`.identify`); the best one is the nominal model;
4. what the nominal model misses (:func:`symptoms`);
5. every valve nonlinearity of the catalogue fitted jointly with a lag model
   (:mod:`.hammerstein`) and ranked on the held-out third;
6. the verdict: an actuator cause when the best one beats the nominal model by
   at least ``gain_threshold_percent`` on held-out data; otherwise, for an
   oscillating loop, a loop cause (aggressive tuning when the loop answers
   setpoint changes poorly damped at the period it oscillates at, else an
   external disturbance; undecided without setpoint changes); otherwise none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import lfilter
from scipy.stats import skew

from phfdi.records.record import Record

from .baselines import run_baselines
from .controller import ControllerEstimate, estimate_pi
from .hammerstein import CauseFit, Problem, fit_causes
from .identify import LinearModel, Split, fit_linear, increments
from .indicators import noise_level
from .oscillation import Oscillation, detect_oscillation, period_regularity
from .vocabulary import ACTUATOR_CAUSES

#: default: the extended model must cut the held-out NRMSE by this much (%) to name a cause
GAIN_THRESHOLD_PERCENT = 10.0
#: extended models within this relative NRMSE of the best count as tied; the simplest wins
TIE_TOLERANCE = 0.01
#: closed-loop damping ratio (from setpoint responses) below which the loop itself oscillates
AGGRESSIVE_DAMPING = 0.25
#: share of PV's variance the setpoint-response model must explain to be trusted
MIN_SP_R2 = 0.3
#: OP must move by more than this share of its mean level (or 0.05 % of span) to identify anything
MIN_OP_MOVEMENT = 1e-3


#: which loops get the valve-model (Hammerstein) fits: those the screen flags (its call stiction or
#: undetermined), all, or none (the screen alone: its stiction calls are then not reconciled with a fit)
FITS = ("flagged", "all", "none")


@dataclass
class Settings:
    """What the loop diagnosis considers: the held-out gain a valve model needs (%), the causes it tries,
    the process type (None: from the loop tag, LIC -> integrating), whether the baselines run, and which loops
    get the valve-model fits (:data:`FITS`: the ones the screen flags, or all).

    Examples
    --------
    >>> from phfdi.loopdiag import Settings
    >>> settings = Settings(baselines=False)
    >>> settings.process_type is None, "stiction" in settings.causes
    (True, True)
    """

    gain_threshold_percent: float = GAIN_THRESHOLD_PERCENT
    causes: tuple[str, ...] = ACTUATOR_CAUSES
    process_type: str | None = None  # None: from the loop tag (LIC -> integrating)
    baselines: bool = True
    fits: str = "flagged"


@dataclass
class Evidence:
    """Everything computed for one loop, before the verdict (kept for re-deciding in evaluations)."""

    oscillation: Oscillation
    controller: ControllerEstimate
    linear: list[LinearModel]
    causes: list[CauseFit]
    symptoms: dict
    setpoint_response: dict
    baselines: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    identifiable: bool = True
    n_eff: float = 10.0

    @property
    def nominal(self) -> LinearModel:
        return self.linear[0]

    def chosen(self) -> CauseFit | None:
        """Best actuator cause on held-out data; among near ties the one with fewest parameters."""
        if not self.causes:
            return None
        best = min(c.model.nrmse_validation for c in self.causes)
        tied = [c for c in self.causes if c.model.nrmse_validation <= best * (1 + TIE_TOLERANCE)]
        return min(tied, key=lambda c: (c.n_params, c.model.nrmse_validation))

    @property
    def nrmse_nominal(self) -> float:
        """Held-out NRMSE of the linear model, or 1 when "PV stays" (the zero-gain linear model,
        persistence) predicts better: a valve model must beat both to explain anything."""
        return min(self.nominal.nrmse_validation, 1.0)

    def gain_percent(self) -> float:
        c = self.chosen()
        nom = self.nrmse_nominal
        if c is None or not math.isfinite(nom) or nom <= 0:
            return 0.0
        return 100.0 * (nom - c.model.nrmse_validation) / nom


def gather_evidence(run: Record, settings: Settings | None = None) -> Evidence:
    settings = settings or Settings()
    op, pv = run["op_pct"], run["pv"]
    sp = run["sp"] if "sp" in run else None
    dt = run.dt_s
    process_type = settings.process_type or run.metadata.get("process_type", "self_regulating")
    integrating = process_type == "integrating"
    split = Split.of(len(run))
    osc = detect_oscillation(pv, sp, dt)
    ctrl = estimate_pi(op, pv, sp, dt)
    notes: list[str] = []
    baselines = {k: v.to_dict() for k, v in run_baselines(op, pv, sp, dt, process_type).items()} \
        if settings.baselines else {}
    op_scale = max(abs(float(np.mean(op))) * MIN_OP_MOVEMENT, 0.05 * MIN_OP_MOVEMENT * 100)
    if np.ptp(op[split.train]) <= op_scale or np.ptp(op[split.validation]) <= op_scale:
        notes.append("OP hardly moves in the training or the validation part: no process model can be "
                     "identified from these data")
        return Evidence(osc, ctrl, [], [], {}, {}, baselines, notes, identifiable=False)
    linear = fit_linear(op, pv, dt, split, integrating, ctrl.gain_sign)
    op_in_percent = bool(np.min(op) >= -1e-9 and np.max(op) <= 100.0 + 1e-9)
    if not op_in_percent:
        notes.append("OP is not within 0..100 (a cascade or engineering-unit output): widths are in OP "
                     "units and saturation is not fitted")
    problem = Problem(op, pv, dt, split, integrating, op_in_percent, ctrl.gain_sign)
    problem.centre_on(next(m for m in linear if m.structure != "arx"))
    causes = fit_causes(problem, settings.causes)
    y_nominal = linear[0].y_model
    if y_nominal is None:
        raise TypeError(f"the {linear[0].structure} model has no y_model")
    ev = Evidence(osc, ctrl, linear, causes, {}, {}, baselines, notes,
                  n_eff=effective_samples(pv, y_nominal, split))
    ev.symptoms = symptoms(op, pv, linear[0], osc, dt, ev.chosen())
    ev.setpoint_response = setpoint_response(pv, sp, dt) if osc.oscillating else {}
    return ev


# ---- what the linear model misses ---------------------------------------------------------
def symptoms(op: np.ndarray, pv: np.ndarray, nominal: LinearModel, osc: Oscillation, dt_s: float,
             best: CauseFit | None) -> dict:
    """Measured signs of a nonlinearity the nominal model cannot produce.

    * ``limit_cycle``: the oscillation survives in the nominal model's residual
      (residual regularity > 1 at a period within 30 % of the loop's);
    * ``asymmetry``: skewness of the residual of PV's 4-sample changes;
    * ``pv_stuck_share``: share of samples where the nominal model moves PV by
      more than 3 noise levels over 3 samples while PV moves by less than one
      (PV not following small OP changes, flat tops);
    * ``stem_stuck_share`` (best valve model): share of samples its stem is at
      rest while OP moves.
    """
    y_model = nominal.y_model
    if y_model is None:
        raise TypeError(f"symptoms: the nominal {nominal.structure} model has no y_model")
    residual = pv - y_model
    out: dict = {}
    per, reg = period_regularity(residual - np.mean(residual), dt_s)
    out["residual_period_s"] = _f(per)
    out["residual_regularity"] = _f(reg)
    out["limit_cycle"] = bool(osc.oscillating and osc.period_s and reg > 1.0 and math.isfinite(per)
                              and abs(per - osc.period_s) <= 0.3 * osc.period_s)
    d4 = increments(pv, (4,)) - increments(y_model, (4,))
    out["asymmetry"] = _f(float(skew(d4))) if np.std(d4) > 0 else 0.0
    noise = noise_level(pv)
    if noise > 0:
        dpv = np.abs(pv[3:] - pv[:-3])
        dmod = np.abs(y_model[3:] - y_model[:-3])
        out["pv_stuck_share"] = _f(float(np.mean((dmod > 3 * noise) & (dpv < noise))))
    else:
        out["pv_stuck_share"] = 0.0
    out["noise_level"] = _f(noise)
    if best is not None:
        dv = np.abs(np.diff(best.position))
        dop = np.abs(np.diff(op))
        moving_op = dop > 1e-9
        out["stem_stuck_share"] = _f(float(np.mean(dv[moving_op] < 1e-12))) if moving_op.any() else 0.0
    return out


def _f(v: float):
    return float(f"{v:.4g}") if isinstance(v, float) and math.isfinite(v) else None


# ---- the closed loop's own damping, from its response to setpoint changes --------------------
def setpoint_response(pv: np.ndarray, sp: np.ndarray | None, dt_s: float) -> dict:
    """Second-order closed-loop model SP -> PV fitted to the setpoint changes (output error).

    ``PV = c + g T(q) (SP - SP(0))``, T the zero-order-hold discretisation of
    ``w^2 / (s^2 + 2 zeta w s + w^2)`` delayed by d samples, on a grid of zeta, w and d with c, g
    by least squares. Setpoint changes are an input the disturbances do not drive, so unlike
    OP -> PV this fit is not biased by the feedback (indirect identification, Ljung 1999,
    ch. 13). Empty when SP does not move by more than 3 noise levels, or the fit explains less
    than :data:`MIN_SP_R2` of PV's variance.
    """
    if sp is None:
        return {}
    noise = noise_level(pv)
    if np.ptp(sp) <= 3 * max(noise, 1e-12):
        return {}
    n = len(pv)
    u = sp - sp[0]
    best = (math.inf, 0.0, 0.0, 0)
    y = pv - np.mean(pv)
    syy = float(y @ y)
    for zeta in (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.55, 0.7, 0.9, 1.2):
        for period_n in np.geomspace(4 * dt_s, n * dt_s / 4, 16):
            den_d = _second_order_poles(zeta, 2 * math.pi / period_n, dt_s)
            resp = lfilter([0.0, float(np.sum(den_d))], den_d, u)  # unit DC gain, one-sample lag
            for d in (0, 1, 2, 4, 8):
                x = np.concatenate((np.zeros(d), resp[: n - d])) if d else resp
                xc = x - np.mean(x)
                sxx = float(xc @ xc)
                if sxx <= 0:
                    continue
                sse = syy - float(xc @ y) ** 2 / sxx
                if sse < best[0]:
                    best = (sse, zeta, period_n, d)
    sse, zeta, period_n, d = best
    r2 = 1.0 - sse / syy if syy > 0 else 0.0
    if r2 < MIN_SP_R2:
        return {"r2": _f(r2)}
    damped = period_n / math.sqrt(1 - zeta ** 2) if zeta < 1 else None
    return {"damping": zeta, "period_s": _f(damped) if damped else None, "r2": _f(r2), "delay_s": d * dt_s}


def _second_order_poles(zeta: float, w: float, dt_s: float) -> np.ndarray:
    """Denominator in z of the poles exp(s dt) of s^2 + 2 zeta w s + w^2."""
    if zeta < 1.0:
        r = math.exp(-zeta * w * dt_s)
        return np.array([1.0, -2.0 * r * math.cos(w * math.sqrt(1 - zeta ** 2) * dt_s), r * r])
    root = w * math.sqrt(zeta ** 2 - 1)
    p1, p2 = math.exp((-zeta * w + root) * dt_s), math.exp((-zeta * w - root) * dt_s)
    return np.array([1.0, -(p1 + p2), p1 * p2])


# ---- the verdict ---------------------------------------------------------------------------
def loop_cause(ev: Evidence) -> tuple[str, str, str]:
    """For an oscillating loop without an actuator cause: (cause, verdict, reason).

    At the oscillation's frequency OP and PV always stand in the controller's ratio, whatever
    drives them, so OP and PV alone cannot tell an aggressive tuning from an external
    disturbance. Setpoint changes can: the loop's damping from its setpoint responses.
    """
    cl = ev.setpoint_response
    period = ev.oscillation.period_s
    if not cl:
        return "none", "not_identifiable", (
            "no valve nonlinearity explains the oscillation; telling aggressive tuning from an external "
            "disturbance needs setpoint changes the loop responds to (or a process model), and SP does not "
            "move in this record")
    if cl.get("damping") is None:
        return "none", "not_explained", (
            f"no valve nonlinearity explains the oscillation, and the setpoint changes explain only "
            f"{100 * max(cl.get('r2') or 0.0, 0.0):.0f} % of PV: neither a tuning nor an external disturbance "
            "can be shown")
    zeta, p_cl = cl["damping"], cl.get("period_s")
    near = p_cl is not None and period is not None and abs(p_cl - period) <= 0.4 * period
    if zeta < AGGRESSIVE_DAMPING and near:
        return "aggressive_tuning", "explained", (
            f"the loop answers setpoint changes with damping {zeta:.2f} and period {p_cl:.0f} s, the period "
            f"it oscillates at ({period:.0f} s): the tuning makes it oscillate")
    return "external_disturbance", "explained", (
        f"the loop answers setpoint changes with damping {zeta:.2f}"
        + (f" and period {p_cl:.0f} s" if p_cl else "") + f", yet PV oscillates at {period:.0f} s: "
        "the oscillation enters from outside the loop")


def decide(ev: Evidence, gain_threshold_percent: float = GAIN_THRESHOLD_PERCENT) -> dict:
    """Cause, family, verdict and confidence from the evidence and a gain threshold."""
    if not ev.identifiable:
        return {"cause": "none", "family": "none", "parameters": {}, "verdict": "not_identifiable",
                "confidence": 0.0, "reason": ev.notes[-1] if ev.notes else "not identifiable"}
    chosen = ev.chosen()
    gain = ev.gain_percent()
    weights = validation_weights(ev)
    if chosen is not None and gain >= gain_threshold_percent:
        fam_conf = sum(w for name, w in weights.items() if name != "nominal")
        return {"cause": chosen.cause, "family": "actuator", "parameters": _params(chosen.parameters),
                "verdict": "explained", "confidence": _f(weights.get(chosen.cause, 0.0)),
                "family_confidence": _f(fam_conf),
                "reason": (f"{chosen.cause} between OP and the process cuts the held-out NRMSE from "
                           f"{ev.nrmse_nominal:.3f} to {chosen.model.nrmse_validation:.3f} "
                           f"({gain:.0f} %)")}
    if ev.oscillation.oscillating:
        cause, verdict, reason = loop_cause(ev)
        conf = weights.get("nominal", 0.0) if verdict == "explained" else 0.0
        return {"cause": cause, "family": "loop", "parameters": {}, "verdict": verdict,
                "confidence": _f(conf), "reason": reason}
    return {"cause": "none", "family": "none", "parameters": {}, "verdict": "none",
            "confidence": _f(weights.get("nominal", 0.0)),
            "reason": (f"the loop does not oscillate and no valve nonlinearity improves the held-out fit by "
                       f"{gain_threshold_percent:g} % or more (best: {max(gain, 0.0):.0f} %)")}


def _params(p: dict) -> dict:
    return {k: float(f"{v:.4g}") for k, v in p.items()}


def validation_weights(ev: Evidence) -> dict:
    """Relative support of the nominal model and each cause on held-out data (sums to 1).

    Gaussian likelihood of the held-out prediction errors with an effective number of
    independent samples n_eff = n_val (1 - rho) / (1 + rho), rho the lag-1 autocorrelation of
    the nominal model's one-step residual; weights exp(-n_eff / 2 ln(MSE_i / MSE_min)).
    """
    nrm = {"nominal": ev.nrmse_nominal}
    for c in ev.causes:
        nrm.setdefault(c.cause, c.model.nrmse_validation)
    finite = {k: v for k, v in nrm.items() if math.isfinite(v) and v > 0}
    if not finite:
        return {k: 0.0 for k in nrm}
    n_eff = ev.n_eff
    lo = min(finite.values())
    logw = {k: -0.5 * n_eff * 2.0 * math.log(v / lo) for k, v in finite.items()}
    total = sum(math.exp(v) for v in logw.values())
    return {k: (math.exp(logw[k]) / total if k in logw else 0.0) for k in nrm}


def effective_samples(pv: np.ndarray, y_model: np.ndarray, split: Split) -> float:
    """Independent errors behind the held-out NRMSE: the h-step errors overlap over h samples,
    so horizon h contributes about (n_val - h) / h; weighted by its share of the squared error."""
    va = split.validation
    y, m = pv[va], y_model[va]
    if not np.all(np.isfinite(m)):
        return 3.0
    n_val = len(y)
    sse = []
    for h in split.horizons:
        e = (y[h:] - y[:-h]) - (m[h:] - m[:-h])
        sse.append(float(e @ e))
    total = sum(sse)
    if total <= 0:
        return float(n_val)
    n_eff = sum(s / total * (n_val - h) / h for s, h in zip(sse, split.horizons))
    return float(min(max(n_eff, 3.0), n_val))


# ---- the report ------------------------------------------------------------------------------
def report(run: Record, ev: Evidence, settings: Settings | None = None) -> dict:
    """The JSON-ready diagnosis of one loop (keys shared with ``phfdi diagnose``)."""
    settings = settings or Settings()
    d = decide(ev, settings.gain_threshold_percent)
    chosen = ev.chosen()
    out = {
        "file": run.metadata.get("file"),
        "loop_tag": run.metadata.get("loop_tag"),
        "process_type": settings.process_type or run.metadata.get("process_type"),
        "samples": len(run),
        "sample_time_s": run.dt_s,
        "oscillation": ev.oscillation.to_dict(),
        "cause": d["cause"],
        "family": d["family"],
        "parameters": d["parameters"],
        "confidence": d["confidence"],
        "verdict": d["verdict"],
        "reason": d["reason"],
    }
    if "family_confidence" in d:
        out["family_confidence"] = d["family_confidence"]
    if ev.identifiable:
        nom = ev.nominal
        out["nrmse_nominal"] = _f(ev.nrmse_nominal)
        out["nominal_is_persistence"] = bool(nom.nrmse_validation > 1.0)
        out["nrmse_extended"] = _f(chosen.model.nrmse_validation) if chosen else None
        out["gain_percent"] = _f(ev.gain_percent())
        out["extended_cause"] = chosen.cause if chosen else None
        out["nominal_model"] = nom.summary()
        out["linear_models"] = [m.summary() for m in ev.linear]
        out["ranking"] = [c.entry() for c in sorted(ev.causes, key=lambda c: c.model.nrmse_validation)]
        out["missed_by_linear_model"] = ev.symptoms
        out["controller"] = ev.controller.to_dict()
        out["setpoint_response"] = ev.setpoint_response
    else:
        out.update(nrmse_nominal=None, nrmse_extended=None, gain_percent=None, extended_cause=None, ranking=[])
        out["controller"] = ev.controller.to_dict()
    out["criterion"] = (f"pooled {'/'.join(map(str, Split.of(len(run)).horizons))}-sample PV predictions "
                        "anchored on measured PV; validation = last third of the record")
    out["baselines"] = ev.baselines
    out["notes"] = list(run.metadata.get("notes") or []) + ev.notes
    out["reading_notes"] = list(run.metadata.get("notes") or [])  # what the reader repaired (phfdi.records)
    return out


def diagnose_run(run: Record, settings: Settings | None = None) -> dict:
    settings = settings or Settings()
    return report(run, gather_evidence(run, settings), settings)
