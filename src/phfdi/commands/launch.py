"""phfdi launch: run a scenario through the ROS 2 node graph, one process per node."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from .common import EPILOG_FORMAT, Progress, add_scenario_args, scenario_from_args

EXAMPLES = """examples:
  phfdi launch --scenario paper --fault backlash --record bags/run.mcap
  phfdi launch --fault stiction --set duration_s=2000 --onset 1000 --record bags/stiction.mcap
  phfdi launch --record bags/live.mcap --pace 20          # 20 x real time, for a live demo
  phfdi launch --domain-id 42 --pace 1                    # real time, join with your own nodes on domain 42

Every node runs as its own process (python -m <package>.node) with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST on a ROS domain of its own. Ctrl-C
or SIGTERM stops all nodes and leaves a readable bag. See docs/ros_graph.md.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("launch", help="run a scenario through the ROS 2 node graph (plant, valve, controllers)",
                       description="Start the plant, valve and controller nodes (and a recorder) as separate "
                                   "processes, run the scenario in lock-step simulated time (or paced), stop "
                                   "everything cleanly and print a summary.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    add_scenario_args(p)
    p.add_argument("--record", metavar="BAG.mcap", default=None, help="record every topic to this MCAP bag")
    p.add_argument("--overwrite", action="store_true", help="replace the --record file if it exists")
    p.add_argument("--pace", type=float, default=0.0, metavar="FACTOR",
                   help="0: lock-step as fast as possible (default); F: F times real time")
    p.add_argument("--domain-id", type=int, default=None, help="ROS domain id (default: a free one)")
    p.add_argument("--executor", choices=("events", "single_threaded"), default="events",
                   help="rclpy executor of the nodes (default: events, the fastest)")
    p.add_argument("--connect-timeout", type=float, default=60.0, metavar="S",
                   help="give up if the graph has not connected after S seconds (default 60)")
    p.add_argument("--log-dir", default=None, help="keep the nodes' parameter files and logs here "
                                                    "(default: a temporary folder, kept only if something fails)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    from phfdi.errors import UserError

    if not (math.isfinite(args.pace) and 0.0 <= args.pace <= 1e6):
        raise UserError(f"--pace {args.pace}: use 0 (lock-step, as fast as possible) or a factor up to 1e6")
    if not 0.1 <= args.connect_timeout <= 3600:
        raise UserError(f"--connect-timeout {args.connect_timeout}: use 0.1 .. 3600 s")
    if args.record is not None and not args.record.endswith(".mcap"):
        raise UserError(f"--record {args.record}: give a .mcap file name")
    if args.record is not None and Path(args.record).exists() and not args.overwrite:
        raise UserError(f"--record {args.record} exists: give another name, or --overwrite to replace it")


def summary_dict(result) -> dict:
    out = {"scenario": result.scenario, "status": result.status, "samples": result.samples_done,
           "of": result.samples, "simulated_s": result.simulated_s, "wall_s": result.run_wall_s,
           "connect_s": result.connect_s, "real_time_factor": result.real_time_factor,
           "domain_id": result.domain_id, "failure": result.failure, "interrupted_by": result.interrupted_by,
           "notes": result.notes, "log_dir": result.log_dir}
    if result.bag is not None:
        out["bag"] = {"path": result.bag["path"], "size_bytes": result.bag["size_bytes"],
                      "counts": {t["topic"]: t["count"] for t in result.bag["topics"]}}
    return out


def format_summary(result) -> str:
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
                     f"{'' if b['finished'] else ', NOT FINISHED'})")
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
    nodes = loop_graph(args.scenario, args.fault, args.onset, args.overrides, args.record, args.pace,
                       args.executor, args.connect_timeout)
    launcher = Launcher(nodes, domain_id=args.domain_id, log_dir=args.log_dir,
                        progress=Progress(f"launch {spec.name}"),
                        status=lambda text: print(f"phfdi launch: {text}", file=sys.stderr))
    result = launcher.run()
    if args.json:
        print(json.dumps(summary_dict(result), indent=2))
    else:
        print(format_summary(result))
    if result.failure:
        print(f"phfdi launch: error: {result.failure}", file=sys.stderr)
        print("phfdi launch: stopped the other nodes" + (", bag closed" if result.bag else ""), file=sys.stderr)
    return result.status
