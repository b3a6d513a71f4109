"""phfdi replay: run a recorded run through the fault detector offline and print the alarms."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass

from phfdi.alarm_text import format_alarms
from phfdi_base.topics import MEASURED_SAMPLE

from .common import (
    EPILOG_FORMAT,
    add_record_args,
    column_map_from_args,
    print_notes,
    reference_column_map,
)

EXAMPLES = """examples:
  phfdi simulate --fault backlash --out runs/backlash.parquet && phfdi replay runs/backlash.parquet
  phfdi replay runs/backlash.csv --json                 # machine-readable list of alarms
  phfdi replay bags/run.mcap --reference my_physics.json   # a bag of phfdi launch, own calibration (calibrate)
  phfdi replay --live bags/run.mcap                     # through a detector NODE, over ROS topics
  phfdi replay plant.csv --column time_s=t --column ph_measured=pH --column valve_command_pct=OP
  phfdi replay rig.csv --reference ref.json              # a learned reference (phfdi calibrate --learn)
  phfdi replay rig.csv --reference ref.json --refit-rows 400 --json
  phfdi replay plant.csv --reference out/diagnose/extended_model.yaml   # the model phfdi diagnose extended

Without --reference a run goes through the multichannel wavelet detector with the
physics reference shipped for its scenario (paper_physics): the healthy plant and
valves on the run's measured commands predict the pH, their model the run's own
plant (its metadata, --scenario or a model .yaml; a note says where it differs
from the one calibrated on). --no-isolation detects without naming the fault
(any reference). The physics detector's own options (--calibration, --level, ...)
were retired with it on 2026-12-07: give them to phfdi calibrate, which writes
the physics reference, and replay with --reference.

With --reference the record's channels go through that reference and the
multichannel wavelet detector instead (any number of channels, no plant model):
each alarm names the channels and bands that carry it; --refit-rows N re-fits
the reference on the record's own first N rows with the file's settings. The
record may be a bag of phfdi bag from-csv (offline or --live: the same alarms).
A note names each channel that leaves the range the reference's healthy runs
had (--json: outside_healthy_range): there the reference extrapolates.

