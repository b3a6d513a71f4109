"""Diagnosis reports for people and for JSON: one loop, and a summary over many files.

The keys of a loop's report are those of the diagnosis catalogue shared with
``phfdi diagnose`` (model diagnosis against a first-principles model):
``cause``, ``family``, ``parameters``, ``confidence``, ``nrmse_nominal``,
``nrmse_extended``, ``gain_percent``, ``ranking`` (each entry: ``cause``,
``family``, ``parameters``, ``nrmse_validation``, ``aic``, ``bic``) and
``verdict`` (``explained``, ``not_explained``, ``none``,
``not_identifiable``); loop diagnosis adds ``oscillation``, ``loop_tag`` and
``file``. This module only formats; it computes nothing.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

#: verdicts of the shared catalogue
VERDICTS = ("explained", "not_explained", "none", "not_identifiable")


def _num(v, fmt: str = ".3f") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def _params(p: dict) -> str:
    return ", ".join(f"{k} = {v:.3g}" for k, v in p.items()) if p else ""


def format_report(rep: dict) -> str:
    """A few lines per loop: oscillation, linear model, what it misses, the ranking, the verdict.

    Examples
    --------
    >>> from phfdi.loopdiag import format_report
    >>> format_report({"file": "FIC101.csv", "error": "no OP column"})
    'FIC101.csv: cannot diagnose: no OP column'
    """
    if "error" in rep:
        return f"{rep['file']}: cannot diagnose: {rep['error']}"
    osc = rep["oscillation"]
    lines = [f"{rep['loop_tag']}  ({Path(rep['file']).name}, {rep['samples']} samples at {rep['sample_time_s']:g} s, "
             f"{rep['process_type'].replace('_', '-')})"]
    lv = rep.get("loop_verdict")
    if lv:
        lines.append(f"  verdict: {lv['summary']}")
        if lv.get("probability") is None:  # not scored: the reasons are the whole answer
            lines += [f"    {r}" for r in lv["evidence"]]
            return "\n".join(lines + [f"  note: {n}" for n in rep.get("notes") or []])
        lines += [f"    {e}" for e in lv["evidence"]]
    if osc is None:
        pass
    elif osc["oscillating"]:
        lines.append(f"  oscillation: yes, period {osc['period_s']:.0f} s, regularity {osc['regularity']:.1f} "
                     f"({osc['cycles']:.1f} cycles)")
    else:
        lines.append(f"  oscillation: no (regularity {_num(osc['regularity'], '.2f')}, threshold 1)")
    nom = rep.get("nominal_model")
    if nom:
        desc = f"{nom['structure']}"
        if nom["structure"] != "arx":
            desc += (f" K = {nom['gain']:.3g}, tau = {nom['time_constant_s']:.0f} s, "
                     f"dead time = {nom['dead_time_s']:.0f} s")
        lines.append(f"  linear model: {desc}; held-out NRMSE {_num(nom['nrmse_validation'])}"
                     + ("  (worse than 'PV stays': 1.0 used)" if rep.get("nominal_is_persistence") else ""))
        miss = rep.get("missed_by_linear_model") or {}
        missed = []
        if miss.get("limit_cycle"):
            missed.append(f"a limit cycle (residual oscillates at {miss['residual_period_s']:.0f} s)")
        if miss.get("asymmetry") is not None and abs(miss["asymmetry"]) > 0.5:
            missed.append(f"asymmetric changes (residual skewness {miss['asymmetry']:.2f})")
        if (miss.get("pv_stuck_share") or 0) > 0.02:
            missed.append(f"PV not moving while the model moves it ({100 * miss['pv_stuck_share']:.0f} % of samples)")
        lines.append("  the linear model misses: " + ("; ".join(missed) if missed else "nothing it could measure"))
    ranking = rep.get("ranking") or []
    if ranking:
        top = "; ".join(f"{r['cause']} {_num(r['nrmse_validation'])}" for r in ranking[:5])
        lines.append(f"  valve models, held-out NRMSE: {top}")
    if rep.get("valve_models") == "not fitted":
        lines.append(f"  {rep['reason']}")
    else:
        lines += _valve_model_lines(rep)
    st = rep.get("stiction")
    if st:
        line = (f"  stiction classifier: calibrated p = {st['probability']:.2f}, undetermined between "
                f"{st['band'][0]:.2f} and {st['band'][1]:.2f} (the model's own p {st['model_probability']:.2f})")
        if st.get("kano_s_pct") is not None:
            line += (f"; Kano fit S = {st['kano_s_pct']:.3g}, J = {st['kano_j_pct']:.3g} (OP units; OP noise "
                     f"{st['op_noise']:.3g})")
        lines.append(line)
    base = rep.get("baselines") or {}
    if base:
        lines.append("  baselines: " + "; ".join(f"{k} {v['decision']}" + (f" ({v['index']:.2f})" if v.get("index")
                                                                             is not None else "")
                                               for k, v in base.items()))
    for note in rep.get("notes") or []:
        lines.append(f"  note: {note}")
    return "\n".join(lines)


def _valve_model_lines(rep: dict) -> list[str]:
    """The valve-model (Hammerstein) fit's verdict and reason."""
    verdict = rep["verdict"]
    cause = rep["cause"]
    head = f"  valve-model fit: {verdict}"
    if cause != "none":
        head += f", cause {cause} ({rep['family']})"
        if rep.get("parameters"):
            head += f" [{_params(rep['parameters'])}]"
    head += f", confidence {_num(rep.get('confidence'), '.2f')}"
    if rep.get("gain_percent") is not None:
        head += f", gain {rep['gain_percent']:.0f} %"
    return [head, f"    {rep['reason']}"]


