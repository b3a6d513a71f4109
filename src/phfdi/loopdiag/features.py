"""The classifier's features of one loop: each indicator's value on a common footing.

A feature is the indicator's index on its published scale, with two rules:

* an indicator that does not apply to the loop (Horch's CCF on a level loop, the shape tests when
  there is no period, ...) takes its *neutral* value, the one that means "no evidence either way"
  (its published decision threshold, or 0 where the index is 0 for a healthy loop), so it adds
  nothing to the verdict;
* unbounded indices are clipped to the range their papers discuss.

Every feature comes from the screen (:func:`screen_evidence`: the oscillation test, the published indicators
and the dead-band screen of :mod:`.deadband`), a few tens of milliseconds per loop; none needs the valve-model
(Hammerstein) fit, which runs only for the loops the screen flags and is then evidence beside the verdict
(:mod:`.verdict`), with Kano's S and J.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from threadpoolctl import threadpool_limits

from phfdi.records.record import Record

from .diagnose import Evidence, Settings, gather_evidence
from .indicator_set import compute_indicators
from .indicators import Indicator
from .oscillation import Oscillation, detect_oscillation
from .vocabulary import FRICTION_CAUSES


@dataclass(frozen=True)
class Feature:
    name: str
    source: str  # indicator name (or "hammerstein"/"oscillation")
    neutral: float
    low: float
    high: float
    description: str
    #: the direction the paper reads as stiction: +1 higher values, -1 lower values; the classifier's
    #: weight is held to this sign (a weight against the published reading is not learned)
    stiction_sign: int = 1


FEATURES: tuple[Feature, ...] = (
    Feature("oscillation_regularity", "oscillation", 0.0, 0.0, math.log1p(10.0),
            "log(1 + r), r the ACF zero-crossing regularity (Thornhill et al. 2003), r capped at 10"),
    Feature("horch_ccf", "horch_ccf", 0.5, 0.0, 1.0, "Horch (1999) CCF oddness psi (0 even, 1 odd)"),
    Feature("he_curve_fit", "he_curve_fit", 0.5, 0.0, 1.0, "He et al. (2007) SI (triangle vs sinusoid)"),
    Feature("kano_stuck", "kano_stuck", 0.0, 0.0, 1.0, "Kano et al. (2004) share of OP travel while stuck"),
    Feature("stick_slip", "stick_slip", 0.0, 0.0, 1.0,
            "share of OP travel in stuck sections that end in a slip (Kano et al.'s model read from OP and PV)"),
    Feature("area_peak_ratio", "area_peak_ratio", 0.0, -2.0, 2.0, "Singhal & Salsbury (2005) log(A1/A2)"),
    Feature("relay_shape", "relay_shape", 0.0, -1.0, 1.0, "Rossi & Scali (2005) SI (relay vs sinusoid)"),
    Feature("bicoherence_ngi", "bicoherence_ngi", 0.0, -0.1, 0.5, "Choudhury et al. (2004) NGI"),
    Feature("bicoherence_nli", "bicoherence_nli", 0.0, 0.0, 1.0, "Choudhury et al. (2004) NLI (0 if Gaussian)"),
    Feature("ellipse_apparent_stiction", "ellipse_apparent_stiction", 0.0, 0.0, 1.0,
            "Choudhury et al. (2006) PV-OP ellipse width along OP / OP span"),
    Feature("deadband_gain", "deadband_evidence", 0.0, -0.5, 1.0,
            "share of the OP model's error of PV's changes a sticking stem removes (the dead-band screen)"),
)
FEATURE_NAMES = tuple(f.name for f in FEATURES)
FEATURE_SIGNS = tuple(f.stiction_sign for f in FEATURES)


def _clip(v: float, f: Feature) -> float:
    return float(min(max(v, f.low), f.high))




def hammerstein_gains(ev: Evidence) -> tuple[float | None, float | None]:
    """(better friction model's gain, Kano stiction model's gain) as fractions of the linear
    model's held-out NRMSE; None when not identifiable or not fitted."""
    if not ev.identifiable:
        return None, None
    nom = ev.nrmse_nominal
    if not math.isfinite(nom) or nom <= 0:
        return None, None
    gains = {c.cause: (nom - c.model.nrmse_validation) / nom for c in ev.causes if c.cause in FRICTION_CAUSES}
    if not gains:
        return None, None
    return max(gains.values()), gains.get("stiction")


def feature_vector(indicators: dict[str, Indicator], oscillation: Oscillation) -> tuple[np.ndarray, dict[str, bool]]:
    """The features in :data:`FEATURE_NAMES` order and, per feature, whether it was measured
    (False: neutral value used)."""
    values, measured = [], {}
    for f in FEATURES:
        v: float | None
        if f.source == "oscillation":
            r = oscillation.regularity
            v = math.log1p(min(r, 10.0)) if math.isfinite(r) else math.log1p(10.0)
        else:
            v = indicators[f.source].value
        if v is not None and math.isfinite(v):
            measured[f.name] = True
            values.append(_clip(v, f))
        else:
            measured[f.name] = False
            values.append(f.neutral)
    return np.array(values), measured


