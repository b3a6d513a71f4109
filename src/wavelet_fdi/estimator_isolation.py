"""Which fault explains an estimator alarm, and whether one does: hypotheses refitted on the alarm's window.

After an alarm of the estimator reference (:mod:`wavelet_fdi.reference_estimator`) the filter is run again
over the window from the fault's estimated start to a little after its detection, from the state it had
there, once per hypothesis, each with one parameter fitted by the innovations' likelihood (bounded scalar
search). The start is the change time of the raw residual (:func:`change_index`, looked for from
``ONSET_LOOKBACK_SAMPLES`` before the alarm's onset to its detection), not the onset itself: that is the band
statistic's last zero seen through the causal filter bank, on a probe jump 2 to 3 s late, and a window
starting there has the filter's partial following of the jump in its state (a 1 pH offset was then named
a pump). An alarm of a noise statistic keeps its onset (a noise change moves no mean), as does one whose
residual has no change point in the lookback (:func:`change_index` gives None). The result carries the
start as ``start_time`` (in ``t_s``'s time).

Fault hypotheses (sensor):

* ``probe_bias``: the reading is off by b pH from the start (a bias; locally also a slope error);
* ``probe_drift``: the reading walks off at r pH/min from the start;
* ``probe_noise``: the reading's noise is s times the healthy one (s > 1: a noisy probe; s < 1: a probe that
  froze or turned sluggish and lost its noise), fitted with the filter tracking as it runs (in the
  model-trusting window a frozen reading diverges from the model and would pass for noise).

Healthy, re-adapted (what the plant does where the calibration never went):

* ``pump:<channel>``, one per feed that ran in the window: the feed's apparent strength is c times the
  calibrated one (a pump setting, batch or pH passage the calibration did not see; or a pump delivering other
  than recorded: on a rig whose flows are the pump commands the two cannot be told apart, docs/detector.md);
* the run's own noise, pump state by pump state: the innovations' scale before the window whatever the
  calibration's was, and a still flask (no feed running) whose reading goes quiet.

Offset, drift and the pumps are fitted in the model-trusting window (the filter's rate and walk
uncertainty cut to ``STIFFNESS``), where a deterministic fault shows as the divergence it causes. An offset's
or a drift's gain (what decides) maps the probe's noise into the curve where it was read, as healthy and the
pumps do; its size is the hypothesis's own maximum-likelihood estimate, the noise mapped where the hypothesis
puts the pH.

**Confirmation** (``EstimatorReference.confirm``, written by ``phfdi calibrate --estimator``). A fault alarm
means a fault. An alarm is confirmed when all of these hold:

1. ``change`` (:func:`change_statistic`): the filter's standardised innovations in the window changed scale
   against the run's own stretch before it (up to ``NOISE_BEFORE_SAMPLES``), pump state by pump state (each state
   its own variance; a state is the pumps' flows now and over the last ``SETTLE_S``), by a profile likelihood ratio
   beyond a calibrated margin. The innovations are normalised by the filter's own predicted variance, which grows
   where the pumps move the pH fast or the curve is steep, and the run is compared with itself in the same pump
   state, so neither a day noisier than the calibration's nor the pumps' stroke ripple reads as a change; a probe
   that jumps, drifts, freezes, lags or turns noisy does change it; or, for a probe bias only, ``jump``
   (:func:`jump_statistic`): the same test, one-sided, on the window's first ``JUMP_SAMPLES`` innovations, where a
   probe that jumped puts its evidence before the filter follows it (and before a controller acting on the
   reading moves the pH back), where the reading itself stepped once, by at least ``STEP_SHARE`` of the offset
   named (:func:`_reading_stepped`);
2. the sensor hypothesis that fits best beats every healthy re-adaptation (a feed's strength) in the likelihood
   of the window, and gains more over healthy than a one-parameter fit of a well-specified model
   gains by chance with the probability each test has (half the chi-square(1) quantile);
3. a probe that lost its noise is not confirmed while no feed runs (a still flask reads quiet too).

**Looks.** A deviation is first judged ``AFTER_DETECTION_SAMPLES`` (64) after its detection. One that no fault
explained then and that is still up is looked at again, its window kept longer after the detection (from the same
start): 128, 256 and 512 samples (:data:`LOOK_AFTER_SAMPLES`), each time all three conditions above with the
change over the longer window as ``change@N`` against its own margin. Why: the change's evidence from a fault
grows with the samples it has been in the window, and a fault that starts small (a drift) or a noise change
against a short stretch of the run in the same pump state had not yet passed the first margin (a probe turning
noisy on the closed-loop rig run: change 76.7 at the first look, 163 at the second). A look that confirms
makes the deviation a fault alarm; the WARN before it stays in the log.

Each margin (change, jump, change@128, change@256, change@512) is the value healthy operation exceeds with
probability ``alpha`` / 5 (:data:`DEFAULT_ALPHA`, 1e-3 per deviation, split equally among the five tests a
deviation can pass: Bonferroni): each statistic is sampled on leave-one-run-out residuals of the calibration runs
(each run by the reference fitted on the others) at every block, in the windows both kinds of alarm have (a later
look's where the run goes on that long), and its tail beyond the 90th percentile taken as exponential
(:func:`confirmation_thresholds`). An alarm not confirmed is a deviation no fault explains: the detector reports
it as "outside calibration" (WARN), never as a fault, with its best healthy explanation.

Tried and not kept (2026-12-05, docs/detector.md): the offset and drift likelihood ratios over the pumps' as
confirmation statistics with margins from the same held-out null (their null depends on the operation: its 99th
percentile 4 to 900 from one three-run calibration to another, and calibrated without the closed loop the closed
loop's pump starts confirmed as probe offsets); the same with the filter tracking (the same spread); a regression
t statistic of the offset (its null has single-sample outliers at the knees); the probe-noise scale's two-sample
ratio without pump states (on simulated on/off control the stroke ripple starting and stopping confirmed faults).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from .calibration import excess_tail_threshold
from .feed_checks import SETTLE_S, WINDOW_SAMPLES, feed_codes, reading_rate_ph_per_min
from .reference_estimator import FACTOR_BOUNDS, EstimatorReference, EstimatorStream
from .statistics import parse_statistic

#: samples after the detection that the window keeps (when the record has them)
AFTER_DETECTION_SAMPLES = 64
#: the looks at a deviation that no fault explained yet and that is still up: the window then keeps this many
#: samples after the detection, each look twice the last (the change statistic's evidence grows with the samples a
#: fault has been in the window, a healthy window's only as far as the model parts from the plant); the first is
#: AFTER_DETECTION_SAMPLES. Each look is one more test the design probability is split among (Bonferroni), and
#: four looks end about three minutes after a detection on the rig
LOOK_AFTER_SAMPLES = (AFTER_DETECTION_SAMPLES, 128, 256, 512)
#: how far before the detector's onset the change time is looked for (samples): the onset is the statistic's
#: last zero seen through the causal filter bank, up to its length (22 samples for sym4, level 2) after the change
ONSET_LOOKBACK_SAMPLES = 32
#: the change-time CUSUM's drift (sigma): half the shift it is designed for, 2 sigma (a smaller drift lets the
#: noise before the change build up and start the estimate early: 80 % within 2 samples of a 3 sigma shift at
#: 0.5, 97 % at 1)
CHANGE_DRIFT = 1.0
#: parameter ranges searched
OFFSET_RANGE_PH = (-4.0, 4.0)
DRIFT_RANGE_PH_PER_MIN = (-5.0, 5.0)
NOISE_RANGE = (0.02, 20.0)  # searched on its logarithm
#: a feed's apparent strength: up to what the adaptation itself may reach, or nothing delivered
PUMP_RANGE = (0.0, FACTOR_BOUNDS[1])
STIFFNESS = 0.1
#: the detector's statistics that watch the reading's noise (wavelet_fdi.learned_detector)
NOISE_STATISTICS = ("energy", "energy_down", "repeats")
#: the statistics whose onset is the change itself: the spike test's is the one innovation beyond its level (where
#: a probe stepped), so the window starts there instead of at a change time looked for before it (a healthy
#: sample above 2 sigma 24 samples before a 1 pH step started the window there, and the jump then lay outside its
#: head); the noise statistics' keep theirs too (a noise change moves no mean)
ONSET_STATISTICS = ("spike", "against_feed", *NOISE_STATISTICS)
#: a feed check's crossing (wavelet_fdi.feed_checks): a reading that moved against the only feed that ran, a test of
#: its own at its own stated rate; what it is evidence for (an error of the reading that moves it one way)
AGAINST_FEED = "against_feed"
AGAINST_FEED_CLASSES = ("probe_bias", "probe_drift")
#: the run's stretch before the window that the two-sample noise test compares with (samples), and the least
#: that makes a comparison (below it: the healthy runs' band of noise scales)
NOISE_BEFORE_SAMPLES = 1024
NOISE_BEFORE_MIN_SAMPLES = 32
#: the least samples of one pump state before the window that the change test compares that state's window
#: samples with
STATE_MIN_SAMPLES = 16
#: the confirmation's statistics (module doc); the design probability is split equally among them (Bonferroni):
#: at the first look the change and the jump, at each later look the change over the longer window
#: (``change@N``, N samples after the detection: :data:`LOOK_AFTER_SAMPLES`)
CONFIRM_STATISTICS = ("change", "jump", *(f"change@{n}" for n in LOOK_AFTER_SAMPLES[1:]))
#: the fault hypotheses each confirmation statistic is evidence for: a scale change over the window is made by
#: every probe fault; large innovations at its start only by one that jumped (a drift starts small, a frozen or
#: noisy probe changes the whole window)
CONFIRMS = {"change": ("probe_bias", "probe_drift", "probe_noise"), "jump": ("probe_bias",),
            **{f"change@{n}": ("probe_bias", "probe_drift", "probe_noise") for n in LOOK_AFTER_SAMPLES[1:]}}
#: the jump confirms an offset only where the reading stepped once at the window's start: by at least this share of
#: the offset named, and no other step of it as large as this share of that step
STEP_SHARE = 0.5
#: the innovations at the window's start that the jump statistic reads (samples): chosen before any run was scored
#: with it, as the head of a window whose change time is placed within 2 samples of a jump (change_index)
JUMP_SAMPLES = 8
#: the median of a chi-square with one degree of freedom: a Gaussian's square over its variance
CHI2_1_MEDIAN = 0.454936
#: the sensor fault hypotheses (what a confirmed alarm is named by)
SENSOR_CLASSES = ("probe_bias", "probe_drift", "probe_noise")
#: the design: the probability that the confirmation takes a healthy deviation for a fault
DEFAULT_ALPHA = 1e-3
#: where the null is sampled: a pretended detection at every block boundary of each held-out run after its
#: fourth, with the onsets a mean statistic's and a noise statistic's alarm have before their detection (samples)
NULL_EVERY_BLOCKS = 1
NULL_ONSET_LAGS = {"mean": (8, 24), "noise": (24, 48)}


def _window_nll(start: EstimatorStream, ref: EstimatorReference, t: np.ndarray, rows: np.ndarray,
                noise_at_ph: np.ndarray | None = None) -> float:
    stream = start.fork(ref)
    stream.residuals(t, rows, noise_at_ph)
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


@dataclass
class _Window:
    """The rows an alarm is judged on and the filter's states around them."""

    a: int  # the fault's estimated start (first row of the window)
    b: int  # one past the window's last row
    start: EstimatorStream  # the non-adapting filter at a
    before: EstimatorStream  # the non-adapting filter at the start of the stretch before the window
    pre: int  # that stretch's first row (it ends where the change-time search began)
    lo: int


