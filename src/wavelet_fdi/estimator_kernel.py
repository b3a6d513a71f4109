"""The estimator's recursion, compiled: one pass of the Kalman filter and its strength adaptation over a chunk.

:class:`wavelet_fdi.reference_estimator.EstimatorStream` keeps the state and calls :func:`compiled` (:func:`_run`
compiled) once per chunk of rows. Why compiled (Numba): the filter is a scalar recursion whose every step depends
on the last (a table lookup at the predicted state, a gain, a correction), so numpy cannot vectorise it; as plain
Python it cost 3.2-3.5 us a sample, half of the whole detector's time on the rig (benchmarks/rig_throughput.py),
and every evaluation of the estimator's likelihood fit runs it over all training runs. No fast-math: the compiled
function computes what the same function interpreted by Python does, operation for operation, to the last bit
(tests/learned/test_estimator.py runs both).

Numba is imported on the first call, not with the module: the commands that never run the estimator do not pay
its import (about 0.7 s) and compilation (cached in ``__pycache__`` after the first run on a machine).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Any, Callable

import numpy as np

_COMPILED: Callable[..., Any] | None = None


def _py_max(a: float, b: float) -> float:  # Python's max(a, b): a unless b is larger (NaN: a)
    return b if b > a else a


def _py_min(a: float, b: float) -> float:  # Python's min(a, b): a unless b is smaller
    return b if b < a else a


def _bisect_left(xs, x: float) -> int:  # bisect.bisect_left, comparisons in the same order
    lo, hi = 0, len(xs)
    while lo < hi:
        mid = (lo + hi) // 2
        if xs[mid] < x:
            lo = mid + 1
        else:
            hi = mid
    return lo


def _bisect_right(xs, x: float) -> int:  # bisect.bisect_right
    lo, hi = 0, len(xs)
    while lo < hi:
        mid = (lo + hi) // 2
        if x < xs[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo


def _ridge_solve(gg, gy, out) -> None:
    """(G + ridge I) r = y for the small normal equations of the adaptation (closed form for one or two feeds),
    ridge 1e-6 of the trace; r into ``out``."""
    m = len(gy)
    trace = 0.0
    for i in range(m):
        trace += gg[i, i]
    ridge = 1e-12 + 1e-6 * trace
    if m == 1:
        out[0] = gy[0] / (gg[0, 0] + ridge)
    elif m == 2:
        a, b, c, d = gg[0, 0] + ridge, gg[0, 1], gg[1, 0], gg[1, 1] + ridge
        det = a * d - b * c
        out[0] = (d * gy[0] - b * gy[1]) / det
        out[1] = (a * gy[1] - c * gy[0]) / det
    else:
        out[:] = np.linalg.solve(gg + ridge * np.eye(m), gy)


def _adapt(zf, gg, gy, on, tau: float, lo: float, hi: float, cap: float, blocks: int,
           tr_block, tr_rel, tr_on, tr_fac, tr_zone, ntrace: int, rel) -> int:
    """At a block boundary, in each zone the block's steps were in: move each feed's factor toward the block's
    least-squares estimate, with gain (seconds the feed ran there in the block) / tau; record it in the trace
    arrays; clear the block's sums. Returns the trace's new length."""
    zones, m = zf.shape
    for zone in range(zones):
        ran = False
        for i in range(m):
            if on[zone, i] != 0.0:
                ran = True
        if tau > 0 and ran:
            _ridge_solve(gg[zone], gy[zone], rel)
            tr_block[ntrace] = blocks
            tr_zone[ntrace] = zone
            for i in range(m):
                tr_rel[ntrace, i] = rel[i]
                tr_on[ntrace, i] = on[zone, i]
                tr_fac[ntrace, i] = zf[zone, i]
            ntrace += 1
            for i in range(m):
                f = zf[zone, i]
                step = _py_min(1.0, on[zone, i] / tau) * _py_max(-cap, _py_min(cap, rel[i]))
                zf[zone, i] = _py_min(hi, _py_max(lo, f * (1.0 + step)))
        for i in range(m):
            for j in range(m):
                gg[zone, i, j] = 0.0
            gy[zone, i] = 0.0
            on[zone, i] = 0.0
    return ntrace


def _predict(x: float, fac, strengths, qp, v: float, dt: float) -> tuple[float, float]:
    """The state's decay factor over the step and the predicted x- (flows held over the step)."""
    inflow = 0.0
    qsum = 0.0
    for i in range(len(strengths)):
        inflow += fac[i] * strengths[i] * qp[i]
        qsum += qp[i]
    d = qsum / v
    if d > 0:
        a = math.exp(-d * dt)
        xss = inflow / v / d
        return a, xss + (x - xss) * a
    return 1.0, x + inflow / v * dt