@dataclass
class ScreenEvidence:
    """What the screen measures on one loop: the indicators, the oscillation and the feature vector."""

    indicators: dict[str, Indicator]
    oscillation: Oscillation
    features: np.ndarray
    measured: dict[str, bool]


def screen_evidence(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, dt_s: float,
                    process_type: str) -> ScreenEvidence:
    """Oscillation, indicators and features of one loop (one BLAS thread: the fits are small, and threads only
    wait on each other; a plant-wide run uses the cores for loops instead)."""
    with threadpool_limits(limits=1, user_api="blas"):
        indicators = compute_indicators(op, pv, sp, dt_s, process_type)
        osc = detect_oscillation(pv, sp, dt_s)
    x, measured = feature_vector(indicators, osc)
    return ScreenEvidence(indicators, osc, x, measured)


@dataclass
class LoopEvidence:
    """The screen and the valve-model (Hammerstein) fit of one loop."""

    indicators: dict[str, Indicator]
    evidence: Evidence
    features: np.ndarray
    measured: dict[str, bool]


def loop_evidence(run: Record, settings: Settings | None = None) -> LoopEvidence:
    """The screen's indicators and features and the valve-model evidence of one loop (``settings.causes`` gets
    :data:`FRICTION_CAUSES` added: Kano's S and J are evidence of the verdict)."""
    settings = settings or Settings()
    missing = [c for c in FRICTION_CAUSES if c not in settings.causes]
    if missing:
        settings = replace(settings, causes=tuple(settings.causes) + tuple(missing))
    process_type = settings.process_type or run.metadata.get("process_type", "self_regulating")
    sp = run["sp"] if "sp" in run else None
    scr = screen_evidence(run["op_pct"], run["pv"], sp, run.dt_s, process_type)
    ev = gather_evidence(run, replace(settings, baselines=False))
    ev.baselines = baselines_of(scr.indicators)
    return LoopEvidence(scr.indicators, ev, scr.features, scr.measured)


def baselines_of(indicators: dict[str, Indicator]) -> dict:
    """Horch's and He et al.'s tests as the report's ``baselines`` (computed once, by the screen)."""
    return {k: {"method": k, "index": indicators[k].value, "decision": indicators[k].decision,
                "detail": indicators[k].detail} for k in ("horch_ccf", "he_curve_fit")}


# ---- the verdict with its evidence ------------------------------------------------------------
def stiction_verdict(le: LoopEvidence | ScreenEvidence, model=None) -> dict:
    """The classifier's verdict on one loop and the evidence behind it: every indicator's value,
    its published decision and its contribution to the log-odds (weight x standardised value; an
    indicator that does not apply sits at its neutral value, and its contribution is that value's
    distance from the training mean). ``probability`` is calibrated (Platt scaling of the model's own
    ``model_probability``), ``verdict`` its call against the undetermined ``band``: stiction, no_stiction or
    undetermined."""
    model = model or _shipped_model()
    if model.features != list(FEATURE_NAMES):
        raise ValueError("the model's features are not this version's: retrain it "
                         "(benchmarks/train_stiction_classifier.py)")
    p_model = float(model.probability(le.features))
    p = float(model.calibrated(le.features))
    call = str(model.call(np.array([p]))[0])
    contrib = model.contributions(le.features)
    evidence = []
    for f, x, c in zip(FEATURES, le.features, contrib):
        item = {"feature": f.name, "value": _r4(x), "measured": le.measured[f.name], "contribution": _r4(c),
                "description": f.description}
        ind = le.indicators.get(f.source)
        if ind is not None:
            item["decision"] = ind.decision
            item["reference"] = ind.reference
        evidence.append(item)
    evidence.sort(key=lambda e: -abs(e["contribution"] or 0.0))
    low, high = model.cuts()
    out = {"verdict": call, "probability": _r4(p), "band": [_r4(low), _r4(high)],
           "model_probability": _r4(p_model), "threshold": _r4(model.threshold), "intercept": _r4(model.bias),
           "evidence": evidence,
           "method": "L2 logistic regression on published indicators and the dead-band screen, trained on simulated "
                     "loops only (docs/loop_diagnosis.md)"}
    return out


def kano_fit(ev: Evidence) -> dict | None:
    """Kano's S and J of the valve-model fit (OP units), None when it did not run."""
    st = next((c for c in ev.causes if c.cause == "stiction"), None) if ev.identifiable else None
    if st is None:
        return None
    return {"kano_s_pct": _r4(st.parameters["s_pct"]), "kano_j_pct": _r4(st.parameters["j_pct"])}


_MODEL = None


def _shipped_model():
    global _MODEL
    if _MODEL is None:
        from .classifier import load_model

        _MODEL = load_model()
    return _MODEL


def _r4(v):
    return float(f"{float(v):.4g}") if v is not None and math.isfinite(float(v)) else None
