"""Speed of the simulated rig (phfdi.rigsim): hours of record simulated per minute of this machine's time.

Simulates HOURS hours of the unseen operations (each in turn, seeds 0, 1, ..., each on its own day; closed
loops step one sample at a time) and prints the wall and CPU time, the samples per second and the time per
simulated hour; with --csv also the time to write every run in the rig's CSV format (to a temporary folder).

Usage: OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/rigsim_speed.py [--hours 10] [--csv]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections import Counter

from phfdi.rigsim import draw_runs, write_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--group", default="unseen", choices=["unseen", "shared"])
    ap.add_argument("--csv", action="store_true", help="also time writing each run as the rig's CSV")
    args = ap.parse_args()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    runs, samples, seconds, kinds = 0, 0, 0.0, Counter()
    write_s = 0.0
    with tempfile.TemporaryDirectory() as folder:
        for run in draw_runs(args.hours, args.group):
            runs += 1
            samples += len(run)
            seconds += float(run.time_s[-1] - run.time_s[0])
            kinds[run.operation.kind] += len(run)
            if args.csv:
                t = time.perf_counter()
                write_run(run, os.path.join(folder, f"run{runs}.csv"))
                write_s += time.perf_counter() - t
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    load = os.getloadavg()[0]
    print(f"{runs} runs, {seconds / 3600:.2f} h of record, {samples} samples "
          f"({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})")
    print(f"wall {wall:.1f} s, CPU {cpu:.1f} s (load average {load:.1f}): {samples / wall:.0f} samples/s, "
          f"{wall / (seconds / 3600):.2f} s of wall per simulated hour")
    if args.csv:
        print(f"of which writing the CSVs and sidecars: {write_s:.1f} s")


if __name__ == "__main__":
    main()
