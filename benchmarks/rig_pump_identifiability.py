"""Can the estimator reference see a pump that delivers other than recorded? What the rig's data allow.

Leave-one-run-out as benchmarks/rig_detection.py: the estimator is fitted on four shared rig runs and run on the
fifth, healthy and with pump_low / pump_high of size 0.5 injected (phfdi inject) at 35, 55 and 75 % of the run.
Printed per held-out run and pump: the block-wise least-squares relative strength error the adaptation sees
(rel, one value per block of 32 samples in which the pump ran: mean and standard deviation over the healthy
run), the range of the adapted strength factor over the healthy run, and the mean rel in the 120 s after each
injected onset (a pump delivering half of what the record says reads rel near -0.5, one delivering 1.5 times
near +0.5, if the model's rates were exact).

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_pump_identifiability.py
(about five minutes on this 2-core machine)
"""

from __future__ import annotations

import argparse
import glob
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from phfdi.benchmarks.rig_detection import CHANNELS
from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.inject import inject_fault
from phfdi.learned import read_measured
from phfdi_base.errors import UserError

WINDOW_S = 120.0
SIZE = 0.5


def adaptation(ref, rec) -> tuple[np.ndarray, list]:
    """Block end times (s from the start) and the adaptation trace of one run through a fresh filter."""
    stream = ref.new_state()
    stream.adapt_trace = []
    t = rec.time_s - rec.time_s[0]
    stream.residuals(t, rec.x)
    ends = np.array([t[min(b * ref.block_samples, len(t)) - 1] for b, *_ in stream.adapt_trace])
    return ends, stream.adapt_trace


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    args = ap.parse_args()
    cmap = shipped_map("ph_rig")
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    recs = {p: read_measured(p, cmap, channels=list(CHANNELS)) for p in paths}
    t0 = time.perf_counter()
    for held in paths:
        ref = fit_estimator([recs[q] for q in paths if q != held], start_from_model("rig_flask")).reference
        rec = recs[held]
        ends, trace = adaptation(ref, rec)
        print(f"\n{Path(held).name} (fitted on the other four, {time.perf_counter() - t0:.0f} s)", flush=True)
        for i, feed in enumerate(ref.feeds):
            pump = feed.channel.split("_")[0]
            rel = np.array([r[i] for _, r, on, *_ in trace if on[i] > 0])
            if len(rel) == 0:
                print(f"  {pump}: off in this run")
                continue
            factors = [f[i] for _, _, _, f, _ in trace]
            line = (f"  {pump}: healthy rel {rel.mean():+.2f} +- {rel.std():.2f} over {len(rel)} blocks; adapted "
                    f"factor {min(factors):.2f}..{max(factors):.2f}; after a {SIZE:g} fault, mean rel in "
                    f"{WINDOW_S:g} s:")
            t_start, t_end = float(rec.time_s[0]), float(rec.time_s[-1])
            with tempfile.TemporaryDirectory() as tmp:
                for kind in ("pump_low", "pump_high"):
                    got = []
                    for frac in (0.35, 0.55, 0.75):
                        onset = round(t_start + frac * (t_end - t_start), 2)
                        try:
                            data, _ = inject_fault(held, kind, onset, SIZE, pump=pump, seed=1, column_map=cmap)
                        except UserError:
                            continue
                        f = Path(tmp) / "case.csv"
                        f.write_bytes(data)
                        e, tr = adaptation(ref, read_measured(f, cmap, channels=list(CHANNELS)))
                        t_on = onset - t_start
                        v = [r[i] for end, (_, r, on, *_) in zip(e, tr) if t_on <= end < t_on + WINDOW_S and on[i] > 0]
                        got.append(f"{np.mean(v):+.2f}" if v else "pump off")
                    line += f" {kind} {', '.join(got) or 'not injectable'};"
            print(line, flush=True)
    print(f"\n{len(paths)} folds in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
