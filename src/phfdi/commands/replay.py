"""phfdi replay: run a recorded run through the fault detector offline and print the alarms."""

from __future__ import annotations

import argparse
import json
import sys
import time

from .calibrate import add_detector_args, settings_from_args
from .common import EPILOG_FORMAT

EXAMPLES = """examples:
  phfdi simulate --fault backlash --out runs/backlash.parquet && phfdi replay runs/backlash.parquet
  phfdi replay runs/backlash.csv --json                 # machine-readable list of alarms
  phfdi replay bags/run.mcap --calibration my.yaml      # a bag (needs phfdi.bagio), own calibration

The detector sees only what a plant would measure: time_s, ph_measured,
valve_command_pct (or ph_controller_output_pct), level_measured_cm,
level_controller_output_pct, ph_setpoint and the flows of feeds the valve does
not drive. The plant model comes from the run's metadata (simulated runs),
else from --scenario; the faults in it are ignored.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="detect and diagnose faults in a recorded run (offline, fast)",
                       description="Feed a recorded run (.csv, .parquet; .mcap bags once phfdi.bagio is "
                                   "installed) through the streaming wavelet-residual detector, as fast as the "
                                   "CPU allows, and print each alarm: onset, detection time, fault class with "
                                   "confidence, parameter estimate, severity, statistic against threshold.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("file", help="run file: .csv, .parquet or .mcap")
    p.add_argument("--json", action="store_true", help="print the alarms as a JSON list")
    p.add_argument("--scenario", default=None,
                   help="plant/loop model (preset or .yaml) when the run does not carry one (default paper)")
    p.add_argument("--calibration", default=None, help="calibration file from phfdi calibrate (default: shipped)")
    add_detector_args(p)
    p.add_argument("--no-isolation", action="store_true", help="detect only (no fault class)")
    p.add_argument("--chunk", type=int, default=4096, help="samples per detector call (default 4096)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi.errors import UserError
    from phfdi.scenario import load_scenario
    from wavelet_fdi.config import Calibration
    from wavelet_fdi.replay import load_any, replay_run, scenario_of

    if args.chunk < 1:
        raise UserError("--chunk must be at least 1")
    run_ = load_any(args.file)
    spec = load_scenario(args.scenario, fault="healthy") if args.scenario else scenario_of(run_)
    settings = settings_from_args(args)
    cal = Calibration.load(args.calibration) if args.calibration else None
    t0 = time.perf_counter()
    result = replay_run(run_, spec, cal, settings, chunk=args.chunk, isolate=not args.no_isolation)
    elapsed = time.perf_counter() - t0
    print(f"replayed {result.samples} samples in {elapsed:.2f} s ({result.samples / max(elapsed, 1e-9):.0f} "
          f"samples/s, isolation included)", file=sys.stderr)
    if args.json:
        print(json.dumps([a.summary() for a in result.alarms], indent=2))
        return 0
    print(format_alarms(result.alarms, result.diagnostics))
    return 0


def format_alarms(alarms: list, diagnostics: dict) -> str:
    lines = []
    if not alarms:
        lines.append("no alarm")
    for a in alarms:
        s = a.summary()
        p = s["parameter"]
        what = s["fault_class"]
        if what != "pending":
            what += f" (confidence {s['confidence']:.2f})"
        if p and s["fault_class"] not in ("pending", "unknown"):
            what += f", {p['name']} = {p['value']:.3g} {p['unit']}"
        elif p and s["fault_class"] == "unknown":
            what += f"; closest: {p['fault_class']}"
        lines.append(f"alarm {a.alarm_id}: {what}")
        lines.append(f"  onset {s['onset_time']:g} s, detected {s['detection_time']:g} s by {s['statistic']} "
                     f"({s['statistic_value']:.1f} > threshold {s['threshold']:.1f}), dominant band "
                     f"{s['dominant_level']}, severity {s['severity']:.3g} pH RMS")
        if s["cleared_time"] is not None:
            lines.append(f"  cleared {s['cleared_time']:g} s")
    problems = {k: v for k, v in diagnostics.items()
                if k in ("bad_time", "duplicate_stamps", "out_of_order", "extra_samples", "missing_samples",
                         "gap_resets", "time_resets", "nonfinite_ph", "out_of_range_ph", "nonfinite_command",
                         "command_stale_episodes", "reference_resets") and v}
    if problems:
        lines.append("input problems: " + ", ".join(f"{k} {v}" for k, v in problems.items()))
    return "\n".join(lines)
