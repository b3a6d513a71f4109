"""The reference protocol: what a healthy reference gives the multichannel wavelet-CUSUM detector.

A reference reads some channels of a record and gives residuals, each in units of its healthy (or
predicted) standard deviation, that :class:`~wavelet_fdi.learned_detector.LearnedDetector` splits
into wavelet bands and watches with CUSUMs. Every kind provides

* ``kind``: its name in the reference file;
* ``channels``: the record's channels it reads, in the order of the rows it is given;
* ``residual_channels``: the names of the residuals it gives (a subset of, or equal to, ``channels``);
* ``lags``: samples it needs before its first residual;
* ``new_state()``: a stream whose ``residuals(t_s, rows)`` gives the next rows' residuals (n, r) and keeps
  its state between calls, so that any chunking of a record gives the same residuals;
* ``to_dict()`` / ``from_dict(d, where)``: the reference file's ``reference`` entry, ``kind`` in it.

A stream may also hold rows back by a rule of its own (the physics kind, while the valve command is missing): it
gives them NaN residuals (counted as healthy), marks them in ``last_held`` (the last call's rows) and says why in
``notices`` ((global row index, text) pairs the detector reports as input events and then clears).

Kinds (chosen by the reference file, :data:`KINDS`):

* ``arx`` (:class:`~wavelet_fdi.reference_learned.LearnedReference`): each channel from its own past and
  the others, learned from healthy rows; any plant, no model;
* ``oe`` (:class:`~wavelet_fdi.reference_oe.OutputErrorReference`): the same linear model in output-error
  form, its own lags from its own past predictions pulled slowly toward the measurement, so a sensor
  fault (a step that stays, a frozen channel) stays in the channel's residual (``--form oe``);
* ``estimator`` (:class:`~wavelet_fdi.reference_estimator.EstimatorReference`, ``correct: true``): a
  Kalman filter on a stirred vessel's reaction invariant driven by the measured pH;
* the same physics run open loop (``correct: false``): the model simulated from the record's first pH on
  the measured pump flows, never corrected, the way ``phfdi diagnose`` compares a model with a run;
* ``physics`` (:class:`~wavelet_fdi.reference_physics.PhysicsReference`): a scenario's healthy plant and valves
  (the paper's loop) run on the measured valve commands, the model the paper's physics detector ran (retired for
  this kind on 2026-12-07); its alarms are named by that detector's isolation (:mod:`wavelet_fdi.physics_naming`).

A kind whose namer needs more (or fewer) samples after a detection than the detector's
``NAMING_AFTER`` says so with ``naming_after_samples``.
Adding a kind: a class with the members above, one entry in :data:`KINDS` (and, if it can name the fault
behind an alarm, one in :data:`NAMERS`).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from phfdi_base.errors import UserError

from .estimator_isolation import isolate, look_schedule
from .physics_naming import name_fault as name_physics_fault
from .physics_naming import naming_looks
from .reference_estimator import EstimatorReference
from .reference_learned import LearnedReference
from .reference_oe import OutputErrorReference
from .reference_physics import PhysicsReference


class ReferenceStream(Protocol):
    def residuals(self, t_s: np.ndarray | None, rows: np.ndarray) -> np.ndarray: ...


class Reference(Protocol):
    kind: str

    @property
    def lags(self) -> int: ...

    @property
    def channels(self) -> tuple[str, ...]: ...

    @property
    def residual_channels(self) -> tuple[str, ...]: ...

    def new_state(self) -> Any: ...

    def to_dict(self) -> dict: ...


#: reference kinds by the name their files carry
KINDS: dict[str, Any] = {"arx": LearnedReference, "oe": OutputErrorReference, "estimator": EstimatorReference,
                         "physics": PhysicsReference}


#: kinds whose alarms can be named (family, class, size): namer(reference, t_s, rows, onset_index,
#: detection_index, statistic) -> dict, called by the detector on the rows it kept (LearnedDetector)
NAMERS: dict[str, Any] = {"estimator": isolate, "physics": name_physics_fault}
#: kinds whose namer looks again at a deviation it did not confirm (or, for a namer that does not confirm, names
#: again an alarm it was unsure of) while it stays up: looks(reference) -> the samples after the detection each
#: look's window keeps, the first look's first (one look: never again)
LOOKS: dict[str, Any] = {"estimator": lambda ref: look_schedule(ref.confirm),
                         "physics": lambda ref: naming_looks(ref.naming_after_samples)}


def reference_from_dict(d: dict, where: str = "reference") -> Reference:
    """The reference a file's ``reference`` entry describes (no ``kind``: ``arx``, the first format)."""
    kind = str(d.get("kind", "arx"))
    if kind not in KINDS:
        raise UserError(f"{where}: unknown reference kind {kind!r} (known: {', '.join(KINDS)})")
    return KINDS[kind].from_dict(d, where)
