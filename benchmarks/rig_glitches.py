"""One-reading glitches on the real rig's healthy runs: how many become fault alarms.

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_glitches.py [--sizes 1 -1 2 -2]
       [--times 15] [--json OUT.json]
Each of the five recorded runs is held out in turn (the estimator fitted on the other four, as
benchmarks/rig_detection.py does), and one reading is moved by each size (pH) and back at the next sample, at
``--times`` times spread evenly from two minutes after the run's start to 70 samples before its end (fixed before
any run was scored: the glitch sits anywhere, plateaus and knees alike); every glitch is a fresh replay of the run.
Prints, per size, the glitches that raised a fault alarm (any, anywhere in the run) and the deviations outside
calibration (WARN), and each fault alarm's run, time and name. About a minute here.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.learned import read_measured
from wavelet_fdi.learned_detector import run_record

CHANNELS = ["acid_flow_ml_s", "base_flow_ml_s", "ph_measured"]
FIRST_SAMPLE = 120  # two minutes after the start at the rig's 0.35 s sampling: past the detector's warm-up
LAST_MARGIN = 70  # samples before the end: room for the naming's 64 samples after a detection


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=float, nargs="+", default=[1.0, -1.0, 2.0, -2.0])
    ap.add_argument("--times", type=int, default=15)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)
    rig = Path(os.environ.get("PHFDI_SHARED_DATA", "../shared/data")) / "ph_rig"
    paths = sorted(rig.glob("*.csv"))
    if len(paths) < 2:
        print(f"rig_glitches: no rig runs under {rig} (set PHFDI_SHARED_DATA)", file=sys.stderr)
        return 2
    cmap = shipped_map("ph_rig")
    records = [read_measured(p, cmap, channels=CHANNELS) for p in paths]
    counts = {s: {"glitches": 0, "fault_alarms": 0, "deviations": 0} for s in args.sizes}
    faults = []
    for k, (path, rec) in enumerate(zip(paths, records)):
        print(f"  {path.name}: fitting on the other {len(records) - 1} runs", file=sys.stderr, flush=True)
        model = fit_estimator([r for j, r in enumerate(records) if j != k], start_from_model("rig_flask"))
        n = len(rec.time_s)
        for at in np.linspace(FIRST_SAMPLE, n - LAST_MARGIN, args.times).astype(int):
            for size in args.sizes:
                x = rec.x.copy()
                x[at, 2] += size
                _, _, det = run_record(model, rec.time_s, x)
                found = [a for a in det.alarms if a.get("verdict") == "fault"]
                c = counts[size]
                c["glitches"] += 1
                c["fault_alarms"] += bool(found)
                c["deviations"] += sum(1 for a in det.alarms if a.get("verdict") == "outside calibration")
                faults += [{"run": path.name, "glitch_s": round(float(rec.time_s[at]), 1), "size_ph": size,
                            "statistic": a["statistic"], "named": (a.get("isolation") or {}).get("fault_class"),
                            "size_named": (a.get("isolation") or {}).get("size")} for a in found]
    for size, c in counts.items():
        print(f"glitch {size:+g} pH: {c['fault_alarms']} of {c['glitches']} with a fault alarm, "
              f"{c['deviations']} deviations outside calibration (WARN)")
    for f in faults:
        print(f"  fault alarm: {f['run']} glitch at {f['glitch_s']} s ({f['size_ph']:+g} pH): {f['statistic']}, "
              f"named {f['named']} {f['size_named']}")
    if args.json:
        from phfdi_base.outputs import write_bytes

        result = {"sizes": {str(k): v for k, v in counts.items()}, "fault_alarms": faults}
        write_bytes(args.json, json.dumps(result, indent=1).encode("utf-8"), overwrite=True)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
