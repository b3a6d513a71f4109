"""phfdi demo: the product end to end on the default scenario (ROS graph, detector, bag, replay, figures)."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .common import EPILOG_FORMAT, Progress, add_overwrite_arg

EXAMPLES = """examples:
  phfdi demo                       # paper scenario, backlash at 7000 s, through the ROS 2 graph; out/demo
  phfdi demo --fault stiction --out /tmp/demo
  phfdi demo --no-ros              # no ROS 2 on this machine: in-process loop, offline replay

What it does (22 s on a 2-core machine):
  1. runs the paper scenario with the fault through the ROS 2 node graph (plant,
     controllers, valve, the fault detector, a recorder), printing each
     /fault_alarm state change as it arrives;
  2. prints the alarms the recorder received on /fault_alarm and a summary of the run;
  3. replays the recorded bag offline through the same detector core and checks
     that it gives the same alarms; replays a healthy run of the scenario too;
  4. writes the bag, the figures (the run; residual and statistics with the alarm)
     and the alarms (JSON) to --out.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the product end to end on the default scenario (graph, detector, replay)",
                       description="Run the paper scenario with a valve fault through the ROS 2 node graph with the "
                                   "fault detector and a recorder, print the /fault_alarm events as they arrive and "
                                   "a summary, replay the bag offline to confirm the same alarms, write figures.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    add_overwrite_arg(p, folder=True)
    p.add_argument("--fault", default="backlash", help="fault preset (default: backlash)")
    p.add_argument("--onset", type=float, default=None, metavar="S", help="fault onset (s; default the fault's, 7000)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set sensors.ph.noise_std=0.02")
    p.add_argument("--no-ros", action="store_true",
                   help="without ROS 2: simulate the loop in this process and replay the run offline")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain id of the graph (default: an exported ROS_DOMAIN_ID, else a free one)")
    p.set_defaults(func=run)


def _say(text: str = "") -> None:
    print(text, flush=True)


