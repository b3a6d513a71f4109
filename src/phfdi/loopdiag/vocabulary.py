"""The loop diagnosis's fault vocabulary, declared once: its valve causes and their ranges in % of each loop's
OP span.

The fault catalogue (:mod:`phfdi_base.faults`, declared with each block) bounds a fault in the physical units
of the simulated pH valve. A control loop read from a plant historian has no such scale: its OP may be in % or
in engineering units, its valve of any size, so the loop diagnosis sizes a nonlinearity relative to the loop's
own OP span (docs/architecture.md, "one fault catalogue"). Those relative ranges are declared with each fault in
the catalogue (``loop=LoopDraws(...)``) and read here; the cause lists (which causes the valve-model fit tries,
in which order) are declared here and nowhere else in the loop diagnosis. tests/test_architecture.py checks
that no other module names a cause's parameter next to a number and that the cause lists are not written
again. The names are registered blocks (:mod:`valve_actuator.blocks`), the same code the simulator runs; their
parameter names are the blocks'.

Examples
--------
>>> from phfdi.loopdiag.vocabulary import ACTUATOR_CAUSES, FRICTION_CAUSES, TRAINING_DRAWS
>>> ACTUATOR_CAUSES
('backlash', 'deadzone', 'saturation', 'quantization', 'stiction')
>>> set(FRICTION_CAUSES) <= set(ACTUATOR_CAUSES), TRAINING_DRAWS["backlash"]["width_pct"]
(True, (0.3, 6.0))
"""

from __future__ import annotations

from phfdi.faults import catalogue

__all__ = ["ACTUATOR_CAUSES", "DOMAIN_DRAWS", "FRICTION_CAUSES", "OTHER_NONLINEARITIES", "TRAINING_DRAWS",
           "WIDTH_SEARCH_SPAN"]

#: causes of the actuator family the Hammerstein fit tries, in catalogue order (simplest first breaks ties)
ACTUATOR_CAUSES = ("backlash", "deadzone", "saturation", "quantization", "stiction")
#: the friction models: the classifier's features compare them with the linear model, and the evaluation
#: counts a Hammerstein verdict naming one as stiction found
FRICTION_CAUSES = ("backlash", "stiction")
#: the nonlinearities that are not friction (the training set's "other_nonlinearity" class draws one)
OTHER_NONLINEARITIES = ("deadzone", "quantization", "saturation")

#: widths the Hammerstein fit searches, as fractions of the training OP span (log-spaced from the first to the
#: last)
WIDTH_SEARCH_SPAN = (0.01, 0.8)

#: the synthetic training loops' valves: block -> parameter -> (low, high) in % of travel (log-uniform), or a
#: ratio to the first parameter (uniform, ``*_over_*``); saturation's high limit is ``base`` plus a log-uniform
#: draw ``above`` it, a little above where the loop works. Kano's S and He's fs over the same range (half of the
#: sticky valves each); a stiction smaller than the records' disturbances shows to no method. Declared with each
#: fault in the catalogue (``loop=LoopDraws(training=...)``), read here.
TRAINING_DRAWS: dict[str, dict] = {f.block: f.loop.training for f in catalogue().values()
                                   if f.loop is not None and f.loop.training}

#: the domain-randomised loops' valves (:mod:`phfdi.loopdiag.domain`, the stiction verdict's training data), as
#: :data:`TRAINING_DRAWS`; saturation's high limit is ``above`` the loop's working point (``LoopDraws.domain``).
DOMAIN_DRAWS: dict[str, dict] = {f.block: f.loop.domain for f in catalogue().values()
                                 if f.loop is not None and f.loop.domain}
