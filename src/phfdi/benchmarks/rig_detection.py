"""Leave-one-run-out fault detection on the real pH rig (issue 21): calibrate on four runs, replay the fifth
healthy and with faults injected by :mod:`phfdi.inject`, for each reference kind side by side.

Per fold: the estimator reference (Kalman filter on the reaction invariant, :mod:`phfdi.estimator`), the
same filter on the nominal physics (the plant model's strengths and volume, the default noise model, no buffer:
nothing fitted; its bands calibrated on the training runs), the fitted physics open loop (simulation
reference), the learned ARX reference and the learned output-error reference (``form=oe``,
:mod:`wavelet_fdi.reference_oe`) fitted on the four training runs, and a plain two-sided CUSUM (k = 0.5, h for
an average run length of 1e5 samples on unit-variance residuals, Siegmund's approximation) on the estimator's
residual. Nothing is chosen on the held-out run: the fault sizes and onsets are fixed below, the thresholds come
from the training runs.
"""

from __future__ import annotations

import itertools
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from phfdi.estimator import fit_estimator, start_from_model
from phfdi.inject import inject_fault
from phfdi.inject_kinds import KINDS
from phfdi.learned import read_measured
from phfdi.records import Record
from wavelet_fdi.healthy_range import healthy_ranges, outside_ranges
from wavelet_fdi.learned_detector import LearnedModel, LearnedSettings, calibrate_bands, fit_reference, run_record

CHANNELS = ("acid_flow_ml_s", "base_flow_ml_s", "ph_measured")
#: fault kinds with (larger, smaller) sizes in their units (phfdi inject --help), fixed before any run
SIZES: dict[str, tuple[float, ...]] = {
    "probe_bias": (1.0, 0.3), "probe_drift": (1.0, 0.2), "probe_frozen": (0.0,), "probe_noise": (0.15, 0.05),
    "probe_lag": (30.0, 10.0), "probe_gain": (0.3, 0.1), "pump_low": (0.5, 0.2), "pump_high": (0.5, 0.2),
    "pump_stuck": (3.0, 1.0)}
ONSET_FRACTIONS = (0.35, 0.55, 0.75)
#: the classes a right name gives each injected probe kind (its catalogue entry's injection form), the first the
#: exact one
PROBE_CLASS = {name: kind.inject.isolated_as for name, kind in KINDS.items() if kind.family == "sensor"}
PLAIN_CUSUM_K = 0.5


def plain_cusum_h(arl0: float = 1e5, k: float = PLAIN_CUSUM_K) -> float:
    """Threshold of a one-sided CUSUM on N(0, 1) for an in-control ARL (Siegmund's approximation), solved."""
    from scipy.optimize import brentq

    def arl(h: float) -> float:
        b = h + 1.166
        return (math.exp(2 * k * b) - 2 * k * b - 1) / (2 * k * k)

    return float(brentq(lambda h: arl(h) - arl0, 0.1, 100.0))


@dataclass
class Outcome:
    alarms_before: int = 0  # fault alarms before the onset (all of them on a healthy run)
    warnings_before: int = 0  # deviations outside calibration before the onset (WARN, never a fault alarm)
    warnings_announced_before: int = 0  # of those, announced (not within the hold of the last one)
    warnings_after: int = 0  # after the onset, before the first fault alarm
    first_after_s: float | None = None
    family: str | None = None  # named by the first alarm after the onset (None: the detector names none)
    fault_class: str | None = None
    size: float | None = None  # in the class's unit (pH offset, x healthy noise, x recorded)
    marked_before: int = 0  # alarms before the onset with a channel beyond the training runs' healthy range
    outside: list | None = None  # the channels the first alarm after the onset lists beyond that range


def expected_class(kind: str, pump: str | None) -> list[str]:
    """The fault classes a right name gives an injected fault of ``kind`` (on ``pump``'s flow for the pumps)."""
    return KINDS[kind].inject.isolation_classes(pump)


