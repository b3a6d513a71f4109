"""Fitting the estimator reference on healthy runs: the prediction-error method (maximum likelihood of the
innovations; Ljung 1999, ch. 7), derivative-free (Powell, bounded) on logarithms of the parameters.

Why derivative-free: the likelihood runs through a tabulated titration curve and block-wise adaptation, so
it is continuous but not smooth; Powell's line searches need no gradient and respect the bounds.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np
from scipy.optimize import minimize

from phfdi_base.errors import UserError

from .reference_estimator import EstimatorReference

#: bounds of the fitted values (physical sense, wide: the rig's fits land well inside)
STRENGTH_BOUNDS_MM = (0.05, 1000.0)
VOLUME_BOUNDS_ML = (100.0, 50000.0)
NOISE_BOUNDS = {"probe_noise_ph": (0.002, 0.5), "rate_rel_std": (0.01, 5.0), "walk_ph_per_sqrt_s": (1e-5, 0.5),
                "timing_s": (0.01, 30.0)}
NOISE_KEYS = tuple(NOISE_BOUNDS)


def _unpack(start: EstimatorReference, theta: np.ndarray) -> EstimatorReference:
    m = len(start.feeds)
    v = np.exp(theta)
    feeds = tuple(replace(f, strength_mM=math.copysign(float(v[i]), f.strength_mM)) for i, f in enumerate(start.feeds))
    noise = replace(start.noise, **{k: float(v[m + 1 + i]) for i, k in enumerate(NOISE_KEYS)})
    return replace(start, feeds=feeds, volume_ml=float(v[m]), noise=noise)


def _pack(start: EstimatorReference) -> tuple[np.ndarray, list[tuple[float, float]]]:
    vals = [abs(f.strength_mM) for f in start.feeds] + [start.volume_ml]
    bounds = [STRENGTH_BOUNDS_MM] * len(start.feeds) + [VOLUME_BOUNDS_ML]
    for k in NOISE_KEYS:
        vals.append(getattr(start.noise, k))
        bounds.append(NOISE_BOUNDS[k])
    lo = np.log([b[0] for b in bounds])
    hi = np.log([b[1] for b in bounds])
    theta = np.clip(np.log(vals), lo, hi)
    return theta, list(zip(lo, hi))


def negative_log_likelihood(ref: EstimatorReference, runs: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
    total = 0.0
    for t, rows in runs:
        stream = ref.new_state()
        stream.residuals(t, rows)
        total += stream.nll
    return total


def fit_reference(runs: Sequence[tuple[np.ndarray, np.ndarray]], start: EstimatorReference,
                  max_evaluations: int = 300) -> EstimatorReference:
    """Strengths, volume and noise model that maximise the innovations' likelihood on healthy runs.

    ``runs``: (time_s, rows) per run, rows in ``start.channels`` order. ``start`` gives the feeds'
    channels and signs, the first guesses and the adaptation settings.
    """
    if not runs or sum(len(t) for t, _ in runs) < 50:
        raise UserError("fitting the estimator needs healthy runs with at least 50 samples in all")
    theta0, bounds = _pack(start)

    def cost(theta: np.ndarray) -> float:
        try:
            value = negative_log_likelihood(_unpack(start, theta), runs)
        except (UserError, FloatingPointError, ValueError, ZeroDivisionError, OverflowError):
            return 1e300
        return value if math.isfinite(value) else 1e300

    res = minimize(cost, theta0, method="Powell", bounds=bounds,
                   options={"maxfev": int(max_evaluations), "xtol": 1e-3, "ftol": 1e-6})
    fitted = _unpack(start, res.x)
    n = sum(len(t) for t, _ in runs)
    info = {"runs": len(runs), "samples": int(n), "nll_per_sample": float(res.fun) / n,
            "evaluations": int(res.nfev), "method": "maximum likelihood of the innovations (Powell, bounded)",
            # the signs the plant model gave (acid -, base +): a file whose strengths disagree is refused on load
            "strength_signs": [1 if f.strength_mM > 0 else -1 for f in start.feeds]}
    return replace(fitted, fit_info=info)
