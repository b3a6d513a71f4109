"""Published stiction indicators from OP, PV and SP alone, one function each.

Each returns an :class:`Indicator`: the index on its published scale, whether it applies to this
loop, the published decision (``stiction``/``no_stiction``/``undetermined``) where the paper gives
a threshold, and the intermediate numbers. :mod:`.classifier` combines them; none is tuned to the
refinery records.

* :func:`horch_ccf` (in :mod:`.baselines`): Horch (1999), OP-PV cross-correlation odd or even.
* :func:`horch_histogram`: Horch (2000, 2002), histogram of PV's first (self-regulating) or second
  (integrating) derivative: one Gaussian peak under stiction, a two-peaked "camel" (a sinusoid plus
  noise) otherwise.
* :func:`kano_stuck_index`: Kano, Maruta, Kugemoto & Shimizu (2004), sections where the valve does not
  move while OP moves monotonically; PV (self-regulating flow-type loops) or PV's slope (integrating)
  stands for the unmeasured stem position.
* :func:`area_peak_ratio`: Singhal & Salsbury (2005), areas of the control error before and after
  its peak in each half cycle; R > 1 stiction, R ~ 1 or below a linear oscillation.
* :func:`relay_shape`: Rossi & Scali (2005), each half cycle of PV fitted by a sinusoid and by the
  response of a relay (a pulse through a first-order lag; a triangle for integrating processes);
  SI = (E_sin - E_relay) / (E_sin + E_relay) > 0.21 stiction, < -0.21 no stiction.
* :mod:`.bicoherence`: Choudhury, Shah & Thornhill (2004) NGI/NLI and the PV-OP ellipse
  (Choudhury et al. 2006) for the apparent stiction.

Every signal is detrended first: slow drifts are not what these tests look at.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.signal import savgol_filter

from .oscillation import detect_oscillation, detrend, zero_crossings

INTEGRATING = "integrating"


@dataclass
class Indicator:
    """One indicator's result (``value`` None when it does not apply to the loop)."""

    name: str
    value: float | None
    decision: str  # stiction | no_stiction | undetermined | not_applicable
    detail: dict = field(default_factory=dict)
    reference: str = ""

    def to_dict(self) -> dict:
        d = asdict(self)
        d["value"] = _r(self.value)
        d["detail"] = {k: _r(v) for k, v in self.detail.items()}
        return d


def _r(v):
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return float(f"{v:.4g}") if math.isfinite(v) else None
    return v


def not_applicable(name: str, reason: str, reference: str) -> Indicator:
    return Indicator(name, None, "not_applicable", {"reason": reason}, reference)


# ---- shared helpers -------------------------------------------------------------------------
def _difference_noise_level(x: np.ndarray, order: int) -> float:
    """Standard deviation of white measurement noise from the MAD of x's ``order``-th differences (white noise's
    k-th difference has sd sqrt(C(2k, k)) times its own: sqrt 2 for the first, sqrt 6 for the second)."""
    d = np.diff(np.asarray(x, float), order)
    return 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(math.comb(2 * order, order))


def noise_level(x: np.ndarray) -> float:
    """Standard deviation of white measurement noise, from the MAD of first differences."""
    return _difference_noise_level(x, 1)


def ramp_noise_level(x: np.ndarray) -> float:
    """Standard deviation of white measurement noise, from the MAD of second differences. A straight ramp adds
    nothing to it: OP integrating a steady error while a valve sticks ramps, and a limit cycle's ramps made first
    differences (:func:`noise_level`) read the cycle's slope as noise, so a sticky valve's Kano S looked "within
    OP's noise" (docs/loop_diagnosis.md). 0 when x has fewer than 3 samples."""
    return 0.0 if len(x) < 3 else _difference_noise_level(x, 2)


