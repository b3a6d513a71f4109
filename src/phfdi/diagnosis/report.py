"""The diagnosis report format shared by ``phfdi diagnose`` and ``phfdi loop-diagnose``.

Both commands answer the same question (what does the model get wrong, and
which catalogued cause explains it) and emit the same JSON keys:

``verdict``
    ``explained`` (a catalogued cause brings the held-out misfit down to the
    noise floor), ``not_explained`` (a misfit remains; ``cause`` is then the
    closest candidate and its family), ``none`` (nothing significant to
    explain) or ``not_identifiable`` (the data cannot tell: constant inputs).
``cause``, ``family``
    catalogue identifier (:data:`CAUSES`; pairs are joined with ``+``) and its
    family (``actuator``, ``sensor``, ``process``, or ``none``).
``parameters``
    fitted values of the winner, ``{name: value}`` in the units of the block.
``confidence``
    number in [0, 1]: one minus the p-value of the held-out comparison between
    the answer and the best alternative answer (the runner-up cause, or for
    ``none`` the best candidate's gain); ``None`` when not applicable.
``nrmse_nominal``, ``nrmse_extended``, ``gain_percent``
    held-out NRMSE (root-mean-square error over the standard deviation of the
    measurement) of the main output for the nominal and the extended model,
    and 100 (1 - extended / nominal).
``ranking``
    every candidate, best first: ``cause``, ``family``, ``parameters``,
    ``confidence_intervals`` (``{name: [low, high]}``, 95 %),
    ``nrmse_validation``, ``aic``, ``bic`` (training, Gaussian likelihood),
    and any extra keys a command adds.
``reason``
    one sentence that says why this verdict.

This module holds the vocabulary and formatting only; it computes nothing.
"""

from __future__ import annotations

import json
import math
from typing import Any

from phfdi.faults import catalogue

#: verdicts, in the order a reader meets them
VERDICTS = ("explained", "not_explained", "none", "not_identifiable")

#: catalogue identifier -> family
CAUSES: dict[str, str] = {
    "stiction": "actuator",
    "backlash": "actuator",
    "deadzone": "actuator",
    "saturation": "actuator",
    "coulomb_viscous_friction": "actuator",
    "leakage": "actuator",
    "valve_gain": "actuator",
    "sensor_delay": "sensor",
    "sensor_lag": "sensor",
    "sensor_bias": "sensor",
    "sensor_drift": "sensor",
    "sensor_gain": "sensor",
    "buffer": "process",
    "reagent_concentration": "process",
    "holdup": "process",
    "disturbance_flow": "process",
    # structural candidates (ph_plant_sim.mixing, ph_plant_sim.feedlines, probe blocks): tried by the structure
    # search (--structure) or when named with --candidates
    "mixing_zone": "process",
    "feed_delay": "process",
    "pump_curve": "actuator",
    "carbonate": "process",
    "probe_asymmetric_lag": "sensor",
    "two_point_calibration": "sensor",
    "pump_lag": "actuator",
    "tanks_in_series": "process",
    "co2_absorption": "process",
    "flask_contents": "process",
    "sensor_second_order": "sensor",
    "none": "none",
}

FAMILIES = ("actuator", "sensor", "process", "none")
#: the family of a catalogued fault (:mod:`phfdi_base.faults`) by where it acts
SITE_FAMILY = {"valve": "actuator", "valve_flow": "actuator", "ph_sensor": "sensor"}


def causes() -> dict[str, str]:
    """:data:`CAUSES` and, before ``none``, each catalogued fault's block not in it (a block of one's own)."""
    out = {k: v for k, v in CAUSES.items() if k != "none"}
    for f in catalogue().values():
        if f.candidate and f.params:  # a fault without parameters (a seized stem) is not fitted
            out.setdefault(f.block, SITE_FAMILY[f.site])
    out["none"] = CAUSES["none"]
    return out

#: keys every report carries (commands may add more)
REPORT_KEYS = ("verdict", "cause", "family", "parameters", "confidence", "nrmse_nominal", "nrmse_extended",
               "gain_percent", "ranking", "reason")

