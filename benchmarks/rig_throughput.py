"""Offline throughput of the estimator reference and its detector on the real rig's records (target 1e5
samples/s, issue 21).

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_throughput.py [--repeat 9]
Fits the estimator on the five runs (about 5 s), then replays them ten times over (69 040 samples) through the
filter alone and through the whole detector, each run through a fresh detector as `phfdi replay` does; prints the
best and the median of --repeat in samples per second of wall time (and the best of CPU time), and the time to name
one alarm's fault. The median is printed beside the best because this shared machine's speed moves by up to a
factor of two between repetitions (2026-11-29, the filter then interpreted: 53 000 to 139 000 samples/s over 40
repetitions in one process). The fit, before the clock starts, compiles the filter (Numba,
wavelet_fdi.estimator_kernel; cached after the first run on a machine). Also the
five runs glued back to back into one record, as this benchmark did until 2026-11-28: the pH jumps where one run
ends and the next begins, the detector alarms there, and each alarm's naming (about 0.08 s) then counts in it.
"""

from __future__ import annotations

import argparse
import glob
import os
import time
from pathlib import Path

import numpy as np

from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.learned import read_measured
from wavelet_fdi.estimator_isolation import isolate
from wavelet_fdi.learned_detector import run_record

CHANNELS = ["acid_flow_ml_s", "base_flow_ml_s", "ph_measured"]


def rates(fn, n: int, repeat: int) -> tuple[float, float, float]:
    """(best wall, median wall, best CPU) samples per second over ``repeat`` calls of ``fn``."""
    walls, cpus = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return n / min(walls), n / float(np.median(walls)), n / min(cpus)


def line(name: str, r: tuple[float, float, float]) -> str:
    return f"{name:33s} {r[0]:9.0f} samples/s wall (median {r[1]:9.0f}), {r[2]:9.0f} samples/s CPU"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--repeat", type=int, default=9)
    args = ap.parse_args()
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    if not paths:
        raise SystemExit(f"no rig runs under {args.data}/ph_rig")
    recs = [read_measured(p, shipped_map("ph_rig"), channels=CHANNELS) for p in paths]
    model = fit_estimator(recs, start_from_model("rig_flask"))
    t1 = np.concatenate([r.time_s - r.time_s[0] + 2000.0 * i for i, r in enumerate(recs)])
    x1 = np.vstack([r.x for r in recs])
    t = np.concatenate([t1 + 10000.0 * k for k in range(10)])
    x = np.vstack([x1] * 10)
    print(f"{len(x)} samples (the five rig runs, ten times); load average {os.getloadavg()[0]:.1f}")
    print(line("estimator filter alone:", rates(lambda: model.reference.new_state().residuals(t, x), len(x),
                                                args.repeat)))
    def each_run() -> None:
        for _ in range(10):
            for r in recs:
                run_record(model, r.time_s - r.time_s[0], r.x)

    whole = rates(each_run, len(x), args.repeat)
    alarms = sum(len(run_record(model, r.time_s - r.time_s[0], r.x)[2].alarms) for r in recs)
    print(line("filter + wavelet-CUSUM detector:", whole) + f" (target 1e5; {alarms} alarms in the five runs)")
    glued = len(run_record(model, t, x)[2].alarms)
    print(line("  the runs glued into one record:", rates(lambda: run_record(model, t, x), len(x), args.repeat))
          + f" ({glued} alarms at the joins, each named)")
    n = len(recs[1].x)
    w0 = time.perf_counter()
    isolate(model.reference, recs[1].time_s, recs[1].x, n // 2, n // 2 + 30)
    print(f"naming one alarm's fault (4 hypotheses, window of about 100 samples): {time.perf_counter() - w0:.3f} s")


if __name__ == "__main__":
    main()