--reference MODEL.yaml (a scenario file, such as the extended_model.yaml that
phfdi diagnose writes into its --out directory) keeps the physics reference and
builds it from that model instead of the run's own or the default scenario (the
same as --scenario MODEL.yaml): its plant, feeds and valve sizes. Fault blocks and
sensor effects in it (a valve or probe effect the diagnosis found) are not part of
the healthy reference (it predicts the process): the detector still looks for
them, and a note says so. The model's
setpoint schedule is not run (the reference follows the record's commands), so
its actuator margin is not checked. Offline only (not with --live).

The detector sees only what a plant would measure: time_s, ph_measured,
valve_command_pct (or ph_controller_output_pct), level_measured_cm,
level_controller_output_pct, ph_setpoint and the flows of feeds the valve does
not drive. The plant model comes from the run's metadata (simulated runs),
else from --scenario; the faults in it are ignored.

The file is read under the reading policy of docs/records.md: exact duplicate
rows dropped, a repeated stamp next to a skipped one re-spaced, other repeated
stamps averaged, NaN/inf/text cells missing (the detector holds its statistics
there); time going back is refused. Every repair is printed on stderr as a
note and listed in --json ("notes").

--live plays the bag's topics (raw CDR, each message at its simulated time
stamp, and /clock) into a ROS graph of two processes started for the
purpose on a ROS domain of their own: a player (phfdi.ros.player) and the
detector node (wavelet_fdi.learned_node), which publishes /fault_alarm. It prints
the alarms the node raised; they equal the offline replay's.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="detect and diagnose faults in a recorded run (offline, fast)",
                       description="Feed a recorded run (.csv, .parquet, or an .mcap bag of phfdi launch) "
                                   "through the streaming wavelet-residual detector, as fast as the "
                                   "CPU allows, and print each alarm: onset, detection time, fault class with "
                                   "confidence, parameter estimate, severity, statistic against threshold.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("file", help="run file: .csv, .parquet or .mcap")
    p.add_argument("--json", action="store_true", help="print the alarms as a JSON list")
    p.add_argument("--scenario", default=None,
                   help="plant/loop model (preset or .yaml) when the run does not carry one (default paper)")
    retired = p.add_argument_group("retired with the physics detector on 2026-12-07 (refused with where they go "
                                   "now: phfdi calibrate writes a physics reference with them, --reference takes it)")
    retired.add_argument("--calibration", default=None, help="a physics detector calibration file")
    for flag, (what, kind) in RETIRED_SETTINGS.items():
        retired.add_argument(flag, dest=flag[2:], type=kind, default=None, help=f"the physics detector's {what}")
    p.add_argument("--no-isolation", action="store_true", help="detect only: no fault named (any detector)")
    p.add_argument("--chunk", type=int, default=4096, help="samples per detector call (default 4096)")
    p.add_argument("--reference", default=None, metavar="REF.json|MODEL.yaml",
                   help="a learned reference (phfdi calibrate, with --learn or --estimator or neither; or "
                        "paper_physics, shipped): watch the record's channels with it; "
                        "or a scenario/model .yaml (phfdi diagnose's extended_model.yaml): the physics "
                        "reference built from it")
    p.add_argument("--refit-rows", type=int, default=None, metavar="N",
                   help="with --reference: re-fit it on the record's first N rows (its settings kept)")
    add_record_args(p)
    live = p.add_argument_group("live replay (ROS 2)")
    live.add_argument("--live", action="store_true",
                      help="play the bag over ROS topics into a detector node instead (.mcap only)")
    live.add_argument("--pace", type=float, default=0.0, metavar="FACTOR",
                      help="with --live: 0 as fast as the detector takes it (default), F: F times real time")
    live.add_argument("--domain-id", type=int, default=None,
                      help="with --live: ROS domain id (default: an exported ROS_DOMAIN_ID, else a free one)")
    live.add_argument("--log-dir", default=None, help="with --live: keep the nodes' logs here")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """One path for every replay: the reference kind (the physics model, or a learned or estimator reference file)
    replays the record offline or plays the bag into its detector node (:func:`_run_live`); the alarms are printed
    as text or as one JSON document."""
    from phfdi_base.errors import UserError

    if args.chunk < 1:
        raise UserError("--chunk must be at least 1")
    if args.reference and _is_model_file(args.reference):
        if args.live:
            raise UserError(f"--live --reference takes a learned reference (REF.json); replay a model reference "
                            f"({args.reference}) offline")
        _model_as_scenario(args)
    if args.refit_rows is not None and not args.reference:
        raise UserError("--refit-rows goes with a learned --reference (REF.json)")
    _refuse_detector_options(args)
    kind: _Kind = _Learned() if args.reference else _ShippedPhysics()
    if args.live and (args.map or args.column or args.encoding or args.refit_rows is not None):
        raise UserError(f"{kind.offline_options} apply to an offline replay, not to --live")
    replayed = _run_live(args, kind) if args.live else kind.offline(args)
    if replayed.document is not None:
        print(json.dumps(replayed.document, indent=2) if args.json else replayed.text)
    return replayed.status


#: the physics detector's settings replay took until 2026-12-07 -> what each set, and its type then
RETIRED_SETTINGS = {"--wavelet": ("wavelet", str), "--level": ("wavelet level", int),
                    "--arl0": ("false-alarm target", float), "--channels": ("residual channels", str)}


def _refuse_detector_options(args: argparse.Namespace) -> None:
    """--calibration or a detector setting (--level, ...): a reference carries its detector's settings, set when
    phfdi calibrate makes it; the physics detector took them here until it was retired on
    2026-12-07 (issue 37: one detector). One line saying where they go now."""
    from phfdi_base.errors import UserError

    if args.calibration:
        raise UserError(f"--calibration {args.calibration}: the physics detector's calibration, retired with it on "
                        f"2026-12-07: make a physics reference with the options you calibrated with (phfdi calibrate "
                        f"... --out REF.json) and replay with --reference REF.json")
    given = [flag for flag in RETIRED_SETTINGS if getattr(args, flag[2:]) is not None]
    if given:
        flags = ", ".join(given)
        raise UserError(f"{flags}: a reference carries its detector's settings: give them to phfdi calibrate when "
                        f"you make it (--out REF.json) and replay with --reference REF.json (the physics detector "
                        f"that took them here was retired on 2026-12-07)")


