"""The estimator's detector on simulated rig runs of operations no calibration run had (issue 34).

Two calibrations, each scored on hours of simulated healthy operation of the unseen operations of
:mod:`phfdi.rigsim` (open-loop additions at new pump settings, slow rises, titrations at new rates and ramps,
on/off control of one or both pumps with and without hysteresis, a chattering pump, PI control; each run on a
day of the rig of its own) and on the same kind of runs with a probe fault acting on the reading the controller
sees, at an onset drawn per run:

* ``real``: the estimator calibrated on the five recorded runs (what a user of the rig would do);
* ``simulated``: calibrated on the five recorded operations replayed on five simulated days (the recorded runs'
  command columns), so that only the operations, not the simulator's own departures from the real rig, are new.

Nothing here is chosen on the scored runs: the seeds, hours, fault sizes and onset ranges are fixed below.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from phfdi.benchmarks.rig_detection import CHANNELS, PROBE_CLASS, learned_alarms, outcome
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.records import Record
from wavelet_fdi.learned_detector import LearnedModel

#: the recorded operations replayed (the ``simulated`` calibration) and the days they run on
SHARED_OPERATIONS = ("shared_add_base", "shared_add_acid", "shared_control_ph7", "shared_acid_to_base",
                     "shared_base_to_acid")
CALIBRATION_DAYS = (1000, 1001, 1002, 1003, 1004)
#: the unseen healthy runs' first seed (day = seed) and the fault runs' (other days, other draws)
HEALTHY_FIRST_SEED = 0
FAULT_FIRST_SEED = 500
#: probe faults hidden in the unseen runs (rigsim.ProbeFault kinds and sizes), onset drawn in the run's middle half
FAULTS: dict[str, float] = {"probe_bias": 0.4, "probe_drift": 1.0, "probe_frozen": 0.0, "probe_noise": 0.15,
                            "probe_lag": 30.0}
ONSET_FRACTIONS = (0.25, 0.75)
#: a faulty run is scored at most this long (s) after its onset: the onsets of long runs drawn late would
#: otherwise give the slow faults hours
SCORED_AFTER_ONSET_S = 900.0


@dataclass
class Scores:
    calibration: str
    healthy_hours: float = 0.0
    healthy_runs: int = 0
    fault_alarms: int = 0
    warnings: int = 0
    warnings_announced: int = 0
    runs_with_fault_alarm: list = field(default_factory=list)
    cases: list = field(default_factory=list)


def calibrate(which: str, data_dir: str | None, column_map, progress: Callable[[str], None]) -> LearnedModel:
    """The ``real`` or ``simulated`` calibration (module doc)."""
    from phfdi.learned import read_measured
    from phfdi.rigsim import simulate_run

    start = start_from_model("rig_flask")
    if which == "real":
        import glob
        from pathlib import Path

        paths = sorted(glob.glob(str(Path(data_dir or "") / "ph_rig" / "*.csv")))
        if not paths:
            raise SystemExit(f"no rig runs under {data_dir}/ph_rig")
        records = [read_measured(p, column_map, channels=list(CHANNELS)) for p in paths]
    else:
        records = [simulate_run(op, seed=day, day=day).measured(CHANNELS)
                   for op, day in zip(SHARED_OPERATIONS, CALIBRATION_DAYS)]
    progress(f"calibration '{which}': {len(records)} runs, {sum(len(r.x) for r in records)} rows")
    return fit_estimator(records, start, progress=lambda m: progress(f"  {m}"))


def _hours(rec: Record) -> float:
    return float(rec.time_s[-1] - rec.time_s[0]) / 3600.0


def score_healthy(model: LearnedModel, hours: float, scores: Scores, progress: Callable[[str], None],
                  seed_offset: int = 0) -> None:
    from phfdi.rigsim import draw_runs

    for run in draw_runs(hours, "unseen", HEALTHY_FIRST_SEED + seed_offset):
        rec = run.measured(CHANNELS)
        o = outcome(learned_alarms(model, rec), None)
        scores.healthy_hours += _hours(rec)
        scores.healthy_runs += 1
        scores.fault_alarms += o.alarms_before
        scores.warnings += o.warnings_before
        scores.warnings_announced += o.warnings_announced_before
        if o.alarms_before:
            scores.runs_with_fault_alarm.append(f"{run.operation.name} seed {run.seed}")
        progress(f"  healthy {run.operation.name:32s} seed {run.seed:3d}: {_hours(rec) * 60:5.1f} min, "
                 f"{o.alarms_before} fault alarm(s), {o.warnings_before} deviation(s) outside calibration")


def score_faults(model: LearnedModel, runs_per_kind: int, scores: Scores, progress: Callable[[str], None],
                 seed_offset: int = 0) -> None:
    from phfdi.rigsim import ProbeFault, operation_names, simulate_run

    names = operation_names("unseen")
    first = FAULT_FIRST_SEED + seed_offset
    rng = np.random.default_rng(first)
    for kind, size in FAULTS.items():
        for i in range(runs_per_kind):
            seed = first + len(scores.cases)
            op = names[i % len(names)]
            healthy = simulate_run(op, seed)
            t0, t1 = float(healthy.time_s[0]), float(healthy.time_s[-1])
            onset = round(t0 + float(rng.uniform(*ONSET_FRACTIONS)) * (t1 - t0), 2)
            run = simulate_run(op, seed, probe_fault=ProbeFault(kind, onset, size, seed=seed))
            rec = run.measured(CHANNELS)
            keep = rec.time_s <= onset + SCORED_AFTER_ONSET_S
            rec = rec.subset(keep)
            o = outcome(learned_alarms(model, rec), onset)
            found = o.alarms_before == 0 and o.first_after_s is not None
            scores.cases.append({"kind": kind, "size": size, "operation": op, "seed": seed, "onset_s": onset,
                                 "alarms_before": o.alarms_before, "warnings_before": o.warnings_before,
                                 "found": found, "delay_s": (o.first_after_s - onset) if found else None,
                                 "family": o.family, "class_named": o.fault_class, "size_named": o.size,
                                 "class_right": o.fault_class in PROBE_CLASS[kind]})
            progress(f"  {kind:13s} {op:32s} seed {seed}: onset {onset:7.1f} s, "
                     + (f"found after {o.first_after_s - onset:.0f} s, named {o.fault_class}" if found
                        else f"missed ({o.alarms_before} fault alarm(s) before the onset)"))


def summary(scores: Scores) -> dict:
    per_kind = {}
    for kind in FAULTS:
        cs = [c for c in scores.cases if c["kind"] == kind]
        found = [c for c in cs if c["found"]]
        delays = sorted(c["delay_s"] for c in found)
        per_kind[kind] = {"cases": len(cs), "found": len(found), "class_right": sum(c["class_right"] for c in found),
                          "median_delay_s": delays[len(delays) // 2] if delays else None}
    h = scores.healthy_hours
    return {"calibration": scores.calibration, "healthy_hours": round(h, 3), "healthy_runs": scores.healthy_runs,
            "fault_alarms": scores.fault_alarms, "fault_alarms_per_hour": round(scores.fault_alarms / h, 3) if h else math.nan,
            "warnings": scores.warnings, "warnings_announced": scores.warnings_announced,
            "warnings_announced_per_hour": round(scores.warnings_announced / h, 2) if h else math.nan,
            "runs_with_fault_alarm": scores.runs_with_fault_alarm, "faults": per_kind}


def evaluate(calibrations: Sequence[str], hours: float, runs_per_kind: int, data_dir: str | None, column_map,
             progress: Callable[[str], None] = print, seed_offset: int = 0) -> dict:
    """Each calibration scored on ``hours`` of unseen healthy runs and ``runs_per_kind`` faulty runs per probe
    fault; ``seed_offset`` moves every run's seed (healthy and faulty) by that much: other days and draws, for a
    measurement on runs no one has looked at (0: the seeds of docs/detector.md's tables)."""
    out = {"hours": hours, "runs_per_kind": runs_per_kind, "seed_offset": seed_offset, "faults": FAULTS,
           "results": [], "cases": {}}
    for which in calibrations:
        model = calibrate(which, data_dir, column_map, progress)
        scores = Scores(which)
        score_healthy(model, hours, scores, progress, seed_offset)
        score_faults(model, runs_per_kind, scores, progress, seed_offset)
        out["results"].append(summary(scores))
        out["cases"][which] = scores.cases
    return out
