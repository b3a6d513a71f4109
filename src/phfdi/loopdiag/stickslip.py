"""Stick-slip events: OP travels while the valve stays, then PV jumps (Kano et al.'s stiction model, read from data).

Kano, Maruta, Kugemoto & Shimizu (2004) model a sticky valve as staying where it stuck until OP has
moved by S from there, then slipping by J; their detection looks for sections where OP moves and the
valve does not. Read from OP and PV alone (no stem position), a *stuck section* cannot be told from a
healthy loop compensating a slow load: there too OP drifts while PV stays at its setpoint, and the
integral action needs the same small error to drive the same drift. What tells them apart is how the
section ends. A sticky valve ends it with a **slip**: PV jumps within a few samples, without OP having
jumped, and the controller then reverses OP (the slip carries PV past its setpoint). A compensated load
ends with nothing in particular. This index counts only stuck sections that end in a slip:

1. OP (3-sample moving average) is cut into *runs* at its turning points, a reversal counting only when
   it exceeds 3 noise levels of the smoothed OP (:func:`zigzag_turns`); a healthy valve or a slipping
   one is followed by the controller reversing OP, so a slip sits near the end of a run.
2. In each run the largest fast change of the valve proxy (PV for self-regulating loops, PV's slope for
   integrating ones, as in Kano et al.) is the slip candidate: the step between the medians of the 3
   samples before and after it (:func:`median_steps`), looked for from 8 samples into the run to 3
   after its turning point, and no further from the turning point than 5 samples or a third of the run.
3. It is a slip when (all in noise levels sigma of the proxy, the MAD of its first differences or its
   quantum if larger):

   * the proxy was flat before it: from 2 samples after the run began (the previous slip settling) to
     the sample before the slip, its 10-90 % spread is at most 4 sigma (Gaussian noise spreads 2.56 sigma);
   * it jumps: the median of the 5 samples after it minus that of the last 5 flat ones is at least
     4 sigma and 1.5 times the flat spread, and at least 60 % of the jump happens in the 3-median step
     (a jump, not a ramp);
   * OP travelled while the valve stayed: the smoothed OP moved by at least 3 of its noise levels from the
     start of the flat stretch to the slip;
   * OP did not cause it: no 2-sample rise of OP in the run's direction over the 5 samples before the
     slip reaches half of that travel (a setpoint kick or an operator's step moves OP first; a slip
     makes OP react against the run's direction, which is allowed).

The index is the OP travel that ended in slips over OP's whole travel (the sum of its runs), in [0, 1].
It is a reading of Kano et al.'s model by this project, not a method published as such; every threshold
above was fixed on the project's synthetic loops (:mod:`.training`), none on the refinery records. Like
Kano's method it assumes the process answers the valve within a few samples (flow, pressure, a level's
inflow); a slow process smooths the slip into a ramp, and the index is then 0 whatever the valve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter

from .indicators import INTEGRATING, Indicator, noise_level, not_applicable

STICK_SLIP_REF = ("Kano, Maruta, Kugemoto & Shimizu (2004), 'Practical model and detection algorithm for valve "
                  "stiction', IFAC DYCOPS: the valve stays until OP has moved by S, then slips; read here as stuck "
                  "runs of OP that end in a jump of PV (this project's reading, phfdi.loopdiag.stickslip)")
#: the index at which the verdict reads stiction (fixed on the synthetic training loops: above it 30 % of
#: sticky valves, 3 % of healthy ones)
STICK_SLIP_DECISION = 0.1
#: OP reversals smaller than this many noise levels of the smoothed OP do not end a run
HYSTERESIS_SIGMAS = 3.0
#: samples skipped after a run begins (PV settling after the previous slip)
SETTLE = 2
#: samples whose median gives the level just before and just after a slip
LEVEL = 5
#: the flat stretch's 10-90 % spread, and the smallest slip, in noise levels
FLAT_SIGMAS = 4.0
SLIP_SIGMAS = 4.0
#: share of the jump that must happen in one 3-sample median step
FAST_SHARE = 0.6
#: an OP rise in the run's direction before the slip larger than this share of the travel caused the jump
KICK_SHARE = 0.5


@dataclass(frozen=True)
class Slip:
    """One stuck section ended by a slip (sample indices into the record)."""

    start: int  # first sample of the flat stretch
    slip: int  # first sample after the jump
    op_travel: float  # OP's move while the valve stayed (OP units)
    jump: float  # the proxy's jump (PV units, or PV units per s for a level's slope)


def zigzag_turns(x: np.ndarray, delta: float) -> list[int]:
    """Indices of x's turning points, a reversal counting once it exceeds ``delta``; the first and last
    sample included (a signal that never moves by ``delta`` gives just those two).

    >>> zigzag_turns(np.array([0.0, 1, 2, 1.9, 3, 2, 1, 1.1, 0]), 0.5)
    [0, 4, 8]
    """
    turns, direction, ext = [0], 0, 0
    lo = hi = 0
    for i in range(1, len(x)):
        if direction == 0:
            hi = i if x[i] > x[hi] else hi
            lo = i if x[i] < x[lo] else lo
            if x[hi] - x[lo] >= delta:
                first, direction, ext = (lo, 1, hi) if hi > lo else (hi, -1, lo)
                if first:
                    turns.append(first)
            continue
        if direction * (x[i] - x[ext]) >= 0:
            ext = i
        elif direction * (x[ext] - x[i]) >= delta:
            turns.append(ext)
            direction, ext = -direction, i
    if direction and turns[-1] != ext:
        turns.append(ext)
    if turns[-1] != len(x) - 1:
        turns.append(len(x) - 1)
    return turns


def median_steps(x: np.ndarray) -> np.ndarray:
    """step[k] = median(x[k:k+3]) - median(x[k-3:k]) (0 where a side is incomplete)."""
    n = len(x)
    step = np.zeros(n)
    if n < 6:
        return step
    med = np.median(np.lib.stride_tricks.sliding_window_view(x, 3), axis=1)  # med[j] = median(x[j:j+3])
    step[3:n - 2] = med[3:n - 2] - med[0:n - 5]
    return step


def _proxy(pv: np.ndarray, process_type: str) -> np.ndarray:
    """The valve's stand-in: PV, or a level's slope (its net inflow) for an integrating process."""
    pv = np.asarray(pv, float)
    if process_type == INTEGRATING:
        return savgol_filter(pv, 7, 2, deriv=1) if len(pv) > 20 else np.gradient(pv)
    return pv


def _noise(proxy: np.ndarray) -> float:
    """Noise level of the proxy; a quantised record's step when that is larger (its noise reads 0)."""
    d = np.abs(np.diff(proxy))
    quantum = float(d[d > 0].min()) if np.any(d > 0) else 0.0
    return max(noise_level(proxy), quantum, 1e-12)