@dataclass
class _Replayed:
    """What a replay gives: the --json document and the text report (None: the replay failed, said on stderr), and
    the exit status."""

    document: dict | None
    text: str = ""
    status: int = 0


class _Kind:
    """A reference kind's part of the one replay path: the record through its detector offline, or the node that
    plays its bag live."""

    #: the options that apply only offline, as the refusal of --live names them
    offline_options = ""
    #: the topic a bag must have for --live, and what to do when it has not
    bag_topic = ""
    bag_hint = ""

    def offline(self, args: argparse.Namespace) -> _Replayed:
        raise NotImplementedError

    def check_live(self, args: argparse.Namespace) -> None:
        """What is checked before any process starts (one line each), after the bag."""

    def live_nodes(self, args: argparse.Namespace, common: dict) -> list:
        """The detector node to start (``common``: the parameters every node of the graph gets)."""
        raise NotImplementedError

    def event_line(self, event: dict) -> str | None:
        """A node's event as a line on stderr while the bag plays (None: not said)."""
        raise NotImplementedError

    def live_result(self, args: argparse.Namespace, report: dict, result, elapsed: float, say) -> _Replayed:
        """The detector node's final report as the replay's result."""
        raise NotImplementedError


class _Learned(_Kind):
    """A learned or estimator reference file (phfdi calibrate --learn or --estimator) and the multichannel
    detector: any record's channels."""

    offline_options = "--map, --column, --encoding and --refit-rows"
    bag_topic, bag_hint = MEASURED_SAMPLE.name, "write the record with phfdi bag from-csv"

    def offline(self, args: argparse.Namespace) -> _Replayed:
        from phfdi.learned import alarm_summaries, event_dict, replay_measured
        from wavelet_fdi.learned_detector import LearnedModel

        model = LearnedModel.load(args.reference)
        rec, columns_said = self.read(args, model)
        if columns_said:
            print(f"phfdi replay: {columns_said}", file=sys.stderr)
        model, followed = self.model_for(args, model, rec)
        notes = rec.notes + ([followed] if followed else [])
        print_notes("replay", notes)
        t0 = time.perf_counter()
        events, states, model = replay_measured(rec, model, args.refit_rows, name_faults=not args.no_isolation)
        elapsed = time.perf_counter() - t0
        print(f"replayed {len(rec.x)} rows x {len(model.channels)} channels in {elapsed:.2f} s", file=sys.stderr)
        outside = outside_healthy_range(model, rec)
        alarms = alarm_summaries(events, rec)
        inputs = [event_dict(e, rec) for e in events if e.kind == "input"]
        document = {"file": args.file, "reference": args.reference, "samples": len(rec.x),
                    "channels": list(model.channels), "columns": columns_said, "notes": notes,
                    "input_problems": inputs, "outside_healthy_range": outside, "alarm_rows": int(states.sum()),
                    "alarms": alarms}
        lines = [format_alarms(alarms)]
        for e in inputs:
            stamp = f"{e['stamp']}, " if e["stamp"] else ""
            lines.append(f"input: {e['message']} ({stamp}{rec.where} {e['line']})")
        return _Replayed(document, "\n".join(lines))

    def read(self, args: argparse.Namespace, model) -> tuple:
        """The record in the reference's channels, and what says where its columns came from."""
        cmap, columns_said = reference_column_map(args, model, args.reference)
        return _read_with_stored_map(args, model, cmap, columns_said)

    def model_for(self, args: argparse.Namespace, model, rec) -> tuple:
        """The model the record is watched with, and a note (None: none): a physics reference runs the record's
        own plant where the record says its scenario."""
        return _follow_record_scenario(model, rec)

    def check_live(self, args: argparse.Namespace) -> None:
        from wavelet_fdi.learned_detector import LearnedModel

        self.model = LearnedModel.load(args.reference)  # one line for a bad file before any process starts
        self.live_notes: list[str] = []

    def live_nodes(self, args: argparse.Namespace, common: dict) -> list:
        from phfdi.ros.launcher import detector_spec

        return [detector_spec({**common, "reference": args.reference, "loop_graph_topics": self.graph_bag,
                               "name_faults": not args.no_isolation})]

    #: the bag is one of the loop graph's (its own topics, read by a physics reference), not a measured record's
    graph_bag = False

    def event_line(self, event: dict) -> str | None:
        if event.get("event") == "fault_alarm":
            return f"/fault_alarm {event['state']} at {event['time_s']:g} s: {event['message']}"
        return None

    def live_result(self, args: argparse.Namespace, report: dict, result, elapsed: float, say) -> _Replayed:
        from wavelet_fdi.healthy_range import describe

        say(f"played {report['samples']} rows through the detector node ({self.model.reference.kind} reference) in "
            f"{elapsed:.1f} s (ROS domain {result.domain_id})")
        alarms = _located_live(args.file, report["alarms"], report["samples"])
        outside = report.get("outside_healthy_range") or []  # what the node's core counted (the offline replay's)
        print_notes("replay", [describe(o) for o in outside])
        document = {"file": args.file, "reference": args.reference, "samples": report["samples"],
                    "channels": list(self.model.channels), "notes": self.live_notes,
                    "outside_healthy_range": outside, "alarms": alarms}
        return _Replayed(document, format_alarms(alarms), result.status)