def _curve_at(xs, betas, xp: float) -> tuple[float, float]:
    """pH(x) and the buffer capacity beta there, from the curve's table (0.001 pH steps)."""
    grid_n = len(xs) - 1
    j = _bisect_left(xs, xp)
    j = 1 if j < 1 else grid_n if j > grid_n else j
    xlo, xhi = xs[j - 1], xs[j]
    frac = (xp - xlo) / (xhi - xlo) if xhi > xlo else 0.0
    frac = 0.0 if frac < 0 else 1.0 if frac > 1 else frac
    return (j - 1 + frac) * 0.001, betas[j]


def _standardised(xp: float, x: float, pv: float, a: float, bp: float, dt: float, k: int, xm, r_meas, ph,
                  php: float, rel2: float, walk2: float, eps2: float, sp2: float, tim: float, in_x: bool) -> float:
    """The standardised innovation of reading k against the prediction (xp, from x and P over dt), as the update
    computes it (the gate's look at the reading after a held one)."""
    step = xp - x
    pm = a * a * pv + rel2 * step * step + walk2 * bp * bp * dt
    rate_error = tim * step / dt if dt > 0 else 0.0
    tv = rate_error * rate_error
    if in_x:
        return (xm[k] - xp) / math.sqrt(pm + r_meas[k] + tv)
    return (ph[k] - php) / math.sqrt((pm + eps2 + tv) / (bp * bp) + sp2)


def _resolve_held(x: float, pv: float, held_nu: float, held_sv: float, held_sign: float, gate: float, fac,
                  strengths, qp, v: float, dt: float, xs, betas, k: int, xm, r_meas, ph, rel2: float, walk2: float,
                  eps2: float, sp2: float, tim: float, in_x: bool) -> tuple[float, float]:
    """The state after a held reading, once reading k says what it was: beyond the gate on the same side, the held
    reading's update made on the state held for it (the pH did move); else the state as it is (a lone outlier,
    dropped)."""
    a, xp = _predict(x, fac, strengths, qp, v, dt)
    php, bp = _curve_at(xs, betas, xp)
    z = _standardised(xp, x, pv, a, bp, dt, k, xm, r_meas, ph, php, rel2, walk2, eps2, sp2, tim, in_x)
    if (z > gate and held_sign > 0) or (z < -gate and held_sign < 0):
        g_held = pv / held_sv
        return x + g_held * held_nu, (1.0 - g_held) * pv
    return x, pv


def _accumulate(gg, gy, on, fac, strengths, qp, dt: float, v: float, corr: float) -> None:
    """A zone's block sums for the least-squares strength correction: regressors g_i = f_i s_i q_i dt / V."""
    m = len(strengths)
    for i in range(m):
        gi = fac[i] * strengths[i] * qp[i] * dt / v
        if gi != 0.0:
            gy[i] += gi * corr
            on[i] += dt
            for j in range(m):
                gg[i, j] += gi * (fac[j] * strengths[j] * qp[j] * dt / v)


