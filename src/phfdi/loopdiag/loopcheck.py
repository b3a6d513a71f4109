"""Is the record a closed loop whose valve can be scored? Frozen PV, and PV that has nothing to do with OP.

A stiction score only means something for a closed loop: a controller that moves OP from PV, and a PV
that OP moves through the valve. Two records are not that and get a verdict of their own instead of a
stiction probability:

* **PV frozen under a moving OP** (``pv_frozen``): PV does not change at all while OP moves. Either the
  valve does not move (stuck, or its air or power is lost) or the transmitter reports a held value;
  from OP and PV alone the two cannot be told apart, and neither is a stiction record to score.
* **not a closed loop** (``not_a_closed_loop``): OP does not move, or OP and PV are statistically
  independent at the loop's time scale (Haugh's test, below): PV does not follow OP and OP does not
  answer PV. A record without a setpoint column says so among the reasons (nothing then shows the
  record was taken under control).

Independence test (Haugh 1976, J. Amer. Statist. Assoc. 71, 378-385): the two series are differenced
(historian PV and OP drift or integrate) and each is prewhitened by its own autoregression (order by
AIC, at most :data:`MAX_AR_ORDER`); under independence the residuals' cross-correlations r_k at lags
-L..L are independent with variance 1/N, so Q = N^2 sum_k r_k^2 / (N - |k|) is chi-square with 2L + 1
degrees of freedom. OP and PV are coupled when its p-value is below :data:`ALPHA`. Raw cross-correlations
of autocorrelated series are not tested: two independent random walks correlate "significantly" most
of the time. L, the loop's time scale, is PV's correlation time: the first lag at which the
autocorrelation of PV (a straight line removed) falls below 1/e, held to 2 .. N/20 samples.
Both directions count (OP at lag k > 0 ahead of PV: the process; PV ahead or together: the controller),
so a closed loop with a valve that does not move is still coupled through its controller.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2

#: significance level of the independence test (a common choice, fixed before any record was tested)
ALPHA = 0.01
#: highest autoregressive order of the prewhitening filters
MAX_AR_ORDER = 10
#: relative spread below which PV counts as frozen (constant to rounding)
FROZEN_RTOL = 1e-9
#: OP must move by more than this share of its mean level (or 0.05 % of span) (as :mod:`.diagnose`)
MIN_OP_MOVEMENT = 1e-3

PV_FROZEN = "pv_frozen"
NOT_A_CLOSED_LOOP = "not_a_closed_loop"


@dataclass
class LoopCheck:
    """What the structure checks found. ``verdict`` None: a closed loop, to be scored."""

    verdict: str | None
    reasons: list[str] = field(default_factory=list)
    has_setpoint: bool = True
    op_moves: bool = True
    pv_frozen: bool = False
    coupling_p_value: float | None = None
    lags: int | None = None

    def to_dict(self) -> dict:
        return {"verdict": self.verdict, "reasons": list(self.reasons), "has_setpoint": self.has_setpoint,
                "op_moves": self.op_moves, "pv_frozen": self.pv_frozen,
                "coupling_p_value": None if self.coupling_p_value is None else float(f"{self.coupling_p_value:.3g}"),
                "lags": self.lags, "alpha": ALPHA,
                "test": "Haugh (1976) independence of prewhitened, differenced OP and PV"}


def check_loop(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None) -> LoopCheck:
    """The structure verdict of one record (see the module docstring).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> op = 50 + np.cumsum(rng.normal(size=600)) * 0.1
    >>> check_loop(op, np.full(600, 3.0), None).verdict
    'pv_frozen'
    >>> check_loop(op, np.cumsum(rng.normal(size=600)), None).verdict  # PV unrelated to OP
    'not_a_closed_loop'
    """
    op, pv = np.asarray(op, float), np.asarray(pv, float)
    has_sp = sp is not None
    op_moves = bool(np.ptp(op) > max(abs(float(np.mean(op))) * MIN_OP_MOVEMENT, 0.05 * MIN_OP_MOVEMENT * 100))
    frozen = bool(np.ptp(pv) <= FROZEN_RTOL * max(1.0, float(np.max(np.abs(pv)))))
    no_sp = [] if has_sp else ["no setpoint"]
    if frozen and op_moves:
        return LoopCheck(PV_FROZEN, ["PV does not respond: valve stuck or transmitter failed"
                                     f" (PV constant at {pv[0]:g} while OP moves over {np.ptp(op):.3g})"] + no_sp,
                         has_sp, op_moves, frozen)
    if not op_moves:
        return LoopCheck(NOT_A_CLOSED_LOOP, ["OP does not move: the loop is open (manual) or OP is held"] + no_sp,
                         has_sp, op_moves, frozen)
    lags = correlation_time(pv)
    p = independence_p_value(op, pv, lags)
    if p >= ALPHA:
        return LoopCheck(NOT_A_CLOSED_LOOP, [f"PV does not follow OP (and OP does not answer PV): independent at "
                                             f"lags up to {lags} samples, p = {p:.2g} >= {ALPHA:g}"] + no_sp,
                         has_sp, op_moves, frozen, p, lags)
    notes = [] if has_sp else ["no setpoint: the record's control error is PV about its mean"]
    return LoopCheck(None, notes, has_sp, op_moves, frozen, p, lags)


def correlation_time(x: np.ndarray) -> int:
    """First lag (samples) at which the autocorrelation of x, a straight line removed, falls below 1/e;
    held to 2 .. len(x) // 20."""
    n = len(x)
    t = np.arange(n)
    e = x - np.polyval(np.polyfit(t, x, 1), t)
    hi = max(2, n // 20)
    if np.std(e) <= 0:
        return 2
    f = np.fft.rfft(e, 2 * n)
    acf = np.fft.irfft(f * np.conj(f))[: hi + 1]
    acf = acf / acf[0]
    below = np.flatnonzero(acf < 1.0 / math.e)
    return int(min(max(below[0] if below.size else hi, 2), hi))


def prewhiten(x: np.ndarray, max_order: int = MAX_AR_ORDER) -> np.ndarray:
    """Residuals of an autoregression of x (least squares, order 0..max_order by AIC), all of length
    len(x) - max_order so two series' residuals stay aligned in time."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    y = x[max_order:]
    best_aic, best_res = len(y) * math.log(max(float(y @ y) / len(y), 1e-300)), y.copy()
    for p in range(1, max_order + 1):
        lagged = np.column_stack([x[max_order - k: n - k] for k in range(1, p + 1)])
        coef, *_ = np.linalg.lstsq(lagged, y, rcond=None)
        res = y - lagged @ coef
        aic = len(y) * math.log(max(float(res @ res) / len(y), 1e-300)) + 2 * p
        if aic < best_aic:
            best_aic, best_res = aic, res
    return best_res


def independence_p_value(op: np.ndarray, pv: np.ndarray, lags: int) -> float:
    """Haugh's (1976) portmanteau p-value for "OP and PV are independent", lags -lags..lags, on the
    prewhitened first differences. 1.0 when either residual has no variance."""
    a = prewhiten(np.diff(op))
    b = prewhiten(np.diff(pv))
    a, b = a - a.mean(), b - b.mean()
    sa, sb = math.sqrt(float(a @ a)), math.sqrt(float(b @ b))
    if sa <= 0 or sb <= 0:
        return 1.0
    n = len(a)
    q = 0.0
    for k in range(-lags, lags + 1):
        r = float(a[max(-k, 0): n - max(k, 0)] @ b[max(k, 0): n - max(-k, 0)]) / (sa * sb)
        q += n * n * r * r / (n - abs(k))
    return float(chi2.sf(q, 2 * lags + 1))