def _follow_record_scenario(model, rec):
    """A physics reference runs the record's own scenario where the record says one (a simulated run, a bag of the
    loop graph), as the launched node runs the launch's (``reference_physics.follow_scenario``); the note, or None."""
    from phfdi_base.spec import validate_scenario
    from wavelet_fdi.reference_physics import KIND, follow_scenario

    spec = rec.metadata.get("spec") if isinstance(rec.metadata, dict) else None
    if getattr(model.reference, "kind", None) != KIND or not isinstance(spec, dict):
        return model, None
    return follow_scenario(model, validate_scenario(spec, source=f"{rec.path}: run metadata"))


class _ShippedPhysics(_Learned):
    """No reference given: the multichannel detector with the physics reference shipped for the record's scenario
    (``<scenario>_physics``), its model running the record's own plant (its metadata, --scenario or a model .yaml;
    the paper loop for a record that says none), as the physics detector ran the run's scenario with its shipped
    calibration."""

    offline_options = "--map, --column and --encoding"
    bag_topic, bag_hint = "/plant/measurement", ("not a bag of the phfdi graph (a measured record's bag: give "
                                                 "--reference REF.json)")
    graph_bag = True

    def offline(self, args: argparse.Namespace) -> _Replayed:
        from phfdi.replay import shipped_physics_name

        args.reference = shipped_physics_name(_given_scenario(args))
        return super().offline(args)

    def read(self, args: argparse.Namespace, model) -> tuple:
        """The run as the physics detector reads one (the measured pH and the pH controller output required, by
        name or through --map/--column; the level and its controller output where the run has them, else missing:
        the model holds the outlet at its starting opening), in the reference's channels."""
        from dataclasses import replace

        import numpy as np

        from phfdi.replay import load_any

        run = load_any(args.file, column_map_from_args(args), args.encoding)
        signals = {c: np.asarray(run[c], float) if c in run else np.full(len(run), np.nan) for c in model.channels}
        if "valve_command_pct" not in run:
            signals["valve_command_pct"] = np.asarray(run["ph_controller_output_pct"], float)
        rec = replace(run, signals=signals, units={c: run.units.get(c, "") for c in signals},
                      notes=list(run.metadata.get("notes", [])), path=str(args.file))
        return rec, ""

    def model_for(self, args: argparse.Namespace, model, rec) -> tuple:
        from phfdi.replay import scenario_of, shipped_physics_model, shipped_physics_name

        spec = _given_scenario(args) or scenario_of(rec)
        args.reference = shipped_physics_name(spec)
        return shipped_physics_model(spec)

    def check_live(self, args: argparse.Namespace) -> None:
        from phfdi.replay import shipped_physics_model, shipped_physics_name

        spec = _given_scenario(args) or _replay_scenario(args.file, None)
        args.reference = shipped_physics_name(spec)
        super().check_live(args)
        _, note = shipped_physics_model(spec)  # the node in the graph follows the bag's scenario the same way
        self.live_notes = [note] if note else []
        print_notes("replay", self.live_notes)


