"""Offline throughput of the learned detector on SKAB-like data (8 channels).

    .venv/bin/python benchmarks/skab_throughput.py ../shared/data/skab/anomaly-free/anomaly-free.csv

Learns the reference on the file's first 400 rows, then runs the detector over the file
repeated to about 200 000 rows (the joins act as faults, so the alarm path runs too), whole
and in chunks, best of three; and one row per call (the node's worst case) on 5000 rows.
Prints rows per second (target: at least 1e5 offline). No pass/fail: figures only.
"""

from __future__ import annotations

import platform
import sys
import time

import numpy as np

from phfdi.benchmarks import skab
from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedDetector, learn, run_record


def best_of(fn, repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        f = skab.read_skab_csv(argv[0])
    except UserError as exc:
        print(f"skab_throughput: error: {exc}", file=sys.stderr)
        return 2
    print(f"python {platform.python_version()} numpy {np.__version__} on {platform.machine()}")
    model = learn(f.values[:skab.TRAIN_ROWS], skab.SENSOR_COLUMNS)
    reps = max(1, 200_000 // len(f.values))
    x = np.tile(f.values, (reps, 1))
    t = np.arange(len(x), dtype=float)
    n, m = x.shape
    print(f"{n} rows x {m} channels ({f.path.name} repeated {reps} times)")
    for chunk in (None, 10_000, 1000, 100):
        sec = best_of(lambda: run_record(model, t, x, chunk))
        alarms = sum(e.kind == "alarm" for e in run_record(model, t, x, chunk)[0])
        label = "whole record" if chunk is None else f"chunks of {chunk}"
        print(f"  {label:<18} {n / sec:12,.0f} rows/s  ({sec:.2f} s, {alarms} alarms)")
    k = 5000
    det = LearnedDetector(model)
    t0 = time.perf_counter()
    for i in range(k):
        det.process(t[i:i + 1], x[i:i + 1])
    sec = time.perf_counter() - t0
    print(f"  {'one row per call':<18} {k / sec:12,.0f} rows/s  ({1e6 * sec / k:.0f} us per row)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