def dominant_period(x: np.ndarray, dt_s: float, min_samples: float = 4.0) -> float:
    """Period (s) of the largest peak of the periodogram of detrended x, between 4 samples and a
    third of the record (the oscillation test's period when it finds one is preferred)."""
    y = detrend(np.asarray(x, float)) * np.hanning(len(x))
    spec = np.abs(np.fft.rfft(y)) ** 2
    f = np.fft.rfftfreq(len(y))
    ok = (f >= 3.0 / len(y)) & (f <= 1.0 / min_samples)
    if not ok.any():
        return math.nan
    return float(1.0 / f[ok][np.argmax(spec[ok])]) * dt_s


def loop_period_s(pv, sp, dt_s: float) -> tuple[float, bool]:
    """The oscillation period of the control error when the loop oscillates, else the dominant
    period of the error's periodogram; and whether the loop oscillates (Thornhill et al. 2003)."""
    osc = detect_oscillation(pv, sp, dt_s)
    if osc.oscillating and osc.period_s:
        return float(osc.period_s), True
    e = (np.asarray(sp, float) - pv) if sp is not None else np.asarray(pv, float)
    return dominant_period(e, dt_s), False


def half_cycles(x: np.ndarray, period_samples: float, min_fraction: float = 0.25) -> list[tuple[int, int]]:
    """Index ranges [a, b) between successive zero crossings of a lightly smoothed x (a moving
    average of a tenth of the period), keeping those at least ``min_fraction`` of a period long
    (shorter ones are noise crossings)."""
    w = max(1, int(round(period_samples / 10)))
    smooth = np.convolve(x, np.ones(w) / w, mode="same") if w > 1 else x
    z = np.floor(zero_crossings(smooth)).astype(int) + 1
    min_len = max(5, int(min_fraction * period_samples))
    return [(int(a), int(b)) for a, b in zip(z[:-1], z[1:]) if b - a >= min_len]


# ---- Horch (2000, 2002): histogram of PV's derivative ----------------------------------------
HORCH_HIST_REF = ("Horch (2002), 'Patents and publications about detection of stiction in control valves' / "
                  "Horch & Isaksson (2001): derivative histogram, Gaussian = stiction, camel = none")
#: Horch's decision, on the share of the derivative's variance a sinusoid explains
HORCH_HIST_THRESHOLD = 0.5


#: sqrt(2 pi), the normal density's constant (as scipy.stats.norm has it)
_SQRT_2PI = math.sqrt(2 * math.pi)


def _sine_noise_loglik(x: np.ndarray, amp: float, phases: np.ndarray) -> float:
    """Log-likelihood of unit-variance x under a sinusoid of amplitude amp plus Gaussian noise
    (variance 1 - amp^2 / 2), averaged over uniformly distributed phases.

    The normal density written out in the same operations as ``scipy.stats.norm.pdf`` (the same
    values bit for bit, tested) without its per-call argument handling: the likelihood is
    maximised over amp with some twenty calls per loop."""
    sig2 = max(1.0 - 0.5 * amp * amp, 1e-6)
    scale = math.sqrt(sig2)
    z = (x[:, None] - amp * np.sin(phases)[None, :]) / scale
    dens = (np.exp(-z ** 2 / 2.0) / _SQRT_2PI / scale).mean(axis=1)
    return float(np.sum(np.log(np.maximum(dens, 1e-300))))