def _given_scenario(args: argparse.Namespace):
    """The scenario given on the command line (a model .yaml or --scenario), None when none is."""
    from phfdi.scenario import load_scenario

    if getattr(args, "model_spec", None) is not None:
        return args.model_spec
    return load_scenario(args.scenario, fault="healthy") if args.scenario else None


def _is_model_file(path: str) -> bool:
    from pathlib import Path

    return Path(path).suffix.lower() in (".yaml", ".yml")


def _model_as_scenario(args: argparse.Namespace) -> None:
    """--reference MODEL.yaml: the physics reference from that scenario (what --scenario does), said once."""
    from phfdi.scenario import load_scenario
    from phfdi_base.errors import UserError

    if args.scenario:
        raise UserError(f"--reference {args.reference} is a model: give it or --scenario {args.scenario}, not both")
    full = load_scenario(args.reference)  # one line naming the file if it is not a scenario
    # The reference is driven by the record's measured commands and never runs the model's setpoint schedule,
    # so the simulator's design check (every setpoint reachable inside the actuator margin) is not applied: an
    # extended plant (a stronger reagent, a smaller valve) often cannot reach the nominal schedule's extremes.
    args.model_spec = load_scenario(args.reference, fault="healthy", overrides=["min_actuator_margin_pct=0"])
    args.scenario, args.reference = args.reference, None
    kinds = sorted({f.type for f in full.faults})
    for name, sensor in (("ph", full.sensors.ph), ("level", full.sensors.level)):
        kinds += [f"{name} sensor {b.type}" for b in sensor.extra]
        kinds += [f"{name} sensor {k}" for k in ("delay_s", "lag_s") if getattr(sensor, k)]
    if kinds:
        print(f"phfdi replay: note: {args.scenario}: its fault blocks and sensor effects ({', '.join(kinds)}) are "
              f"not part of the healthy reference (it predicts the process); the detector looks for them",
              file=sys.stderr)


def _read_with_stored_map(args: argparse.Namespace, model, cmap, columns_said: str):
    """The record read with the map the replay chose; when that is the reference's stored map and the file does not
    have its columns but names the reference's channels itself (a record already in the project's names, e.g. a
    gridded or converted export), the file's own names, said so."""
    from phfdi.learned import read_measured
    from phfdi_base.errors import UserError

    try:
        return read_measured(args.file, cmap, channels=model.channels, encoding=args.encoding), columns_said
    except UserError as exc:
        if cmap is None or column_map_from_args(args) is not None:
            raise
        try:
            rec = read_measured(args.file, None, channels=model.channels, encoding=args.encoding)
        except UserError:
            raise exc from None
        return rec, (f"columns: the file's own column names (they are the reference's channels; the map stored in "
                     f"{args.reference} does not fit this file: {exc})")


def outside_healthy_range(model, rec) -> list[dict]:
    """phfdi.learned.outside_healthy_range, each stretch said in one note."""
    from phfdi.learned import outside_healthy_range as outside_of
    from wavelet_fdi.healthy_range import describe

    outside = outside_of(model, rec)
    print_notes("replay", [describe(o) for o in outside])
    return outside


def _located_live(bag: str, alarms: list[dict], samples: int) -> list[dict]:
    """The node's alarms (0-based sample indices) with the positions the offline replay gives: the source
    record's lines and stamps that ``bag from-csv`` stored in the bag, else the bag's own sample numbers."""
    from datetime import datetime, timedelta
    from pathlib import Path

    import numpy as np

    from phfdi import bagio
    from phfdi.bagread import lines_from_runs
    from phfdi.learned import located

    meta = json.loads(bagio.read_metadata(Path(bag)).get(bagio.RUN_METADATA, {}).get("json", "{}"))
    runs, clock = meta.get("source_lines"), meta.get("wall_clock")
    # a record whose time does not fit a stamp is stamped from its first row (time_origin_s): add it back
    wall_clock = datetime.fromisoformat(clock) + timedelta(seconds=float(meta.get("time_origin_s") or 0.0)) \
        if clock else None
    if runs:
        lines, where = lines_from_runs(runs, samples), str(meta.get("source_where", "line"))
    else:
        lines, where = np.arange(1, samples + 1), "sample"
    return [located(a, lines, where, wall_clock) for a in alarms]


