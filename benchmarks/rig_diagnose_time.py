"""Time `phfdi diagnose` on the five shared rig runs with the structure search (target: under 5 min on 2 cores).

The command is the `phfdi diagnose --help` example a user runs on ../shared/data/ph_rig (PROVENANCE.md): four runs
fitted, the April titration held out, reagent strengths and probe offset per day, the unseen day adapted on its
first 20 %, at the data's own 0.35 s sampling, every catalogue and structural candidate. Prints the wall time, the
CPU time of the command and its worker processes, and the load average before and after (the machine is shared:
wall time on a busy machine says little, CPU time much more).

    .venv/bin/python benchmarks/rig_diagnose_time.py                  # the command above, nice -n 10
    .venv/bin/python benchmarks/rig_diagnose_time.py --workers 1 --out out/rig_time
"""

from __future__ import annotations

import argparse
import glob
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data"))
                    / "ph_rig")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: every core)")
    ap.add_argument("--out", type=Path, default=Path("out") / "rig_diagnose_time")
    args = ap.parse_args(argv)
    runs = lambda pattern: sorted(glob.glob(str(args.data / pattern)))  # noqa: E731
    fit, val = runs("2025.02.24-*.csv") + runs("2025.03.03-*.csv"), runs("2025.04.07-*.csv")
    if len(fit) != 4 or len(val) != 1:
        print(f"rig_diagnose_time: expected the five rig runs in {args.data}", file=sys.stderr)
        return 2
    phfdi = str(Path(sys.executable).with_name("phfdi"))
    cmd = ["nice", "-n", "10", phfdi, "diagnose", "--model", "rig_flask", "--map", "ph_rig", "--initial", "fit",
           "--structure", "--group", "^([0-9.]{10})", "--adapt", "0.2", "--fit", *fit, "--validate", *val,
           "--out", str(args.out), "--overwrite"] + (["--workers", str(args.workers)] if args.workers else [])
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    status = subprocess.run(cmd, stdout=subprocess.DEVNULL).returncode  # progress stays on stderr
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    load1 = os.getloadavg()
    print(f"phfdi diagnose, five rig runs, --structure: wall {wall:.0f} s, CPU {cpu:.0f} s (command and workers), "
          f"exit {status}; load average {load0[0]:.1f} before, {load1[0]:.1f} after (1 min), on "
          f"{os.cpu_count()} cores; target: wall under 300 s on 2 cores")
    return status


if __name__ == "__main__":
    sys.exit(main())
