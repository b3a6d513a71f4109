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

Then, in this process, the CPU time per loop of each stage on the first ``--stage-loops`` loops:
reading the CSV, the published indicators, the valve models with the linear fits (oscillation,
controller, linear models, every valve model's grid search), and the classifier with the report.
CPU time, not wall time, so a loaded machine changes it less; the loops per minute above are wall
time on the cluster and move with the load (printed at the end).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from phfdi.loopdiag.diagnose import Settings, gather_evidence
from phfdi.loopdiag.indicator_set import compute_indicators
from phfdi.loopdiag.plantwide import diagnose_jobs, expand, write_table
from phfdi.loopdiag.readers import read_loop
from phfdi.loopdiag.single import diagnose_run
from phfdi.loopdiag.training import draw_loops


def stage_times(paths: list[str]) -> dict[str, float]:
    """CPU seconds per loop of each stage (the whole diagnosis is run once more to time the rest)."""
    total = {"read": 0.0, "indicators": 0.0, "valve models and linear fits": 0.0, "classifier and report": 0.0}
    for path in paths:
        t0 = time.process_time()
        run = read_loop(path)
        t1 = time.process_time()
        sp = run["sp"] if "sp" in run else None
        compute_indicators(run["op_pct"], run["pv"], sp, run.dt_s, run.metadata.get("process_type", "self_regulating"))
        t2 = time.process_time()
        gather_evidence(run, Settings(baselines=False))
        t3 = time.process_time()
        diagnose_run(run)
        t4 = time.process_time()
        total["read"] += t1 - t0
        total["indicators"] += t2 - t1
        total["valve models and linear fits"] += t3 - t2
        total["classifier and report"] += max((t4 - t3) - (t3 - t1), 0.0)
    return {k: v / len(paths) for k, v in total.items()}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--loops", type=int, default=1000)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--scheduler", default=None)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--chunk", type=int, default=None,
                   help="loops per Dask task (default: up to 16, about 8 tasks per worker thread)")
    p.add_argument("--stage-loops", type=int, default=20, help="loops timed stage by stage in this process")
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
        shown = [0]  # loops arrive in chunks: print at each 5 % mark passed

        def show(done, total):
            if done // step > shown[0] or done == total:
                shown[0] = done // step
                print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

        reports = diagnose_jobs(jobs, scheduler=args.scheduler, workers=args.workers, progress=show, chunk=args.chunk)
        write_table(reports, Path(tmp) / "out")
        wall = time.perf_counter() - t0
        load_after_run = os.getloadavg()
        stages = stage_times([j.path for j in jobs[:args.stage_loops]]) if args.stage_loops > 0 else {}
    failed = sum("error" in r for r in reports)
    right = sum((r["stiction"]["verdict"] == "stiction") == truth[r["file"]] for r in reports if "error" not in r)
    where = args.scheduler or f"LocalCluster, {args.workers} worker processes"
    print(f"{len(reports)} loops ({failed} failed) in {wall:.1f} s on Dask ({where}): "
          f"{60.0 * len(reports) / wall:.1f} loops/minute")
    print(f"stiction verdicts right on {right}/{len(reports) - failed} of these fresh simulated loops")
    print("load average at the end of the Dask run (1, 5, 15 min): " + ", ".join(f"{v:.1f}" for v in load_after_run))
    if stages:
        print(f"CPU per loop, in this process, first {min(args.stage_loops, len(jobs))} loops: "
              + ", ".join(f"{k} {1000 * v:.0f} ms" for k, v in stages.items())
              + f"; total {1000 * sum(stages.values()):.0f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
