"""The estimator reference for a plant model with pumped feeds (application floor).

``phfdi calibrate --estimator RUN... --model rig_flask --map ph_rig`` ends here: the plant model (an
overflow vessel with feeds of strong acid and base) gives the filter's feeds and first guesses
(strength in mM of charge, flask volume), :func:`wavelet_fdi.estimator_fit.fit_reference`
fits strengths, volume and noise model on the healthy runs by the innovations' likelihood, and
:func:`wavelet_fdi.learned_detector.calibrate_bands` measures the residual's healthy band RMS on the same
runs. The result is a detector model file that ``phfdi replay --reference`` and the detector node load
like a learned one.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from phfdi.learned import MeasuredRecord, read_measured
from phfdi_base.errors import UserError
from wavelet_fdi.estimator_calibration import calibrate_estimator
from wavelet_fdi.learned_detector import LearnedModel, LearnedSettings
from wavelet_fdi.reference_estimator import EstimatorReference, Feed

PH_CHANNEL = "ph_measured"

#: the rig's runs are short (2 to 17 minutes): the bands' observer learns within a minute and an alarm
#: clears after 32 samples (11 s at 0.35 s sampling); every threshold stays in healthy sigmas
ESTIMATOR_SETTINGS = {"observer_time_constant_s": 60.0, "observer_alarm_time_constant_s": 600.0,
                      # a probe that freezes or turns sluggish loses its noise: watch the detail bands' energy
                      # for a fall to a twentieth (the likelihood-ratio CUSUM of that variance ratio; a quiet healthy
                      # plateau reads about a quarter of the pooled noise)
                      "energy_down_variance_ratio": 0.05,
                      # a probe that turns noisy: the detail bands' energy against this run's own noise (healthy rig
                      # runs differ fourfold in it from day to day), learned with the strengths' 120 s and frozen on
                      # a rise; the likelihood-ratio CUSUM of a fourfold variance, a sample counting at most fourfold
                      "energy_variance_ratio": 4.0, "energy_baseline_time_constant_s": 120.0,
                      # a probe that freezes or turns sluggish stops dithering across its meter's 0.01 pH steps:
                      # the Bernoulli CUSUM of exact repeats (wavelet_fdi.repeat_test) against the run's own share
                      # (7-13 % on the rig), designed for a reading that repeats in 9 of 10 samples
                      "repeat_probability": 0.9}


def feed_strength_mM(recipe: dict[str, float]) -> float:
    """A feed's strong base minus strong acid in mM of charge (+ base, - acid): strong ions by their charge;
    an acid's protons with a pKa below 7 count as released (H2SO4: 2; NaHCO3: 0)."""
    from ph_plant_sim.chemistry import COMPONENTS, COMPOUNDS

    total = 0.0
    for compound, mol_l in recipe.items():
        for comp, nu in COMPOUNDS.get(compound, {}).items():
            c = COMPONENTS.get(comp)
            if c is None:
                continue
            released = sum(1 for p in c.pka if p < 7.0)
            total += nu * mol_l * 1000.0 * (c.charge - released)
    return total


def start_from_model(model: str, ph_channel: str = PH_CHANNEL, correct: bool = True) -> EstimatorReference:
    """The estimator's feeds and first guesses from a plant model (preset name or .yaml): an overflow vessel."""
    from ph_plant_sim.build import load_plant_model

    spec = load_plant_model(model)
    if not spec.tank.overflow or spec.tank.volume_ml is None:
        raise UserError(f"--model {model}: the estimator reference models an overflow vessel (constant volume); "
                        f"this plant has an outlet valve")
    feeds = []
    for name, f in spec.feeds.items():
        s = feed_strength_mM(f.recipe)
        if s != 0.0:
            feeds.append(Feed(f"{name}_flow_ml_s", s))
    if not feeds:
        raise UserError(f"--model {model}: no feed carries strong acid or base")
    return EstimatorReference(tuple(feeds), ph_channel, float(spec.tank.volume_ml), correct=correct)


def read_runs(paths: Sequence[str | Path], channels: Sequence[str], column_map=None) -> list[MeasuredRecord]:
    return [read_measured(p, column_map, channels=list(channels)) for p in paths]


def fit_estimator(records: Sequence[MeasuredRecord], start: EstimatorReference,
                  settings: LearnedSettings | None = None, progress: Callable[[str], None] | None = None
                  ) -> LearnedModel:
    """Fit the estimator on healthy records; its bands and confirmation margins from each record held out
    (:func:`wavelet_fdi.estimator_calibration.calibrate_estimator`)."""
    if not records:
        raise UserError("the estimator needs at least one healthy run")
    runs = [(r.time_s - r.time_s[0], r.x) for r in records]
    dt = float(np.median(np.concatenate([np.diff(t) for t, _ in runs if len(t) > 1])))
    base = settings or LearnedSettings(**ESTIMATOR_SETTINGS)
    s = LearnedSettings(**{**base.__dict__, "sample_time_s": dt})
    return calibrate_estimator(runs, start, s, {"files": [r.path for r in records],
                                                "rows": int(sum(len(r.x) for r in records))}, progress=progress)
