"""Does the same sample interval carry dead-band evidence the screen leaves out? Measured, not shipped.

    .venv/bin/python benchmarks/stiction_same_interval.py               # 400 loops a generator (about 1 min)
    .venv/bin/python benchmarks/stiction_same_interval.py --loops 1000  # the figures of docs/loop_diagnosis.md

The dead-band screen (``phfdi.loopdiag.deadband``) explains PV's change over a sample interval by the input's
changes over the intervals before it (input lags 1-12): with the controller acting once per record sample, the
change of the same interval is not yet the process's answer. Under a historian's 10 s, a DCS scans several
times per sample, and a fast process (a flow) answers a slip within the interval it happens in, so the same
interval's change (lag 0) carries the answer; it also carries the controller's answer to PV's own change (OP
relays PV's noise through the proportional action), which is feedback, not the valve. This script measures
three variants of the screen's index against the shipped one, on both generators' loops at the simulator's scan
and at ten scans per record sample (``SyntheticLoop.scan_s``):

* ``lag 0``: the input's lags 0-12, for OP and for every stem alike;
* ``OP's lag 0 as nuisance``: the shipped lags 1-12, and OP's same-interval change as one more regressor of
  every model (it takes up the controller's feedback alike for OP and the stems).

Where the controller acts once per record sample, OP's changes and PV's are tied by the PI controller's own
equation, which has no noise in it (its velocity form, differenced once more, links OP's changes at lags 0 and 1
with PV's at lags 0 and 1). So a model given OP's lag 0 and PV's own lags fits PV's change exactly: it has found
the controller, not the process, and the index (a ratio of round-off) is undefined. Those loops are counted
(``OP model exact``) and scored -1 in that variant. For each variant: the rank AUC (sticky against the other
loops), and the sticky loops whose index passes the verdict's false-call rule (at most 2 % of the loops without
stiction, and of the hard negatives, reach it; ``stiction_information_bound.false_call_cut``). The 59 refinery
records are read only as a pool (shuffled, labels.csv not read, nothing printed per record): the share of the
pool that passes each cut. Development seeds
no training set, test or earlier bound uses; prints figures, no pass/fail; changes nothing.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace

import numpy as np
from stiction_domain_shift import DATA, real_records
from stiction_information_bound import HARD, draw, false_call_cut, rank_auc

#: development seeds: neither training (35001, 35002), the fresh tests (1013, 2026-2032), the bounds nor the
#: earlier development draws (35101-35111, 4242-4253) use them
SEEDS = {"domain": 35112, "training": 4254}
SCANS = 10
#: (name, the input's lag 0 in the model, OP's same-interval change as a nuisance regressor)
VARIANTS = (("shipped (lags 1-12)", False, False), ("lag 0", True, False), ("OP's lag 0 as nuisance", False, True))
#: an OP model that leaves less than this share of PV's changes' sum of squares unexplained has fitted the
#: controller's own equation (below), not the process: the index is undefined there
EXACT_FIT = 1e-6


def rss(y: np.ndarray, u: np.ndarray, integrating: bool, lag0: bool, nuisance: np.ndarray | None) -> float:
    """Residual sum of squares of the screen's ARX model of PV's changes ``y`` (``phfdi.loopdiag.deadband``),
    with the input's lag 0 when ``lag0`` and ``nuisance`` as one more regressor."""
    from phfdi.loopdiag.deadband import AR_LAGS, LAGS

    base = u - float(np.mean(u)) if integrating else np.diff(np.concatenate([u[:1], u]))
    n = len(y)
    cols = [y[LAGS - i:n - i] for i in range(1, AR_LAGS + 1)]
    cols += [base[LAGS - j:n - j] for j in range(0 if lag0 else 1, LAGS + 1)]
    if nuisance is not None:
        cols.append(nuisance[LAGS:n])
    cols.append(np.ones(n - LAGS))
    x, t = np.column_stack(cols), y[LAGS:]
    coef, *_ = np.linalg.lstsq(x, t, rcond=None)
    r = t - x @ coef
    return float(r @ r)