def expected_size(kind: str, size: float) -> float | None:
    """The named size a right estimate gives, in the class's unit, where the injected size maps onto it: a bias's
    pH; a pump's delivered / recorded (1 - f less, 1 + f more, 0 stuck). None for the others (a drift's or a
    gain's offset depends on when and where it is named; added noise is not a multiple of the healthy one)."""
    return {"probe_bias": size, "pump_low": 1.0 - size, "pump_high": 1.0 + size, "pump_stuck": 0.0}.get(kind)


def outcome(alarms: Sequence[dict], onset_s: float | None) -> Outcome:
    """What a detector's alarms (:func:`learned_alarms`) say of a run whose fault starts at ``onset_s`` (None:
    healthy): fault alarms and deviations outside calibration (``verdict``) counted apart."""
    out = Outcome()
    for a in alarms:
        ta = a["t"]
        if a.get("verdict", "fault") != "fault":
            if onset_s is None or ta < onset_s:
                out.warnings_before += 1
                out.warnings_announced_before += bool(a.get("announced", True))
            elif out.first_after_s is None:
                out.warnings_after += 1
            continue
        if onset_s is None or ta < onset_s:
            out.alarms_before += 1
            out.marked_before += bool(a.get("outside"))
        elif out.first_after_s is None:
            out.first_after_s, out.family = float(ta), a.get("family")
            out.fault_class, out.size, out.outside = a.get("fault_class"), a.get("size"), a.get("outside")
    return out


def learned_alarms(model: LearnedModel, rec: Record) -> list[dict]:
    """Each deviation the detector raised: ``t``, when it became a fault alarm (a confirming reference: when the
    fault was confirmed, i.e. when /fault_alarm says ALARM) or was raised (others, and deviations outside
    calibration: ``verdict``), the time it cleared (``until``; the record's end if it did not), the fault
    family, class and size named (estimator references; None for the others), whether it was announced, and
    the channels it lists beyond the training runs' healthy range (``outside``)."""
    _, _, det = run_record(model, rec.time_s, rec.x)
    out: list[dict] = []
    for a in det.alarms:
        iso = a.get("isolation") or {}
        verdict = a.get("verdict", "fault")
        t = a.get("confirmed_time", a["detection_time"]) if verdict == "fault" else a["detection_time"]
        until = a.get("cleared_time")
        out.append({"t": float(t), "until": float(rec.time_s[-1] if until is None else max(until, t)),
                    "verdict": verdict, "announced": a.get("announced", True), "family": iso.get("family"),
                    "fault_class": iso.get("fault_class"), "size": iso.get("size"),
                    "confirmation": (iso.get("confirmation") or {}).get("statistics"),
                    "outside": a.get("outside_healthy_range")})
    return sorted(out, key=lambda a: a["t"])


def held_share(alarms: Sequence[dict], onset_s: float, end_s: float) -> float:
    """Share of the time from the onset to the record's end with an alarm up (the fault stays to the end)."""
    if not end_s > onset_s:
        return 0.0
    up = sum(max(0.0, min(a["until"], end_s) - max(a["t"], onset_s)) for a in alarms
             if a.get("verdict", "fault") == "fault")
    return up / (end_s - onset_s)


def cusum_alarm_times(residual: np.ndarray, t: np.ndarray, h: float, k: float = PLAIN_CUSUM_K) -> list[float]:
    """Two-sided CUSUM restarted after each alarm (NaN counts as 0)."""
    up = down = 0.0
    times = []
    for ti, r in zip(t, np.nan_to_num(residual)):
        up = max(0.0, up + r - k)
        down = max(0.0, down - r - k)
        if up > h or down > h:
            times.append(float(ti))
            up = down = 0.0
    return times


@dataclass
class Fold:
    held_out: str
    detectors: dict[str, Callable[[Record], list[float]]]
    info: dict


