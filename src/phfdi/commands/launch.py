"""phfdi launch: run a scenario through the ROS 2 node graph, one process per node."""

from __future__ import annotations

import argparse
import errno
import json
import math
import sys
from pathlib import Path

from .common import EPILOG_FORMAT, Progress, add_scenario_args, scenario_from_args

#: the launcher's watchdog defaults (phfdi.ros.launcher.WATCHDOG_S, WATCHDOG_SAMPLE_PERIODS), here so that the
#: parser is built without importing the launcher
WATCHDOG_S = 30.0
WATCHDOG_SAMPLE_PERIODS = 5.0
#: the live view's defaults (phfdi_base.live_view.DEFAULT_PORT, LOOPBACK), here for the same reason
FOXGLOVE_PORT = 8765
FOXGLOVE_HOST = "127.0.0.1"

EXAMPLES = """examples:
  phfdi launch --scenario paper --fault backlash --record bags/run.mcap
  phfdi launch --fault backlash --detector --record bags/run.mcap   # + the fault detector (/fault_alarm)
  phfdi launch --fault stiction --set duration_s=2000 --set 'setpoints.ph.changes=[]' --onset 1000 --record bags/s.mcap
  phfdi launch --record bags/live.mcap --pace 20          # 20 x real time, for a live demo
  phfdi launch --record bags/day.mcap --pace 1 --split-s 3600   # live, a new bag file every hour
  phfdi launch --domain-id 42 --pace 1                    # real time, join with your own nodes on domain 42
  phfdi launch --fault backlash --detector --pace 20 --foxglove   # watch it live in Foxglove (ws://127.0.0.1:8765)
  phfdi launch --fault stiction --detector-param reference=paper_physics  # the multichannel detector's node

Every node runs as its own process (python -m <package>.node) with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST on a ROS domain of its own. Ctrl-C
or SIGTERM stops all nodes and leaves a readable bag. See docs/ros_graph.md.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario through the ROS 2 node graph (plant, valve, controllers, detector)",
                       description="Start the plant, valve and controller nodes (and a recorder, and the fault "
                                   "detector) as separate processes, run the scenario in lock-step simulated time "
                                   "(or paced), stop everything cleanly and print a summary.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    add_scenario_args(p)
    p.add_argument("--record", metavar="BAG.mcap", default=None, help="record every topic to this MCAP bag")
    p.add_argument("--overwrite", action="store_true", help="replace the --record file if it exists")
    p.add_argument("--split-s", type=float, default=0.0, metavar="S",
                   help="start a new bag file every S s of simulated time (run.mcap, run.1.mcap, ...): bounds the "
                        "recorder's memory in runs of days; 0 (default): one file")
    p.add_argument("--detector", action="store_true",
                   help="add the fault detector node (wavelet_fdi.learned_node with the physics reference shipped "
                        "for the scenario): publishes /fault_alarm and /diagnostics")
    p.add_argument("--detector-param", dest="detector_params", action="append", default=[], metavar="NAME=VALUE",
                   help="a parameter of the detector node, e.g. --detector-param reference=my_physics.json (a "
                        "physics reference from phfdi calibrate; see python -m wavelet_fdi.learned_node "
                        "--help); implies --detector")
    p.add_argument("--foxglove", type=int, nargs="?", const=FOXGLOVE_PORT, default=None, metavar="PORT",
                   help=f"serve the graph's signals (with --detector also its residuals, statistics and alarm state) live "
                        f"over the Foxglove WebSocket protocol on PORT (default {FOXGLOVE_PORT}); open "
                        f"ws://127.0.0.1:PORT in Foxglove with config/foxglove_layout.json (docs/ros_graph.md)")
    p.add_argument("--foxglove-host", default=FOXGLOVE_HOST, metavar="ADDRESS",
                   help=f"address the live view listens on (default {FOXGLOVE_HOST}: this machine only)")
    p.add_argument("--pace", type=float, default=0.0, metavar="FACTOR",
                   help="0: lock-step as fast as possible (default); F: F times real time")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS domain id (default: an exported ROS_DOMAIN_ID, else a free one)")
    p.add_argument("--executor", choices=("events", "single_threaded"), default="events",
                   help="rclpy executor of the nodes (default: events, the fastest)")
    p.add_argument("--connect-timeout", type=float, default=60.0, metavar="S",
                   help="give up if the graph has not connected after S seconds (default 60)")
    p.add_argument("--watchdog-s", type=float, default=WATCHDOG_S, metavar="S",
                   help=f"stop the graph, naming the stall, when the connected graph makes no progress for S "
                        f"seconds of wall time (default {WATCHDOG_S:g}; never less than "
                        f"{WATCHDOG_SAMPLE_PERIODS:g} sample periods at the run's --pace; 0: no watchdog)")
    p.add_argument("--log-dir", default=None, help="keep the nodes' parameter files and logs here "
                                                    "(default: a temporary folder, kept only if something fails)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    from phfdi_base.errors import UserError

    if not (math.isfinite(args.pace) and 0.0 <= args.pace <= 1e6):
        raise UserError(f"--pace {args.pace}: use 0 (lock-step, as fast as possible) or a factor up to 1e6")
    if not 0.1 <= args.connect_timeout <= 3600:
        raise UserError(f"--connect-timeout {args.connect_timeout}: use 0.1 .. 3600 s")
    if not (args.watchdog_s == 0 or 1.0 <= args.watchdog_s <= 1e6):
        raise UserError(f"--watchdog-s {args.watchdog_s}: use 1 .. 1e6 s, or 0 for no watchdog")
    if not (math.isfinite(args.split_s) and 0.0 <= args.split_s <= 1e12):
        raise UserError(f"--split-s {args.split_s}: use 0 (one file) or a positive number of seconds")
    if args.split_s > 0 and args.record is None:
        raise UserError("--split-s needs --record")
    if args.foxglove is not None:
        check_port_free(args.foxglove_host, args.foxglove)
    if args.record is not None and not args.record.endswith(".mcap"):
        raise UserError(f"--record {args.record}: give a .mcap file name")
    if args.record is not None:  # a bag being recorded: say so, whether or not --overwrite was given
        from phfdi.bagio import bag_parts, check_not_recording

        for part in bag_parts(args.record):
            check_not_recording(part)
    if args.record is not None and Path(args.record).exists() and not args.overwrite:
        raise UserError(f"--record {args.record} exists: give another name, or --overwrite to replace it")
    if args.split_s > 0:
        from phfdi.bagio import part_path

        if part_path(args.record, 1).exists():
            raise UserError(f"--split-s: {part_path(args.record, 1)} exists (a part of an earlier split bag); "
                            f"remove those parts or give another --record name")


def check_port_free(host: str, port: int) -> None:
    """One line before any node starts if the live view could not listen on host:port."""
    import socket

    from phfdi_base.errors import UserError

    if not 1 <= port <= 65535:
        raise UserError(f"--foxglove {port}: use a port 1 .. 65535")
    try:
        with socket.create_server((host, port)):  # closed at once; the bridge binds it moments later
            pass
    except OSError as exc:
        why = "already in use" if exc.errno == errno.EADDRINUSE else exc.strerror or str(exc)
        raise UserError(f"--foxglove {port}: cannot listen on {host}:{port}: {why}") from None


def detector_params(items: list[str]) -> dict:
    """--detector-param NAME=VALUE items as typed node parameters (VALUE read as YAML: 2.0, true, [ph, level])."""
    from phfdi_base.errors import UserError
    from phfdi_base.yamlfile import DuplicateKeyError, load_yaml

    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise UserError(f"--detector-param {item!r}: write NAME=VALUE")
        try:
            out[name.strip()] = load_yaml(value, f"--detector-param {name.strip()}") if value.strip() else ""
        except DuplicateKeyError:
            raise
        except UserError:
            raise UserError(f"--detector-param {item!r}: cannot read the value") from None
    return out


def live_params(args: argparse.Namespace) -> dict | None:
    """The live view's bridge parameters (None: no live view)."""
    return None if args.foxglove is None else {"port": args.foxglove, "host": args.foxglove_host}