def horch_histogram(pv: np.ndarray, sp: np.ndarray | None, dt_s: float, process_type: str) -> Indicator:
    """Horch's histogram test, index = share of the derivative's variance a sinusoid explains.

    PV is smoothed and differentiated by a Savitzky-Golay filter (window an eighth of the loop's
    period, odd, at least 5 samples) once for self-regulating and twice for integrating processes.
    The standardised derivative is fitted by maximum likelihood with "sinusoid of amplitude A plus
    Gaussian noise"; A = 0 is Horch's single Gaussian peak (stiction: PV moves in jumps, a square
    wave, or in ramps for integrating processes), A near sqrt(2) his two-peaked camel (a smooth,
    sinusoidal oscillation). Index = A^2 / 2 in [0, 1]; stiction when below 0.5.
    """
    name = "horch_histogram"
    period_s, oscillating = loop_period_s(pv, sp, dt_s)
    if not math.isfinite(period_s):
        return not_applicable(name, "no dominant period", HORCH_HIST_REF)
    order = 2 if process_type == INTEGRATING else 1
    w = max(5, int(round(period_s / dt_s / 8)))
    w += 1 - w % 2
    if w >= len(pv) // 2:
        return not_applicable(name, "period too long for the record", HORCH_HIST_REF)
    deriv = savgol_filter(detrend(np.asarray(pv, float)), w, polyorder=min(3, w - 2), deriv=order)
    deriv = deriv[w:-w]
    sd = float(np.std(deriv))
    if sd <= 0:
        return not_applicable(name, "PV does not move", HORCH_HIST_REF)
    x = (deriv - np.mean(deriv)) / sd
    phases = np.linspace(0.0, 2 * math.pi, 96, endpoint=False)
    res = minimize_scalar(lambda a: -_sine_noise_loglik(x, a, phases), bounds=(0.0, math.sqrt(2) * 0.995),
                          method="bounded", options={"xatol": 1e-3})
    amp = float(res.x)
    ll_gauss = _sine_noise_loglik(x, 0.0, phases)
    share = 0.5 * amp * amp
    decision = "stiction" if share < HORCH_HIST_THRESHOLD else "no_stiction"
    return Indicator(name, share, decision,
                     {"derivative_order": order, "window_samples": w, "period_s": period_s,
                      "oscillating": oscillating, "loglik_gain_per_sample": (-res.fun - ll_gauss) / len(x)},
                     HORCH_HIST_REF)


# ---- Kano et al. (2004): stuck sections ----------------------------------------------------
KANO_REF = ("Kano, Maruta, Kugemoto & Shimizu (2004), 'Practical model and detection algorithm for valve "
            "stiction', IFAC DYCOPS: share of OP movement while the valve does not move")
#: sections shorter than this many samples are not counted as stuck
KANO_MIN_SECTION = 4


def kano_stuck_index(op: np.ndarray, pv: np.ndarray, dt_s: float, process_type: str) -> Indicator:
    """Share of OP's travel made in sections where OP moves monotonically and the valve does not.

    The stem position is not recorded, so PV stands for it in self-regulating loops (a flow
    follows the stem within a few samples) and PV's slope in integrating ones (a level's inflow
    is its slope). Both signals are smoothed by a 3-sample moving average; OP moves monotonically
    while its smoothed increments keep one sign; the valve "does not move" while the proxy stays
    within +-2 noise levels of where the section began. Index in [0, 1]; Kano et al. flag stiction
    when stuck sections carry a large share of the movement (they give no universal threshold:
    0.25 is used here as the published-style decision, the classifier uses the value itself).
    """
    name = "kano_stuck"
    op = np.asarray(op, float)
    proxy = np.asarray(pv, float)
    if process_type == INTEGRATING:
        proxy = savgol_filter(proxy, 7, 2, deriv=1) if len(proxy) > 20 else np.gradient(proxy)
    k = np.ones(3) / 3
    ops = np.convolve(op, k, mode="valid")
    prs = np.convolve(proxy, k, mode="valid")
    noise = noise_level(proxy)
    if noise <= 0:
        noise = 1e-6 * max(float(np.ptp(proxy)), 1e-12)
    band = 2.0 * noise
    dop = np.diff(ops)
    total = float(np.sum(np.abs(dop)))
    op_noise = noise_level(op)
    if total <= 0 or float(np.ptp(ops)) <= 3 * op_noise:
        return not_applicable(name, "OP does not move", KANO_REF)
    stuck_travel = 0.0
    sections = 0
    i, n = 0, len(dop)
    while i < n:
        s = np.sign(dop[i])
        if s == 0:
            i += 1
            continue
        j = i
        ref = prs[i]
        while j < n and np.sign(dop[j]) == s and abs(prs[j + 1] - ref) <= band:
            j += 1
        travel = abs(ops[j] - ops[i])
        if j - i >= KANO_MIN_SECTION and travel > 2 * op_noise:
            stuck_travel += travel
            sections += 1
            i = j
        else:
            i += 1
    index = stuck_travel / total
    return Indicator(name, index, "stiction" if index >= 0.25 else "no_stiction",
                     {"sections": sections, "proxy": "pv_slope" if process_type == INTEGRATING else "pv",
                      "proxy_noise": noise}, KANO_REF)


