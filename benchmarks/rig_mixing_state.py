"""Prototype (measurement only, not the shipped filter): does a probe-side mixing zone, a second state of the
reaction invariant that the probe reads and that exchanges with the bulk with time constant tau, explain the
misfit that the estimator's fitted rate uncertainty (130-150 % a step) absorbs?

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_mixing_state.py [FOLD ...]
(FOLD: index of the held-out run in name order, default all five; about a minute each).

Per leave-one-run-out fold: the estimator fitted on four runs gives the strengths and volume; then the one-state
filter (the shipped recursion without the strength adaptation) and the two-state one have their noise model (rate
uncertainty, pH walk, probe noise; and tau) fitted by maximum likelihood (Powell) on the same four runs, and both
score the held-out run by its innovations' negative log-likelihood per sample (lower is better). Pure Python and
numpy per sample: slow, and only for this question.
"""

from __future__ import annotations

import glob
import math
import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from phfdi.benchmarks.rig_detection import CHANNELS
from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.learned import read_measured


def _predict(ref, xb: float, q, dt: float) -> tuple[float, float]:
    """The bulk's invariant after dt (exact for constant flows, as the shipped filter) and the decay factor."""
    s, v = [f.strength_mM for f in ref.feeds], ref.volume_ml
    inflow = s[0] * q[0] + s[1] * q[1]
    d = (q[0] + q[1]) / v
    if d > 0:
        a = math.exp(-d * dt)
        xss = inflow / v / d
        return xss + (xb - xss) * a, a
    return xb + inflow / v * dt, 1.0


def nll(ref, rec, rel: float, walk: float, pnoise: float, tau: float, two: bool) -> tuple[float, int]:
    """Negative log-likelihood of the innovations over a record, and the samples scored."""
    t, x = rec.time_s - rec.time_s[0], rec.x
    ph = x[:, 2]
    ok = np.isfinite(ph)
    xm = ref.x_of_ph(np.where(ok, ph, 7.0))
    beta = ref.beta_of_ph(np.where(ok, ph, 7.0))
    xb = xp = float(xm[0])
    cov = np.eye(2) * (pnoise * beta[0]) ** 2
    total, n = 0.0, 0
    for k in range(1, len(t)):
        dt = t[k] - t[k - 1]
        if not dt > 0:
            continue
        xb_new, a = _predict(ref, xb, x[k - 1, :2], dt)
        step = xb_new - xb
        bp = ref.beta_of_ph(np.array([ref.ph_of_x(xb_new)]))[0]
        qv = rel * rel * step * step + walk * walk * bp * bp * dt
        if two:  # the probe's zone relaxes towards the bulk's mean over the step
            e = math.exp(-dt / tau)
            xp = xp * e + (1 - e) * 0.5 * (xb + xb_new)
            f = np.array([[a, 0.0], [(1 - e) * 0.5 * (1 + a), e]])
            pm = f @ cov @ f.T + np.diag([qv, 0.0])
        else:  # the probe reads the bulk: one state, written in the same two-by-two form
            xp = xb_new
            pm = np.full((2, 2), a * a * cov[0, 0] + qv)
        xb = xb_new
        if ok[k]:
            s = pm[1, 1] + (pnoise * beta[k]) ** 2 + 1e-12
            nu = xm[k] - xp
            gain = pm[:, 1] / s
            xb, xp = xb + gain[0] * nu, xp + gain[1] * nu
            cov = pm - np.outer(gain, pm[1, :])
            total += 0.5 * (math.log(s) + nu * nu / s)
            n += 1
        else:
            cov = pm
        if not two:
            xp = xb
    return total, n


def fit(ref, train, two: bool) -> tuple[np.ndarray, float]:
    """(rate, walk, probe noise[, tau]) of lowest training NLL, and that NLL."""
    def cost(th: np.ndarray) -> float:
        rel, walk, pn = np.exp(th[:3])
        tau = math.exp(th[3]) if two else 1.0
        return sum(nll(ref, r, rel, walk, pn, tau, two)[0] for r in train)

    x0 = [math.log(1.4), math.log(0.003), math.log(0.04)] + ([math.log(3.0)] if two else [])
    res = minimize(cost, x0, method="Powell", options={"maxfev": 250, "xtol": 1e-2, "ftol": 1e-4})
    return np.exp(res.x), float(res.fun)


def main() -> None:
    data = os.environ.get("PHFDI_SHARED_DATA", "../shared/data")
    paths = sorted(glob.glob(str(Path(data) / "ph_rig" / "*.csv")))
    if not paths:
        raise SystemExit(f"no rig runs under {data}/ph_rig")
    cmap = shipped_map("ph_rig")
    recs = {p: read_measured(p, cmap, channels=list(CHANNELS)) for p in paths}
    for i in [int(a) for a in sys.argv[1:]] or range(len(paths)):
        held = paths[i]
        train = [recs[q] for q in paths if q != held]
        ref = fit_estimator(train, start_from_model("rig_flask")).reference
        print(f"held out {Path(held).name}: the estimator's fitted rate uncertainty {ref.noise.rate_rel_std:.3f}",
              flush=True)
        for two in (False, True):
            th, val = fit(ref, train, two)
            rel, walk, pn = th[:3]
            tau = th[3] if two else 1.0
            h, n = nll(ref, recs[held], rel, walk, pn, tau, two)
            print(f"  {'two-state' if two else 'one-state'}: rate {rel:.3f}, walk {walk:.4f} pH/sqrt(s), probe "
                  f"{pn:.4f} pH" + (f", tau {tau:.2f} s" if two else "") + f"; training NLL {val:.1f}, "
                  f"held-out NLL per sample {h / n:.3f} ({n} samples)", flush=True)


if __name__ == "__main__":
    main()
