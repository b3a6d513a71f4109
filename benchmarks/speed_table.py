"""The README's speed table, measured: runs the benchmark of each row and writes the table.

    .venv/bin/python benchmarks/speed_table.py                    # every row (about 25 min on 2 cores); prints it
    .venv/bin/python benchmarks/speed_table.py --quick            # the rows that take seconds (about 2 min)
    .venv/bin/python benchmarks/speed_table.py --only detector plant_wide
    .venv/bin/python benchmarks/speed_table.py --quick --update   # and write the results and the README's table

Each row's command is run as printed in the table (from the repository's root, ``.venv/bin/python`` being this
interpreter), and its figure read off the command's output; a row timed here (no benchmark script of its own) is
the command's wall time. The table is printed in markdown. ``--update`` writes the rows measured into
``benchmarks/results/speed_table.json`` (each with its date, the load average before and after, the commit) and
rewrites from it the README's table (between its two ``speed table`` markers) and docs/speed_table.md (the same
rows with their dates and load averages); rows not run keep their last measurement. Without ``--update`` nothing
committed is written (the results go to ``out/speed_table.json``); each command's output is kept in
``out/speed_table/ROW.out``. tests/docs/test_speed_table.py checks that the
README's table is the one written from the committed results: it is never edited by hand.

A row needs ROS 2 (the graph), or ../shared/data (``PHFDI_SHARED_DATA``); a row that cannot run here, fails or
times out is said and keeps its last measurement. The machine is shared: the load average is recorded with every
row, and a figure measured at a high load is a lower bound of the speed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results" / "speed_table.json"
SCRATCH = ROOT / "out" / "speed_table.json"
README = ROOT / "README.md"
DETAILS = ROOT / "docs" / "speed_table.md"
BEGIN = "<!-- speed table: written by `.venv/bin/python benchmarks/speed_table.py --update` from " \
        "benchmarks/results/speed_table.json; do not edit by hand -->"
END = "<!-- end of speed table -->"


@dataclass(frozen=True)
class Row:
    """One row: what is measured, the command (as the table prints it), how its figure is read off the output.

    ``read(output) -> (measured text, value, met)``; None: the command's wall time is the figure (``timed``).
    ``met`` is None where no target is set."""

    key: str
    what: str
    command: str
    target: str
    read: Callable[[str], tuple[str, float, bool | None]] | None
    quick: bool = False
    ros: bool = False
    data: bool = False
    timeout_s: float = 1800.0
    timed: Callable[[float], tuple[str, float, bool | None]] | None = None


def _find(pattern: str, text: str) -> tuple[str, ...]:
    m = re.search(pattern, text, re.M)
    if m is None:
        raise ValueError(f"no line matching {pattern!r} in the output")
    return m.groups()


def _num(text: str) -> float:
    return float(text.replace(",", ""))


def _thousands(x: float) -> str:
    """42 300 -> '42 300' (a space between thousands, as the README writes them)."""
    return f"{x:,.0f}".replace(",", " ")


def _simulate(out: str):
    best, median = (_num(g) for g in _find(r"real-time factor best ([\d,]+) x, median ([\d,]+) x", out))
    return f"{_thousands(best)} x real time (median of 5 runs {_thousands(median)} x)", median, median >= 20000


def _lockstep(out: str):
    factor = _num(_find(r"graph \(\w+, recorded\):\s+[\d.]+ s\s+=\s+(\d+) x real time", out)[0])
    lost = int(_find(r"lost: (-?\d+) messages", out)[0])
    return f"{_thousands(factor)} x real time, {lost} messages lost", factor, factor >= 1000 and lost == 0


def _detector(out: str):
    rate = _num(_find(r"replay, 4096 samples per call:\s+(\d+) samples/s", out)[0])
    return f"{_thousands(rate)} samples/s", rate, rate >= 1e5


def _startup(out: str):
    median, low, high = (float(g) for g in _find(r"start-up wall: median ([\d.]+) s, range ([\d.]+)-([\d.]+) s", out))
    return f"{median:.1f} s median ({low:.1f}-{high:.1f} s)", median, median <= 4.3 / 2


def _detector_node(out: str):
    median, most = (_num(g) for g in _find(r"backlog .*: median (\d+), max (\d+) samples", out))
    alarm = _find(r"(?:received (\d+) ms after that sample)|(alarm: none received)", out)
    said = f"alarm {alarm[0]} ms after its sample" if alarm[0] else "no alarm"
    keeps_up = median <= 5  # samples: 50 ms at 100 Hz
    return (f"{'keeps up' if keeps_up else 'falls behind'} (backlog median {median:.0f}, max {most:.0f} samples), "
            f"{said}", median, keeps_up and bool(alarm[0]))


def _soak(out: str):
    growth = [float(g) for g in re.findall(r"^\w+\s+[\d.]+\s+[\d.]+\s+[\d.]+\s+[\d.]+\s+([+-][\d.]+)%", out, re.M)]
    if not growth:
        raise ValueError("no memory table in the output")
    lost = int(_find(r"messages lost in all: (\d+)", out)[0])
    return f"memory growth at most {max(growth):+.1f} %, {lost} lost", max(growth), max(growth) < 10 and lost == 0


def _analysis(out: str):
    warm = float(_find(r"warm best of \d+ ([\d.]+) s", out)[0])
    return f"{warm:.2f} s", warm, warm < 2.0


def _diagnose_hidden(out: str):
    seconds = float(_find(r"timing: diagnose on a \d+-sample record .*?: ([\d.]+) s", out)[0])
    found, cases = (int(g) for g in _find(r"catalogue effects: (\d+)/(\d+)", out))
    return f"{seconds:.1f} s; hidden causes found {found}/{cases}", seconds, seconds < 60 and found == cases


def _rig_diagnose(out: str):
    wall = float(_find(r"wall (\d+) s, CPU \d+ s", out)[0])
    return f"{wall:.0f} s wall", wall, wall < 300


def _skab_throughput(out: str):
    rate = _num(_find(r"whole record\s+([\d,]+) rows/s", out)[0])
    return f"{_thousands(rate)} rows/s", rate, rate >= 1e5


def _rig_throughput(out: str):
    best, median = (float(g) for g in _find(
        r"filter \+ wavelet-CUSUM detector:\s+(\d+) samples/s wall \(median\s+(\d+)\)", out))
    return f"{_thousands(best)} samples/s (median of 9 repetitions {_thousands(median)})", median, median >= 1e5


def _plant_wide(out: str):
    rate = float(_find(r"([\d.]+) loops/minute", out)[0])
    return f"{rate:.0f} loops/min on 2 workers", rate, rate >= 1000.0


def _plant_records(wall_s: float):
    return f"{wall_s:.0f} s with figures, local Dask cluster of 2 workers", wall_s, None


PY = ".venv/bin/python"
DATA = "PHFDI_SHARED_DATA=../shared/data"
ROWS = (
    Row("simulate", "10000 s paper scenario in process, 1 s sampling", f"{PY} benchmarks/simulate.py --repeat 5",
        "20 000 x", _simulate, quick=True),
    Row("graph_lockstep", "the same through the ROS 2 graph, lock-step, recorded", f"{PY} benchmarks/graph_lockstep.py",
        "1000 x", _lockstep, ros=True),
    Row("detector", "offline replay through the detector", f"{PY} benchmarks/detector.py", "1e5 samples/s",
        _detector, quick=True),
    Row("graph_startup", "graph start-up with the detector",
        f"{PY} benchmarks/graph_startup.py --repeat 3 --detector", "under half of 4.3 s", _startup, ros=True),
    Row("detector_node", "detector node against a 100 Hz stream", f"{PY} benchmarks/detector_node.py",
        "no backlog", _detector_node, ros=True),
    Row("soak", "soak, 100 000 s simulated with detector and recorder",
        f"{PY} benchmarks/soak.py --sim-s 100000 --overwrite", "< 10 %, 0 lost", _soak, ros=True, timeout_s=3600.0),
    Row("analysis", "Section 6 analysis of 35 x 1440 samples", f"{PY} benchmarks/analysis.py", "< 2 s", _analysis,
        quick=True),
    Row("diagnose_hidden", "diagnose, 10001 samples, whole catalogue",
        f"{PY} benchmarks/diagnose_hidden.py --controls 3 --outside --seed 2026", "< 60 s, 100 %", _diagnose_hidden,
        timeout_s=3600.0),
    Row("rig_diagnose_time", "diagnose --structure on the five rig runs",
        f"{PY} benchmarks/rig_diagnose_time.py", "< 5 min on 2 cores", _rig_diagnose, data=True),
    Row("skab_throughput", "learned detector, 8 channels",
        f"{PY} benchmarks/skab_throughput.py ../shared/data/skab/anomaly-free/anomaly-free.csv", "1e5 rows/s",
        _skab_throughput, quick=True, data=True),
    Row("rig_throughput", "estimator reference on the rig's records", f"{DATA} {PY} benchmarks/rig_throughput.py",
        "1e5 samples/s", _rig_throughput, quick=True, data=True),
    Row("plant_wide", "plant-wide loop-diagnose screen, 3000 simulated loops",
        f"{PY} benchmarks/plant_wide.py --loops 3000 --full-loops 0 --cpu-loops 0 --no-long", ">= 1000 loops/min",
        _plant_wide, timeout_s=3600.0),
    Row("plant_records", "loop-diagnose on the 59 shared records (section 3)",
        ".venv/bin/phfdi loop-diagnose ../shared/data/plant_loops/stiction ../shared/data/plant_loops/no_stiction "
        "--out out/speed_table/plant --figures out/speed_table/plant/figs --overwrite", "none set", None,
        data=True, timed=_plant_records),
)
KEYS = {r.key: r for r in ROWS}


# ---- running -------------------------------------------------------------------------------------------
def argv_of(command: str) -> tuple[dict[str, str], list[str]]:
    """(environment additions, argv) of a row's command, as run from the repository's root."""
    words = shlex.split(command)
    env = {}
    while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):
        name, _, value = words.pop(0).partition("=")
        env[name] = value
    if words[0] == PY:
        words[0] = sys.executable  # this interpreter: the venv's when run as the docstring says
    return env, words


def why_not(row: Row) -> str | None:
    """Why the row cannot run here (None: it can)."""
    import importlib.util

    if row.ros and importlib.util.find_spec("rclpy") is None:
        return "ROS 2 (rclpy) is not installed"
    if row.data and not (ROOT.parent / "shared" / "data").is_dir():  # the commands name ../shared/data
        return "../shared/data is not there"
    return None


def measure(row: Row, commit: str) -> dict:
    """Run the row's command; its measurement (or an ``error``)."""
    env, argv = argv_of(row.command)
    environ = {**os.environ, **env, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    load_before = os.getloadavg()[0]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(argv, cwd=ROOT, env=environ, capture_output=True, text=True, timeout=row.timeout_s)
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {row.timeout_s:.0f} s"}
    wall_s = time.perf_counter() - t0
    entry = {"date": datetime.date.today().isoformat(), "commit": commit, "load1_before": round(load_before, 1),
             "load1_after": round(os.getloadavg()[0], 1), "wall_s": round(wall_s, 1)}
    if done.returncode not in (0,) and not (row.key == "plant_records" and done.returncode == 1):
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        return {"error": f"exit {done.returncode}: {' / '.join(tail)}"}
    log = SCRATCH.parent / "speed_table" / f"{row.key}.out"  # the command's own output, for reference
    log.parent.mkdir(parents=True, exist_ok=True)
    log.write_text(done.stdout + done.stderr[-20000:])
    try:
        measured, value, met = row.timed(wall_s) if row.timed else row.read(done.stdout)  # type: ignore[misc]
    except ValueError as exc:
        return {"error": f"{exc} (output: {done.stdout[-300:]!r})"}
    return {**entry, "measured": measured, "value": value, "met": met}


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


# ---- the table ------------------------------------------------------------------------------------------
#: cores of the machine the table is measured on: above this load average, a speed missed is not judged
CORES = 2


def target_cell(row: Row, entry: dict | None) -> str:
    """'TARGET: met', 'TARGET: **not met**', or, missed while the machine was busier than its cores, said so (a
    figure measured at a load average of 13 on 2 cores is not the machine's: no verdict)."""
    if entry is None or entry.get("met") is None:
        return row.target
    if entry["met"]:
        return f"{row.target}: met"
    load = max(entry["load1_before"], entry["load1_after"])
    if load > CORES:
        return f"{row.target}: missed at load average {load:.0f} on {CORES} cores (not judged)"
    return f"{row.target}: **not met**"


def table(results: dict[str, dict]) -> str:
    """The README's table (markdown) from the results (key -> entry)."""
    lines = ["| what | command | measured | target |", "| --- | --- | --- | --- |"]
    for row in ROWS:
        entry = results.get(row.key)
        measured = f"{entry['measured']} (load average {_load(entry)})" if entry else "not measured yet"
        lines.append(f"| {row.what} | `{row.command}` | {measured} | {target_cell(row, entry)} |")
    return "\n".join(lines)


def _load(entry: dict) -> str:
    """'2.2-2.7': the 1-minute load average before and after the command (one figure when they agree)."""
    low, high = sorted((entry["load1_before"], entry["load1_after"]))
    return f"{low:.1f}" if f"{low:.1f}" == f"{high:.1f}" else f"{low:.1f}-{high:.1f}"


def details(results: dict[str, dict]) -> str:
    """docs/speed_table.md: the rows with their dates, load averages and commits."""
    lines = ["# The README's speed table, with dates", "",
             "Written by `.venv/bin/python benchmarks/speed_table.py --update` from "
             "benchmarks/results/speed_table.json (do not edit by hand). Load average: 1 minute, before and after "
             "the row's command, on this 2-core machine shared by several developers (a figure measured at a high "
             "load is a lower bound of the speed). The history of each figure, with its caveats: "
             "[results.md](results.md#benchmarks-speed-and-accuracy-as-measured).", "",
             "| what | measured | target | date | load average | wall of the command | commit |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for row in ROWS:
        e = results.get(row.key)
        if e is None:
            lines.append(f"| {row.what} | not measured yet | {row.target} | | | | |")
            continue
        lines.append(f"| {row.what} | {e['measured']} | {target_cell(row, e)} | {e['date']} | "
                     f"{e['load1_before']} -> {e['load1_after']} | {e['wall_s']:.0f} s | {e['commit']} |")
    return "\n".join(lines) + "\n"


def readme_with(text: str, new_table: str) -> str:
    """The README's text with the table between the markers replaced."""
    if BEGIN not in text or END not in text:
        raise SystemExit(f"speed_table: README.md has no {BEGIN!r} ... {END!r} markers")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{new_table}\n{END}{tail}"


def readme_table(text: str) -> str:
    """The table between the README's markers (as written there)."""
    return text.split(BEGIN, 1)[1].split(END, 1)[0].strip()


def _write(path: Path, text: str) -> None:
    from phfdi_base.outputs import write_text

    write_text(path, text, overwrite=True)  # atomically: a reader never sees half a table


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=__doc__.split("\n\n", 1)[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="only the rows that take seconds")
    ap.add_argument("--only", nargs="+", choices=list(KEYS), metavar="ROW", help=f"only these rows: {', '.join(KEYS)}")
    ap.add_argument("--update", action="store_true",
                    help="write benchmarks/results/speed_table.json, the README's table and docs/speed_table.md")
    args = ap.parse_args(argv)
    rows = [KEYS[k] for k in args.only] if args.only else [r for r in ROWS if r.quick or not args.quick]
    results = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    commit = _commit()
    for row in rows:
        why = why_not(row)
        if why:
            print(f"speed_table: {row.key}: not run ({why}); keeps its last measurement", file=sys.stderr)
            continue
        print(f"speed_table: {row.key}: {row.command}", file=sys.stderr, flush=True)
        entry = measure(row, commit)
        if "error" in entry:
            print(f"speed_table: {row.key}: {entry['error']}; keeps its last measurement", file=sys.stderr)
            continue
        print(f"speed_table: {row.key}: {entry['measured']} (load average {entry['load1_before']} -> "
              f"{entry['load1_after']}, {entry['wall_s']:.0f} s)", file=sys.stderr, flush=True)
        results[row.key] = entry
    text = json.dumps({k: results[k] for k in KEYS if k in results}, indent=1) + "\n"
    print(table(results))
    if args.update:
        _write(RESULTS, text)
        _write(README, readme_with(README.read_text(encoding="utf-8"), table(results)))
        _write(DETAILS, details(results))
        print(f"speed_table: wrote {RESULTS.relative_to(ROOT)}, README.md's table and "
              f"{DETAILS.relative_to(ROOT)}", file=sys.stderr)
    else:
        _write(SCRATCH, text)
        print(f"speed_table: wrote {SCRATCH.relative_to(ROOT)} (--update writes the committed results and the "
              f"README's table)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
