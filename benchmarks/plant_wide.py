"""Plant scale: the screen's loops per minute, the screen with the fits where it flags, and long records.

    .venv/bin/python benchmarks/plant_wide.py                      # 10 000 loops, a 1 M and a 10 M-sample record
    .venv/bin/python benchmarks/plant_wide.py --loops 2000 --full-loops 200 --no-long
    .venv/bin/python benchmarks/plant_wide.py --only-long          # the long records only

1. **Screen**: ``--loops`` loops (default 10 000) drawn from the per-class generator (phfdi.loopdiag.training,
   seed 7; never trained on), each written as a CSV historian record of 751 samples into a temporary folder,
   then the plant-wide path of ``phfdi loop-diagnose FOLDER --out DIR --fits none`` on a Dask LocalCluster of
   ``--workers`` processes (default 2): expand the folder, read, structure checks, screen (indicators, dead-band
   screen, calibrated p), the table. Prints loops per minute (wall time, the cluster's start included).
   Then the screen's CPU time per loop in this process (``--cpu-loops`` of the same files, default 200), which
   the machine's load changes less, and the loops per minute two cores give at that cost.
2. **Screen and fits where flagged** (the default ``--fits flagged``) on the first ``--full-loops`` of them: loops
   per minute and the share flagged.
3. **Long records**: a simulated loop of 1 000 000 and of 10 000 000 samples written as CSV, each diagnosed by
   ``phfdi loop-diagnose FILE`` in a child process: wall time and its peak memory (its own rusage, taken by a
   small launcher), and the note saying how the record was bounded.

Wall times move with the machine's load (other sessions share its 2 cores): the load average is printed with
each figure.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from phfdi.loopdiag.diagnose import Settings
from phfdi.loopdiag.plantwide import diagnose_jobs, expand, write_table
from phfdi.loopdiag.synthetic import SyntheticLoop, simulate_loop
from phfdi.loopdiag.training import class_round_robin, draw_class_loops

ROOT = Path(__file__).resolve().parents[1]
PHFDI = str(Path(sys.executable).parent / "phfdi")


def write_loops(folder: Path, n: int, seed: int) -> dict[str, bool]:
    """``n`` loops of the per-class generator as CSV records (tags tell the process type); the truth by file."""
    classes = class_round_robin(n // 6 + 1)[:n]
    truth = {}
    for loop, run in draw_class_loops(classes, seed, "PW"):
        kind = "LIC" if loop.process_type == "integrating" else "FIC"
        path = run.to_csv(folder / f"{kind}_{loop.group}.csv")
        truth[str(path)] = loop.stiction
    return truth


def screen_cpu_ms(paths: list[Path]) -> float:
    """CPU milliseconds per loop of the screen-only diagnosis of each file, in this process (the first file once
    before, so imports and caches are not counted)."""
    from phfdi.loopdiag.plantwide import Job, diagnose_job

    settings = Settings(baselines=False, fits="none")
    diagnose_job(Job(str(paths[0])), settings)
    t0 = time.process_time()
    for path in paths:
        diagnose_job(Job(str(path)), settings)
    return 1000.0 * (time.process_time() - t0) / len(paths)


def run_plant(folder: Path, out: Path, fits: str, workers: int, scheduler: str | None) -> tuple[list[dict], float]:
    t0 = time.perf_counter()
    jobs = expand([str(folder)])
    step = max(1, len(jobs) // 10)
    shown = [0]

    def show(done, total):
        if done // step > shown[0] or done == total:
            shown[0] = done // step
            print(f"  {done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    reports = diagnose_jobs(jobs, Settings(baselines=False, fits=fits), scheduler=scheduler, workers=workers,
                            progress=show)
    write_table(reports, out)
    return reports, time.perf_counter() - t0


def long_record(path: Path, samples: int) -> Path:
    """A sticky flow loop of ``samples`` samples at 1 s as CSV (simulated in pieces of a million samples)."""
    if path.exists():
        return path
    piece = min(samples, 1_000_000)
    with open(path, "w") as fh:
        fh.write("time_s,op_pct,pv,sp\n")
        for k in range(0, samples, piece):
            spec = SyntheticLoop(valve=("stiction", {"s_pct": 2.0, "j_pct": 1.0}), dt_s=1.0,
                                 duration_s=float(min(piece, samples - k)), time_constant_s=20.0, dead_time_s=3.0,
                                 kp=0.5, ti_s=30.0, load_ar_std=0.5, load_ar_pole=0.99,
                                 setpoint_steps=[(500.0, 52.0)], noise_std=0.05, seed=k + 1, loop_tag="FIC_LONG")
            run = simulate_loop(spec)
            block = np.column_stack([run.time_s + k, run["op_pct"], run["pv"], run["sp"]])
            np.savetxt(fh, block, delimiter=",", fmt=["%.0f", "%.5f", "%.5f", "%.5f"])
    return path


#: a small launcher whose own child runs the command: a child forked straight from this process would start with
#: this process's resident memory (10 000 reports) in its peak, so the peak is taken from a fresh, small parent
LAUNCHER = ("import os, sys\npid = os.fork()\nif pid == 0:\n    os.execv(sys.argv[1], sys.argv[1:])\n"
            "_, status, usage = os.wait4(pid, 0)\nprint(f'PEAK_KB {usage.ru_maxrss}', file=sys.stderr)\n"
            "sys.exit(os.waitstatus_to_exitcode(status))")


def timed_child(args: list[str]) -> tuple[float, int, str, int]:
    """(wall s, peak resident memory in MB of the command's own process, its stdout + stderr, exit status)."""
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", LAUNCHER, *args], capture_output=True, text=True)
    wall = time.perf_counter() - t0
    peak = next((int(ln.split()[1]) for ln in proc.stderr.splitlines() if ln.startswith("PEAK_KB")), 0)
    err = "\n".join(ln for ln in proc.stderr.splitlines() if not ln.startswith("PEAK_KB"))
    return wall, peak // 1024, proc.stdout + err, proc.returncode


def load() -> str:
    return ", ".join(f"{v:.1f}" for v in os.getloadavg())


def long_records(tmp: Path, sizes: list[int]) -> None:
    for n in sizes:
        t0 = time.perf_counter()
        path = long_record(tmp / f"FIC_LONG_{n}.csv", n)
        print(f"{n} samples written ({path.stat().st_size / 1e6:.0f} MB) in {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)
        wall, mb, out, rc = timed_child([PHFDI, "loop-diagnose", str(path), "--no-baselines"])
        verdict = next((ln.strip() for ln in out.splitlines() if ln.strip().startswith("verdict:")), "?")
        note = next((ln.strip() for ln in out.splitlines() if "rows, more than" in ln or "windows of up to" in ln), "")
        print(f"{n}-sample record: {wall:.1f} s, peak memory {mb} MB, exit {rc} (load average {load()})")
        print(f"  {verdict}")
        if note:
            print(f"  {note[:400]}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--loops", type=int, default=10_000)
    p.add_argument("--full-loops", type=int, default=1000, help="loops run with the fits where flagged")
    p.add_argument("--cpu-loops", type=int, default=200, help="loops whose screen CPU time is measured in process")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--scheduler", default=None)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--no-long", action="store_true", help="skip the 1 M and 10 M-sample records")
    p.add_argument("--only-long", action="store_true", help="only the long records")
    p.add_argument("--long", default="1000000,10000000", help="long record sizes (samples, comma separated)")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="plant_wide_") as tmp_name:
        tmp = Path(tmp_name)
        if not args.only_long:
            screen_and_fits(tmp, args)
        if not args.no_long:
            long_records(tmp, [int(v) for v in args.long.split(",") if v.strip()])
    return 0


