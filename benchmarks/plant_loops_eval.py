"""Stiction detection on the 59 labelled refinery loop records, leave-one-loop-out.

    .venv/bin/python benchmarks/plant_loops_eval.py                       # full run, both cores
    .venv/bin/python benchmarks/plant_loops_eval.py --records out.json    # also keep the per-file records
    .venv/bin/python benchmarks/plant_loops_eval.py --from-records benchmarks/results/plant_loops_records.json
    .venv/bin/python benchmarks/plant_loops_eval.py --classifier    # the one verdict (benchmarks/stiction_real_test.py)

``--classifier``: the one verdict of ``phfdi loop-diagnose`` on every record, its model trained on simulated
loops only: precision, recall, false calls and undetermined share (benchmarks/stiction_real_test.py).

Prints the table of docs/loop_diagnosis.md (accuracy, precision and recall for "stiction" of
the Hammerstein diagnosis and of the Horch and He et al. baselines), the wall time, and the
per-loop decisions. ``--from-records`` re-runs only the leave-one-loop-out part from saved
per-file records (seconds instead of minutes).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from phfdi.loopdiag.batch import diagnose_files, stderr_progress
from phfdi.loopdiag.diagnose import Settings
from phfdi.loopdiag.evaluate import evaluate, format_table, read_labels, record

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data")) / "plant_loops"


def collect(labels_csv: Path, workers: int | None, limit: int | None = None) -> list[dict]:
    items = read_labels(labels_csv)[:limit]
    # the valve-model (Hammerstein) diagnosis of every file, not only those the stiction screen flags
    reports = diagnose_files([it.file for it in items], settings=Settings(fits="all"), workers=workers,
                             progress=stderr_progress(True))
    return [record(rep, it) for rep, it in zip(reports, items)]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--labels", type=Path, default=DATA / "labels.csv")
    p.add_argument("--workers", type=int, default=None, help="processes (default: 2)")
    p.add_argument("--records", type=Path, default=None, help="write the per-file records (JSON) here")
    p.add_argument("--from-records", type=Path, default=None, help="evaluate saved records instead of diagnosing")
    p.add_argument("--json", action="store_true", help="print the results as JSON")
    p.add_argument("--classifier", action="store_true",
                   help="the one verdict on the records (benchmarks/stiction_real_test.py)")
    args = p.parse_args(argv)
    if args.classifier:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from stiction_real_test import main as real_test_main

        return real_test_main([])
    t0 = time.perf_counter()
    if args.from_records:
        records = json.loads(args.from_records.read_text())
    else:
        if not args.labels.is_file():
            print(f"no labels at {args.labels} (set PHFDI_SHARED_DATA)", file=sys.stderr)
            return 2
        records = collect(args.labels, args.workers)
    t_diag = time.perf_counter() - t0
    for r in records:
        r["file"] = str(Path(r["file"]).relative_to(DATA)) if Path(r["file"]).is_relative_to(DATA) else r["file"]
    if args.records:
        args.records.parent.mkdir(parents=True, exist_ok=True)
        args.records.write_text(json.dumps(records, indent=1))
    results = evaluate(records)
    if args.json:
        print(json.dumps({k: {kk: vv for kk, vv in v.items() if kk != "predictions"} for k, v in results.items()},
                         indent=2))
        return 0
    errors = [r for r in records if r.get("error")]
    print(f"{len(records)} files, {len({r['loop_tag'] for r in records})} loops, "
          f"{sum(r['stiction'] for r in records)} labelled stiction; {len(errors)} unreadable")
    for r in errors:
        print(f"  {r['file']}: {r['error']}")
    print(f"diagnosis wall time: {t_diag:.1f} s" + (" (records loaded)" if args.from_records else ""))
    print()
    print(format_table(results))
    print()
    print("per loop (files called stiction / files), Hammerstein valve | stiction-named | Horch | He:")
    loops = sorted({(r["loop_tag"], r["stiction"]) for r in records}, key=lambda x: (not x[1], x[0]))
    for tag, lab in loops:
        files = [r["file"] for r in records if r["loop_tag"] == tag]
        cells = []
        for m in ("hammerstein_valve", "hammerstein_stiction", "horch_ccf", "he_curve_fit"):
            k = sum(results[m]["predictions"][f] for f in files)
            cells.append(f"{k}/{len(files)}")
        print(f"  {'stiction   ' if lab else 'no stiction'} {tag:28s} " + " | ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