def _window(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, onset_index: int, detection_index: int,
            keep_onset: bool, after: int = AFTER_DETECTION_SAMPLES) -> _Window:
    n = len(rows)
    onset = max(1, min(int(onset_index), n - 1))
    det = min(n - 1, max(int(detection_index), onset))
    lo = max(1, onset - ONSET_LOOKBACK_SAMPLES)
    pre = max(1, lo - NOISE_BEFORE_SAMPLES)
    # the filter as the detector runs it (strengths adapted to this run) up to the stretch before the window; from
    # there on nothing adapts (an actuator hypothesis would be absorbed)
    run = ref.new_state()
    run.residuals(t_s[:pre], rows[:pre])
    run = run.fork(replace(ref, adapt_time_constant_s=0.0))
    before = run.fork()
    run.residuals(t_s[pre:lo], rows[pre:lo])
    # the window starts where the raw residual changed, not at the band statistic's onset (a noise change moves
    # no mean, and a residual with no change point in the lookback has none to place: the onset stays)
    k = None if keep_onset else change_index(run.fork().residuals(t_s[lo:det + 1], rows[lo:det + 1])[:, 0])
    a = onset if k is None else lo + k
    run.residuals(t_s[lo:a], rows[lo:a])
    return _Window(a, min(n, det + after), run, before, pre, lo)