def indices(op: np.ndarray, pv: np.ndarray, process_type: str) -> list[float]:
    """Every variant's index, 1 - RSS(best stem) / RSS(OP), on the screen's stems (NaN where the screen does not
    apply: OP within its noise; inf where the OP model fits the controller's equation exactly)."""
    import valve_actuator.blocks  # noqa: F401  (registers the valve blocks)
    from phfdi.loopdiag.deadband import LAGS, WIDTH_RANGE, WIDTHS
    from phfdi.loopdiag.indicators import INTEGRATING, noise_level
    from valve_actuator.batch import positions
    from valve_actuator.blocks import Backlash, Stiction

    op, pv = np.asarray(op, float), np.asarray(pv, float)
    lo, hi = np.percentile(op, [2.5, 97.5])
    span = float(hi - lo)
    if span <= 3.0 * noise_level(op) or span <= 0.0:
        return [math.nan] * len(VARIANTS)
    y, u, integrating = np.diff(pv), op[1:], process_type == INTEGRATING
    d_op = np.diff(np.concatenate([u[:1], u]))  # OP's change over the same interval as y
    widths = span * np.geomspace(*WIDTH_RANGE, WIDTHS)
    stems = positions([Backlash(width_pct=float(w)) for w in widths]
                      + [Stiction(s_pct=float(w), j_pct=float(w)) for w in widths], u)
    total = float(np.sum((y[LAGS:] - np.mean(y[LAGS:])) ** 2))
    out = []
    for _, lag0, nuis in VARIANTS:
        nuisance = d_op if nuis else None
        r_op = rss(y, u, integrating, lag0, nuisance)
        if r_op <= EXACT_FIT * total:  # the controller's equation, fitted exactly (module docstring)
            out.append(math.inf)
            continue
        best = min(rss(y, s, integrating, lag0, nuisance) for s in stems)
        out.append(1.0 - best / r_op)
    return out


def loop_row(loop) -> list[float]:
    """Sticky, hard negative, then every variant at the simulator's scan and at SCANS scans per sample."""
    from phfdi.loopdiag.synthetic import simulate_loop

    out = [float(loop.stiction), float(loop.loop_class in HARD)]
    for scan_s in (0.0, loop.spec.dt_s / SCANS):
        run = simulate_loop(replace(loop.spec, scan_s=scan_s))
        out += indices(run["op_pct"], run["pv"], loop.process_type)
    return out


def real_pool() -> np.ndarray:
    """Every variant's index on the usable records, in a shuffled order (no file name or label kept)."""
    rows = [indices(run["op_pct"], run["pv"], run.metadata.get("process_type", "self_regulating"))
            for run in real_records()]
    return np.array(rows).reshape(-1, len(VARIANTS))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loops", type=int, default=400, help="simulated loops per generator, half sticky (default 400)")
    args = ap.parse_args(argv)
    if args.loops < 20:
        ap.error(f"--loops {args.loops}: at least 20, so that both classes and the hard negatives are drawn")
    from phfdi.loopdiag.dask_run import dask_client, map_ordered

    t0 = time.perf_counter()
    real = real_pool()
    if len(real) == 0:
        print(f"stiction_same_interval: no usable loop record under {DATA} (set PHFDI_SHARED_DATA to the folder "
              "that holds plant_loops/)", file=sys.stderr)
        return 2
    real_exact = np.mean(np.isinf(real), axis=0)
    real = np.nan_to_num(real, nan=-1.0, posinf=-1.0)
    k = len(VARIANTS)
    print(f"real pool of {len(real)} records (labels not read); the index below the screen's reach, or undefined "
          "(OP model exact), counts as -1")
    print("| generator | scan | index | OP model exact | rank AUC | sticky loops past the 2 % cut | cut | "
          "real pool past the cut (OP model exact) |")
    print("|---|---|---|---|---|---|---|---|")
    with dask_client(None, None) as client:
        for generator, seed in SEEDS.items():
            loops = [loop for loop, _ in draw(generator, args.loops, seed)]
            raw = np.array(map_ordered(
                client, loop_row, loops,
                lambda d, n, g=generator: print(f"{g}: {d}/{n} loops ({time.perf_counter() - t0:.0f} s)",
                                                file=sys.stderr) if d % 100 == 0 or d == n else None, chunk=4))
            a = np.nan_to_num(raw, nan=-1.0, posinf=-1.0)
            st, hard = a[:, 0] > 0.5, a[:, 1] > 0.5
            for s, scan in enumerate(("every sample", f"{SCANS} a sample")):
                x = a[:, 2 + s * k:2 + (s + 1) * k]
                exact = np.isinf(raw[:, 2 + s * k:2 + (s + 1) * k])
                for j, (name, _, _) in enumerate(VARIANTS):
                    cut = false_call_cut(x[:, j], [~st, ~st & hard])
                    print(f"| {generator} (seed {seed}) | {scan} | {name} | {np.mean(exact[:, j]):.0%} | "
                          f"{rank_auc(x[:, j], st):.3f} | {np.mean(x[st, j] >= cut):.3f} | {cut:.3f} | "
                          f"{np.mean(real[:, j] >= cut):.2f} ({real_exact[j]:.0%}) |")
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