def loop_summary(reports: list[dict]) -> list[dict]:
    """Per loop tag: files, the most frequent cause, the share of files agreeing and their mean confidence."""
    by_loop: dict[str, list[dict]] = {}
    for r in reports:
        if "error" not in r:
            by_loop.setdefault(r["loop_tag"], []).append(r)
    out = []
    for tag, reps in by_loop.items():
        counts = Counter(r["cause"] for r in reps)
        cause, n = max(counts.items(), key=lambda kv: (kv[1], _mean_conf(reps, kv[0])))
        out.append({"loop_tag": tag, "files": len(reps), "cause": cause,
                    "family": next(r["family"] for r in reps if r["cause"] == cause),
                    "agreement": n / len(reps), "confidence": _mean_conf(reps, cause),
                    "causes": dict(counts),
                    "verdicts": dict(Counter((r.get("loop_verdict") or {}).get("verdict") for r in reps))})
    return sorted(out, key=lambda d: d["loop_tag"])


def _mean_conf(reps: list[dict], cause: str) -> float:
    vals = [r.get("confidence") or 0.0 for r in reps if r["cause"] == cause]
    return float(f"{sum(vals) / len(vals):.3g}") if vals else 0.0


def format_summary(reports: list[dict]) -> str:
    """Table per file, then per loop tag; failed files last."""
    ok = [r for r in reports if "error" not in r]
    bad = [r for r in reports if "error" in r]
    lines = [f"{'file':44s} {'loop':26s} {'osc':4s} {'verdict':17s} {'p':>5s}  valve-model fit (cause, gain %)"]
    for r in ok:
        gain = "-" if r.get("gain_percent") is None else f"{r['gain_percent']:.0f}"
        lv = r.get("loop_verdict") or {}
        osc = "-" if r.get("oscillation") is None else "yes" if r["oscillation"]["oscillating"] else "no"
        lines.append(f"{Path(r['file']).name[:44]:44s} {str(r['loop_tag'])[:26]:26s} {osc:4s} "
                     f"{lv.get('verdict', '-'):17s} {_num(lv.get('probability'), '.2f'):>5s}  {r['cause']}, {gain}")
    summary = loop_summary(reports)
    if summary:
        lines.append("")
        lines.append(f"{'loop':30s} {'files':>5s}  {'cause':21s} {'agree':>6s} {'conf':>5s}")
        for s in summary:
            lines.append(f"{s['loop_tag'][:30]:30s} {s['files']:5d}  {s['cause']:21s} {100 * s['agreement']:5.0f}% "
                         f"{s['confidence']:5.2f}")
    for r in bad:
        lines.append(f"failed: {r['error']}")
    return "\n".join(lines)


def to_json(reports: list[dict]) -> str:
    """``{"files": [...], "loops": [...], "failed": [...]}``."""
    doc = {"files": [r for r in reports if "error" not in r], "loops": loop_summary(reports),
           "failed": [r for r in reports if "error" in r]}
    return json.dumps(clean(doc), indent=2, allow_nan=False)


def clean(o):
    """JSON-safe copy: numpy scalars to Python, non-finite floats to None."""
    if isinstance(o, dict):
        return {str(k): clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    if hasattr(o, "item") and not isinstance(o, (str, bytes)):
        o = o.item()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    return o
