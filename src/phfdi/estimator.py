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

from typing import Callable, Sequence

import numpy as np

from phfdi.records import Record
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
                      "repeat_probability": 0.9,
                      # a probe that steps where the filter's state is uncertain (a strong acid's plateau) is followed
                      # within a sample and shows as one innovation the band statistics see limited to clip_sigma: the
                      # spike test at the level held-out innovations pass once in a million samples (about 4 days of
                      # the rig's 0.35 s sampling), measured on the calibration's leave-one-run-out residuals
                      "spike_per_sample": 1e-6,
                      # a probe that drifts against the only feed that runs (up while acid alone runs): a reading
                      # that a one-reagent vessel cannot give, whatever its model (wavelet_fdi.feed_checks), at the
                      # spike test's rate per sample
                      "against_feed_per_sample": 1e-6}


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


#: a reading outside this range is not a pH (a probe's range: 0 to 14)
PH_RANGE = (0.0, 14.0)
#: the least pH range over all runs that lets the fit see the curve (a constant reading identifies nothing)
MIN_PH_SPAN = 0.1


def check_excitation(records: Sequence[Record], start: EstimatorReference) -> None:
    """Refuse runs the estimator cannot be identified from, naming what is missing: a reading outside 0-14 pH, a
    feed that never runs in any run (its strength), a pH that never moves (the curve and the volume)."""
    m = len(start.feeds)
    for r in records:
        ph = r.x[:, m]
        bad = np.flatnonzero(np.isfinite(ph) & ((ph < PH_RANGE[0]) | (ph > PH_RANGE[1])))
        if len(bad):
            i = int(bad[0])
            raise UserError(f"{r.path}: {r.where} {r.lines[i]}: pH {ph[i]:g} is outside 0-14 ({len(bad)} such rows): "
                            f"not a pH reading (a wrong column or unit?)")
    for i, feed in enumerate(start.feeds):
        if not any(np.nanmax(np.abs(np.nan_to_num(r.x[:, i]))) > 0 for r in records):
            raise UserError(f"feed {feed.channel}: it never runs in the calibration runs, so its strength cannot be "
                            f"fitted (it would end at a bound); give at least one healthy run in which it runs")
    spans = [float(np.nanmax(r.x[:, m]) - np.nanmin(r.x[:, m])) for r in records if np.isfinite(r.x[:, m]).any()]
    if not spans or max(spans) < MIN_PH_SPAN:
        raise UserError(f"the pH moves by less than {MIN_PH_SPAN} pH in every calibration run: the volume and the "
                        f"strengths cannot be fitted from it; give healthy runs in which the pumps move the pH")


def identifiability_notes(ref: EstimatorReference) -> list[str]:
    """The fitted values that ended at a bound of the fit: not identified by these runs (said, not refused: a noise
    term at a bound is the model saying that term is not needed)."""
    from wavelet_fdi.estimator_fit import NOISE_BOUNDS, STRENGTH_BOUNDS_MM, VOLUME_BOUNDS_ML

    notes = []

    def at_bound(v: float, lo: float, hi: float) -> str | None:
        return "lower" if v <= lo * 1.02 else "upper" if v >= hi / 1.02 else None

    for f in ref.feeds:
        side = at_bound(abs(f.strength_mM), *STRENGTH_BOUNDS_MM)
        if side:
            notes.append(f"{f.channel} strength {f.strength_mM:g} mM is at the fit's {side} bound: not identified by "
                         f"these runs (does the feed change the pH in them?)")
    side = at_bound(ref.volume_ml, *VOLUME_BOUNDS_ML)
    if side:
        notes.append(f"volume {ref.volume_ml:g} mL is at the fit's {side} bound: not identified by these runs")
    for k, (lo, hi) in NOISE_BOUNDS.items():
        side = at_bound(getattr(ref.noise, k), lo, hi)
        if side:
            notes.append(f"noise term {k} = {getattr(ref.noise, k):g} is at the fit's {side} bound (the runs do "
                         f"not need {'it' if side == 'lower' else 'less of it'})")
    return notes


def fit_estimator(records: Sequence[Record], start: EstimatorReference,
                  settings: LearnedSettings | None = None, progress: Callable[[str], None] | None = None
                  ) -> LearnedModel:
    """Fit the estimator on healthy records; its bands and confirmation margins from each record held out
    (:func:`wavelet_fdi.estimator_calibration.calibrate_estimator`)."""
    if not records:
        raise UserError("the estimator needs at least one healthy run")
    check_excitation(records, start)
    runs = [(r.time_s - r.time_s[0], r.x) for r in records]
    dt = float(np.median(np.concatenate([np.diff(t) for t, _ in runs if len(t) > 1])))
    base = settings or LearnedSettings(**ESTIMATOR_SETTINGS)
    s = LearnedSettings(**{**base.__dict__, "sample_time_s": dt})
    return calibrate_estimator(runs, start, s, {"files": [r.path for r in records],
                                                "rows": int(sum(len(r.x) for r in records))}, progress=progress,
                               check_fit=refuse_unidentified)


def refuse_unidentified(ref: EstimatorReference) -> None:
    """Refuse a fit whose strength or volume ended at a bound of the fit (:func:`identifiability_notes`): those
    runs did not identify it, and a reference built on it would extrapolate from a guess."""
    hard = [n for n in identifiability_notes(ref) if not n.startswith("noise term")]
    if hard:
        raise UserError(f"not written: {hard[0]}" + (f" (and {len(hard) - 1} more)" if len(hard) > 1 else ""))