#: keys every ranking entry carries
RANKING_KEYS = ("cause", "family", "parameters", "confidence_intervals", "nrmse_validation", "aic", "bic")


def family_of(cause: str) -> str:
    """Family of a cause or of a pair ``a+b`` (``actuator+sensor``; one name when both agree)."""
    parts = cause.split("+")
    known = causes()
    fams = []
    for p in parts:
        if p not in known:
            raise ValueError(f"unknown cause {p!r}; catalogue: {', '.join(known)}")
        if known[p] not in fams:
            fams.append(known[p])
    return "+".join(fams)


def check_report(report: dict) -> dict:
    """Raise ValueError if a report lacks a shared key or uses an unknown verdict/cause."""
    missing = [k for k in REPORT_KEYS if k not in report]
    if missing:
        raise ValueError(f"report lacks {', '.join(missing)}")
    if report["verdict"] not in VERDICTS:
        raise ValueError(f"unknown verdict {report['verdict']!r}; use one of {', '.join(VERDICTS)}")
    if report["family"] != family_of(report["cause"]):
        raise ValueError(f"family {report['family']!r} does not match cause {report['cause']!r}")
    for i, entry in enumerate(report["ranking"]):
        lacking = [k for k in RANKING_KEYS if k not in entry]
        if lacking:
            raise ValueError(f"ranking entry {i} lacks {', '.join(lacking)}")
    return report


def clean(o: Any) -> Any:
    """JSON-safe copy: numpy scalars and arrays to Python, non-finite floats to None."""
    if isinstance(o, dict):
        return {str(k): clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    if hasattr(o, "tolist") and not isinstance(o, (str, bytes)):
        return clean(o.tolist())
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o


def to_json(report: dict) -> str:
    """The report as JSON text (numpy values as plain numbers, non-finite numbers as null).

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.diagnosis import to_json
    >>> print(to_json({"verdict": "none", "gain_percent": np.float64("nan"), "samples": np.int64(600)}))
    {
      "verdict": "none",
      "gain_percent": null,
      "samples": 600
    }
    """
    return json.dumps(clean(report), indent=2, allow_nan=False)


def fmt_num(v: Any, fmt: str = ".3f") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def fmt_params(params: dict, intervals: dict | None = None) -> str:
    """'width_pct = 1.02 [0.98, 1.06]' style, in the dict's order."""
    out = []
    for k, v in params.items():
        text = f"{k} = {v:.4g}" if isinstance(v, (int, float)) else f"{k} = {v}"
        ci = (intervals or {}).get(k)
        if ci and all(isinstance(c, (int, float)) and math.isfinite(c) for c in ci):
            text += f" [{ci[0]:.3g}, {ci[1]:.3g}]"
        out.append(text)
    return ", ".join(out)


def verdict_line(report: dict) -> str:
    """One line: verdict, cause (family) [parameters], confidence, gain.

    Examples
    --------
    >>> from phfdi.diagnosis import verdict_line
    >>> verdict_line({"verdict": "explained", "cause": "backlash", "family": "actuator",
    ...               "parameters": {"width_pct": 1.02}, "confidence": 0.97, "gain_percent": 61.0,
    ...               "nrmse_nominal": 0.42, "nrmse_extended": 0.164})
    'verdict: explained; cause backlash (actuator) [width_pct = 1.02]; confidence 0.97; held-out NRMSE 0.420 -> 0.164 (+61 %)'
    """
    v = report["verdict"]
    text = f"verdict: {v.replace('_', ' ')}"
    if report["cause"] != "none":
        label = "cause" if v == "explained" else "closest"
        text += f"; {label} {report['cause']} ({report['family']})"
        if report.get("parameters"):
            text += f" [{fmt_params(report['parameters'])}]"
    if report.get("confidence") is not None:
        text += f"; confidence {report['confidence']:.2f}"
    if report.get("gain_percent") is not None:
        text += (f"; held-out NRMSE {fmt_num(report['nrmse_nominal'])} -> {fmt_num(report['nrmse_extended'])} "
                 f"({report['gain_percent']:+.0f} %)")
    return text
