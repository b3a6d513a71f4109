"""One verdict per loop record, with its evidence listed.

The verdict is one of

* ``pv_frozen`` - PV does not respond: valve stuck or transmitter failed (:mod:`.loopcheck`);
* ``not_a_closed_loop`` - no setpoint, OP still, or PV does not follow OP (:mod:`.loopcheck`);
* ``stiction``, ``no_stiction`` or ``undetermined`` - the stiction classifier's calibrated probability
  against its undetermined band (:mod:`.classifier`: trained, calibrated and its operating point set on
  simulated loops only).

How the valve-model (Hammerstein) fit is reconciled. It runs on the loops the screen flags, and what it names is
listed as evidence beside the verdict, with whether it agrees. It can only take confidence away: a "stiction"
call whose valve-model evidence contradicts it becomes ``undetermined``, with the reason, when

* the fit names another valve nonlinearity (dead-zone, quantisation, saturation) as the cause, i.e. that model
  beats the linear one by the gain threshold and the friction models (Kano's stiction, backlash) do not come
  within the tie tolerance of it; or
* Kano's S of the fit is below :data:`KANO_S_NOISE` times OP's noise level: a stiction that small cannot hold
  the valve while OP travels, so the indicators must be reading something else.

A fit that finds no valve nonlinearity at all does not overrule the indicators: on simulated sticky loops the
fit beats the linear model by 10 % on only about a third of them (docs/loop_diagnosis.md).

Where the indicators do not decide, the fit does when it is sure: an ``undetermined`` screen becomes ``stiction``
when the fit explains the loop by friction (the cause it names is Kano's stiction or a backlash dead-band, which
beats the linear model by the gain threshold on held-out data) and Kano's S is not within OP's noise: the same two
tests that take a stiction call away, passed rather than failed (:func:`friction_decides`). The classifier's
operating point is set on simulated loops with this rule applied (benchmarks/train_stiction_classifier.py), so the
verdict's false-call rate there is that of the final calls.
There is one verdict, never two.
"""

from __future__ import annotations

from .classifier import NO_STICTION, STICTION, UNDETERMINED
from .loopcheck import NOT_A_CLOSED_LOOP, PV_FROZEN, LoopCheck
from .vocabulary import FRICTION_CAUSES

VERDICTS = (STICTION, NO_STICTION, UNDETERMINED, PV_FROZEN, NOT_A_CLOSED_LOOP)
#: Kano's S below this many OP noise levels (:func:`.indicators.ramp_noise_level`: from OP's second differences,
#: so that OP's ramps while the valve sticks are not read as noise) contradicts a stiction call
KANO_S_NOISE = 3.0


def _fitted_cause(rep: dict) -> tuple[str, float] | None:
    """The valve nonlinearity the fit names as what explains the loop, with its held-out gain (%), or None (no
    fit, or no valve nonlinearity beats the linear model by the gain threshold)."""
    if rep.get("valve_models") != "fitted" or rep.get("family") != "actuator" or rep.get("verdict") != "explained":
        return None
    cause, gain = rep.get("cause"), rep.get("gain_percent")
    return None if gain is None else (str(cause), float(gain))


def _kano_s(rep: dict) -> tuple[float, float] | None:
    """Kano's S of the fit and OP's noise level, or None when either is missing."""
    st = rep.get("stiction") or {}
    s, noise = st.get("kano_s_pct"), st.get("op_noise")
    return None if s is None or not noise else (float(s), float(noise))


def contradiction(rep: dict) -> tuple[str, str] | None:
    """Why the valve-model fit contradicts a stiction call (module docstring), short and in full, or None."""
    if rep.get("valve_models") != "fitted":
        return None
    named = _fitted_cause(rep)
    if named is not None and named[0] not in FRICTION_CAUSES:
        cause, gain = named
        return (f"the valve-model fit names {cause}, not friction",
                f"the valve-model fit names {cause}, not friction: it cuts the held-out error by {gain:.0f} % and "
                "neither Kano's stiction nor a backlash comes as close")
    kano = _kano_s(rep)
    if kano is not None and kano[0] < KANO_S_NOISE * kano[1]:
        s, noise = kano
        return (f"Kano's S ({s:.3g}) is within OP's noise",
                f"Kano's S from the valve-model fit, {s:.3g}, is below {KANO_S_NOISE:g} times OP's noise level "
                f"({noise:.3g}): a stiction that small cannot hold the valve while OP travels")
    return None


