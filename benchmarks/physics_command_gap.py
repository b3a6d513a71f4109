"""A valve command missing for a while on healthy runs: fault alarms of the physics detector and the physics kind.

    .venv/bin/python benchmarks/physics_command_gap.py                   # gaps 60, 600, 1800 s; seeds 1-16 (minutes)
    .venv/bin/python benchmarks/physics_command_gap.py --gaps 1800 --seeds 48

A historian or a bridge that drops the valve command leaves the detector without its model's input: the valve may
move unseen while the pH keeps its measurements. Both detectors hold the last command for ``command_timeout_s``
(10 s); beyond it the physics detector (``StreamingDetector``) holds detection and, when the command returns,
re-aligns its model on the measured pH and level and warms up again; the physics kind
(``wavelet_fdi.reference_physics``) holds its residuals and restarts its model on the measurements as at a
record's start, then warms up again. Every fault alarm here is a false one: the runs are healthy (the paper
scenario of ``phfdi evaluate``, seeds 1..N), and the command is removed (NaN, both ``valve_command_pct`` and the pH
controller's output) from 4000 s for the gap's length. The physics kind is calibrated as in
``benchmarks/physics_reference.py`` (seeds 1001-1016, the physics detector's design); nothing here is fitted to
these runs.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

HERE = str(Path(__file__).resolve().parent)
GAP_START_S = 4000.0


def _benchmarks():
    """benchmarks/physics_reference.py (its scenario, settings and calibration runs), here and on a Dask worker."""
    if HERE not in sys.path:
        sys.path.insert(0, HERE)
    import physics_reference

    return physics_reference


def healthy_rows(seed: int) -> tuple:
    return _benchmarks().healthy_rows(seed)


def score(item: tuple) -> dict:
    """Both detectors on one healthy run with the command removed for ``gap_s`` from GAP_START_S."""
    seed, gap_s, model = item
    pr = _benchmarks()
    from phfdi.loop import simulate
    from phfdi.records import Record
    from phfdi.replay import run_chunks
    from wavelet_fdi import DetectorSettings, StreamingDetector, load_default_calibration
    from wavelet_fdi.learned_detector import run_record

    spec = pr._spec(pr.Task("healthy", {}, seed))
    run = simulate(spec)
    t = np.asarray(run.time_s, float)
    signals = {n: np.asarray(run[n], float).copy() for n in run.names}
    gap = (t >= GAP_START_S) & (t < GAP_START_S + gap_s)
    for name in ("valve_command_pct", "ph_controller_output_pct"):
        if name in signals:
            signals[name][gap] = np.nan
    settings = DetectorSettings()
    det = StreamingDetector(spec, load_default_calibration("paper", settings), settings, isolate=False)
    run_chunks(det, Record.of({"time_s": t, **signals}, run.metadata))
    rows = np.column_stack([signals[c] for c in model.channels])
    _, _, kind = run_record(model, t, rows)
    return {"seed": seed, "gap_s": gap_s, "hours": float((t[-1] - t[0]) / 3600.0),
            "physics_detector": [round(a.detection_time_s) for a in det.alarms],
            "physics_kind": [round(a["detection_time"]) for a in kind.alarms]}


def report(rows: list[dict]) -> None:
    print("| valve command missing (s) | runs | physics detector: fault alarms (runs with one) | "
          "physics kind: fault alarms (runs with one) |")
    print("|---|---|---|---|")
    for gap_s in sorted({r["gap_s"] for r in rows}):
        these = [r for r in rows if r["gap_s"] == gap_s]
        cells = []
        for name in ("physics_detector", "physics_kind"):
            alarms = sum(len(r[name]) for r in these)
            cells.append(f"{alarms} ({sum(bool(r[name]) for r in these)})")
        print(f"| {gap_s:g} | {len(these)} | {cells[0]} | {cells[1]} |")
    for r in rows:
        if r["physics_detector"] or r["physics_kind"]:
            print(f"seed {r['seed']}, gap {r['gap_s']:g} s: physics detector at {r['physics_detector']} s, "
                  f"physics kind at {r['physics_kind']} s")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--gaps", type=float, nargs="+", default=[0.0, 60.0, 600.0, 1800.0],
                   help="lengths of the missing stretch, s (0: the run as recorded)")
    p.add_argument("--seeds", type=int, default=16, help="healthy runs, seeds 1..N (default 16)")
    p.add_argument("--scheduler", default=None, help="an existing Dask scheduler's address (default: a local one)")
    args = p.parse_args(argv)
    if args.seeds < 1 or any(not (0.0 <= g < 6000.0) for g in args.gaps):
        p.error("--seeds must be >= 1 and every gap in [0, 6000) s (the runs last 10 000 s, the gap starts at 4000 s)")
    pr = _benchmarks()
    from phfdi.loopdiag.dask_run import dask_client, map_ordered
    from phfdi.scenario import load_scenario
    from wavelet_fdi.learned_detector import calibrate_bands
    from wavelet_fdi.reference_physics import PhysicsReference

    t0 = time.perf_counter()

    def show(done: int, total: int) -> None:
        print(f"{done}/{total} runs, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    with dask_client(args.scheduler, None) as client:
        runs = map_ordered(client, healthy_rows, list(pr.CALIBRATION_SEEDS), show)
        reference = PhysicsReference.from_spec(load_scenario("paper", fault="healthy"), watch_level=False)
        model = calibrate_bands(reference, runs, pr.physics_settings(), {"seeds": list(pr.CALIBRATION_SEEDS)})
        items = [(seed, gap, model) for gap in args.gaps for seed in range(1, args.seeds + 1)]
        rows = map_ordered(client, score, items, show)
    report(rows)
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