def build_fold(train: list[Record], held_out: str, model: str = "rig_flask",
               only: Sequence[str] | None = None) -> Fold:
    physics = only is None or bool({"estimator", "nominal estimator", "open loop",
                                    "plain CUSUM (estimator residual)"} & set(only))
    runs = [(r.time_s - r.time_s[0], r.x) for r in train]
    dt = float(np.median(np.concatenate([np.diff(t) for t, _ in runs if len(t) > 1])))
    x_all = np.vstack([r.x for r in train])
    files = {"files": [r.path for r in train]}
    arx_settings = LearnedSettings(sample_time_s=dt)
    arx_model = calibrate_bands(fit_reference(x_all, CHANNELS, arx_settings), runs, arx_settings, files)
    oe_settings = LearnedSettings(sample_time_s=dt, form="oe")
    oe_model = calibrate_bands(fit_reference(x_all, CHANNELS, oe_settings), runs, oe_settings, files)
    dets: dict[str, Callable[[Record], list[dict]]] = {
        "learned ARX": lambda rec: learned_alarms(arx_model, rec),
        "learned OE": lambda rec: learned_alarms(oe_model, rec)}
    info: dict = {}
    if physics:
        est = fit_estimator(train, start_from_model(model))
        # an open-loop simulation reference compares measured with simulated pH over its spread (as diagnose does):
        # the pH innovation, unlimited; the estimator's x-space innovation of a never-corrected state is no such thing
        open_ref = est.reference.with_values(correct=False, innovation="ph", clip_sigma=0.0)  # type: ignore[attr-defined]
        open_model = calibrate_bands(open_ref, runs, est.settings, files)
        h = plain_cusum_h()

        def plain(rec: Record) -> list[dict]:
            r = est.reference.new_state().residuals(rec.time_s - rec.time_s[0], rec.x)[:, 0]
            return [{"t": t, "until": t} for t in cusum_alarm_times(r, rec.time_s, h)]  # every alarm a fault

        # the extended model's gain: the same filter and detector on the plant model as declared, nothing fitted
        nominal_model = calibrate_bands(start_from_model(model), runs, est.settings, files)
        dets = {"estimator": lambda rec: learned_alarms(est, rec),
                "nominal estimator": lambda rec: learned_alarms(nominal_model, rec),
                "open loop": lambda rec: learned_alarms(open_model, rec), **dets,
                "plain CUSUM (estimator residual)": plain}
        ref = est.reference
        info = {"strengths_mM": [f.strength_mM for f in ref.feeds], "volume_ml": ref.volume_ml,  # type: ignore[attr-defined]
                "noise": ref.noise.__dict__, "plain_cusum_h": h}  # type: ignore[attr-defined]
    return Fold(held_out, dets, info)


def injected_cases(path: str, rec: Record, workdir: Path, column_map) -> list[tuple[dict, Record]]:
    """Every (kind, size, onset, pump) that changes this run, as (truth, record)."""
    from phfdi_base.errors import UserError

    t0, t1 = float(rec.time_s[0]), float(rec.time_s[-1])
    cases = []
    sizes_of = dict(SIZES)
    if Path(path).name in CONTROLLED:  # the controlled-run bias, scored apart (rank "controlled")
        sizes_of["probe_bias"] = (*SIZES["probe_bias"], CONTROLLED_BIAS_PH)
    for kind, sizes in sizes_of.items():
        pumps: tuple[str | None, ...] = ("acid", "base") if kind.startswith("pump") else (None,)
        for rank, size in enumerate(sizes):
            for frac in ONSET_FRACTIONS:
                onset = round(t0 + frac * (t1 - t0), 2)
                for pump in pumps:
                    try:
                        data, truth = inject_fault(path, kind, onset, size, pump=pump, seed=rank + 1,
                                                   column_map=column_map)
                    except UserError:
                        continue  # no effect on this run (a pump that is off, ...)
                    f = workdir / f"{kind}-{rank}-{frac}-{pump}.csv"
                    f.write_bytes(data)
                    truth.update({"size_rank": ("larger", "smaller", "controlled")[rank], "onset_s": onset})
                    cases.append((truth, read_measured(f, column_map, channels=list(CHANNELS))))
    return cases


