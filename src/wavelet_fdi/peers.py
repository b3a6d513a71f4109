"""The change detectors a user would otherwise pick, run on the same residual stream.

Each peer sees the raw pH residual divided by its healthy standard deviation
(u ~ N(0, 1) when healthy), on the samples our detector monitors, and is
held to the same false-alarm target (average run length ARL0) by the same
procedure on the same healthy calibration runs (window maxima and
exponential tail fit, :mod:`wavelet_fdi.calibration`), except ADWIN, whose
only knob (delta) is set by counting its false alarms on those runs.

* ``cusum``: Page's two-sided CUSUM on u, reference k = delta / 2 (the same
  design shift as our approximation-band CUSUMs), restarted after an alarm;
* ``focus``: FOCuS (``changepoint_online.Focus``, Gaussian, pre-change mean 0
  known): the CUSUM likelihood ratio for every change size at once;
* ``page_hinkley``: river's ``PageHinkley`` (two-sided, delta = k, no
  forgetting: alpha = 1), threshold calibrated. With river's default
  alpha = 1 - 1e-4 its sums settle near -delta / (1 - alpha) after about
  1 / (1 - alpha) samples and then wander: on 10000-sample healthy runs it
  raised 7 false alarms in 13 h at the threshold calibrated on 1000-sample
  windows, whatever the threshold's calibration;
* ``adwin``: river's ``ADWIN`` (clock 1: checks every sample), delta
  calibrated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .calibration import tail_threshold, window_maxima
from .statistics import CusumBank

PEERS = ("cusum", "focus", "page_hinkley", "adwin")
PEER_LABELS = {"cusum": "CUSUM", "focus": "FOCuS", "page_hinkley": "Page-Hinkley", "adwin": "ADWIN"}
#: every detector the evaluation compares (ours first) and its label in tables and figures
DETECTORS = ("wavelet", "wavelet_bands") + PEERS
LABELS = {"wavelet": "wavelet (ours)", "wavelet_bands": "bands only", **PEER_LABELS}
PH_ALPHA = 1.0
ADWIN_DELTAS = tuple(float(d) for d in np.logspace(-6, math.log10(0.9), 12))


@dataclass
class Peer:
    name: str
    threshold: float  # CUSUM, FOCuS, Page-Hinkley: statistic threshold; ADWIN: delta
    k: float = 0.5

    def alarms(self, u: np.ndarray) -> list[int]:
        """Positions in u where the detector alarms (restarting after each)."""
        return {"cusum": self._cusum, "focus": self._focus, "page_hinkley": self._page_hinkley,
                "adwin": self._adwin}[self.name](np.asarray(u, dtype=float))

    def _cusum(self, u: np.ndarray) -> list[int]:
        out, pos = [], 0
        while pos < len(u):
            bank = CusumBank(2)
            s = bank.update(np.vstack((u[pos:] - self.k, -u[pos:] - self.k)), pos)
            over = np.flatnonzero((s > self.threshold).any(axis=0))
            if not len(over):
                break
            out.append(pos + int(over[0]))
            pos += int(over[0]) + 1
        return out

    def _focus(self, u: np.ndarray) -> list[int]:
        from changepoint_online import Focus, Gaussian

        out = []
        det = Focus(Gaussian(loc=0.0))
        for i, x in enumerate(u.tolist()):
            det.update(x)
            if det.statistic() >= self.threshold:
                out.append(i)
                det = Focus(Gaussian(loc=0.0))
        return out

    def _page_hinkley(self, u: np.ndarray) -> list[int]:
        from river.drift import PageHinkley

        return _river_alarms(PageHinkley(delta=self.k, threshold=self.threshold, alpha=PH_ALPHA, mode="both"), u)

    def _adwin(self, u: np.ndarray) -> list[int]:
        from river.drift import ADWIN

        return _river_alarms(ADWIN(delta=self.threshold, clock=1), u)


def _river_alarms(det, u: np.ndarray) -> list[int]:
    """Positions where a river drift detector flags (it resets itself after each)."""
    out = []
    for i, x in enumerate(u.tolist()):
        det.update(x)
        if det.drift_detected:
            out.append(i)
    return out


# ---- calibration ------------------------------------------------------------------------
def _focus_window_max(u: np.ndarray) -> float:
    from changepoint_online import Focus, Gaussian

    det = Focus(Gaussian(loc=0.0))
    m = 0.0
    for x in u.tolist():
        det.update(x)
        m = max(m, det.statistic())
    return m


def _page_hinkley_window_max(u: np.ndarray, k: float) -> float:
    """Largest test statistic of a fresh river PageHinkley over u (read from its state: river
    exposes only the crossing, and calibration needs the value)."""
    from river.drift import PageHinkley

    det = PageHinkley(delta=k, threshold=math.inf, alpha=PH_ALPHA, mode="both")
    m = 0.0
    for x in u.tolist():
        det.update(x)
        if det._x_mean.n >= det.min_instances:
            m = max(m, det._sum_increase - det._min_increase, det._max_decrease - det._sum_decrease)
    return m


def calibrate_peers(streams: list[np.ndarray], arl0: float, k: float, window: int,
                    progress=None, names: tuple[str, ...] = PEERS) -> dict[str, dict]:
    """Threshold (delta for ADWIN) of each peer in ``names`` for ARL0, from healthy normalised residual streams."""
    out: dict[str, dict] = {}
    p_target = window / arl0
    windows = [s[i:i + window] for s in streams for i in range(0, len(s) - window + 1, window)]
    maxima = {
        "cusum": lambda: np.concatenate([np.maximum(window_maxima(s - k, window), window_maxima(-s - k, window))
                                         for s in streams]),
        "focus": lambda: np.array([_focus_window_max(w) for w in windows]),
        "page_hinkley": lambda: np.array([_page_hinkley_window_max(w, k) for w in windows]),
    }
    for name in names:
        if name == "adwin":
            out[name] = calibrate_adwin(streams, arl0)
        else:
            fit = tail_threshold(maxima[name](), p_target)
            out[name] = {"threshold": fit.threshold, "tail_fit": fit.as_dict(), "method": "window maxima, tail fit"}
        if progress:
            progress(name)
    return out


def calibrate_adwin(streams: list[np.ndarray], arl0: float) -> dict:
    """Largest delta whose false-alarm rate on the healthy streams stays at 1 / ARL0 (log-log interpolation)."""
    total = sum(len(s) for s in streams)
    rates = []
    for d in ADWIN_DELTAS:
        n = sum(len(Peer("adwin", d).alarms(s)) for s in streams)
        rates.append(n / total)
    target = 1.0 / arl0
    chosen, note = ADWIN_DELTAS[0], ""
    for i, (d, r) in enumerate(zip(ADWIN_DELTAS, rates)):
        if r <= target:
            chosen = d
            continue
        prev_d, prev_r = (ADWIN_DELTAS[i - 1], rates[i - 1]) if i else (None, 0.0)
        if prev_d is not None and prev_r > 0.0:
            f = (math.log(target) - math.log(prev_r)) / (math.log(r) - math.log(prev_r))
            chosen = math.exp(math.log(prev_d) + f * (math.log(d) - math.log(prev_d)))
        break
    else:
        note = (f"no false alarm up to delta {ADWIN_DELTAS[-1]:.2g}: ADWIN cannot reach the target rate on these "
                f"streams; the most sensitive delta tested is used")
    return {"threshold": chosen, "method": "false alarms counted on the healthy streams per delta",
            "deltas": list(ADWIN_DELTAS), "rates_per_sample": rates, "healthy_samples": total, "note": note}


# ---- several channels at once (measured records) -----------------------------------------
def hold_states(alarm_positions: list[int], n: int, hold_samples: int) -> np.ndarray:
    """0/1 per sample from point alarms: 1 from each alarm until ``hold_samples`` samples pass without
    another one (the peers restart after an alarm, so a lasting fault keeps re-alarming and holds the state)."""
    states = np.zeros(n, dtype=np.int8)
    for p in sorted(set(int(a) for a in alarm_positions)):
        states[p:min(n, p + hold_samples)] = 1
    return states


def multichannel_states(peer: Peer, u: np.ndarray, hold_samples: int) -> np.ndarray:
    """One copy of ``peer`` per column of u (n, m; each healthy ~N(0, 1)); the alarm state (0/1 per row) of
    their union, each alarm held for ``hold_samples`` rows. Causal: row i depends on rows <= i only."""
    u = np.asarray(u, dtype=float)
    if u.ndim != 2:
        raise ValueError(f"expected rows x channels, got shape {u.shape}")
    u = np.where(np.isfinite(u), u, 0.0)  # a missing sample counts as healthy, as in our detector
    pos = [p for c in range(u.shape[1]) for p in peer.alarms(u[:, c])]
    return hold_states(pos, len(u), hold_samples)
