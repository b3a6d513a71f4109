"""Plant-wide throughput: simulated loops diagnosed through Dask, loops per minute.

    .venv/bin/python benchmarks/plant_wide.py                     # 1000 loops, LocalCluster of 2 workers
    .venv/bin/python benchmarks/plant_wide.py --loops 200 --workers 2
    .venv/bin/python benchmarks/plant_wide.py --scheduler tcp://host:8786

Draws loops from the classifier's simulator (phfdi.loopdiag.training, seed 7: half with a sticky
valve, every process type and disturbance), writes each as a CSV historian record (751 samples at
10 s) into a temporary folder, and runs the plant-wide path of ``phfdi loop-diagnose FOLDER --out``
(expand the folder, read, diagnose with every valve model and the stiction classifier, write
loops.parquet/loops.csv) on Dask. Prints the wall time, loops per minute, and the accuracy of the
stiction verdicts on these loops (they are fresh draws, never trained on).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from phfdi.loopdiag.plantwide import diagnose_jobs, expand, write_table
from phfdi.loopdiag.training import draw_loops


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--loops", type=int, default=1000)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--scheduler", default=None)
    p.add_argument("--seed", type=int, default=7)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="plant_wide_") as tmp:
        folder = Path(tmp) / "loops"
        folder.mkdir()
        truth = {}
        for loop, run in draw_loops(args.loops, args.seed, "PW"):
            kind = "LIC" if loop.process_type == "integrating" else "FIC"  # the tag tells the process type
            path = run.to_csv(folder / f"{kind}_{loop.group}.csv")
            truth[str(path)] = loop.stiction
        t0 = time.perf_counter()
        jobs = expand([str(folder)])
        step = max(1, len(jobs) // 20)

        def show(done, total):
            if done % step == 0 or done == total:
                print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

        reports = diagnose_jobs(jobs, scheduler=args.scheduler, workers=args.workers, progress=show)
        write_table(reports, Path(tmp) / "out")
        wall = time.perf_counter() - t0
    failed = sum("error" in r for r in reports)
    right = sum((r["stiction"]["verdict"] == "stiction") == truth[r["file"]] for r in reports if "error" not in r)
    where = args.scheduler or f"LocalCluster, {args.workers} worker processes"
    print(f"{len(reports)} loops ({failed} failed) in {wall:.1f} s on Dask ({where}): "
          f"{60.0 * len(reports) / wall:.1f} loops/minute")
    print(f"stiction verdicts right on {right}/{len(reports) - failed} of these fresh simulated loops")
    print("load average at the end (1, 5, 15 min): " + ", ".join(f"{v:.1f}" for v in os.getloadavg()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
