"""One verdict per loop record, with its evidence listed.

The verdict is one of

* ``pv_frozen`` - PV does not respond: valve stuck or transmitter failed (:mod:`.loopcheck`);
* ``not_a_closed_loop`` - no setpoint, OP still, or PV does not follow OP (:mod:`.loopcheck`);
* ``stiction``, ``no_stiction`` or ``undetermined`` - the stiction classifier's calibrated probability
  against its undetermined band (:mod:`.classifier`, chosen inside the nested evaluation).

How the valve-model (Hammerstein) fit is reconciled: its held-out gains of the friction models are two of
the classifier's inputs, so its weight in the verdict is the one the training data gave it (0 on the
refinery records: their published direction did not help there), and the probability already holds it.
What it names is listed as evidence beside the verdict, with whether it agrees; it does not overrule the
probability, because on the refinery records the named cause is not reliable (docs/loop_diagnosis.md:
of 9 stiction files flagged at 10 %, 5 were named dead-zone). There is one verdict, never two.
"""

from __future__ import annotations

from .classifier import NO_STICTION, STICTION, UNDETERMINED
from .loopcheck import NOT_A_CLOSED_LOOP, PV_FROZEN, LoopCheck
from .vocabulary import FRICTION_CAUSES

VERDICTS = (STICTION, NO_STICTION, UNDETERMINED, PV_FROZEN, NOT_A_CLOSED_LOOP)


def valve_model_evidence(rep: dict, verdict: str) -> dict | None:
    """What the valve-model fit says and whether it agrees with ``verdict`` (None when it did not run)."""
    if rep.get("family") is None or rep.get("gain_percent") is None:
        return None
    cause, family, gain = rep.get("cause"), rep.get("family"), rep.get("gain_percent")
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
    if verdict == STICTION:
        summary = f"stiction, p = {p:.2f} (confident from {high:.2f})"
    elif verdict == NO_STICTION:
        summary = f"no stiction, p = {p:.2f} (confident below {low:.2f})"
    else:
        summary = f"undetermined, p = {p:.2f} (between {low:.2f} and {high:.2f}: the evidence does not decide)"
    evidence = ["indicators (value, contribution to the log-odds): "
                + "; ".join(f"{e['feature']} {e['value']:.3g} ({e['contribution']:+.2f})"
                            for e in [e for e in st["evidence"] if e["measured"]][:5])]
    valve = valve_model_evidence(rep, verdict)
    if valve is not None:
        evidence.append(f"valve-model fit: {valve['says']} ({valve['agreement']})")
    evidence += list(check.reasons)
    return {"verdict": verdict, "summary": summary, "probability": p, "band": [low, high], "evidence": evidence,
            "valve_model": valve, "structure": check.to_dict()}
