"""Which fault explains an estimator alarm: one-parameter hypotheses refitted on the alarm's window.

After an alarm of the estimator reference (:mod:`wavelet_fdi.reference_estimator`) the filter is run again
over the window from the fault's estimated start to a little after its detection, from the state it had
there, once per hypothesis, each with one parameter fitted by the innovations' likelihood (bounded scalar
search). The start is the change time of the raw residual (:func:`change_index`, looked for from
``ONSET_LOOKBACK_SAMPLES`` before the alarm's onset to its detection), not the onset itself: that is the band
statistic's last zero seen through the causal filter bank, on a probe jump 2 to 3 s late, and a window
starting there has the filter's partial following of the jump in its state (a 1 pH offset was then named
a pump). An alarm of a noise statistic keeps its onset (a noise change moves no mean), as does one whose
residual has no change point in the lookback (:func:`change_index` gives None). The result carries the
start as ``start_time`` (in ``t_s``'s time). The hypotheses:

* ``probe_offset`` (sensor): the reading is off by b pH from the onset (a bias; locally also a drift or a
  slope error);
* ``probe_noise`` (sensor): the reading's noise is s times the healthy one (s > 1: a noisy probe; s < 1: a
  probe that froze or turned sluggish and lost its noise), fitted with the filter tracking as it runs (in the
  model-trusting window a frozen reading diverges from the model and would pass for noise);
* ``pump`` (actuator), one per feed that ran in the window: the feed delivers c times what is recorded
  (c < 1: less, c = 0: nothing; c > 1: more).

The hypothesis with the largest gain in log-likelihood over "healthy" (same window, same start, the fitted
parameter at its healthy value) names the family and the class; its parameter is the size estimate. The
strength adaptation is off inside the window (it would absorb an actuator hypothesis). This is generalised
likelihood-ratio isolation (Willsky & Jones 1976; Basseville & Nikiforov 1993, ch. 7) with a one-parameter
fault model per hypothesis.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.optimize import minimize_scalar

from .reference_estimator import EstimatorReference, EstimatorStream
from .statistics import parse_statistic

#: samples after the detection that the window keeps (when the record has them)
AFTER_DETECTION_SAMPLES = 64
#: how far before the detector's onset the change time is looked for (samples): the onset is the statistic's
#: last zero seen through the causal filter bank, up to its length (22 samples for sym4, level 2) after the change
ONSET_LOOKBACK_SAMPLES = 32
#: the change-time CUSUM's drift (sigma): half the shift it is designed for, 2 sigma (a smaller drift lets the
#: noise before the change build up and start the estimate early: 80 % within 2 samples of a 3 sigma shift at
#: 0.5, 97 % at 1)
CHANGE_DRIFT = 1.0
#: parameter ranges searched
OFFSET_RANGE_PH = (-4.0, 4.0)
NOISE_RANGE = (0.02, 20.0)  # searched on its logarithm
PUMP_RANGE = (0.0, 3.0)
STIFFNESS = 0.1
#: the detector's statistics that watch the reading's noise (wavelet_fdi.learned_detector)
NOISE_STATISTICS = ("energy", "energy_down", "repeats")


def _window_nll(start: EstimatorStream, ref: EstimatorReference, t: np.ndarray, rows: np.ndarray) -> float:
    stream = start.fork(ref)
    stream.residuals(t, rows)
    return stream.nll


def change_index(residual: np.ndarray, drift: float = CHANGE_DRIFT) -> int | None:
    """Where ``residual`` most likely began to depart from zero: the last zero before the peak of a one-sided
    CUSUM g_k = max(0, g_(k-1) + s r_k - drift), in the direction s (up or down) whose peak is larger (the
    CUSUM's change-time estimate: Page 1954; Basseville & Nikiforov 1993, sec. 2.2), moved on to the first
    sample from there that itself departs by more than 2 drift in that direction. It reads the raw residual,
    where a jump is one sample (a tracking filter's innovation: a spike, then a tail its gain shrinks), not a
    band seen through the filter bank's delay. Why the last step: the window is named by a filter that trusts
    its model, and one healthy sample taken for faulty moves its state for good (a 1 pH offset started one
    sample early was sized 1.27, from its first faulty sample 1.05, three samples late 1.05). None when the
    CUSUM never returns to zero before its peak: the residual departed before the window began, or crept away
    with no change point to place (a pump's slow mismatch). Missing values count as 0."""
    r = np.nan_to_num(np.asarray(residual, dtype=float))
    best = (0.0, 0, 0, 1.0)  # peak, its last zero, the peak's index, direction
    for sign in (1.0, -1.0):
        g, start = 0.0, 0
        for k, v in enumerate(r):
            g = max(0.0, g + sign * v - drift)
            if g == 0.0:
                start = k + 1
            elif g > best[0]:
                best = (g, start, k, sign)
    _, start, peak, sign = best
    if start == 0:
        return None
    while start < peak and sign * r[start] <= 2.0 * drift:
        start += 1
    return start


def isolate(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, onset_index: int,
            detection_index: int, statistic: str = "") -> dict:
    """Family, class and size of the fault behind an alarm (see the module docstring).

    ``rows``/``t_s``: the record from its start (the filter is re-run to the onset to get its state there).
    ``statistic``: the detector's statistic that raised the alarm. When it is an energy statistic of a detail
    band (the reading's noise changed), only the probe-noise hypothesis is fitted: a pump delivering other than
    recorded changes what the pH does, never how noisy its reading is.
    """
    n = len(rows)
    onset = max(1, min(int(onset_index), n - 1))
    det = min(n - 1, max(int(detection_index), onset))
    lo = max(1, onset - ONSET_LOOKBACK_SAMPLES)
    before = replace(ref, adapt_time_constant_s=0.0).new_state()
    before.residuals(t_s[:lo], rows[:lo])
    noise_alarm = bool(statistic) and parse_statistic(statistic)[2] in NOISE_STATISTICS
    # the window starts where the raw residual changed, not at the band statistic's onset (a noise change moves
    # no mean, and a residual with no change point in the lookback has none to place: the onset stays)
    k = None if noise_alarm else change_index(before.fork().residuals(t_s[lo:det + 1], rows[lo:det + 1])[:, 0])
    a = onset if k is None else lo + k
    b = min(n, det + AFTER_DETECTION_SAMPLES)
    start = before.fork()
    start.residuals(t_s[lo:a], rows[lo:a])
    # in the window the filter trusts its model (rate and walk uncertainty cut to STIFFNESS of the healthy
    # one): a deterministic fault then shows as the divergence it causes, not as corrections the filter makes
    quiet = replace(ref, adapt_time_constant_s=0.0,
                    noise=replace(ref.noise, rate_rel_std=ref.noise.rate_rel_std * STIFFNESS,
                                  walk_ph_per_sqrt_s=ref.noise.walk_ph_per_sqrt_s * STIFFNESS))
    tw, xw = t_s[a:b], np.array(rows[a:b], dtype=float)
    m = len(ref.feeds)
    healthy = _window_nll(start, quiet, tw, xw)

    def offset(bias: float) -> float:
        shifted = xw.copy()
        shifted[:, m] -= bias
        return _window_nll(start, quiet, tw, shifted)

    tracking = replace(ref, adapt_time_constant_s=0.0)  # the filter as it runs: a noise change is seen in it
    healthy_tracking = _window_nll(start, tracking, tw, xw)

    def noise(log_s: float) -> float:
        nz = replace(tracking.noise, probe_noise_ph=tracking.noise.probe_noise_ph * float(np.exp(log_s)))
        return _window_nll(start, replace(tracking, noise=nz), tw, xw) - healthy_tracking + healthy

    def pump(i: int):
        def cost(c: float) -> float:
            feeds = list(quiet.feeds)
            feeds[i] = replace(feeds[i], strength_mM=feeds[i].strength_mM * c)
            return _window_nll(start, replace(quiet, feeds=tuple(feeds)), tw, xw)
        return cost

    hyps: list[tuple[str, str, str, str, object, tuple[float, float], float]] = [
        ("probe_offset", "sensor", "probe offset", "pH", offset, OFFSET_RANGE_PH, 0.0),
        ("probe_noise", "sensor", "probe noise", "x healthy noise", noise, tuple(np.log(NOISE_RANGE)), 0.0)]
    if noise_alarm:
        hyps = hyps[1:]
    for i, f in enumerate(ref.feeds if not noise_alarm else ()):
        if np.nanmax(np.abs(xw[:, i])) > 0:
            hyps.append((f"pump:{f.channel}", "actuator", f"{f.channel} delivers other than recorded",
                         "x recorded", pump(i), PUMP_RANGE, 1.0))
    evidence = {}
    best = None
    for name, family, what, unit, cost, bounds, _ in hyps:
        res = minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-3})
        gain = healthy - float(res.fun)
        size = float(np.exp(res.x)) if name == "probe_noise" else float(res.x)
        evidence[name] = {"log_likelihood_gain": round(gain, 3), "size": round(size, 4), "unit": unit}
        if best is None or gain > best[0]:
            best = (gain, name, family, what, size, unit)
    assert best is not None
    gain, name, family, what, size, unit = best
    return {"family": family, "fault_class": name, "description": what, "size": round(size, 4), "unit": unit,
            "log_likelihood_gain": round(gain, 3), "window": [int(a), int(b)], "start_time": float(t_s[a]),
            "evidence": evidence}
