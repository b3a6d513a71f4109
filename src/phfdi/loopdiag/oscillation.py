"""Does the loop oscillate? Regularity of the autocorrelation's zero crossings.

Thornhill, Huang & Zhang (2003, J. Process Control 13, 91-100): the
autocorrelation function (ACF) of an oscillating signal oscillates with the
same period, and noise hardly moves its zero crossings. The intervals between
alternate zero crossings of the ACF are estimates of the period Tp; the
oscillation is *regular* when

    r = mean(Tp) / (3 std(Tp)) > 1,

i.e. the period is known to better than about a third of itself. The signal
is the control error SP - PV (PV about its mean when there is no setpoint),
with a straight line removed (slow drifts are not oscillations).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

#: regularity above which an oscillation counts as present (Thornhill et al. 2003)
REGULARITY_THRESHOLD = 1.0
#: zero crossings of the ACF used (the first ones carry the most information)
MAX_CROSSINGS = 11
#: an oscillation needs at least this many periods in the record to be called one
MIN_CYCLES = 3.0


@dataclass
class Oscillation:
    """What the oscillation test found (``period_s`` None when there are too few crossings).

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.loopdiag import detect_oscillation
    >>> osc = detect_oscillation(np.sin(np.arange(0.0, 3000.0, 4.0) * 2 * np.pi / 200.0), None, 4.0)
    >>> osc.oscillating, round(osc.period_s), osc.signal
    (True, 200, 'pv')
    """

    oscillating: bool
    period_s: float | None
    regularity: float
    cycles: float
    amplitude: float
    signal: str
    method: str = "ACF zero-crossing regularity (Thornhill et al. 2003), r > 1"

    def to_dict(self) -> dict:
        d = asdict(self)
        for k in ("period_s", "regularity", "cycles", "amplitude"):
            v = d[k]
            if isinstance(v, float) and math.isfinite(v):
                d[k] = float(f"{v:.6g}")
            elif isinstance(v, float):
                d[k] = None
        return d


def autocorrelation(x: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample ACF r(0..max_lag) of x about its mean (r(0) = 1)."""
    x = np.asarray(x, float) - np.mean(x)
    n = len(x)
    nfft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(x, nfft)
    c = np.fft.irfft(f * np.conj(f), nfft)[: max_lag + 1]
    return c / c[0] if c[0] > 0 else np.zeros(max_lag + 1)


def zero_crossings(r: np.ndarray) -> np.ndarray:
    """Fractional indices where r changes sign (linear interpolation between samples)."""
    s = np.sign(r)
    idx = np.flatnonzero(s[:-1] * s[1:] < 0)
    exact = np.flatnonzero(s == 0)
    frac = idx + r[idx] / (r[idx] - r[idx + 1])
    return np.sort(np.concatenate((frac, exact.astype(float))))


def detrend(x: np.ndarray) -> np.ndarray:
    t = np.arange(len(x), dtype=float)
    coef = np.polyfit(t, x, 1)
    return x - np.polyval(coef, t)


def period_regularity(x: np.ndarray, dt_s: float, max_crossings: int = MAX_CROSSINGS) -> tuple[float, float]:
    """(mean period in s, regularity r) from the ACF zero crossings of x; (nan, 0) if too few."""
    n = len(x)
    r = autocorrelation(x, n // 2)
    z = zero_crossings(r)[:max_crossings]
    if len(z) < 4:
        return math.nan, 0.0
    periods = z[2:] - z[:-2]
    mean, std = float(np.mean(periods)), float(np.std(periods))
    regularity = mean / (3.0 * std) if std > 0 else math.inf
    return mean * dt_s, regularity


def detect_oscillation(pv: np.ndarray, sp: np.ndarray | None, dt_s: float) -> Oscillation:
    """Oscillation of the control error (or of PV when there is no setpoint).

    Parameters
    ----------
    pv, sp : ndarray
        Process value and setpoint (``sp`` None: the PV itself is tested).
    dt_s : float
        Sample time (s).

    Returns
    -------
    Oscillation

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.loopdiag import detect_oscillation
    >>> rng = np.random.default_rng(0)
    >>> detect_oscillation(rng.normal(size=750), np.zeros(750), 4.0).oscillating  # noise does not oscillate
    False
    """
    if sp is not None:
        e, name = np.asarray(sp, float) - np.asarray(pv, float), "control_error"
    else:
        e, name = np.asarray(pv, float), "pv"
    x = detrend(e)
    period_s, regularity = period_regularity(x, dt_s)
    duration_s = len(x) * dt_s
    cycles = duration_s / period_s if period_s and math.isfinite(period_s) else 0.0
    oscillating = regularity > REGULARITY_THRESHOLD and cycles >= MIN_CYCLES
    amplitude = float(np.sqrt(2.0) * np.std(x))  # of a sinusoid with that RMS
    return Oscillation(oscillating, period_s if math.isfinite(period_s) else None, regularity, cycles,
                       amplitude, name)
