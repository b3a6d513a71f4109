"""Calibrating the estimator's detector on days it has not seen: leave-one-run-out residuals.

A reference fitted on healthy runs predicts those runs better than any other day, so scales measured on its own
training runs are too small for the next day (on the rig: no alarm on the calibration runs, six in 160 min
of runs held out of a three-run fit). Here every scale the detector's false-alarm rate rests on comes from
residuals of runs the reference did not see:

1. the reference is fitted on all runs (:func:`wavelet_fdi.estimator_fit.fit_reference`), and once more
   without each run (the run's *fold reference*);
2. the wavelet bands' healthy RMS (the detector's thresholds are in these units) is measured on each run's
   residuals from its fold reference (:func:`wavelet_fdi.learned_detector.calibrate_bands`);
3. the confirmation's null (:func:`wavelet_fdi.estimator_isolation.null_statistics`: the fault-against-healthy
   statistics as if an alarm were detected at every other block) is sampled on the same held-out residuals,
   and each margin placed where healthy operation exceeds it with the design probability
   (:func:`wavelet_fdi.estimator_isolation.confirmation_thresholds`);

With one run there is nothing to hold out: the scales come from the run itself and the result says so
(``held_out: false``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Callable, Sequence

import numpy as np

from .estimator_fit import fit_reference
from .estimator_isolation import DEFAULT_ALPHA, confirmation_thresholds, null_statistics
from .learned_detector import LearnedModel, LearnedSettings, calibrate_bands
from .reference_estimator import EstimatorReference

Runs = Sequence[tuple[np.ndarray, np.ndarray]]


def fold_references(runs: Runs, start: EstimatorReference, progress: Callable[[str], None] | None = None
                    ) -> list[EstimatorReference]:
    """Each run's fold reference: fitted on every other run (with one run, the run's own fit)."""
    if len(runs) < 2:
        return [fit_reference(runs, start)]
    out = []
    for j in range(len(runs)):
        if progress:
            progress(f"fitting without run {j + 1} of {len(runs)} (to score it as an unseen day)")
        out.append(fit_reference([r for i, r in enumerate(runs) if i != j], start))
    return out


def calibrate_estimator(runs: Runs, start: EstimatorReference, settings: LearnedSettings,
                        source: dict | None = None, alpha: float = DEFAULT_ALPHA,
                        progress: Callable[[str], None] | None = None,
                        check_fit: Callable[[EstimatorReference], None] | None = None) -> LearnedModel:
    """The estimator's detector model: the reference fitted on all ``runs``, its band scales, confirmation
    margins and noise band from leave-one-run-out residuals (module doc). ``check_fit`` sees the reference
    fitted on all runs before the folds are (it raises to refuse one the runs did not identify)."""
    say = progress or (lambda _msg: None)
    say(f"fitting the estimator on {len(runs)} run(s)")
    ref = fit_reference(runs, start)
    if check_fit is not None:
        check_fit(ref)
    folds = fold_references(runs, start, say) if len(runs) >= 2 else [ref]
    held_out = len(runs) >= 2
    say("sampling the confirmation's null on " + ("each run held out" if held_out else "the run itself"))
    nulls: list[dict[str, float]] = []
    for (t, rows), fold in zip(runs, folds):
        nulls += null_statistics(fold, t, rows)
    confirm = confirmation_thresholds(nulls, alpha)
    confirm.update(held_out=held_out,
                   design=(f"a healthy deviation confirmed as a fault with probability {alpha:.2g} at most, split "
                           f"equally among the statistics {', '.join(confirm['thresholds'])}; each null measured "
                           f"on {'leave-one-run-out' if held_out else 'in-sample'} residuals of {len(runs)} run(s), "
                           f"its tail beyond the 90th percentile exponential"))
    ref = replace(ref, confirm=confirm)
    model = calibrate_bands(ref, runs, settings, {**(source or {}), "bands_from": "leave-one-run-out residuals"
                                                  if held_out else "the run's own residuals"}, folds)
    # a reading beyond the spike level is held until the next says what it was: a lone glitch is dropped (the state
    # does not jump to it and crawl back, a mean deviation the offset hypothesis fits), a step is followed as before
    # (wavelet_fdi.estimator_kernel)
    model.reference = replace(ref, gate_sigma=float(model.settings.spike_sigma))
    return model