def _fit(cost, bounds: tuple[float, float]) -> tuple[float, float]:
    from scipy.optimize import minimize_scalar  # here: half a second of import a node's start would pay

    res = minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-3})
    return float(res.fun), float(res.x)


def _with_noise(ref: EstimatorReference, scale: float) -> EstimatorReference:
    return replace(ref, noise=replace(ref.noise, probe_noise_ph=ref.noise.probe_noise_ph * scale))


def _hypotheses(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, w: _Window,
                noise_only: bool = False) -> dict:
    """Every hypothesis's gain in log-likelihood over healthy and its fitted size, and the two-sample noise
    statistic (``noise_vs_run``): {name: (gain, size)}."""
    m = len(ref.feeds)
    tw, xw = t_s[w.a:w.b], np.array(rows[w.a:w.b], dtype=float)
    # in the window the filter trusts its model (rate and walk uncertainty cut to STIFFNESS of the healthy
    # one): a deterministic fault then shows as the divergence it causes, not as corrections the filter makes
    quiet = replace(ref, adapt_time_constant_s=0.0,
                    noise=replace(ref.noise, rate_rel_std=ref.noise.rate_rel_std * STIFFNESS,
                                  walk_ph_per_sqrt_s=ref.noise.walk_ph_per_sqrt_s * STIFFNESS))
    tracking = replace(ref, adapt_time_constant_s=0.0)  # the filter as it runs: a noise change is seen in it
    out: dict[str, tuple[float, float]] = {}
    mean_ref = quiet
    read_ph = xw[:, m].copy()
    healthy = _window_nll(w.start, mean_ref, tw, xw)
    healthy_tracking = _window_nll(w.start, tracking, tw, xw)
    log_range = tuple(np.log(NOISE_RANGE))

    def noise_cost(log_s: float) -> float:
        return _window_nll(w.start, _with_noise(tracking, math.exp(log_s)), tw, xw)

    f, x = _fit(noise_cost, log_range)  # type: ignore[arg-type]
    out["probe_noise"] = (healthy_tracking - f, math.exp(x))
    seen = _innovations_by_state(tracking, t_s, rows, w)  # once for both statistics (the null samples thousands)
    out["noise_vs_run"] = (change_statistic(tracking, t_s, rows, w, seen), 0.0)
    out["jump_vs_run"] = (jump_statistic(tracking, t_s, rows, w, seen), 0.0)
    out["compared_vs_run"] = (float(_compared_samples(seen, w)), 0.0)
    if noise_only:
        return out
    elapsed_min = (tw - tw[0]) / 60.0

    def shifted(shift: np.ndarray | float, noise_where_read: bool = True) -> float:
        moved = xw.copy()
        moved[:, m] -= shift
        return _window_nll(w.start, mean_ref, tw, moved, read_ph if noise_where_read else None)

    for name, per_size in (("probe_bias", lambda b: b), ("probe_drift", lambda r: r * elapsed_min)):
        bounds = OFFSET_RANGE_PH if name == "probe_bias" else DRIFT_RANGE_PH_PER_MIN
        # the gain that decides: the probe's noise mapped into the curve where it was read, as for healthy and
        # the pumps (a shift of the curve's buffer capacity must not pass for evidence)
        f, _ = _fit(lambda v: shifted(per_size(v)), bounds)
        # the size: the hypothesis's own maximum likelihood, the noise mapped where the reading minus the probe's
        # error puts the pH (with the noise kept where read, a 1 pH offset hidden at pH 3 was sized 0.61; so 0.95)
        _, x = _fit(lambda v: shifted(per_size(v), noise_where_read=False), bounds)
        out[name] = (healthy - f, x)
    for i, feed in enumerate(ref.feeds):
        if np.nanmax(np.abs(xw[:, i])) > 0:
            def pump(c: float, i: int = i) -> float:
                feeds = list(mean_ref.feeds)
                feeds[i] = replace(feeds[i], strength_mM=feeds[i].strength_mM * c)
                return _window_nll(w.start, replace(mean_ref, feeds=tuple(feeds)), tw, xw)
            f, x = _fit(pump, PUMP_RANGE)
            out[f"pump:{feed.channel}"] = (healthy - f, x)
    return out