def friction_decides(rep: dict) -> str | None:
    """Why the valve-model fit decides an undetermined screen for stiction (module docstring), or None: it names
    friction (Kano's stiction or backlash) as what explains the loop, and Kano's S is above :data:`KANO_S_NOISE`
    times OP's noise level: :func:`contradiction`'s two tests, passed."""
    named, kano = _fitted_cause(rep), _kano_s(rep)
    if named is None or named[0] not in FRICTION_CAUSES or kano is None or kano[0] < KANO_S_NOISE * kano[1]:
        return None
    (cause, gain), (s, noise) = named, kano
    return (f"the valve-model fit names {cause}: it cuts the held-out error by {gain:.0f} %, and Kano's S ({s:.3g}) "
            f"is {s / noise:.0f} times OP's noise level")


def valve_model_evidence(rep: dict, verdict: str) -> dict | None:
    """What the valve-model fit says and whether it agrees with ``verdict`` (None when it did not run)."""
    cause, family, gain = rep.get("cause"), rep.get("family"), rep.get("gain_percent")
    if rep.get("valve_models") == "not fitted" or family is None or gain is None:
        return None
    if family == "actuator" and cause in FRICTION_CAUSES:
        says, points_to_stiction = f"{cause} (a friction dead-band) cuts the held-out error by {gain:.0f} %", True
    elif family == "actuator":
        says, points_to_stiction = f"another valve nonlinearity, {cause}, cuts the held-out error by {gain:.0f} %", None
    else:
        says, points_to_stiction = f"no valve nonlinearity improves the held-out fit enough (best {max(gain, 0):.0f} %)", \
            False
    if verdict == UNDETERMINED or points_to_stiction is None:
        agreement = "neither"
    else:
        agreement = "agrees" if points_to_stiction == (verdict == STICTION) else "disagrees"
    return {"says": says, "cause": cause, "gain_percent": gain, "agreement": agreement}


def loop_verdict(check: LoopCheck, rep: dict) -> dict:
    """The one verdict of a loop report: the structure check's when it has one, else the stiction
    classifier's banded call (``rep["stiction"]``) with the valve-model fit listed as evidence."""
    if check.verdict is not None:
        head = "PV does not respond: valve stuck or transmitter failed" if check.verdict == PV_FROZEN else \
            "not a closed loop: " + ", ".join(r.split(":")[0] for r in check.reasons)
        return {"verdict": check.verdict, "summary": head, "probability": None, "band": None,
                "evidence": list(check.reasons), "structure": check.to_dict()}
    st = rep["stiction"]
    verdict, p = st["verdict"], st["probability"]
    low, high = st["band"]
    why = contradiction(rep) if verdict == STICTION else None
    decided = friction_decides(rep) if verdict == UNDETERMINED else None
    if why is not None:
        verdict = UNDETERMINED
        summary = f"undetermined, p = {p:.2f}: the indicators say stiction, but {why[0]}"
    elif decided is not None:
        verdict = STICTION
        summary = (f"stiction, p = {p:.2f}: the indicators do not decide (between {low:.2f} and {high:.2f}), the "
                   f"valve-model fit does")
    elif verdict == STICTION:
        summary = f"stiction, p = {p:.2f} (confident from {high:.2f})"
    elif verdict == NO_STICTION:
        summary = f"no stiction found, p = {p:.2f} (below {low:.2f})"
    else:
        summary = f"undetermined, p = {p:.2f} (between {low:.2f} and {high:.2f}: the evidence does not decide)"
    evidence = ["indicators (value, contribution to the log-odds): "
                + "; ".join(f"{e['feature']} {e['value']:.3g} ({e['contribution']:+.2f})"
                            for e in [e for e in st["evidence"] if e["measured"]][:5])]
    valve = valve_model_evidence(rep, verdict)
    if valve is not None:
        evidence.append(f"valve-model fit: {valve['says']} ({valve['agreement']})")
    if why is not None:
        evidence.insert(0, f"undetermined because {why[1]}")
    if decided is not None:
        evidence.insert(0, f"stiction because {decided}")
    evidence += list(check.reasons)
    return {"verdict": verdict, "summary": summary, "probability": p, "band": [low, high], "evidence": evidence,
            "valve_model": valve, "contradiction": None if why is None else why[1],
            "decided_by_valve_model": decided, "structure": check.to_dict()}
