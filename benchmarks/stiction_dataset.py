"""The stiction classifier's data set: the screen's features of domain-randomised simulated loops, nothing else.

    .venv/bin/python benchmarks/stiction_dataset.py                   # writes benchmarks/results/stiction_dataset.json
    .venv/bin/python benchmarks/stiction_dataset.py --train 400 --calibration 200 --out /tmp/small.json
    .venv/bin/python benchmarks/stiction_dataset.py --scheduler tcp://host:8786

Two sets of loops from phfdi.loopdiag.domain (the domain-randomised generator), each with its own seed:
``train`` (the logistic regression's weights and its L2 strength, by cross-validation inside it) and
``calibration`` (Platt's calibration and the operating point of the verdict). No real record is read: the
refinery records of ../shared/data/plant_loops are a test set (benchmarks/stiction_real_test.py), and the
fresh test (benchmarks/stiction_fresh_test.py) draws from another generator with another seed.
Runs on Dask (a local cluster of 2 workers unless --scheduler); prints progress on stderr.
benchmarks/train_stiction_classifier.py trains and writes the shipped model from this file in seconds.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from phfdi.loopdiag.dask_run import dask_client, map_ordered
from phfdi.loopdiag.dataset import simulated_row
from phfdi.loopdiag.domain import draw_domain_loops
from phfdi.loopdiag.features import FEATURE_NAMES

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
#: seeds of the two sets (the fresh test uses benchmarks/stiction_fresh_test.py's own generator and seed)
TRAIN_SEED, CALIBRATION_SEED = 35001, 35002


def _row(args: tuple) -> dict:
    loop, source = args
    return simulated_row(loop, source)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train", type=int, default=4000, help="training loops (default 4000)")
    p.add_argument("--calibration", type=int, default=2000, help="calibration loops (default 2000)")
    p.add_argument("--out", type=Path, default=OUT)
    p.add_argument("--scheduler", default=None, help="address of a running Dask scheduler")
    p.add_argument("--workers", type=int, default=None)
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    train, red_t = draw_domain_loops(args.train, TRAIN_SEED, "TRAIN")
    cal, red_c = draw_domain_loops(args.calibration, CALIBRATION_SEED, "CAL")
    jobs = [(d, "train") for d, _ in train] + [(d, "calibration") for d, _ in cal]
    print(f"{len(jobs)} loops drawn in {time.perf_counter() - t0:.0f} s (redrawn: train {red_t}, calibration "
          f"{red_c})", file=sys.stderr, flush=True)
    step = max(1, len(jobs) // 20)
    shown = [0]

    def show(done: int, total: int) -> None:
        if done // step > shown[0] or done == total:
            shown[0] = done // step
            print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    with dask_client(args.scheduler, args.workers) as client:
        rows = map_ordered(client, _row, jobs, show, chunk=16)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"features": list(FEATURE_NAMES), "generator": "phfdi.loopdiag.domain",
                                    "seeds": {"train": TRAIN_SEED, "calibration": CALIBRATION_SEED},
                                    "redrawn": {"train": red_t, "calibration": red_c}, "rows": rows}, indent=0))
    print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