def _octaves(q: np.ndarray) -> np.ndarray:
    """Per value: 0 for off, else the octave of the flow above 0.25 mL/s (1..15)."""
    return np.where(q > 1e-6, np.clip(np.floor(np.log2(np.maximum(q, 1e-9) / 0.25)) + 1, 1, 15), 0).astype(int)


def pump_states(t_s: np.ndarray, flows: np.ndarray) -> np.ndarray:
    """Each row's pump state, one integer: per feed the octave its flow is in now (0: off) and the octave of its
    mean flow over the last ``SETTLE_S``. The pumps' stroke ripple (noise the model does not know) grows with a
    pump's setting and stops with it, and the mixing after a pump switched takes a while: a run is compared with
    itself only where it runs alike, now and over the last half minute (a chattering pump is a state of its own,
    the half minute after a start one of its own)."""
    t = np.asarray(t_s, dtype=float)
    q = np.nan_to_num(np.asarray(flows, dtype=float))
    dt = np.diff(t, prepend=t[0] if len(t) else 0.0)
    area = np.cumsum(q * dt[:, None], axis=0)  # delivered volume so far, per feed
    start = np.searchsorted(t, t - SETTLE_S, side="left")
    span = np.maximum(t - t[start], 1e-9)
    mean = (area - area[start]) / span[:, None]
    code = _octaves(q) + 16 * _octaves(mean)
    return (code * (256 ** np.arange(q.shape[1]))).sum(axis=1)


