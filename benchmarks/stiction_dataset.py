"""The stiction classifier's data set: the screen's features of domain-randomised simulated loops, nothing else.

    .venv/bin/python benchmarks/stiction_dataset.py                   # writes benchmarks/results/stiction_dataset.json
    .venv/bin/python benchmarks/stiction_dataset.py --train 400 --calibration 200 --out /tmp/small.json
    .venv/bin/python benchmarks/stiction_dataset.py --scheduler tcp://host:8786
    .venv/bin/python benchmarks/stiction_dataset.py --add-valve-fits      # only the calibration loops' fits, added

Two sets of loops from phfdi.loopdiag.domain (the domain-randomised generator), each with its own seed:
``train`` (the logistic regression's weights and its L2 strength, by cross-validation inside it) and
``calibration`` (Platt's calibration and the operating point of the verdict). Each calibration loop also gets
what the valve-model fit says of it (``valve_fit``: whether it would decide an undetermined screen for stiction,
or take a stiction call back; :func:`phfdi.loopdiag.dataset.valve_fit_row`), so that the operating point holds for
the verdict's final calls. No real record is read: the
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
from phfdi.loopdiag.dataset import simulated_row, valve_fit_row
from phfdi.loopdiag.domain import draw_domain_loops
from phfdi.loopdiag.features import FEATURE_NAMES
from phfdi_base.outputs import write_text

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
    p.add_argument("--add-valve-fits", action="store_true",
                   help="only run the valve-model fit on the calibration loops of the data set at --out, and add it")
    args = p.parse_args(argv)
    if args.add_valve_fits:
        return add_valve_fits(args)
    t0 = time.perf_counter()
    train, red_t = draw_domain_loops(args.train, TRAIN_SEED, "TRAIN")
    cal, red_c = draw_domain_loops(args.calibration, CALIBRATION_SEED, "CAL")
    jobs = [(d, "train") for d, _ in train] + [(d, "calibration") for d, _ in cal]
    print(f"{len(jobs)} loops drawn in {time.perf_counter() - t0:.0f} s (redrawn: train {red_t}, calibration "
          f"{red_c})", file=sys.stderr, flush=True)
    with dask_client(args.scheduler, args.workers) as client:
        rows = map_ordered(client, _row, jobs, _progress(t0, len(jobs)), chunk=16)
        print("the valve-model fit on the calibration loops", file=sys.stderr, flush=True)
        fits = map_ordered(client, valve_fit_row, [d for d, _ in cal], _progress(t0, len(cal)), chunk=4)
    _merge_fits(rows, fits)
    write_text(args.out, json.dumps({"features": list(FEATURE_NAMES), "generator": "phfdi.loopdiag.domain",
                                     "seeds": {"train": TRAIN_SEED, "calibration": CALIBRATION_SEED},
                                     "redrawn": {"train": red_t, "calibration": red_c}, "rows": rows}, indent=0),
               overwrite=True)
    print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s -> {args.out}")
    return 0


def _progress(t0: float, total: int):
    """A progress callback for map_ordered: a line on stderr each twentieth of ``total`` loops done."""
    step = max(1, total // 20)
    shown = [0]

    def show(done: int, _total: int) -> None:
        if done // step > shown[0] or done == total:
            shown[0] = done // step
            print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return show


def _merge_fits(rows: list[dict], fits: list[dict]) -> None:
    """Each calibration row gets its loop's ``valve_fit`` (matched by name)."""
    by_name = {f["name"]: f for f in fits}
    for r in rows:
        if r["source"] == "calibration":
            r["valve_fit"] = {k: v for k, v in by_name[r["name"]].items() if k != "name"}


def add_valve_fits(args) -> int:
    """The valve-model fit of every calibration loop of an existing data set, added to it (written atomically)."""
    if not args.out.is_file():
        print(f"no data set at {args.out}: run benchmarks/stiction_dataset.py first", file=sys.stderr)
        return 2
    doc = json.loads(args.out.read_text())
    t0 = time.perf_counter()
    n_cal = sum(r["source"] == "calibration" for r in doc["rows"])
    cal, _ = draw_domain_loops(n_cal, doc["seeds"]["calibration"], "CAL")
    names = [r["name"] for r in doc["rows"] if r["source"] == "calibration"]
    if [d.group for d, _ in cal] != names:
        print("the calibration loops drawn again are not the data set's: re-run benchmarks/stiction_dataset.py",
              file=sys.stderr)
        return 2
    print(f"{n_cal} calibration loops drawn in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    with dask_client(args.scheduler, args.workers) as client:
        fits = map_ordered(client, valve_fit_row, [d for d, _ in cal], _progress(t0, n_cal), chunk=4)
    _merge_fits(doc["rows"], fits)
    write_text(args.out, json.dumps(doc, indent=0), overwrite=True)
    print(f"valve-model fits of {n_cal} calibration loops added in {time.perf_counter() - t0:.0f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
