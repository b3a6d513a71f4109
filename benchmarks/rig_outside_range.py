"""How often the rig's alarms carry a channel beyond the calibration runs' range (``outside_healthy_range``).

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_outside_range.py [--leave-out K]
(the estimator reference only; 2 to 4 min on this 2-core machine).

The folds and injected faults of ``benchmarks/rig_detection.py`` (``held_out_sets``, ``injected_cases``, larger
sizes): for every alarm on a held-out healthy run (a false alarm) and for the first alarm after the onset of every
injected fault found with no alarm before it (a true detection), whether a channel left the training runs' healthy
range between the alarm's onset and its detection. A marker that every false alarm carries and few true
detections do would tell them apart; one that both carry says only where to look twice.
"""

from __future__ import annotations

import argparse
import glob
import os
import tempfile
from pathlib import Path

from phfdi.benchmarks.rig_detection import CHANNELS, held_out_sets, injected_cases
from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.learned import read_measured
from wavelet_fdi.learned_detector import run_record


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--leave-out", type=int, default=1, metavar="K")
    args = ap.parse_args()
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    if not paths:
        raise SystemExit(f"no rig runs under {args.data}/ph_rig")
    cmap = shipped_map("ph_rig")
    recs = {p: read_measured(p, cmap, channels=list(CHANNELS)) for p in paths}
    false_alarms = marked_false = found = marked_found = 0
    with tempfile.TemporaryDirectory() as tmp:
        for train, held in held_out_sets(paths, args.leave_out):
            print(f"fold: {', '.join(Path(p).name for p in held)} held out", flush=True)
            est = fit_estimator([recs[q] for q in train], start_from_model("rig_flask"))
            for p in held:
                for a in run_record(est, recs[p].time_s, recs[p].x)[2].alarms:
                    false_alarms += 1
                    marked_false += bool(a["outside_healthy_range"])
                for truth, rec in injected_cases(p, recs[p], Path(tmp), cmap):
                    if truth["size_rank"] != "larger":
                        continue
                    alarms = run_record(est, rec.time_s, rec.x)[2].alarms
                    after = [a for a in alarms if a["detection_time"] >= truth["onset_s"]]
                    if after and len(after) == len(alarms):
                        found += 1
                        marked_found += bool(after[0]["outside_healthy_range"])
    print(f"leave-{args.leave_out}-out: false alarms {false_alarms}, {marked_false} with a channel beyond the "
          f"range; true first detections (larger size) {found}, {marked_found} with one")


if __name__ == "__main__":
    main()