# ---- Singhal & Salsbury (2005): area-peak ratio ---------------------------------------------
AREA_REF = ("Singhal & Salsbury (2005), 'A simple method for detecting valve stiction in oscillating "
            "control loops', J. Process Control 15, 371-382: R = A1 / A2 > 1 stiction")


def area_peak_ratio(pv: np.ndarray, sp: np.ndarray | None, dt_s: float, process_type: str) -> Indicator:
    """Median over the error's half cycles of log(A1 / A2), A1 the area of |SP - PV| from the
    zero crossing to the half cycle's peak, A2 from the peak to the next crossing.

    Under stiction with a self-regulating process the error jumps to near its extreme when the
    valve slips and creeps on while it sticks: the peak comes late (R > 1). A sinusoid gives R = 1
    and a linear loop's error, which overshoots and relaxes, R <= 1. The published threshold is
    R > 1 (log R > 0); Singhal & Salsbury derived it for self-regulating processes, so integrating
    loops get the value with decision ``undetermined``.
    """
    name = "area_peak_ratio"
    e = detrend((np.asarray(sp, float) if sp is not None else np.mean(pv)) - np.asarray(pv, float))
    period_s, oscillating = loop_period_s(pv, sp, dt_s)
    if not math.isfinite(period_s):
        return not_applicable(name, "no dominant period", AREA_REF)
    w = max(1, int(round(period_s / dt_s / 20)))
    es = np.convolve(e, np.ones(w) / w, mode="same") if w > 1 else e
    logs = []
    for a, b in half_cycles(e, period_s / dt_s):
        seg = np.abs(es[a:b])
        p = int(np.argmax(seg))
        a1, a2 = float(np.sum(seg[: p + 1])), float(np.sum(seg[p:]))
        if a1 > 0 and a2 > 0:
            logs.append(math.log(a1 / a2))
    if len(logs) < 2:
        return not_applicable(name, "fewer than two half cycles of the control error", AREA_REF)
    value = float(np.median(logs))
    if process_type == INTEGRATING:
        decision = "undetermined"
    else:
        decision = "stiction" if value > 0.0 else "no_stiction"
    return Indicator(name, value, decision, {"half_cycles": len(logs), "ratio_R": math.exp(value),
                                             "period_s": period_s, "oscillating": oscillating}, AREA_REF)


# ---- Rossi & Scali (2005): relay vs sinusoid ----------------------------------------------
RELAY_REF = ("Rossi & Scali (2005), 'A comparison of techniques for automatic detection of stiction', "
             "J. Process Control 15, 505-514: SI = (E_sin - E_relay)/(E_sin + E_relay), > 0.21 stiction")
RELAY_THRESHOLD = 0.21


def _fit_sine(y: np.ndarray) -> float:
    """Least mean squared error of y ~ c + A sin(pi (t - t0) / length) over a grid of length and t0
    (every grid point's least-squares fit at once; residuals computed, not subtracted sums)."""
    n = len(y)
    t = np.arange(n, dtype=float)
    lengths = np.linspace(0.7 * (n + 1), 1.3 * (n + 1), 9)
    t0s = np.linspace(-0.3 * n, 0.3 * n, 9) - 0.5
    g = np.sin(np.pi * (t[None, None, :] - t0s[None, :, None]) / lengths[:, None, None]).reshape(-1, n)
    gc = g - np.mean(g, axis=1, keepdims=True)
    yc = y - np.mean(y)
    sgg = np.einsum("ij,ij->i", gc, gc)
    amp = np.where(sgg > 0, gc @ yc / np.where(sgg > 0, sgg, 1.0), 0.0)
    resid = yc[None, :] - amp[:, None] * gc
    return float(np.min(np.mean(resid * resid, axis=1)))


