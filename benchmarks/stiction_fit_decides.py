"""Should the valve-model fit decide where the screen does not? Development loops, before and after the rule.

    .venv/bin/python benchmarks/stiction_fit_decides.py                 # 2000 loops a generator (about 7 min, Dask)
    .venv/bin/python benchmarks/stiction_fit_decides.py --loops 400 --out OUT.json

The verdict's screen (indicators and the dead-band screen, a logistic model) leaves a loop ``undetermined`` when
its calibrated p falls between 0.5 and the operating point; the valve-model (Hammerstein) fit runs on those loops
too, but until 2026-12-07 it could only take a stiction call back. This script runs the whole diagnosis on loops
of both generators drawn with development seeds no training set, test or earlier measurement uses (domain 35107,
training 4248; half sticky, the rest spread over the generator's other classes) and counts, for the verdict as
shipped and with the rule of :func:`phfdi.loopdiag.verdict.friction_decides` applied to its undetermined loops
(the fit names friction, and Kano's S is above 3 noise levels of OP), the recall and the false calls on the loops
without stiction and on the hard negatives among them. Run against a model whose operating point already
includes the rule, "shipped" and "with the rule" are the same. No real record is read.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from stiction_information_bound import HARD, draw

#: development seeds: neither training (35001, 35002), the fresh tests (1013, 2026-2030), nor earlier bounds use them
SEEDS = {"domain": 35107, "training": 4248}


def fit_row(loop) -> dict:
    """The verdict of one loop through the whole diagnosis, and what the valve-model fit said."""
    from phfdi.loopdiag.diagnose import Settings
    from phfdi.loopdiag.single import diagnose_run
    from phfdi.loopdiag.synthetic import simulate_loop
    from phfdi.loopdiag.verdict import friction_decides

    run = simulate_loop(loop.spec)
    run.metadata["process_type"] = loop.process_type
    rep = diagnose_run(run, Settings(baselines=False))
    lv = rep.get("loop_verdict") or {}
    st = rep.get("stiction") or {}
    return {"class": loop.loop_class, "stiction": bool(loop.stiction), "verdict": lv.get("verdict", "error"),
            "screen": st.get("verdict"), "decided": lv.get("decided_by_valve_model") is not None,
            "fit_decides": friction_decides(rep) is not None if "stiction" in rep and rep["stiction"] else False,
            "cause": rep.get("cause"), "error": rep.get("error")}


def report(generator: str, rows: list[dict]) -> None:
    y = np.array([r["stiction"] for r in rows])
    hard = np.array([r["class"] in HARD for r in rows])
    v = np.array([r["verdict"] for r in rows])
    decides = np.array([r["fit_decides"] for r in rows])
    without = np.where(v == "stiction", ~np.array([r["decided"] for r in rows]), False)
    with_rule = (v == "stiction") | ((v == "undetermined") & decides)
    print(f"\n{generator} generator (seed {SEEDS[generator]}): {int(y.sum())} sticky loops, {int((~y).sum())} without "
          f"({int(hard.sum())} hard negatives)")
    print("| verdict | recall | false calls | on hard negatives | undetermined |\n|---|---|---|---|---|")
    for label, called in (("without the rule", without), ("with the rule", with_rule)):
        und = (v == "undetermined") & ~called | ((v == "stiction") & ~called)
        print(f"| {label} | {called[y].mean():.3f} ({int(called[y].sum())}) | {called[~y].mean():.1%} "
              f"({int(called[~y].sum())}) | {called[hard].mean():.1%} ({int(called[hard].sum())}) | {und.mean():.1%} |")
    moved = with_rule & ~without
    print("decided by the fit, by class: " + ", ".join(f"{c} {k}" for c, k in
                                                     Counter(r["class"] for r, m in zip(rows, moved) if m).items()))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--loops", type=int, default=2000, help="loops per generator, half of them sticky (default 2000)")
    p.add_argument("--out", type=Path, default=None, help="also write the rows here (JSON)")
    args = p.parse_args(argv)
    from phfdi.loopdiag.dask_run import dask_client, map_ordered

    t0 = time.perf_counter()
    out = {}
    with dask_client(None, None) as client:
        for generator, seed in SEEDS.items():
            loops = [loop for loop, _ in draw(generator, args.loops, seed)]
            print(f"{generator}: {len(loops)} loops drawn, {time.perf_counter() - t0:.0f} s", file=sys.stderr)

            def show(done: int, total: int) -> None:
                if done % 200 == 0 or done == total:
                    print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
            out[generator] = map_ordered(client, fit_row, loops, show, chunk=4)
            report(generator, out[generator])
    if args.out:
        args.out.write_text(json.dumps(out))
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