def _slip_in_run(a: int, b: int, proxy: np.ndarray, op: np.ndarray, ops: np.ndarray, step: np.ndarray,
                 sigma: float, op_sigma: float) -> Slip | None:
    """The slip ending the OP run [a, b] (module docstring, steps 2 and 3), or None."""
    n = len(proxy)
    lo, hi = a + SETTLE + 6, min(b + 3, n - LEVEL - 1)
    if hi <= lo:
        return None
    k = lo + int(np.argmax(np.abs(step[lo:hi])))
    if b - k > max(5, (b - a) // 3):
        return None
    start = a + SETTLE
    flat = proxy[start:k - 1]
    if len(flat) < LEVEL:
        return None
    spread = float(np.percentile(flat, 90) - np.percentile(flat, 10))
    jump = float(np.median(proxy[k + 1:k + 1 + LEVEL]) - np.median(flat[-LEVEL:]))
    if spread > FLAT_SIGMAS * sigma or abs(jump) < max(SLIP_SIGMAS * sigma, 1.5 * spread):
        return None
    if abs(step[k]) < FAST_SHARE * abs(jump):
        return None
    travel = float(ops[k - 1] - ops[start])
    if abs(travel) < HYSTERESIS_SIGMAS * op_sigma:
        return None
    direction = math.copysign(1.0, travel)
    kick = max((direction * (op[j + 2] - op[j]) for j in range(max(k - LEVEL - 2, 0), min(k, n - 2))),
               default=0.0)
    if kick >= KICK_SHARE * abs(travel):
        return None
    return Slip(start, k, abs(travel), jump)


def stick_slip_events(op: np.ndarray, pv: np.ndarray, process_type: str) -> tuple[list[Slip], float, dict]:
    """The slips of a record, OP's whole travel (sum of its runs) and the levels used."""
    op = np.asarray(op, float)
    proxy = _proxy(pv, process_type)
    ops = np.convolve(op, np.ones(3) / 3, mode="same")
    ops[0], ops[-1] = op[0], op[-1]
    sigma = _noise(proxy)
    op_sigma = max(noise_level(op) / math.sqrt(3.0), 1e-12)
    turns = zigzag_turns(ops, HYSTERESIS_SIGMAS * op_sigma)
    total = float(np.sum(np.abs(np.diff(ops[turns]))))
    step = median_steps(proxy)
    slips = [s for a, b in zip(turns[:-1], turns[1:])
             if (s := _slip_in_run(a, b, proxy, op, ops, step, sigma, op_sigma)) is not None]
    return slips, total, {"runs": len(turns) - 1, "proxy_noise": sigma, "op_noise": op_sigma}


def stick_slip_index(op: np.ndarray, pv: np.ndarray, dt_s: float, process_type: str) -> Indicator:
    """Share of OP's travel made in stuck sections that end in a slip (module docstring), in [0, 1]."""
    name = "stick_slip"
    op = np.asarray(op, float)
    if len(op) < 30:
        return not_applicable(name, "record shorter than 30 samples", STICK_SLIP_REF)
    slips, total, detail = stick_slip_events(op, pv, process_type)
    if total <= 0 or detail["runs"] < 2:
        return not_applicable(name, "OP does not move beyond its noise", STICK_SLIP_REF)
    index = min(sum(s.op_travel for s in slips) / total, 1.0)
    detail.update({"slips": len(slips), "proxy": "pv_slope" if process_type == INTEGRATING else "pv",
                   "slip_times_s": [round(s.slip * dt_s, 1) for s in slips[:20]]})
    return Indicator(name, index, "stiction" if index >= STICK_SLIP_DECISION else "no_stiction", detail,
                     STICK_SLIP_REF)