def _run(t, flows, ok, xm, r_meas, ph, out, unlimited,  # noqa: C901 - one tight loop, as the filter's equations
         strengths, xs, betas, bounds_ph, zf, gg, gy, on, qp, rel,
         tr_block, tr_rel, tr_on, tr_fac, tr_zone, consts, flags, scalars):
    """The recursion over the chunk's rows (module doc of reference_estimator for the equations). ``flows`` is
    written (a missing flow holds the last one); ``out`` gets the residual limited to +-clip, ``unlimited`` the
    same standardised innovation before the limit; the state arrays (factors, block sums, last flows) are updated
    in place; ``scalars`` = (started, x, P, last_t, zone, samples, nll, blocks, held_nu, held_sv, held_sign) in,
    the same out (returned with the trace's length).

    The gate: a reading whose standardised innovation exceeds ``gate`` is held (the state is predicted across it,
    its innovation and likelihood are those of its prediction) until the next reading says what it was. Beyond the
    gate on the same side too: the pH did move so far (a step, a knee the model's timing missed), and the held
    reading's update is made after all (the state and its variance as they would have been, the strength
    adaptation's block sums without it), before the next reading's; else it was a lone outlier and is dropped."""
    v, rel2, walk2, eps2, sp2, tim, clip, gate, tau, lo, hi, cap = consts
    block, correct, adapting, in_x = flags
    started, x, pv, last_t, zone, samples, nll, blocks, held_nu, held_sv, held_sign = scalars
    m = len(strengths)
    ntrace = 0
    for k in range(len(t)):
        for i in range(m):  # a missing flow holds the last one
            if flows[k, i] != flows[k, i]:
                flows[k, i] = qp[i]
        if not started:  # the first sample with a pH starts the state
            if ok[k]:
                started, x, pv, last_t = True, xm[k], r_meas[k], t[k]
                for i in range(m):
                    qp[i] = flows[k, i]
                out[k] = 0.0  # the start: no evidence either way
                unlimited[k] = 0.0
                zone = _bisect_right(bounds_ph, ph[k])  # the zone: how many boundaries lie at or below the pH
            samples += 1
            continue
        dt = t[k] - last_t
        if not dt > 0:
            dt = 0.0
        if held_sign != 0.0:  # the reading before was held at the gate: this one says what it was
            if ok[k] and correct:
                x, pv = _resolve_held(x, pv, held_nu, held_sv, held_sign, gate, zf[zone], strengths, qp, v, dt, xs,
                                      betas, k, xm, r_meas, ph, rel2, walk2, eps2, sp2, tim, in_x)
            held_sign = 0.0
        a, xp = _predict(x, zf[zone], strengths, qp, v, dt)
        php, bp = _curve_at(xs, betas, xp)  # pH(x-) and beta there: the curve's table
        step = xp - x
        pm = a * a * pv + rel2 * step * step + walk2 * bp * bp * dt
        if ok[k]:
            # the reading's timing is uncertain by `tim` seconds: an error of rate * tim, large only while the pH
            # moves fast (a titration's steep part), added to the measurement's variance
            rate_error = tim * step / dt if dt > 0 else 0.0
            tv = rate_error * rate_error  # (a product, not ** 2: libm's pow may differ from it in the last bit)
            sv = pm + r_meas[k] + tv
            nu = xm[k] - xp
            z = nu / math.sqrt(sv) if in_x else (ph[k] - php) / math.sqrt((pm + eps2 + tv) / (bp * bp) + sp2)
            hold = z > gate or z < -gate
            if hold:
                held_nu, held_sv, held_sign = nu, sv, (1.0 if z > 0 else -1.0)
            gain = pm / sv if correct and not hold else 0.0
            corr = gain * nu
            x = xp + corr
            pv = (1.0 - gain) * pm
            out[k] = -clip if z < -clip else clip if z > clip else z
            unlimited[k] = z
            nll += 0.5 * (math.log(sv) + nu * nu / sv)
            if adapting and corr != 0.0:
                _accumulate(gg[zone], gy[zone], on[zone], zf[zone], strengths, qp, dt, v, corr)
        else:
            x, pv = xp, pm
        zone = _bisect_right(bounds_ph, php)  # the next step predicts with the factors of its pH's zone
        last_t = t[k]
        for i in range(m):
            qp[i] = flows[k, i]
        samples += 1
        if samples % block == 0:
            blocks += 1
            ntrace = _adapt(zf, gg, gy, on, tau, lo, hi, cap, blocks, tr_block, tr_rel, tr_on, tr_fac, tr_zone,
                            ntrace, rel)
    return (started, x, pv, last_t, zone, samples, nll, blocks, held_nu, held_sv, held_sign), ntrace


def compiled() -> Callable[..., Any]:
    """:func:`_run` compiled (on the first call in a process; Numba's cache makes later processes quick)."""
    global _COMPILED
    if _COMPILED is None:
        from numba import njit

        if not list((Path(__file__).parent / "__pycache__").glob("estimator_kernel._run-*.nbi")):
            # long work shows progress: without the cache (scripts/setup.sh writes it) this takes about 10 s
            print("wavelet_fdi: compiling the estimator's filter (once, about 10 s) ...", file=sys.stderr, flush=True)

        jit = njit(cache=True)
        for name in ("_py_max", "_py_min", "_bisect_left", "_bisect_right", "_ridge_solve", "_adapt", "_predict",
                     "_curve_at", "_standardised", "_resolve_held", "_accumulate"):
            globals()[name] = jit(globals()[name])
        _COMPILED = jit(_run)
    return _COMPILED