def _replay_scenario(bag: str, fallback: str | None):
    """The bag's own scenario (its metadata); else --scenario (default paper)."""
    from pathlib import Path

    from phfdi import bagio
    from phfdi.scenario import load_scenario
    from phfdi_base.spec import validate_scenario

    meta = json.loads(bagio.read_metadata(Path(bag)).get(bagio.RUN_METADATA, {}).get("json", "{}"))
    if fallback or not isinstance(meta.get("spec"), dict):
        return load_scenario(fallback or "paper", fault="healthy")
    return validate_scenario(meta["spec"], source=f"{bag} metadata")


def _run_live(args: argparse.Namespace, kind: _Kind) -> _Replayed:
    """The bag through the kind's detector NODE over ROS: a player and the detector, started and stopped here."""
    from pathlib import Path

    from phfdi.ros.launcher import NodeSpec
    from phfdi.ros.player import PLAYER
    from phfdi_base.topics import DETECTOR

    _check_live_bag(args, kind.bag_topic, kind.bag_hint)
    kind.check_live(args)
    spec = _replay_scenario(args.file, args.scenario)
    common = {"scenario": spec.name, "fault": "", "graph_nodes": [PLAYER, DETECTOR]}
    detector = kind.live_nodes(args, common)
    say = lambda text: print(f"phfdi replay: {text}", file=sys.stderr)  # noqa: E731

    def on_event(node: str, event: dict) -> None:
        line = kind.event_line(event)
        if line:
            say(line)

    nodes = [NodeSpec(PLAYER, "phfdi.ros.player", {**common, "path": str(Path(args.file).resolve()),
                                                    "pace": float(args.pace)}), *detector]
    result, report, elapsed = _play_live(args, nodes, spec, say, on_event)
    if report is None:
        return _Replayed(None, status=result.status or 1)
    return kind.live_result(args, report, result, elapsed, say)


def _check_live_bag(args: argparse.Namespace, topic: str, hint: str) -> None:
    """One line (UserError) for a file --live cannot play: not a finished .mcap with ``topic``, or a bad --pace."""
    import math

    from phfdi import bagio
    from phfdi_base.errors import UserError

    if not args.file.endswith(".mcap"):
        raise UserError(f"--live plays a bag: give an .mcap file, not {args.file}")
    if not (math.isfinite(args.pace) and 0.0 <= args.pace <= 1e6):
        raise UserError(f"--pace {args.pace}: use 0 (as fast as possible) or a factor up to 1e6")
    info = bagio.bag_info(args.file)
    if not info["finished"]:
        raise UserError(f"{args.file}: the bag is not finished; run phfdi bag recover {args.file} FIXED.mcap")
    counts = {t["topic"]: t["count"] for t in info["topics"]}
    if topic not in counts:
        raise UserError(f"{args.file}: no {topic} topic: {hint}")
    if counts[topic] == 0:  # it was played as "0 samples", exit 0
        raise UserError(f"{args.file}: the bag holds no sample of {topic}")


def _play_live(args: argparse.Namespace, nodes: list, spec, say, on_event) -> tuple:
    """Start the player and detector ``nodes`` from one resolved part, play the bag, stop them.

    Returns (launch result, the detector's final report or None when it failed (said), wall seconds).
    """
    from pathlib import Path

    from phfdi.ros.launcher import Launcher
    from phfdi.ros.parts import recorded_part
    from phfdi.ros.player import PLAYER
    from phfdi_base.topics import DETECTOR

    from .common import Progress

    part = recorded_part(spec)  # resolved once; both nodes start from it
    for node in nodes:
        node.part = part
    t0 = time.perf_counter()
    result = Launcher(nodes, domain_id=args.domain_id, log_dir=args.log_dir, status=say, clock_node=PLAYER,
                      progress=Progress(f"replay --live {Path(args.file).name}"), on_event=on_event).run()
    elapsed = time.perf_counter() - t0
    done = [e for e in result.node_events.get(DETECTOR, []) if e["event"] == "detector_done"]
    if result.failure or not done:
        say(f"error: {result.failure or 'the detector node did not report'}"
            + (f"; node logs: {result.log_dir}" if result.log_dir else ""))
        return result, None, elapsed
    return result, done[-1], elapsed