#: the operation each shared rig run is (its PROVENANCE.md): a leave-one-operation-out split holds out every run of
#: one operation, so that the calibration has never seen that way of running the rig
OPERATIONS = {"2025.03.03-001_acid_to_base_titration.csv": "titration",
              "2025.04.07-001-base_to_acid_titration.csv": "titration",
              "2025.02.24-add_acid_pH7-3.csv": "open-loop addition",
              "2025.02.24-001_add_base_pH9.5-11.5.csv": "open-loop addition",
              "2025.02.24-005_control_pH7_from_basic.csv": "closed-loop control"}
#: runs under closed-loop control (where a controller acts on the reading): a 0.4 pH bias is scored on them too
CONTROLLED = {p for p, op in OPERATIONS.items() if op == "closed-loop control"}
CONTROLLED_BIAS_PH = 0.4


def operation_of(path: str) -> str:
    return OPERATIONS.get(Path(path).name, Path(path).name)


def held_out_sets(paths: Sequence[str], leave_out: int | str = 1) -> list[tuple[list[str], list[str]]]:
    """(training runs, held-out runs) of every fold: each set of ``leave_out`` runs held out once, the others
    fitted on (1: leave-one-run-out; 2: leave-two-out, a harder test of what the calibration does not cover;
    ``"operation"``: every run of one operation (:data:`OPERATIONS`) held out at once)."""
    if leave_out == "operation":
        ops = sorted({operation_of(p) for p in paths})
        return [([q for q in paths if operation_of(q) != op], [q for q in paths if operation_of(q) == op])
                for op in ops if any(operation_of(q) != op for q in paths)]
    k = int(leave_out)
    if not 1 <= k < len(paths):
        raise ValueError(f"leave_out must be 1..{len(paths) - 1} for {len(paths)} runs, got {leave_out}")
    return [([q for q in paths if q not in held], list(held)) for held in itertools.combinations(paths, k)]


def evaluate(paths: Sequence[str], column_map, progress: Callable[[str], None] = print,
             only: Sequence[str] | None = None, leave_out: int | str = 1) -> dict:
    records = {p: read_measured(p, column_map, channels=list(CHANNELS)) for p in paths}
    rows: list[dict] = []
    folds = {}
    with tempfile.TemporaryDirectory() as tmp:
        for train, held in held_out_sets(paths, leave_out):
            names = ", ".join(Path(p).name for p in held)
            progress(f"fold: {names} held out")
            fold = build_fold([records[q] for q in train], names, only=only)
            folds[names] = fold.info
            if only:
                fold.detectors = {k: v for k, v in fold.detectors.items() if k in only}
            ranges = healthy_ranges([records[q].x for q in train], CHANNELS)
            for p in held:
                outside = [o["channel"] for o in outside_ranges(ranges, records[p].x, CHANNELS)]
                _score_run(p, records[p], fold, Path(tmp), column_map, rows, outside)
    return {"rows": rows, "folds": folds, "leave_out": leave_out}


def _score_run(p: str, rec: Record, fold: Fold, tmp: Path, column_map, rows: list[dict],
               outside: list[str]) -> None:
    """One held-out run through the fold's detectors: healthy (``outside``: the channels that leave the training
    runs' healthy range, replay's note), then with each injected fault."""
    hours = (rec.time_s[-1] - rec.time_s[0]) / 3600.0
    for name, det in fold.detectors.items():
        o = outcome(det(rec), None)
        rows.append({"run": Path(p).name, "fold": fold.held_out, "detector": name, "case": "healthy",
                     "hours": hours, "false_alarms": o.alarms_before, "false_alarms_marked": o.marked_before,
                     "warnings": o.warnings_before, "warnings_announced": o.warnings_announced_before,
                     "outside_healthy_range": outside})
    for truth, frec in injected_cases(p, rec, tmp, column_map):
        for name, det in fold.detectors.items():
            alarms = det(frec)
            o = outcome(alarms, truth["onset_s"])
            rows.append({"run": Path(p).name, "fold": fold.held_out, "detector": name, "case": truth["kind"],
                         "family": truth["family"], "size": truth["size"], "size_rank": truth["size_rank"],
                         "pump": truth.get("pump"), "onset_s": truth["onset_s"],
                         "alarms_before": o.alarms_before, "warnings_before": o.warnings_before,
                         "warnings_after": o.warnings_after, "family_named": o.family,
                         "class": expected_class(truth["kind"], truth.get("pump")),
                         "class_named": o.fault_class, "size_named": o.size,
                         "held_share": held_share(alarms, truth["onset_s"], float(frec.time_s[-1])),
                         "outside_at_detection": o.outside,
                         "delay_s": None if o.first_after_s is None else o.first_after_s - truth["onset_s"]})


