"""Leave-one-run-out fault detection on the real pH rig: held-out healthy runs and injected faults.

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_detection.py [--json OUT.json]
       [--leave-out 2] [--detectors estimator]
(about half a minute per fold on this 2-core machine; --leave-out 2: ten folds of three training runs, each
held-out run scored four times). Method: src/phfdi/benchmarks/rig_detection.py.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import time
from pathlib import Path

from phfdi.benchmarks.rig_detection import evaluate, summary
from phfdi.commands.common import shipped_map


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--json", default=None, help="write every case and the summary here")
    ap.add_argument("--detectors", nargs="+", default=None, metavar="NAME",
                    help="only these (estimator, 'nominal estimator', 'open loop', 'learned ARX', 'learned OE', "
                         "'plain CUSUM (estimator residual)'); without the physics ones the estimator is not fitted")
    ap.add_argument("--leave-out", default="1", metavar="K",
                    help="hold out every set of K runs in turn and calibrate on the others (default 1); 'operation': "
                         "every run of one operation (titrations, open-loop additions, closed-loop control) at once")
    args = ap.parse_args()
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    if not paths:
        raise SystemExit(f"no rig runs under {args.data}/ph_rig")
    t0 = time.perf_counter()
    result = evaluate(paths, shipped_map("ph_rig"), progress=lambda s: print(s, flush=True),
                      only=args.detectors, leave_out=args.leave_out if args.leave_out == "operation"
                      else int(args.leave_out))
    result["summary"] = summary(result)
    print(f"\n{len(result['folds'])} folds (leave-{args.leave_out}-out) in {time.perf_counter() - t0:.0f} s; "
          f"load average {os.getloadavg()[0]:.1f}")
    for e in result["summary"]:
        hours = e['healthy_hours']
        print(f"\n{e['detector']}: held-out healthy runs: {e['healthy_false_alarms']} fault alarms in "
              f"{hours * 60:.1f} min ({e['healthy_false_alarms'] / hours:.2f} per hour; "
              f"{e['healthy_runs_with_alarm']} of {e['healthy_replays']} replays with one); "
              f"{e['healthy_warnings']} deviations outside calibration (WARN; {e['healthy_warnings_announced']} "
              f"announced, {e['healthy_warnings_announced'] / hours:.1f} per hour); outside the training runs' healthy "
              f"range: {e['outside_range_with_alarm']} of the replays with a fault alarm, "
              f"{e['outside_range_without_alarm']} of the others; fault alarms listing a channel beyond it "
              f"{e['false_alarms_marked']}")
        for k, v in e["kinds"].items():
            d = "" if v["median_delay_s"] is None else f", median delay {v['median_delay_s']:.1f} s"
            d += f", alarm up {100 * v.get('median_held_share', 0.0):.0f} % of the time after the onset (median)"
            fam = "" if e["detector"] not in ("estimator", "nominal estimator", "open loop") \
                else f", family right {v['family_right']}, class right {v['class_right']}"
            if fam and v["median_size_named"] is not None:
                fam += f" (median size named {v['median_size_named']:.3g}"
                fam += ")" if v["size_expected"] is None else f"; true {v['size_expected']:.3g})"
            marked = f", {v['detected_marked']} of them listing a channel beyond the range" if v["detected"] else ""
            print(f"  {k:22s} detected {v['detected']:3d}/{v['cases']:<3d}{d}{fam}{marked}")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1), encoding="utf-8")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
