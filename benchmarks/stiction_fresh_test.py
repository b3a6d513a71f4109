"""The stiction classifier on a fresh synthetic test set, per class of loop (never trained on).

    .venv/bin/python benchmarks/stiction_fresh_test.py                      # 40 loops per class, seed 1013 (Dask)
    .venv/bin/python benchmarks/stiction_fresh_test.py --from-rows benchmarks/results/stiction_fresh_test.json
    .venv/bin/python benchmarks/stiction_fresh_test.py --model other_model.json --from-rows ROWS.json

Draws loops of each class of ``phfdi.loopdiag.training.LOOP_CLASSES`` with a seed no training set
uses (1013): healthy valves answering load steps and ramps, healthy loops tuned to oscillate,
healthy loops under other disturbances, sticky valves (Kano and He models), other valve
nonlinearities (dead-zone, quantisation, saturation) and backlash. Computes every feature of the
classifier (indicators and the Kano/backlash Hammerstein fits) on Dask, writes the rows, and
prints for the model (the shipped one by default): accuracy, precision and recall for "stiction"
over all classes but backlash (a dead-band is Kano's model with J = 0: neither label is right, so
it is reported apart and not scored), and the share of each class called stiction.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from phfdi.loopdiag.classifier import load_model
from phfdi.loopdiag.dask_run import dask_client, map_ordered
from phfdi.loopdiag.dataset import synthetic_row
from phfdi.loopdiag.features import FEATURE_NAMES
from phfdi.loopdiag.training import LOOP_CLASSES, class_round_robin, draw_class_loops

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "stiction_fresh_test.json"
#: never used by a training set (benchmarks/stiction_dataset.py)
TEST_SEED = 1013
UNSCORED = ("backlash",)


def evaluate(rows: list[dict], model) -> dict:
    """Metrics over the scored classes and the share called stiction per class."""
    x = np.array([r["features"] for r in rows], float)
    called = model.probability(x) >= model.threshold
    y = np.array([r["stiction"] for r in rows], bool)
    cls = [r["loop_class"] for r in rows]
    scored = np.array([c not in UNSCORED for c in cls])
    yy, pp = y[scored], called[scored]
    tp, fp = int(np.sum(pp & yy)), int(np.sum(pp & ~yy))
    fn, tn = int(np.sum(~pp & yy)), int(np.sum(~pp & ~yy))
    out = {"loops": int(scored.sum()), "tp": tp, "fp": fp, "fn": fn, "tn": tn,
           "accuracy": (tp + tn) / max(len(yy), 1), "precision": tp / (tp + fp) if tp + fp else float("nan"),
           "recall": tp / (tp + fn) if tp + fn else float("nan"), "classes": {}}
    for c in LOOP_CLASSES:
        idx = [i for i, cc in enumerate(cls) if cc == c]
        if idx:
            out["classes"][c] = {"loops": len(idx), "called_stiction": int(np.sum(called[idx]))}
    kinds: dict[str, list[int]] = {}
    for i, r in enumerate(rows):
        if r["loop_class"] == "other_nonlinearity":
            kinds.setdefault(r["valve"][0], []).append(i)
    out["other_nonlinearity_kinds"] = {k: {"loops": len(v), "called_stiction": int(np.sum(called[v]))}
                                       for k, v in sorted(kinds.items())}
    return out


def print_report(m: dict, label: str) -> None:
    print(f"{label}: accuracy {m['accuracy']:.3f}, precision {m['precision']:.3f}, recall {m['recall']:.3f} "
          f"(TP {m['tp']}, FP {m['fp']}, FN {m['fn']}, TN {m['tn']}; {m['loops']} scored loops)")
    print("| class | label | loops | called stiction |\n|---|---|---|---|")
    for c, v in m["classes"].items():
        lab = "stiction" if c == "stiction" else ("not scored" if c in UNSCORED else "no stiction")
        print(f"| {c} | {lab} | {v['loops']} | {v['called_stiction']} ({v['called_stiction'] / v['loops']:.0%}) |")
    for k, v in m["other_nonlinearity_kinds"].items():
        print(f"| other_nonlinearity: {k} | no stiction | {v['loops']} | {v['called_stiction']} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--per-class", type=int, default=40)
    p.add_argument("--seed", type=int, default=TEST_SEED)
    p.add_argument("--out", type=Path, default=OUT, help="where the computed rows are written")
    p.add_argument("--from-rows", type=Path, default=None, help="evaluate rows written earlier")
    p.add_argument("--model", type=Path, default=None, help="model JSON (default: the shipped model)")
    p.add_argument("--scheduler", default=None)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--json", type=Path, default=None, help="also write the metrics here")
    args = p.parse_args(argv)
    model = load_model(args.model)
    if args.from_rows:
        doc = json.loads(args.from_rows.read_text())
        if doc["features"] != list(FEATURE_NAMES):
            print(f"{args.from_rows}: its features are not this version's; compute the rows again", file=sys.stderr)
            return 2
        rows = doc["rows"]
    else:
        t0 = time.perf_counter()
        loops = [d for d, _ in draw_class_loops(class_round_robin(args.per_class), args.seed, "TEST")]

        def show(done, total):
            if done % 20 == 0 or done == total:
                print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

        with dask_client(args.scheduler, args.workers) as client:
            rows = map_ordered(client, synthetic_row, loops, show)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"features": list(FEATURE_NAMES), "seed": args.seed, "rows": rows}, indent=0))
        print(f"{len(rows)} loops in {time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    m = evaluate(rows, model)
    print_report(m, f"fresh synthetic test set (seed {args.seed}, {args.model or 'shipped model'})")
    if args.json:
        args.json.write_text(json.dumps(m, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