def _progress(label: str):
    """A progress line on a terminal; else a line every quarter (logs, CI)."""
    if sys.stderr.isatty():
        return Progress(label, enabled=True)
    t0, said = time.perf_counter(), set()

    def report(fraction: float) -> None:
        quarter = int(fraction * 4 + 1e-9)
        if quarter not in said:
            said.add(quarter)
            print(f"{label}: {100 * quarter // 4} % ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)

    return report


def _ros_available() -> str | None:
    """Why the graph cannot run here (None: it can)."""
    import importlib.util

    for module in ("rclpy", "phfdi_interfaces"):
        if importlib.util.find_spec(module) is None:
            return f"{module} is not installed"
    return None


def run(args: argparse.Namespace) -> int:
    from phfdi.scenario import load_scenario
    from phfdi_base.errors import UserError

    spec = load_scenario("paper", fault=args.fault, overrides=args.overrides, onset_s=args.onset)
    if args.fault in ("healthy", "none"):
        raise UserError("the demo shows a fault being found: give a fault preset, e.g. --fault backlash")
    from phfdi_base.outputs import output_folder

    out = output_folder(args.out, args.overwrite)  # an earlier demo's files: kept unless --overwrite
    t0 = time.perf_counter()
    if args.no_ros:
        run_, received = _in_process(spec, out)
    else:
        why = _ros_available()
        if why:
            raise UserError(f"ROS 2 is not usable here ({why}): run bash scripts/setup.sh, or phfdi demo --no-ros")
        run_, received = _through_graph(args, spec, out)
        if run_ is None:
            return 1
    same, det = _replay_and_compare(run_, received, out, args.no_ros)
    _healthy_check(args)
    _figures(run_, det, out)
    _say(f"\ndone in {time.perf_counter() - t0:.0f} s; wrote to {out}/: "
         + ("run.parquet" if args.no_ros else "run.mcap (the bag)")
         + ", run.png, detection.png, alarms.json")
    return 0 if same else 1


# ---- 1. the run --------------------------------------------------------------------------
def _through_graph(args, spec, out: Path):
    from phfdi import bagio
    from phfdi.ros.launcher import Launcher, loop_graph
    from phfdi.summary import format_summary, summarize
    from wavelet_fdi import alarm_messages

    from .launch import alarm_event_line

    bag = out / "run.mcap"
    onset = spec.faults[0].onset_s if spec.faults else None
    _say(f"[1/4] ROS 2 graph: plant, controllers, valve, fault detector, recorder; scenario {spec.name}, "
         f"{spec.duration_s:g} s simulated, {args.fault} from {onset:g} s")
    nodes = loop_graph("paper", args.fault, args.onset, args.overrides, bag, detector={}, overwrite=args.overwrite)

    def on_event(node: str, event: dict) -> None:
        line = alarm_event_line(event)
        if line:
            if sys.stderr.isatty():
                sys.stderr.write("\n")  # below the progress line
            _say(f"      {line}")

    result = Launcher(nodes, domain_id=args.domain_id, progress=_progress("      lock-step run"), on_event=on_event,
                      status=lambda text: print(f"      {text}", file=sys.stderr, flush=True)).run()
    if result.failure or result.status:
        print(f"phfdi demo: error: the graph failed: {result.failure or f'status {result.status}'}",
              file=sys.stderr)
        return None, None
    _say(f"      {result.samples_done} samples in {result.run_wall_s:.1f} s wall "
         f"({result.real_time_factor:.0f} x real time) after connecting in {result.connect_s:.1f} s; "
         f"bag {bag} ({result.bag['messages']} messages)")
    received = alarm_messages.per_alarm(bagio.fault_alarms(bag))
    _say("\n[2/4] alarms the recorder received on /fault_alarm:")
    _say(alarm_messages.format_table(received).replace("\n", "\n    ").replace("  ", "      ", 1))
    run_ = bagio.load_run(bag)
    _say("      the run: " + format_summary(summarize(run_)).replace("\n", "\n      "))
    return run_, received


def _in_process(spec, out: Path):
    from phfdi.loop import simulate
    from phfdi.summary import format_summary, summarize

    _say(f"[1/4] in-process loop (no ROS): scenario {spec.name}, {spec.duration_s:g} s simulated")
    run_ = simulate(spec, progress=_progress("      simulate"))
    run_.save(out / "run.parquet")
    _say("\n[2/4] the run: " + format_summary(summarize(run_)).replace("\n", "\n      "))
    return run_, None


# ---- 2. offline replay ---------------------------------------------------------------------
def _offline(run_, record_trace: bool = False):
    """The run through the multichannel detector with the paper's shipped physics reference, its model running the
    run's own plant (``phfdi replay RUN`` does the same)."""
    import numpy as np

    from phfdi.replay import scenario_of, shipped_physics_model
    from wavelet_fdi.learned_detector import run_record

    model, _note = shipped_physics_model(scenario_of(run_))
    rows = np.column_stack([np.asarray(run_[c], float) for c in model.channels])
    return run_record(model, np.asarray(run_.time_s, float), rows, record_trace=record_trace)[2]


def _replay_and_compare(run_, received, out: Path, no_ros: bool):
    """Offline replay; whether its alarms equal those received live (True without a live run), and the detector."""
    import json

    from phfdi.alarm_text import format_alarms
    from wavelet_fdi.alarm_messages import from_summaries

    _say("\n[3/4] offline replay of " + ("the run" if no_ros else "the bag") + " through the same detector core:")
    t0 = time.perf_counter()
    det = _offline(run_, record_trace=True)
    _say(f"      {len(run_)} samples in {time.perf_counter() - t0:.1f} s")
    _say("      " + format_alarms(det.alarms).replace("\n", "\n      "))
    from phfdi_base.outputs import write_text

    # the demo's own folder: each run replaces its outputs (the README's command is idempotent)
    write_text(out / "alarms.json", json.dumps(det.alarms, indent=2, default=_json_value) + "\n", overwrite=True)
    if received is None:
        return True, det
    differences = _differences(from_summaries(det.alarms), received)
    if differences:
        _say("      DIFFERENT from the alarms published on /fault_alarm: " + "; ".join(differences))
        return False, det
    _say(f"      same alarms as published live on /fault_alarm ({len(received)}: detection, onset, class, "
         f"confidence and size identical)")
    return True, det


def _json_value(x):
    import numpy as np

    return x.item() if isinstance(x, (np.floating, np.integer)) else x.tolist() if isinstance(x, np.ndarray) else str(x)


def _differences(offline: list[dict], received: list[dict]) -> list[str]:
    if len(offline) != len(received):
        return [f"{len(offline)} alarm(s) offline, {len(received)} live"]
    out = []
    for i, (a, b) in enumerate(zip(offline, received), 1):
        for key in ("detection_time", "onset_time", "fault_class", "confidence", "severity"):
            if a[key] != b[key]:
                out.append(f"alarm {i} {key}: {a[key]} offline, {b[key]} live")
    return out


def _healthy_check(args) -> None:
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    t0 = time.perf_counter()
    healthy = simulate(load_scenario("paper", fault="healthy", overrides=args.overrides))
    alarms = _offline(healthy).alarms
    _say("      healthy run of the same scenario (in-process, replayed): "
         + (f"{len(alarms)} alarm(s): FALSE ALARM" if alarms else "no alarm")
         + f" ({time.perf_counter() - t0:.1f} s)")


# ---- 3. figures --------------------------------------------------------------------------
@dataclass
class _Marks:
    """What the detection figure marks of an alarm (phfdi.study.detector_figures.plot_detection)."""
    detection_time_s: float
    onset_time_s: float
    onset_refined_s: float | None
    isolation_time_s: float | None
    fault_class: str
    statistic: str


def _marks(a: dict, naming_after_s: float) -> _Marks:
    iso = a.get("isolation") or {}
    named = a["detection_time"] + naming_after_s if iso else None
    return _Marks(a["detection_time"], a.get("statistic_onset_time") or a["onset_time"], a["onset_time"], named,
                  iso.get("fault_class", "pending"), a["statistic"])


def _figures(run_, det, out: Path) -> None:
    import numpy as np

    from phfdi.figures import plot_run
    from phfdi.study.detector_figures import plot_detection
    from wavelet_fdi.reference_physics import NAMING_AFTER_S

    _say("\n[4/4] figures")
    plot_run(run_, out / "run.png")
    onsets = [f["onset_s"] for f in run_.metadata.get("faults") or []]
    s, tr = det.settings, det.trace()
    unit = float(det.model.reference.noise[0])  # the residual's unit: the pH sensor's noise (pH)
    measured = np.asarray(run_["ph_measured"], float)
    residual = tr["residual"][:, 0] * unit
    trace = {"time_s": np.asarray(run_.time_s, float), "ph_measured": measured, "ph_predicted": measured - residual,
             "ph_residual": residual, "ratio": tr["stat"]}
    title = (f"{run_.metadata.get('scenario', 'run')}: multichannel wavelet-residual detector, the paper's physics "
             f"as its reference ({s.wavelet} level {s.level}, ARL0 {s.arl0_samples:g} samples) on the recorded run")
    plot_detection(trace, det.stat_names, det.h, unit, [_marks(a, NAMING_AFTER_S) for a in det.alarms],
                   out / "detection.png", title, onsets)
    _say(f"      {out / 'run.png'}: pH and setpoint, controller output and valve position, level")
    _say(f"      {out / 'detection.png'}: measured vs healthy-model pH, residual, statistics/threshold, alarm")
