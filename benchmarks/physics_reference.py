"""The paper loop's physics as the reference of the multichannel detector: false alarms, delays and namings.

    .venv/bin/python benchmarks/physics_reference.py                  # paper severities, seeds 1-3 (Dask, minutes)
    .venv/bin/python benchmarks/physics_reference.py --all-severities
    .venv/bin/python benchmarks/physics_reference.py --all-severities --healthy 48     # 133 h of healthy runs
    .venv/bin/python benchmarks/physics_reference.py --all-severities --kind-setting aj_energy_variance_ratio=0

Issue 37 made the physics model one more reference kind of the multichannel detector (``wavelet_fdi.reference_physics``,
kind ``physics``) and retired the physics detector (``StreamingDetector``) on 2026-12-07, after this benchmark had
measured the two side by side (docs/detector.md keeps that table). It now measures the kind alone:

* calibration: the physics kind's band scales and thresholds (``learned_detector.calibrate_bands``) on healthy
  runs of the paper scenario with the seeds ``phfdi evaluate`` calibrates on (1001-1016);
* held-out healthy runs (seeds 1-8 of ``phfdi evaluate``): fault alarms per hour of monitored time;
* every fault of ``phfdi evaluate``'s matrix (``study.evaluation.severities``), onset 7000 s, seeds 1-3: found or
  missed, the delay from the onset to the first alarm after it, and the class that alarm is named
  (``isolation.FaultIsolator``, 300 s after the detection; right: the fault's own class, ``unknown`` for probe
  noise, which no hypothesis models, as ``phfdi evaluate`` scores it).

The multichannel detector's settings are its declared defaults with the physics detector's design
(``reference_physics.PHYSICS_DESIGN``): the same wavelet and level; the residual's own mean (``residual_mean_k``,
the physics detector's R) and AJ's mean designed for a shift of one residual sigma (k in AJ's sigmas); energy
CUSUMs designed for a fourfold variance; the pH alone (``watch_level`` false); and its false-alarm target
(``arl0_samples``, 1e5 samples for the whole detector), for which each statistic's threshold is measured on the
calibration runs (``learned_detector.calibrate_bands``). Nothing was chosen on a fault run.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

import numpy as np

ONSET_S = 7000.0
CALIBRATION_SEEDS = tuple(range(1001, 1017))
HEALTHY_SEEDS = tuple(range(1, 9))
FAULT_SEEDS = (1, 2, 3)


@dataclass(frozen=True)
class Task:
    fault: str  # "healthy" or a fault of study.evaluation.severities()
    params: dict
    seed: int


def physics_settings(**given):
    """The multichannel detector's settings with the physics detector's design (``reference_physics.design_settings``),
    ``given`` set otherwise."""
    from wavelet_fdi.reference_physics import design_settings

    return design_settings(sample_time_s=1.0, **given)


def _spec(task: Task):
    from phfdi.study.evaluation import _spec as evaluation_spec

    return evaluation_spec("paper", task.fault, task.params, task.seed, None if task.fault == "healthy" else ONSET_S)


def healthy_rows(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A healthy run's time and the physics kind's channels."""
    from phfdi.loop import simulate
    from wavelet_fdi.reference_physics import PhysicsReference

    spec = _spec(Task("healthy", {}, seed))
    run = simulate(spec)
    ref = PhysicsReference.from_spec(spec)
    return np.asarray(run.time_s, float), np.column_stack([np.asarray(run[c], float) for c in ref.channels])


def score(task: Task, model) -> dict:
    """The detector on one run: alarms before the onset, and the delay and naming of the first one after it."""
    from phfdi.loop import simulate
    from wavelet_fdi.learned_detector import run_record

    spec = _spec(task)
    run = simulate(spec)
    t = np.asarray(run.time_s, float)
    onset = ONSET_S if task.fault != "healthy" else None
    rows = np.column_stack([np.asarray(run[c], float) for c in model.channels])
    _, _, det = run_record(model, t, rows)
    alarms = [(a["detection_time"], (a.get("isolation") or {}).get("fault_class", "pending")) for a in det.alarms]
    before = [x for x, _ in alarms if onset is None or x < onset]
    after = [(x, c) for x, c in alarms if onset is not None and x >= onset]
    return {"fault": task.fault, "params": task.params, "seed": task.seed,
            "monitored_h": float((t[-1] - t[0]) / 3600.0), "alarms_before": len(before),
            "delay_s": (after[0][0] - onset) if after else None, "named": after[0][1] if after else None,
            "statistics_before": [a["statistic"] for a in det.alarms if onset is None or a["detection_time"] < onset]}


def tasks(all_severities: bool, healthy: int = len(HEALTHY_SEEDS)) -> list[Task]:
    from phfdi.study.evaluation import PAPER_SEVERITY, severities

    out = [Task("healthy", {}, s) for s in range(1, healthy + 1)]
    for fault, (_, levels) in severities().items():
        chosen = levels if all_severities else [levels[PAPER_SEVERITY]]
        out += [Task(fault, p, s) for p in chosen for s in FAULT_SEEDS]
    return out


