"""Naming the fault behind an alarm of the ``physics`` reference kind: the physics detector's isolation.

The multichannel detector calls :func:`name_fault` (the kind's entry in ``references.NAMERS``) with the rows it kept,
:data:`~wavelet_fdi.reference_physics.NAMING_AFTER_S` after a detection. The rows start where its ring of recent
rows starts, so the kind's model is re-run from there (:class:`~wavelet_fdi.reference_physics.PhysicsStream` with
``keep``: every sample's prediction, flows and valve opening, a snapshot of the model at every block boundary), and
:class:`~wavelet_fdi.isolation.FaultIsolator` (the code the physics detector names its alarms with) fits every
valve and probe hypothesis from the last snapshot before the onset. The isolator's noise levels are the scenario's
sensor noise, the residual unit of the kind.

The answer has the keys every namer gives (``family``, ``fault_class``, ``description``, ``size``, ``unit``) and
the isolator's ``confidence``, ``parameter``, ``alternatives`` and ``evidence``, and where it names a fault the
onset its fit found (``onset_time``, s), which the detector takes as the alarm's onset. ``unknown`` (no hypothesis
explains the residual) is family ``none``.
"""

from __future__ import annotations

import math

import numpy as np

from phfdi_base.faults import faults

from .filterbank import CausalSwt
from .history import History
from .isolation import FaultIsolator, IsolationResult
from .reference_physics import PHYSICS_DESIGN, PhysicsReference, PhysicsStream

#: the filter bank of the residual the isolator reads (its evidence's band energies): the physics detector's
WAVELET, LEVEL = str(PHYSICS_DESIGN["wavelet"]), int(PHYSICS_DESIGN["level"])


def _isolator(ref: PhysicsReference) -> FaultIsolator:
    """One isolator per reference (its hypotheses and the model it re-simulates are built once, kept on it)."""
    cached = ref.__dict__.get("_isolator")
    if cached is not None:
        return cached
    noise = ref.sensor_noise
    made = FaultIsolator(ref.spec, noise["ph"], noise["level"], LEVEL)
    object.__setattr__(ref, "_isolator", made)  # a cache, not a field: the reference stays what its file says
    return made


def _history(ref: PhysicsReference, t_s: np.ndarray, rows: np.ndarray) -> tuple[History, dict]:
    """The kind's model re-run over the rows: what the isolator reads, and the snapshots it starts from."""
    stream = PhysicsStream(ref, keep=True)
    stream.residuals(t_s, rows)
    kept = stream.kept
    assert kept is not None, "made with keep=True"
    cmd, _, ph, level = stream.columns(rows)
    ph_pred = np.concatenate(kept["ph_pred"])
    residual = np.where(np.isfinite(ph - ph_pred), ph - ph_pred, 0.0)
    out = CausalSwt(WAVELET, LEVEL).process(residual)
    coef = np.vstack((out.details, out.approx[None, :], residual[None, :])).T
    flows = np.concatenate(kept["flows"])
    n = len(rows)
    hist = History(n + 1, {"t": 1, "ph": 1, "level": 1, "command": 1, "ph_pred": 1, "level_pred": 1,
                           "flows": flows.shape[1], "opening": 1, "setpoint": 1, "coef": LEVEL + 2})
    hist.write(0, {"t": np.asarray(t_s, float), "ph": ph, "level": level, "command": cmd, "ph_pred": ph_pred,
                   "level_pred": np.concatenate(kept["level_pred"]), "flows": flows,
                   "opening": np.concatenate(kept["opening"]), "setpoint": np.full(n, math.nan), "coef": coef})
    return hist, kept["snapshots"]


#: namings made while the first stays unsure: the physics detector's isolation retries
RETRIES = 2
#: below this confidence a naming is unsure (the physics detector's isolation_confidence)
SURE = 0.9


def naming_looks(first: int) -> tuple[int, ...]:
    """Samples after the detection of each naming: the first, then one more first-delay for every retry."""
    return tuple(first * (k + 1) for k in range(RETRIES + 1))


def name_fault(ref: PhysicsReference, t_s: np.ndarray, rows: np.ndarray, onset_index: int, detection_index: int,
               statistic: str = "", after: int | None = None) -> dict:
    """The fault behind an alarm (module docstring); ``rows`` in ``ref.channels`` order, indices into them."""
    isolator = _isolator(ref)
    hist, snapshots = _history(ref, np.asarray(t_s, float), np.asarray(rows, float))
    start = [k for k in snapshots if k <= onset_index]
    result = (isolator.isolate(hist, snapshots[max(start)], max(start), onset_index, len(rows) - 1)
              if start else None)
    return _answer(result)


def _answer(result: IsolationResult | None) -> dict:
    """The namer's answer; ``name_again`` when unsure (no class, ``unknown`` or a confidence below :data:`SURE`), as
    the physics detector isolates again one delay later."""
    unsure = result is None or result.fault_class == "unknown" or result.confidence < SURE
    return {**_named(result), "confirmed": True, "name_again": bool(unsure)}


def _named(result: IsolationResult | None) -> dict:
    if result is None or result.fault_class == "unknown":
        why = "no fault hypothesis explains the residual" if result is not None else "too few samples to fit"
        return {"family": "none", "fault_class": "unknown", "description": why, "size": 0.0, "unit": "",
                "confidence": float(result.confidence) if result is not None else 0.0,
                "parameter": None if result is None else result.parameter}
    onset = result.evidence.get("onset_fit_s")  # the isolation's fitted onset (s), as the physics detector reports
    fault = faults().get(result.fault_class)
    p = result.parameter or {}
    size = float(p.get("value", math.nan))  # the fitted main parameter: {"name", "value", "unit", "fault_class"}
    return {"family": fault.family if fault is not None else "unknown", "fault_class": result.fault_class,
            "description": result.fault_class.replace("_", " "),  # the fitted size follows in size and unit
            "size": round(size, 4) if math.isfinite(size) else 0.0, "unit": str(p.get("unit", "")),
            "confidence": round(float(result.confidence), 4), "parameter": result.parameter,
            "alternatives": result.alternatives, "evidence": result.evidence,
            **({"onset_time": float(onset)} if onset is not None else {})}
