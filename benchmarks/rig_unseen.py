"""The rig detector on simulated operations no calibration run had: fault alarms per hour on healthy runs,
probe faults found.

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_unseen.py [--hours 10] [--runs-per-kind 12]
       [--calibrations real simulated] [--seed-offset N] [--json OUT.json]
(about 5 minutes on this 2-core machine). Method: src/phfdi/benchmarks/rig_unseen.py.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from phfdi.benchmarks.rig_unseen import evaluate
from phfdi.commands.common import shipped_map


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--hours", type=float, default=10.0, help="simulated healthy hours per calibration (default 10)")
    ap.add_argument("--runs-per-kind", type=int, default=12, help="faulty runs per probe fault kind (default 12)")
    ap.add_argument("--calibrations", nargs="+", default=["real", "simulated"], choices=["real", "simulated"])
    ap.add_argument("--seed-offset", type=int, default=0, metavar="N",
                    help="move every run's seed by N: other simulated days and draws, never scored before (default 0: "
                         "the runs of docs/detector.md's tables)")
    ap.add_argument("--json", default=None, help="write every case and the summary here")
    ap.add_argument("--quiet", action="store_true", help="no line per run")
    args = ap.parse_args()
    t0 = time.perf_counter()
    say = (lambda s: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    if args.seed_offset < 0:
        raise SystemExit("--seed-offset must be 0 or more")
    result = evaluate(args.calibrations, args.hours, args.runs_per_kind, args.data, shipped_map("ph_rig"), say,
                      args.seed_offset)
    print(f"{time.perf_counter() - t0:.0f} s; load average {os.getloadavg()[0]:.1f}")
    for r in result["results"]:
        which = "five recorded runs" if r["calibration"] == "real" else "recorded operations on simulated days"
        print(f"\ncalibrated on the {which}: "
              f"{r['healthy_runs']} simulated healthy runs of unseen operations, {r['healthy_hours']:.2f} h: "
              f"{r['fault_alarms']} fault alarms ({r['fault_alarms_per_hour']:.3f} per hour"
              + (f"; in {', '.join(r['runs_with_fault_alarm'])}" if r["runs_with_fault_alarm"] else "")
              + f"), {r['warnings']} deviations outside calibration ({r['warnings_announced']} announced, "
              f"{r['warnings_announced_per_hour']:.1f} per hour)")
        for kind, v in r["faults"].items():
            d = "" if v["median_delay_s"] is None else f", median delay {v['median_delay_s']:.0f} s"
            print(f"  {kind:13s} {result['faults'][kind]:g}: found {v['found']:2d}/{v['cases']}{d}, "
                  f"class right {v['class_right']}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1), encoding="utf-8")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
