"""Dead-band evidence: does PV follow a stem that sticks better than it follows OP? A screen-sized valve-model test.

A sticky valve's stem stands still while OP travels its dead-band and then catches up (Kano et al. 2004); a
dead-band of width S between OP and the process does the same without the jump. So, on the record itself:
pass OP through a backlash and through Kano's model with J = S over a grid of widths (1 to 120 % of OP's
central 95 % span, log-spaced), and ask which input explains PV's sample-to-sample changes best, OP itself or
one of these stems. The explanation is an ARX model fitted by least squares, the same for every candidate input:

    dPV(k) = a1 dPV(k-1) + a2 dPV(k-2) + sum_{j=1..L} b_j du(k-j+1) + c,     dPV(k) = PV(k+1) - PV(k)

with du the input's change (its level, less its mean, for an integrating process: a level's change is its net
inflow) and L = :data:`LAGS` samples of input lags, enough for the dead times of the training loops (up to 10
samples); the autoregression carries the process lag and coloured disturbances. The index is the share of the
OP model's residual sum of squares the best stem removes, 1 - RSS_stem / RSS_OP: 0 (or below) when OP explains
PV as well as any stem (a healthy valve), towards 1 when PV moves only when a stem that sticks moves.

It is the project's valve-model (Hammerstein) fit (:mod:`.hammerstein`) cut down to what a screen of thousands
of loops can afford: no held-out split, no FOPTD search, two valve models on a ten-point grid, one batched
pass of the blocks (:func:`valve_actuator.batch.positions`) and 21 small least-squares fits, a few tens of
milliseconds per 751-sample loop. Its weakness is the one of every OP-PV fit in closed loop: a healthy loop
whose OP keeps compensating a load looks like a dead-band (docs/loop_diagnosis.md, Limitations), which is why
it is one input of the classifier and not a verdict of its own.
"""

from __future__ import annotations

import math

import numpy as np

from valve_actuator.batch import positions
from valve_actuator.blocks import Backlash, Stiction

from .indicators import INTEGRATING, Indicator, noise_level, not_applicable

DEADBAND_REF = ("Kano, Maruta, Kugemoto & Shimizu (2004), 'Practical model and detection algorithm for valve "
                "stiction', IFAC DYCOPS: a stem that sticks for S and slips; here fitted as the input of an ARX "
                "model of PV's changes against OP itself (this project's screen, phfdi.loopdiag.deadband)")
#: input lags of the ARX model (samples)
LAGS = 12
#: autoregressive lags
AR_LAGS = 2
#: dead-band widths tried, as fractions of OP's central 95 % span (log-spaced, :data:`WIDTHS` of them)
WIDTH_RANGE = (0.01, 1.2)
WIDTHS = 10


def _design(y: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Regressors of y[k] for k = LAGS .. len(y) - 1: y's own lags, the input's lags 1..LAGS (``base`` aligned
    with y) and a constant."""
    n = len(y)
    cols = [y[LAGS - i:n - i] for i in range(1, AR_LAGS + 1)]
    cols += [base[LAGS - j:n - j] for j in range(1, LAGS + 1)]
    cols.append(np.ones(n - LAGS))
    return np.column_stack(cols)


def arx_rss(y: np.ndarray, u: np.ndarray, integrating: bool) -> float:
    """Residual sum of squares of the ARX model of PV's changes y with input u (module docstring)."""
    base = u - float(np.mean(u)) if integrating else np.diff(np.concatenate([u[:1], u]))
    x = _design(y, base)
    t = y[LAGS:]
    coef, *_ = np.linalg.lstsq(x, t, rcond=None)
    r = t - x @ coef
    return float(r @ r)


def deadband_evidence(op: np.ndarray, pv: np.ndarray, process_type: str) -> Indicator:
    """Share of the OP model's error a sticking stem removes (module docstring), with the best stem's model and
    width (% of OP's span) in ``detail``."""
    name = "deadband_evidence"
    op, pv = np.asarray(op, float), np.asarray(pv, float)
    if len(op) < 4 * LAGS:
        return not_applicable(name, f"record shorter than {4 * LAGS} samples", DEADBAND_REF)
    lo, hi = np.percentile(op, [2.5, 97.5])
    span = float(hi - lo)
    if span <= 3.0 * noise_level(op) or span <= 0.0:
        return not_applicable(name, "OP does not move beyond its noise", DEADBAND_REF)
    y = np.diff(pv)
    u = op[1:]
    integrating = process_type == INTEGRATING
    r_op = arx_rss(y, u, integrating)
    if r_op <= 0.0:
        return not_applicable(name, "PV's changes are explained exactly (no noise)", DEADBAND_REF)
    widths = span * np.geomspace(*WIDTH_RANGE, WIDTHS)
    blocks = [Backlash(width_pct=float(w)) for w in widths] + [Stiction(s_pct=float(w), j_pct=float(w)) for w in widths]
    stems = positions(blocks, u)
    rss = np.array([arx_rss(y, s, integrating) for s in stems])
    k = int(np.argmin(rss))
    gain = 1.0 - float(rss[k]) / r_op
    kind = "backlash" if k < WIDTHS else "stiction (J = S)"
    return Indicator(name, gain, "stiction" if gain >= 0.1 else "no_stiction",
                     {"model": kind, "width_pct_of_span": 100.0 * float(widths[k % WIDTHS]) / span,
                      "rss_ratio": float(rss[k]) / r_op, "log_likelihood_ratio":
                      0.5 * (len(y) - LAGS) * math.log(r_op / max(float(rss[k]), 1e-300))}, DEADBAND_REF)