def _class_and_size(detected: list[dict], kind: str) -> dict:
    """How many detected cases were named the right class, and the median size named for those, beside the
    size a right estimate gives (None where the injected size does not map onto the class's unit)."""
    right = [r for r in detected if r.get("class_named") is not None and r["class_named"] in _classes(r)]
    sizes = sorted(r["size_named"] for r in right if r.get("size_named") is not None)
    true = expected_size(kind, detected[0]["size"]) if detected else None
    return {"class_right": len(right), "median_size_named": sizes[len(sizes) // 2] if sizes else None,
            "size_expected": true}


def _classes(row: dict) -> list[str]:
    c = row.get("class")
    return [c] if isinstance(c, str) else list(c or [])  # rows written before 2026-12-05 hold one class


def summary(result: dict) -> list[dict]:
    """Per detector: false alarms per hour on held-out healthy runs; per kind and size: detected share."""
    rows = result["rows"]
    out = []
    for det in sorted({r["detector"] for r in rows}, key=lambda d: list(dict.fromkeys(r["detector"] for r in rows)).index(d)):
        healthy = [r for r in rows if r["detector"] == det and r["case"] == "healthy"]
        fa = sum(r["false_alarms"] for r in healthy)
        hours = sum(r["hours"] for r in healthy)
        entry = {"detector": det, "healthy_false_alarms": fa, "healthy_hours": hours, "healthy_replays": len(healthy),
                 "healthy_warnings": sum(r.get("warnings", 0) for r in healthy),
                 "healthy_warnings_announced": sum(r.get("warnings_announced", 0) for r in healthy),
                 "healthy_runs_with_alarm": sum(1 for r in healthy if r["false_alarms"]),
                 # replays that leave the training runs' healthy range (phfdi replay's note), with and without alarm
                 "outside_range_with_alarm": sum(1 for r in healthy if r["false_alarms"] and r.get("outside_healthy_range")),
                 "outside_range_without_alarm": sum(1 for r in healthy
                                                    if not r["false_alarms"] and r.get("outside_healthy_range")),
                 # alarms that list a channel beyond that range between their onset and detection
                 "false_alarms_marked": sum(r.get("false_alarms_marked", 0) for r in healthy),
                 "kinds": {}}
        for kind in SIZES:
            for rank in ("larger", "smaller", "controlled"):
                cs = [r for r in rows if r["detector"] == det and r["case"] == kind and r["size_rank"] == rank]
                if not cs:
                    continue
                ok = [r for r in cs if r["alarms_before"] == 0 and r["delay_s"] is not None]
                delays = sorted(r["delay_s"] for r in ok)
                held = sorted(r["held_share"] for r in cs)
                entry["kinds"][f"{kind} {rank}"] = {"cases": len(cs), "detected": len(ok),
                                                     "family_right": sum(1 for r in ok if r["family_named"] == r["family"]),
                                                     "detected_marked": sum(1 for r in ok if r.get("outside_at_detection")),
                                                     **_class_and_size(ok, kind),
                                                     "median_delay_s": delays[len(delays) // 2] if delays else None,
                                                     "median_held_share": held[len(held) // 2]}
        out.append(entry)
    return out