def _innovations_by_state(tracking: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, w: _Window
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """From the stretch before the window to its end: the filter's standardised innovations (tracking, nothing
    adapting, no limit), the reading's second difference, each row's pump state (:func:`pump_states`) and its
    record index."""
    m = len(tracking.feeds)
    raw = replace(tracking, clip_sigma=0.0)
    stream = w.before.fork(raw)
    r = stream.residuals(t_s[w.pre:w.b], rows[w.pre:w.b])[:, 0]
    lead = max(0, w.pre - int(4 * SETTLE_S / max(float(np.median(np.diff(t_s[w.pre:w.b]))), 1e-3)))
    states = pump_states(t_s[lead:w.b], np.asarray(rows[lead:w.b], dtype=float)[:, :m])[w.pre - lead:]
    # the reading's own second difference: what a probe that froze or turned sluggish loses, a still or slowly
    # curving pH does not (the innovations stay near their scale then: the filter follows the reading)
    ph = np.asarray(rows[w.pre:w.b], dtype=float)[:, m]
    d2 = np.full(len(ph), np.nan)
    d2[2:] = ph[2:] - 2.0 * ph[1:-1] + ph[:-2]
    return r, d2, states, np.arange(w.pre, w.b)


def change_statistic(tracking: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, w: _Window,
                     seen: tuple | None = None) -> float:
    """How far the window's innovations changed scale against the run's own stretch before it, pump state by pump
    state (:func:`pump_states`): the profile likelihood ratio of one factor s on the window's variance, each pump
    state keeping a variance of its own (estimated on both stretches), from the filter's standardised innovations
    (tracking, nothing adapting, no limit: they are normalised by the filter's own predicted variance), and the
    same on the reading's second difference; the larger. A window sample whose pump state the stretch before did
    not show at least ``STATE_MIN_SAMPLES`` times says nothing (its state's noise is unknown to the run); none
    left: 0. With the filter's gate set (``gate_sigma``), no single sample counts for more than one at the gate.
    ``seen``: :func:`_innovations_by_state` of this window, when already computed."""
    r, d2, states, k = seen or _innovations_by_state(tracking, t_s, rows, w)
    before, window = k < w.lo, k >= w.a
    r2, d2sq = r ** 2, d2 ** 2
    gate = float(tracking.gate_sigma)
    if gate > 0:
        # no single sample counts for more than one at the spike level does (the filter's gate: the level a healthy
        # innovation passes once in spike_per_sample): a lone glitch of 1 pH made a scale change of 94-113 on its
        # own, beyond the margin, and was named a noisy probe. The reading's second difference is capped at the same
        # multiple of its robust scale before the window (the median of a chi-square(1) is 0.455). The margins
        # were measured without the cap: the capped statistic is never larger, so their probability still bounds
        r2 = np.minimum(r2, gate * gate)
        ok = before & np.isfinite(d2sq)
        if ok.any():
            d2sq = np.minimum(d2sq, gate * gate * float(np.median(d2sq[ok])) / CHI2_1_MEDIAN)
    return max(_scale_change(r2, before, window, states), _scale_change(d2sq, before, window, states))


def _compared_samples(seen: tuple, w: _Window) -> int:
    """The window's samples the change statistic compares with the run's own past: those in a pump state the
    stretch before showed at least ``STATE_MIN_SAMPLES`` times."""
    r, _, states, k = seen
    before, window = (k < w.lo) & np.isfinite(r), (k >= w.a) & np.isfinite(r)
    known, counts = np.unique(states[before], return_counts=True)
    return int(np.isin(states[window], known[counts >= STATE_MIN_SAMPLES]).sum())


def jump_statistic(tracking: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, w: _Window,
                   seen: tuple | None = None) -> float:
    """The same scale change as :func:`change_statistic`, on the innovations of the window's first
    ``JUMP_SAMPLES`` only (from the change time): where an abrupt fault (a probe that jumped) puts its evidence
    before the tracking filter follows it. Over the whole window those few large innovations are diluted among
    the ones after them; a controller that moves the pH back after a biased reading hides the rest (on the
    closed-loop rig run a 0.4 pH bias gave a change of 21.9 against a margin of 86.2)."""
    r, _, states, k = seen or _innovations_by_state(tracking, t_s, rows, w)
    before, head = k < w.lo, (k >= w.a) & (k < w.a + JUMP_SAMPLES)
    # one-sided: a jump is large innovations; a few quiet ones are what any pause of the pumps gives (a probe that
    # froze is the whole window's change)
    return _scale_change(r ** 2, before, head, states, upward=True)


def _scale_change(square: np.ndarray, before: np.ndarray, window: np.ndarray, states: np.ndarray,
                  upward: bool = False) -> float:
    """The profile likelihood ratio of one factor s^2 on the window's mean square (Gaussian values), each pump
    state with a variance of its own estimated from both stretches; states with fewer than
    ``STATE_MIN_SAMPLES`` usable samples before the window are left out (none left: 0). ``upward``: s^2 >= 1 only
    (one-sided: a rise in scale)."""
    ok = np.isfinite(square)
    before, window = before & ok, window & ok
    sums = []
    for st in np.unique(states[window]):
        b_st, w_st = before & (states == st), window & (states == st)
        nb, nw = int(b_st.sum()), int(w_st.sum())
        if nb >= STATE_MIN_SAMPLES and nw:
            sums.append((nb, float(square[b_st].sum()), nw, float(square[w_st].sum())))
    if not sums:
        return 0.0
    n_b, s_b, n_w, s_w = (np.array(v, dtype=float) for v in zip(*sums))
    floor = 1e-12 * max(float(np.sum(s_b + s_w)), 1e-300)  # an exactly frozen window: a ratio, not a log of 0

    def profile(log_s2: float) -> float:  # minus the log-likelihood, each state's variance profiled out
        s2 = math.exp(log_s2)
        var = (s_b + s_w / s2) / (n_b + n_w)
        return float(0.5 * np.sum((n_b + n_w) * np.log(np.maximum(var, floor)) + n_w * log_s2))

    from scipy.optimize import minimize_scalar

    res = minimize_scalar(profile, bounds=(0.0 if upward else math.log(1e-4), math.log(1e4)), method="bounded",
                          options={"xatol": 1e-4})
    return max(0.0, profile(0.0) - float(res.fun))


def confirmation_statistics(evidence: dict, after: int = AFTER_DETECTION_SAMPLES) -> dict[str, float]:
    """The confirmation's statistics (module doc) from a window's hypotheses: at the first look ``change`` and
    ``jump``; at a later one (``after`` samples after the detection) the change over that window, ``change@after``
    (the jump reads the window's first samples, which a later look does not change)."""
    if after == AFTER_DETECTION_SAMPLES:
        return {"change": evidence["noise_vs_run"][0], "jump": evidence["jump_vs_run"][0]}
    return {f"change@{after}": evidence["noise_vs_run"][0]}


def look_schedule(confirm: dict | None) -> tuple[int, ...]:
    """The looks (samples after a detection) a calibration has margins for: the first always, a later one where
    its ``change@N`` margin was calibrated (files written before 2026-12-06 have none: one look)."""
    margins = (confirm or {}).get("thresholds") or {}
    return (AFTER_DETECTION_SAMPLES, *(n for n in LOOK_AFTER_SAMPLES[1:] if f"change@{n}" in margins))


def isolate(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, onset_index: int,
            detection_index: int, statistic: str = "", after: int = AFTER_DETECTION_SAMPLES) -> dict:
    """Family, class and size of the fault behind an alarm, and whether one explains it (module docstring).

    ``rows``/``t_s``: the record from its start (the filter is re-run to the onset to get its state there).
    ``statistic``: the detector's statistic that raised the alarm. When it is a statistic of the reading's
    noise, only the noise hypothesis is fitted: a pump delivering other than recorded changes what the pH does,
    never how noisy its reading is.

    ``after``: the look, the samples after the detection the window keeps (:data:`LOOK_AFTER_SAMPLES`; the
    window's start is found as at the first look, from the rows up to the detection).

    Returns ``confirmed`` (True when the reference has no confirmation margins: every alarm is named as before)
    and, with margins, ``confirmation``: each statistic, its margin and which confirmed. An alarm not confirmed
    is named by the healthy explanation that fits best: a feed's apparent strength (``pump:<channel>``, "outside
    calibration") or none (``unexplained``).
    """
    kind = parse_statistic(statistic)[2] if statistic else ""
    noise_alarm = kind in NOISE_STATISTICS
    w = _window(ref, t_s, rows, onset_index, detection_index, kind in ONSET_STATISTICS, after)
    conf = dict(ref.confirm or {})
    ev = _hypotheses(ref, t_s, rows, w, noise_only=noise_alarm)
    evidence = {name: {"log_likelihood_gain": round(g, 3), "size": round(x, 4), "unit": _unit(name)}
                for name, (g, x) in ev.items() if not name.endswith("_vs_run")}
    result = {"window": [int(w.a), int(w.b)], "start_time": float(t_s[w.a]), "evidence": evidence}
    named = _best(ev, [k for k in ev if k in SENSOR_CLASSES or k.startswith("pump:")])
    if not conf.get("thresholds"):
        return {**result, **_naming(named, ev), "confirmed": True}
    stats = confirmation_statistics(ev, after)
    margins = conf["thresholds"]
    ratios = {k: v / margins[k] for k, v in stats.items() if margins.get(k, 0) > 0}
    sensor = _best(ev, [k for k in SENSOR_CLASSES if k in ev])
    # a statistic confirms only the faults that make it: a jump at the window's start is a step's (an offset's),
    # and only where the reading itself stepped once, by at least half the offset named (a model that parted from
    # the plant slowly is fitted by an offset too, with no step in the reading; a steep passage steps many times)
    stepped = "probe_bias" in ev and _reading_stepped(ref, rows, w, ev["probe_bias"][1])
    # the jump confirms by its own rule below (before this one), never through the window's best fit
    confirmed_by = [k for k, r in ratios.items() if r > 1.0 and sensor in CONFIRMS.get(k, ()) and k != "jump"]
    confirmation = {"statistics": {k: round(v, 3) for k, v in stats.items()},
                    "thresholds": {k: margins[k] for k in stats if k in margins},
                    "confirmed_by": confirmed_by, "alpha_per_test": conf.get("alpha_per_test")}
    healthy_ones = [k for k in ev if k.startswith("pump:") and ev[k][0] > 0]
    explanation = _best(ev, healthy_ones) if healthy_ones else None
    # a fault: the window changed beyond the margin AND a sensor fault explains it better than any healthy
    # re-adaptation (a feed's apparent strength): else the plant left what the reference knows
    beaten = explanation is not None and ev[explanation][0] >= ev[sensor][0]
    # the fault hypothesis must explain the window itself: its gain over healthy beyond what a one-parameter fit
    # of a well-specified model gains by chance with probability alpha (chi-square(1) / 2)
    from scipy.stats import chi2  # here: scipy.stats takes about 1 s to import, which every node start would pay

    alpha = float(conf.get("alpha_per_test") or DEFAULT_ALPHA)
    weak = ev[sensor][0] <= 0.5 * float(chi2.isf(alpha, 1))
    confirmation["best_healthy_explanation"] = explanation
    # a reading that went quiet while no feed ran is a still flask as much as a frozen probe: nothing to confirm
    still = sensor == "probe_noise" and ev[sensor][1] < 1.0 and not _feeds_ran(ref, rows, w)
    confirmation["still_flask"] = still
    confirmation.update(sensor_gain_margin=round(0.5 * float(chi2.isf(alpha, 1)), 3))
    # a jump beyond its margin where the reading stepped once by at least half the offset fitted is evidence only
    # an offset gives, whichever hypothesis fits the window best: a feed's strength scales how fast the pH moves and
    # never steps the reading, a noisier probe steps it at every sample, not once. Over the window an offset can be
    # another hypothesis: on a strong acid's plateau pH = -log10 [H+] with [H+] linear in the acid added, so a probe
    # reading b pH high reads as every acid feed scaled by 10^-b (a 1 pH offset hidden at pH 3.7 of April's
    # titration: the acid at 0.11 of its strength gained 1192 over healthy, the offset, sized 0.92, 25), and the
    # one innovation of the step (20 to 40 sigma there) is what a probe 20 times noisier fits best
    if stepped and ratios.get("jump", 0.0) > 1.0:
        confirmation.update(confirmed_by=["jump"], stepped=True)
        return {**result, **_naming("probe_bias", ev), "confirmed": True, "confirmation": confirmation}
    if kind == AGAINST_FEED:
        return _judge_against_feed(ref, t_s, rows, w, ev, result, confirmation)
    if confirmed_by and not beaten and not still and not weak:
        return {**result, **_naming(sensor, ev), "confirmed": True, "confirmation": confirmation}
    named = explanation or "unexplained"
    # a later look only where this one compared the window with the run's own past, on at least as many samples
    # as a pump state needs before the window to be compared at all: a deviation in pump states the run had not
    # shown before is an operation new to the run (what a longer window adds there is the model parting from a
    # plant in a state nobody calibrated, not evidence of a fault: docs/detector.md)
    compared = int(ev["compared_vs_run"][0])
    confirmation["compared_samples"] = compared
    return {**result, **_naming(named, ev), "confirmed": False, "confirmation": confirmation,
            "look_again": compared >= STATE_MIN_SAMPLES}


def _judge_against_feed(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray, w: _Window, ev: dict,
                        result: dict, confirmation: dict) -> dict:
    """A feed check's window: the reading moved against the only feed that ran, by a test of its own at its own
    stated rate (wavelet_fdi.feed_checks), which no healthy re-adaptation can pass: a feed's strength scaled by any
    c >= 0 moves the pH with the feed or not at all. So the check confirms, and the window only names the fault:
    the probe offset or drift that moves the reading against the feed and fits best. Where neither fitted one moves
    it that way (a drift that began long before the window has its error in the filter's state there, and the fits
    answer another question), a drift at the rate the reading moved against the feed in the test's window, a lower
    bound (the pH itself moved with the feed)."""
    m = len(ref.feeds)
    window = np.asarray(rows[w.a:w.b], dtype=float)
    codes = feed_codes(window[:, :m], np.array([f.strength_mM for f in ref.feeds]))
    direction = int(np.sign(codes.sum()))  # the feed that ran in most of the window (the test's own)
    moving = [k for k in AGAINST_FEED_CLASSES if direction and np.sign(ev[k][1]) == -direction]
    confirmation.update(confirmed_by=[AGAINST_FEED], against_feed_direction=direction)
    if moving:
        return {**result, **_naming(_best(ev, moving), ev), "confirmed": True, "confirmation": confirmation}
    head = slice(w.a, min(w.a + WINDOW_SAMPLES, w.b))
    rate = reading_rate_ph_per_min(np.asarray(t_s[head], dtype=float), np.asarray(rows[head], dtype=float)[:, m])
    named = {**ev, "probe_drift": (ev["probe_drift"][0], rate)}
    return {**result, **_naming("probe_drift", named), "confirmed": True, "confirmation": confirmation,
            "size_is_lower_bound": True}


def _reading_stepped(ref: EstimatorReference, rows: np.ndarray, w: _Window, offset_ph: float) -> bool:
    """Whether the pH reading stepped once at the window's start: over its first ``JUMP_SAMPLES`` (and the two
    samples before, the change time's uncertainty) the largest sample-to-sample change is at least ``STEP_SHARE`` of
    the offset named, and no other change is as large as ``STEP_SHARE`` of it (a steep passage moves the reading
    by large steps one after another; a probe that jumped moves it once)."""
    ph = np.asarray(rows[max(w.a - 3, 0):w.a + JUMP_SAMPLES], dtype=float)[:, len(ref.feeds)]
    steps = np.sort(np.nan_to_num(np.abs(np.diff(ph))))[::-1]
    if not len(steps) or steps[0] < STEP_SHARE * abs(offset_ph):
        return False
    return len(steps) < 2 or steps[1] < STEP_SHARE * steps[0]


def _feeds_ran(ref: EstimatorReference, rows: np.ndarray, w: _Window) -> bool:
    """Whether any feed ran in at least half of the window's samples (its recorded flow above zero)."""
    flows = np.nan_to_num(np.asarray(rows[w.a:w.b], dtype=float)[:, :len(ref.feeds)])
    return bool(len(flows)) and float(np.mean(np.any(flows > 0, axis=1))) >= 0.5


def _best(ev: dict, names: Sequence[str]) -> str:
    return max(names, key=lambda k: ev[k][0])


def _unit(name: str) -> str:
    return {"probe_bias": "pH", "probe_drift": "pH/min", "probe_noise": "x healthy noise"}.get(name, "x recorded")


def _naming(name: str, ev: dict) -> dict:
    """The family, class, description, size and gain of hypothesis ``name`` (``unexplained``: none fits)."""
    if name == "unexplained":
        return {"family": "none", "fault_class": name, "description": "no fault hypothesis explains it",
                "size": 0.0, "unit": "", "log_likelihood_gain": 0.0}
    gain, size = ev[name]
    if name.startswith("pump:"):
        family, what = "actuator", f"{name[5:]} delivers other than recorded (or runs where the calibration never did)"
    else:
        family = "sensor"
        what = {"probe_bias": "probe bias", "probe_drift": "probe drift", "probe_noise": "probe noise"}[name]
    return {"family": family, "fault_class": name, "description": what, "size": round(size, 4),
            "unit": _unit(name), "log_likelihood_gain": round(gain, 3)}


def null_statistics(ref: EstimatorReference, t_s: np.ndarray, rows: np.ndarray,
                    every_blocks: int = NULL_EVERY_BLOCKS) -> list[dict[str, float]]:
    """The confirmation statistics of a healthy run a reference did not see, as if an alarm had been detected
    at every ``every_blocks``-th block boundary, in the windows both kinds of alarm have (a mean statistic's:
    from the change time found in the lookback; a noise statistic's: from its onset; :data:`NULL_ONSET_LAGS`):
    the null distribution the margin comes from."""
    block = ref.block_samples
    tracking = replace(ref, adapt_time_constant_s=0.0)  # as _hypotheses runs it
    out = []
    for det in range(4 * block, len(rows) - 1, every_blocks * block):
        for kind, lags in NULL_ONSET_LAGS.items():
            for lag in lags:
                w = _window(ref, t_s, rows, det - lag, det, kind == "noise")
                values = confirmation_statistics(_hypotheses(ref, t_s, rows, w, noise_only=True))
                # the later looks: the same window kept longer, where the run has the rows (a look the record
                # ends before is never made); the innovations once, to the longest, each shorter look their prefix
                later = [after for after in LOOK_AFTER_SAMPLES[1:] if det + after <= len(rows)]
                if later:
                    seen = _innovations_by_state(tracking, t_s, rows, replace(w, b=det + later[-1]))
                    for after in later:
                        keep = seen[3] < det + after
                        values[f"change@{after}"] = change_statistic(tracking, t_s, rows, replace(w, b=det + after),
                                                                     tuple(v[keep] for v in seen))
                out.append(values)
    return out


def confirmation_thresholds(nulls: Sequence[dict[str, float]], alpha: float = DEFAULT_ALPHA) -> dict:
    """Each statistic's margin (:func:`~wavelet_fdi.calibration.excess_tail_threshold`) from the pooled null
    values, at ``alpha`` split equally
    among the statistics that have a null (Bonferroni: a healthy deviation passes any of them with probability at
    most ``alpha``)."""
    have = [k for k in CONFIRM_STATISTICS if sum(1 for d in nulls if k in d) >= 20]
    per_test = alpha / max(len(have), 1)
    tails = {k: excess_tail_threshold([d[k] for d in nulls if k in d], per_test) for k in have}
    return {"thresholds": {k: t["threshold"] for k, t in tails.items()}, "null_tail": tails,
            "alpha_per_test": per_test, "alpha": alpha}
