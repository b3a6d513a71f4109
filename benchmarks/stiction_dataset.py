"""The stiction classifier's data set: features of the 59 labelled refinery records and of synthetic loops.

    .venv/bin/python benchmarks/stiction_dataset.py                  # writes benchmarks/results/stiction_dataset.json
    .venv/bin/python benchmarks/stiction_dataset.py --synthetic 200 --fresh 100 --scheduler tcp://host:8786

Rows (see phfdi.loopdiag.dataset): the real records (``source`` real, grouped by loop tag), the
training loops of the simulator (``synthetic``, seed 1) and fresh loops never used in training
(``fresh``, seed 2), each with the feature vector, the label and the decisions of Horch, He et al.
and the Hammerstein diagnosis. Runs on Dask (a local cluster of 2 workers unless --scheduler).
benchmarks/train_stiction_classifier.py trains and evaluates from this file in seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from phfdi.loopdiag.dask_run import dask_client, map_ordered
from phfdi.loopdiag.dataset import real_row, synthetic_row
from phfdi.loopdiag.evaluate import read_labels
from phfdi.loopdiag.features import FEATURE_NAMES
from phfdi.loopdiag.training import draw_loops

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data")) / "plant_loops"
OUT = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
TRAIN_SEED, FRESH_SEED = 1, 2


def _real(args):
    item, root = args
    return real_row(item, root)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--labels", type=Path, default=DATA / "labels.csv")
    p.add_argument("--synthetic", type=int, default=200, help="training loops from the simulator")
    p.add_argument("--fresh", type=int, default=100, help="fresh loops for the check (never trained on)")
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--real-from", type=Path, default=None,
                   help="take the real records' rows from this data set (when only the generator changed)")
    args = p.parse_args(argv)
    if not args.labels.is_file():
        print(f"no labels at {args.labels} (set PHFDI_SHARED_DATA)", file=sys.stderr)
        return 2
    items = read_labels(args.labels)
    train = [d for d, _ in draw_loops(args.synthetic, TRAIN_SEED, "SYN")]
    fresh = [d for d, _ in draw_loops(args.fresh, FRESH_SEED, "FRESH")]
    t0 = time.perf_counter()

    def show(done, total):
        print(f"\r{done}/{total}", end="\n" if done == total else "", file=sys.stderr, flush=True)

    with dask_client(args.scheduler, args.workers) as client:
        if args.real_from:
            real = [r for r in json.loads(args.real_from.read_text())["rows"] if r["source"] == "real"]
        else:
            real = map_ordered(client, _real, [(it, str(args.labels.parent)) for it in items], show)
        syn = map_ordered(client, synthetic_row, train + fresh, show)
    for row in syn[len(train):]:
        row["source"] = "fresh"
    rows = real + syn
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"features": list(FEATURE_NAMES), "train_seed": TRAIN_SEED,
                                    "fresh_seed": FRESH_SEED, "rows": rows}, indent=0))
    print(f"{len(real)} real, {len(train)} synthetic, {len(fresh)} fresh rows in {time.perf_counter() - t0:.0f} s "
          f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