def _lsq_two(y: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Mean squared error of y ~ c + A g (closed form), for each row of g."""
    g = np.atleast_2d(g)
    gc = g - np.mean(g, axis=1, keepdims=True)
    yc = y - np.mean(y)
    sgg = np.einsum("ij,ij->i", gc, gc)
    sgy = gc @ yc
    sse = float(yc @ yc) - np.where(sgg > 0, sgy ** 2 / np.where(sgg > 0, sgg, 1.0), 0.0)
    return np.maximum(sse, 0.0) / len(y)


def _fit_relay(y: np.ndarray, integrating: bool) -> float:
    """A relay seen through the process over one half cycle: it switches one way at t0 (near the
    start) and back at t1 (near the end). Self-regulating: first-order responses
    c + A (s(t - t0) - s(t - t1)), s(t) = 1 - exp(-t / tau) for t > 0; integrating: a triangle (a
    ramp whose slope reverses at a knot). t0, t1, tau and the knot on grids; c and A by least squares."""
    n = len(y)
    t = np.arange(n, dtype=float)
    best = math.inf
    if integrating:
        for knot in np.linspace(0.15 * n, 0.85 * n, 10):
            design = np.column_stack([np.ones(n), t, np.maximum(t - knot, 0.0)])
            coef, *_ = np.linalg.lstsq(design, y, rcond=None)
            best = min(best, float(np.mean((y - design @ coef) ** 2)))
        return best
    t0s = np.linspace(-0.1 * n, 0.25 * n, 4)
    t1s = np.linspace(0.5 * n, 1.05 * n, 6)
    taus = np.geomspace(0.3, max(0.6, n / 2), 8)[:, None, None]

    def step(ts):  # (tau, switch time, t): the first-order response to a unit step at each switch
        lag = t[None, None, :] - ts[None, :, None]
        return np.where(lag > 0, 1.0 - np.exp(-np.maximum(lag, 0.0) / taus), 0.0)

    g = step(t0s)[:, :, None, :] - step(t1s)[:, None, :, :]  # (tau, t0, t1, t)
    return float(np.min(_lsq_two(y, g.reshape(-1, n))))


def relay_shape(pv: np.ndarray, sp: np.ndarray | None, dt_s: float, process_type: str,
                max_half_cycles: int = 30) -> Indicator:
    """Rossi & Scali's stiction index on the half cycles of detrended PV (see module docstring)."""
    name = "relay_shape"
    period_s, oscillating = loop_period_s(pv, sp, dt_s)
    if not math.isfinite(period_s):
        return not_applicable(name, "no dominant period", RELAY_REF)
    x = detrend(np.asarray(pv, float))
    integrating = process_type == INTEGRATING
    e_sin, e_rel = [], []
    for a, b in half_cycles(x, period_s / dt_s)[:max_half_cycles]:
        seg = x[a:b]
        e_sin.append(_fit_sine(seg))
        e_rel.append(_fit_relay(seg, integrating))
    if not e_sin:
        return not_applicable(name, "no complete half cycle", RELAY_REF)
    es, er = float(np.mean(e_sin)), float(np.mean(e_rel))
    si = (es - er) / (es + er) if es + er > 0 else 0.0
    decision = ("stiction" if si > RELAY_THRESHOLD else "no_stiction" if si < -RELAY_THRESHOLD
                else "undetermined")
    return Indicator(name, si, decision, {"half_cycles": len(e_sin), "period_s": period_s,
                                          "oscillating": oscillating,
                                          "relay": "triangle" if integrating else "first-order pulse"}, RELAY_REF)