def alarm_event_line(event: dict) -> str | None:
    """One line for a state change the detector published on /fault_alarm (None: not worth a line)."""
    if event.get("event") != "fault_alarm" or event.get("kind") == "state" and event.get("state") == "OK":
        return None
    return f"/fault_alarm {event['state']} at {event['time_s']:g} s: {event['message']}"


def received_alarms(result) -> tuple[list[dict], str]:
    """The alarms of the run: as the recorder received them on /fault_alarm (bag), else as the detector
    reported publishing them."""
    from phfdi import bagio
    from wavelet_fdi import alarm_messages

    if result.bag is not None and any(t["topic"] == "/fault_alarm" for t in result.bag["topics"]):
        messages = [m for part in result.bag.get("parts", [result.bag["path"]]) for m in bagio.fault_alarms(part)]
        return alarm_messages.per_alarm(messages), "received in the bag"
    done = [e for e in result.node_events.get("detector", []) if e["event"] == "detector_done"]
    return alarm_messages.from_summaries(done[-1]["alarms"] if done else []), "as the detector reported them"


def summary_dict(result, alarms: list[dict] | None = None) -> dict:
    out = {"scenario": result.scenario, "status": result.status, "samples": result.samples_done,
           "of": result.samples, "simulated_s": result.simulated_s, "wall_s": result.run_wall_s,
           "connect_s": result.connect_s, "real_time_factor": result.real_time_factor,
           "domain_id": result.domain_id, "failure": result.failure, "interrupted_by": result.interrupted_by,
           "notes": result.notes, "log_dir": result.log_dir}
    if result.bag is not None:
        out["bag"] = {"path": result.bag["path"], "size_bytes": result.bag["size_bytes"],
                      "counts": {t["topic"]: t["count"] for t in result.bag["topics"]}}
        if "parts" in result.bag:
            out["bag"]["parts"] = result.bag["parts"]
    if alarms is not None:
        out["alarms"] = alarms
    return out