def expected(fault: str) -> str:
    """The class a right naming gives (phfdi evaluate's rule: probe noise is no hypothesis, so "unknown")."""
    from phfdi.study.evaluation import EXPECTED_CLASS

    return EXPECTED_CLASS.get(fault, fault)


def report(rows: list[dict]) -> None:
    healthy = [r for r in rows if r["fault"] == "healthy"]
    hours = sum(r["monitored_h"] for r in healthy)
    print(f"\nheld-out healthy runs: {len(healthy)} ({hours:.1f} h)")
    print("| detector | fault alarms on healthy runs | per hour | faults found | median delay (s) | named right |")
    print("|---|---|---|---|---|---|")
    faulty = [r for r in rows if r["fault"] != "healthy"]
    fa = sum(r["alarms_before"] for r in healthy)
    found = [r["delay_s"] for r in faulty if r["delay_s"] is not None]
    right = sum(r["named"] == expected(r["fault"]) for r in faulty)
    med = f"{np.median(found):.0f}" if found else "-"
    print(f"| physics_kind | {fa} | {fa / hours:.2f} | {len(found)}/{len(faulty)} | {med} | {right}/{len(faulty)} |")
    by_statistic: dict[str, int] = {}
    for r in healthy:
        for name in r["statistics_before"]:
            by_statistic[name] = by_statistic.get(name, 0) + 1
    print("the physics kind's fault alarms on healthy runs, by statistic:", by_statistic or "none")
    print("\n| fault | parameters | physics kind: found, delays (s); named | alarms before the onset |")
    print("|---|---|---|---|")
    groups: dict[tuple, list[dict]] = {}
    for r in faulty:
        groups.setdefault((r["fault"], tuple(sorted(r["params"].items()))), []).append(r)
    for (fault, params), rs in groups.items():
        d = [r["delay_s"] for r in rs]
        found_here = [x for x in d if x is not None]
        names = ", ".join(sorted({str(r["named"]) for r in rs if r["named"] is not None}))
        cell = (f"{len(found_here)}/{len(d)}: " + ", ".join("-" if x is None else f"{x:.0f}" for x in d)
                + (f"; {names}" if names else ""))
        before = sum(r["alarms_before"] for r in rs)
        print(f"| {fault} | {', '.join(f'{k} {v:g}' for k, v in params)} | {cell} | {before} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--all-severities", action="store_true", help="the three severities of every fault, not only "
                                                                 "the paper's")
    p.add_argument("--healthy", type=int, default=len(HEALTHY_SEEDS),
                   help=f"held-out healthy runs, seeds 1..N (default {len(HEALTHY_SEEDS)}, phfdi evaluate's)")
    p.add_argument("--kind-setting", action="append", default=[], metavar="KEY=VALUE",
                   help="a setting of the physics kind other than its design (e.g. aj_energy_variance_ratio=0)")
    p.add_argument("--scheduler", default=None, help="an existing Dask scheduler's address (default: a local one)")
    args = p.parse_args(argv)
    given = {}
    for item in args.kind_setting:
        key, _, value = item.partition("=")
        given[key.strip()] = float(value)
    from phfdi.loop import simulate  # noqa: F401  (fails early, before the cluster starts, if the install is broken)
    from phfdi.loopdiag.dask_run import dask_client, map_ordered
    from phfdi.scenario import load_scenario
    from wavelet_fdi.learned_detector import calibrate_bands
    from wavelet_fdi.reference_physics import PhysicsReference

    t0 = time.perf_counter()

    def show(done: int, total: int) -> None:
        print(f"{done}/{total} runs, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    with dask_client(args.scheduler, None) as client:
        runs = map_ordered(client, healthy_rows, list(CALIBRATION_SEEDS), show)
        # the pH alone, as the physics detector watched it by default
        reference = PhysicsReference.from_spec(load_scenario("paper", fault="healthy"), watch_level=False)
        model = calibrate_bands(reference, runs, physics_settings(**given), {"seeds": list(CALIBRATION_SEEDS)})
        print("band scales (healthy RMS, sensor-noise units):", {c: np.round(row, 3).tolist() for c, row in
                                                                 zip(model.residual_channels, model.band_sigma)})
        print("thresholds measured for ARL0 =", f"{model.settings.arl0_samples:g} samples:",
              {k: round(v, 1) for k, v in model.thresholds.items()})
        todo = tasks(args.all_severities, args.healthy)
        rows = map_ordered(client, _score_with, [(t, model) for t in todo], show)
    report(rows)
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


def _score_with(item: tuple) -> dict:
    task, model = item
    return score(task, model)


if __name__ == "__main__":
    raise SystemExit(main())
