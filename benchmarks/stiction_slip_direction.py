"""Does a slip's direction tell a sticky valve from a healthy loop? The stick-slip index with and without it.

    .venv/bin/python benchmarks/stiction_slip_direction.py                 # 2000 + 1000 loops (about 3 min)
    .venv/bin/python benchmarks/stiction_slip_direction.py --loops 400

The stick-slip index (``phfdi.loopdiag.stickslip``) counts stuck sections of OP that end in a jump of PV. A
slip of a sticky valve under a PI controller moves PV *towards* the setpoint: while the valve stands the error
SP - PV holds its sign, the integral action drives OP that way, and the stem's jump carries PV with it (for a
level, its slope). A load step on a healthy loop sitting at its setpoint moves PV either way. This script asks
whether keeping only the slips that move PV towards the setpoint (``toward``), and only those after an error
of at least 1 or 2 noise levels of PV (``toward, abs(e) >= k sigma``), separates sticky loops better. Loops are
drawn from both generators with development seeds no training set or test uses (domain 35103, training 4243);
the cut on each index is the verdict's rule (at most 2 % of the loops without stiction, and of the hard
negatives among them, reach it: :func:`stiction_information_bound.false_call_cut`). No real record is read.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
from stiction_information_bound import HARD, draw, false_call_cut

#: development seeds: neither training (35001, 35002), the fresh test (1013, 2026) nor the information bound
#: (35102, 4242) uses them
SEEDS = {"domain": 35103, "training": 4243}
#: the variants: None keeps every slip (the shipped index); k >= 0 keeps slips towards SP after abs(e) >= k sigma
VARIANTS = {"shipped (every slip)": None, "toward the setpoint": 0.0, "toward, abs(e) >= 1 sigma": 1.0,
            "toward, abs(e) >= 2 sigma": 2.0}


def indices(op: np.ndarray, pv: np.ndarray, sp: np.ndarray | None, process_type: str) -> dict[str, float]:
    """The index of each variant on one loop (0 where the shipped index does not apply)."""
    from phfdi.loopdiag.indicators import noise_level
    from phfdi.loopdiag.stickslip import stick_slip_events

    slips, total, detail = stick_slip_events(op, pv, process_type)
    if total <= 0 or detail["runs"] < 2 or len(op) < 30:
        return {name: 0.0 for name in VARIANTS}
    err = None if sp is None else np.asarray(sp, float) - np.asarray(pv, float)
    sigma = max(noise_level(np.asarray(pv, float)), 1e-12)
    out = {}
    for name, k in VARIANTS.items():
        kept = 0.0
        for s in slips:
            if k is not None and err is not None:
                e = float(np.median(err[s.start:s.slip - 1]))
                if np.sign(s.jump) != np.sign(e) or abs(e) < k * sigma:
                    continue
            kept += s.op_travel
        out[name] = min(kept / total, 1.0)
    return out


def auc(pos: np.ndarray, neg: np.ndarray) -> float:
    """Rank AUC (ties count half)."""
    from scipy.stats import mannwhitneyu

    return float(mannwhitneyu(pos, neg).statistic / (len(pos) * len(neg)))


def report(generator: str, loops: list) -> None:
    rows = []
    for loop, run in loops:
        sp = run["sp"] if "sp" in run else None
        rows.append((loop.stiction, loop.loop_class, indices(run["op_pct"], run["pv"], sp, loop.process_type)))
    y = np.array([r[0] for r in rows])
    hard = np.array([r[1] in HARD for r in rows])
    print(f"\n{generator} generator (seed {SEEDS[generator]}): {int(y.sum())} sticky loops, {int((~y).sum())} without")
    print("| stick-slip index | rank AUC | cut (2 % false calls) | sticky loops past the cut | loops with a slip: "
          "sticky / without |")
    print("|---|---|---|---|---|")
    for name in VARIANTS:
        v = np.array([r[2][name] for r in rows])
        cut = false_call_cut(v, [~y, ~y & hard])
        found = v[y] >= cut if cut > 0 else np.zeros(int(y.sum()), bool)
        print(f"| {name} | {auc(v[y], v[~y]):.3f} | {cut:.3f} | {found.mean():.3f} ({int(found.sum())}/{len(found)}) | "
              f"{np.mean(v[y] > 0):.2f} / {np.mean(v[~y] > 0):.2f} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--loops", type=int, default=None,
                   help="loops per generator (default: 2000 domain, 1000 training; half of the latter sticky)")
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    for generator, n in (("domain", args.loops or 2000), ("training", args.loops or 1000)):
        loops = draw(generator, n, SEEDS[generator])
        print(f"{generator}: {len(loops)} loops drawn, {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        report(generator, loops)
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