def format_summary(result) -> str:
    if result.connect_s != result.connect_s:  # NaN: the graph never connected ("in nan s wall = nan x" before)
        head = f"launch {result.scenario or '?'}: the graph did not connect; no sample ran (ROS domain {result.domain_id})"
    else:
        head = (f"launch {result.scenario or '?'}: {result.samples_done} of {result.samples} samples "
                f"({result.simulated_s:g} s simulated) in {result.run_wall_s:.2f} s wall = "
                f"{result.real_time_factor:.0f} x real time; graph connected in {result.connect_s:.1f} s "
                f"(ROS domain {result.domain_id})")
    lines = [head]
    if result.interrupted_by:
        lines.append(f"  stopped by {result.interrupted_by}: all nodes stopped")
    if result.bag is not None:
        b = result.bag
        lines.append(f"  bag {b['path']} ({b['size_bytes'] / 1e6:.2f} MB, {b['messages']} messages"
                     f"{'' if b['finished'] else ', NOT FINISHED'}"
                     + (f"; in {len(b['parts'])} files, {Path(b['parts'][-1]).name} the last" if "parts" in b else "")
                     + ")")
        width = max(len(t["topic"]) for t in b["topics"]) if b["topics"] else 0
        for t in b["topics"]:
            lines.append(f"    {t['topic']:{width}s} {t['count']:8d}")
    for note in result.notes:
        lines.append(f"  note: {note}")
    if result.log_dir:
        lines.append(f"  node logs: {result.log_dir}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from phfdi.ros.launcher import Launcher, loop_graph

    _check(args)
    spec = scenario_from_args(args)  # one clear line for a bad scenario before any process starts
    detector = detector_params(args.detector_params) if args.detector or args.detector_params else None
    nodes = loop_graph(args.scenario, args.fault, args.onset, args.overrides, args.record, args.pace,
                       args.executor, args.connect_timeout, detector=detector, split_after_s=args.split_s,
                       overwrite=args.overwrite, live=live_params(args))
    say = lambda text: print(f"phfdi launch: {text}", file=sys.stderr)  # noqa: E731

    def on_event(node: str, event: dict) -> None:
        if event.get("event") == "live_view":
            say(f"live view: open {event['url']} in Foxglove (open connection -> Foxglove WebSocket), layout "
                f"config/foxglove_layout.json")
        line = alarm_event_line(event)
        if line:
            say(line)

    launcher = Launcher(nodes, domain_id=args.domain_id, log_dir=args.log_dir,
                        progress=Progress(f"launch {spec.name}"), status=say, on_event=on_event,
                        watchdog_s=args.watchdog_s)
    result = launcher.run()
    alarms, source = received_alarms(result) if detector is not None else (None, "")
    if args.json:
        print(json.dumps(summary_dict(result, alarms), indent=2))
    else:
        print(format_summary(result))
        if alarms is not None:
            from wavelet_fdi.alarm_messages import format_table

            print(f"  alarms on /fault_alarm ({source}):")
            print(format_table(alarms))
    if result.failure:
        print(f"phfdi launch: error: {result.failure}", file=sys.stderr)
        bag = ("" if result.bag is None else ", bag closed" if result.bag["finished"]
               else ", bag NOT finished (readable up to its last complete chunk; see the notes above)")
        print("phfdi launch: stopped the other nodes" + bag, file=sys.stderr)
    return result.status