def screen_and_fits(tmp: Path, args) -> None:
    folder = tmp / "loops"
    folder.mkdir()
    t0 = time.perf_counter()
    truth = write_loops(folder, args.loops, args.seed)
    print(f"{len(truth)} loops written in {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    reports, wall = run_plant(folder, tmp / "screen", "none", args.workers, args.scheduler)
    failed = sum("error" in r for r in reports)
    where = args.scheduler or f"LocalCluster, {args.workers} worker processes"
    print(f"screen: {len(reports)} loops ({failed} failed) in {wall:.1f} s on Dask ({where}): "
          f"{60.0 * len(reports) / wall:.0f} loops/minute (load average {load()})")
    if args.cpu_loops > 0:
        ms = screen_cpu_ms(sorted(folder.iterdir())[:args.cpu_loops])
        print(f"screen CPU per loop in this process (read, structure checks, screen, report; {args.cpu_loops} loops): "
              f"{ms:.0f} ms, so {2 * 60000.0 / ms:.0f} loops/minute on 2 cores at that cost (load average {load()})")
    if args.full_loops <= 0:
        return
    sub = tmp / "subset"
    sub.mkdir()
    for f in sorted(folder.iterdir())[:args.full_loops]:
        os.link(f, sub / f.name)
    reports, wall = run_plant(sub, tmp / "full", "flagged", args.workers, args.scheduler)
    flagged = sum(r.get("valve_models") == "fitted" for r in reports)
    calls = [((r.get("loop_verdict") or {}).get("verdict"), truth.get(str(folder / Path(r["file"]).name)))
             for r in reports if "error" not in r]
    st = sum(v == "stiction" for v, _ in calls)
    right = sum(v == "stiction" for v, t in calls if t)
    print(f"screen and fits where flagged: {len(reports)} loops in {wall:.1f} s: {60.0 * len(reports) / wall:.0f} "
          f"loops/minute; {flagged} flagged and fitted ({flagged / max(len(reports), 1):.0%}); {st} called "
          f"stiction, {right} of them sticky (load average {load()})")


if __name__ == "__main__":
    sys.exit(main())
