"""Train the stiction classifier on simulated loops only, and write the shipped model.

    .venv/bin/python benchmarks/stiction_dataset.py             # the simulated loops' features (minutes, Dask)
    .venv/bin/python benchmarks/train_stiction_classifier.py    # seconds: weights, calibration, operating point
    .venv/bin/python benchmarks/train_stiction_classifier.py --no-write   # print only

From benchmarks/results/stiction_dataset.json (phfdi.loopdiag.domain's loops, two seeds):

* the L2 strength by 5-fold cross-validated log-loss on the ``train`` loops, then the weights on all of them
  (each held to the sign its paper reads as stiction);
* Platt's calibration on the ``calibration`` loops (half sticky: the probability is at even prior odds);
* the operating point: "stiction" from the lowest calibrated p at which at most 2 % of the calibration loops
  without stiction, and 2 % of its hard negatives (loops tuned too tight, external oscillations), are called
  stiction by the verdict: p at the cut, unless the valve-model fit takes the call back, or p undetermined and
  the fit decides for stiction (the rows' ``valve_fit``, phfdi.loopdiag.verdict); "no stiction" below 0.5;
  undetermined between;
* the calls on the calibration loops per class, the weights, and writes
  src/phfdi/loopdiag/models/stiction_classifier.json.

No real record is read or scored here: benchmarks/stiction_real_test.py tests the shipped model on the refinery
records, benchmarks/stiction_fresh_test.py on loops of another generator.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from phfdi.loopdiag.classifier import call_rates, final_calls
from phfdi.loopdiag.dataset import simulated_data, train_from_rows
from phfdi.loopdiag.features import FEATURE_NAMES

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
MODEL = ROOT / "src" / "phfdi" / "loopdiag" / "models" / "stiction_classifier.json"


def clean(o):
    """JSON-safe: NaN to None, numpy scalars to floats."""
    if isinstance(o, dict):
        return {str(k): clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [clean(v) for v in o]
    if isinstance(o, (float, np.floating)):
        return None if not math.isfinite(float(o)) else float(o)
    return o


def verdicts(model, rows: list[dict]) -> np.ndarray:
    """The verdict's calls on calibration rows: the screen's banded call, then the valve-model fit's decision or
    taking back where the rows carry it (phfdi.loopdiag.verdict)."""
    d = simulated_data(rows)
    p = model.calibrated(d.x)
    calls = model.call(p).astype(object)
    if rows and all("valve_fit" in r for r in rows):
        decides = np.array([r["valve_fit"]["decides"] for r in rows], bool)
        back = np.array([r["valve_fit"]["takes_back"] for r in rows], bool)
        called = final_calls(p, model.band[1], decides, back, model.band[0])
        calls[(calls == "stiction") & ~called] = "undetermined"
        calls[(calls == "undetermined") & called] = "stiction"
    return calls


def class_table(model, rows: list[dict]) -> str:
    """The verdict's calls of the calibration loops per class."""
    calls = verdicts(model, rows)
    out = ["| class | loops | stiction | undetermined | no stiction |", "|---|---|---|---|---|"]
    for c in sorted({r["loop_class"] for r in rows}, key=lambda c: (c != "stiction", c)):
        idx = [i for i, r in enumerate(rows) if r["loop_class"] == c]
        k = [int(np.sum(calls[idx] == v)) for v in ("stiction", "undetermined", "no_stiction")]
        out.append(f"| {c} | {len(idx)} | {k[0]} ({k[0] / len(idx):.1%}) | {k[1]} ({k[1] / len(idx):.1%}) | "
                   f"{k[2]} ({k[2] / len(idx):.1%}) |")
    return "\n".join(out)


def train_from(doc: dict):
    """The shipped model from a data set document (what tests/loops/test_stiction_dataset.py re-runs)."""
    rows = [r for r in doc["rows"] if not r.get("error")]
    model = train_from_rows(rows)
    train_rows = [r for r in rows if r["source"] == "train"]
    cal_rows = [r for r in rows if r["source"] == "calibration"]
    model.info.update({"dataset": {"generator": doc.get("generator"), "seeds": doc.get("seeds"),
                                   "train": len(train_rows), "calibration": len(cal_rows)},
                       "script": "benchmarks/train_stiction_classifier.py"})
    model.info = clean(model.info)
    return model, train_rows, cal_rows


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", type=Path, default=DATASET)
    p.add_argument("--model", type=Path, default=MODEL)
    p.add_argument("--no-write", action="store_true", help="do not write the model JSON")
    args = p.parse_args(argv)
    if not args.dataset.is_file():
        print(f"no data set at {args.dataset}: run benchmarks/stiction_dataset.py first", file=sys.stderr)
        return 2
    doc = json.loads(args.dataset.read_text())
    if doc["features"] != list(FEATURE_NAMES):
        print("the data set's features are not the classifier's: re-run benchmarks/stiction_dataset.py",
              file=sys.stderr)
        return 2
    model, train_rows, cal_rows = train_from(doc)
    op = model.info["operating_point"]
    print(f"{len(train_rows)} training and {len(cal_rows)} calibration loops (simulated, {doc.get('generator')}, "
          f"seeds {doc.get('seeds')}); no real record")
    print("cross-validated log-loss by L2: " + ", ".join(f"{k}: {v:.4f}" for k, v in model.info["cv_log_loss"].items())
          + f" -> L2 {model.l2:g}")
    print(f"Platt calibration a = {model.calibration[0]:.3f}, b = {model.calibration[1]:.3f}; band: no stiction "
          f"below {model.band[0]:.2f}, stiction from {model.band[1]:.3f} (calibration loops: false calls "
          f"{op['false_call_rate']:.1%}, hard negatives {op['hard_false_call_rate']:.1%}, recall {op['recall']:.1%})")
    d_cal = simulated_data(cal_rows)
    for label, calls in (("screen's calls", model.call(model.calibrated(d_cal.x))),
                         ("the verdict (with the valve-model fit)", verdicts(model, cal_rows))):
        r = call_rates(np.asarray(calls, str), d_cal.y)
        print(f"calibration loops, {label}: precision {r['precision']:.3f}, recall {r['recall']:.3f}, false calls "
              f"{r['false_stiction_rate']:.1%}, undetermined {r['undetermined_share']:.1%}")
    print()
    print(class_table(model, cal_rows))
    print("\n| feature | mean | scale | weight (log-odds per standard deviation) |\n|---|---|---|---|")
    for f, mu, sc, w in sorted(zip(model.features, model.mean, model.scale, model.weights), key=lambda t: -abs(t[3])):
        print(f"| {f} | {mu:.3g} | {sc:.3g} | {w:+.3f} |")
    print(f"intercept {model.bias:+.3f}")
    if not args.no_write:
        model.save(args.model)
        print(f"model written to {args.model.relative_to(ROOT) if args.model.is_relative_to(ROOT) else args.model}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
