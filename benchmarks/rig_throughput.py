"""Offline throughput of the estimator reference and its detector on the real rig's records (target 1e5
samples/s, issue 21).

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_throughput.py [--repeat 5]
Fits the estimator on the five runs (about 15 s), then replays them ten times over (69 040 samples) through the
filter alone and through the whole detector, each run through a fresh detector as `phfdi replay` does; prints the
best of --repeat in samples per second of wall and of CPU time, and the time to name one alarm's fault. Also the
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


def best_rate(fn, n: int, repeat: int) -> tuple[float, float]:
    wall = cpu = float("inf")
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - w0)
        cpu = min(cpu, time.process_time() - c0)
    return n / wall, n / cpu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--repeat", type=int, default=5)
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
    w, c = best_rate(lambda: model.reference.new_state().residuals(t, x), len(x), args.repeat)
    print(f"estimator filter alone:          {w:9.0f} samples/s wall, {c:9.0f} samples/s CPU")
    def each_run() -> None:
        for _ in range(10):
            for r in recs:
                run_record(model, r.time_s - r.time_s[0], r.x)

    w, c = best_rate(each_run, len(x), args.repeat)
    alarms = sum(len(run_record(model, r.time_s - r.time_s[0], r.x)[2].alarms) for r in recs)
    print(f"filter + wavelet-CUSUM detector: {w:9.0f} samples/s wall, {c:9.0f} samples/s CPU (target 1e5; "
          f"{alarms} alarms in the five runs)")
    w, c = best_rate(lambda: run_record(model, t, x), len(x), args.repeat)
    glued = len(run_record(model, t, x)[2].alarms)
    print(f"  the runs glued into one record:   {w:9.0f} samples/s wall, {c:9.0f} samples/s CPU ({glued} alarms at "
          f"the joins, each named)")
    n = len(recs[1].x)
    w0 = time.perf_counter()
    isolate(model.reference, recs[1].time_s, recs[1].x, n // 2, n // 2 + 30)
    print(f"naming one alarm's fault (4 hypotheses, window of about 100 samples): {time.perf_counter() - w0:.3f} s")


if __name__ == "__main__":
    main()
