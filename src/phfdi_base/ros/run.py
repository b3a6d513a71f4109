"""Running one graph node as a process: LOCALHOST discovery, one clear line for bad parameters, clean shutdown.

:func:`main` keeps DDS on this machine (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``
set before rclpy starts), prints one line and returns 2 for bad parameters,
and on SIGINT or SIGTERM flushes the publishers to their reliable readers
before it ends. Nothing happens at import.
"""

from __future__ import annotations

import signal
import sys
import time
from typing import Any, Callable, Sequence

import rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from phfdi_base.errors import UserError

from .env import die_with_launcher, ensure_localhost, use_discovery_profile
from .params import NodeStartError, ParamSpec, common_params, print_parameter_help

__all__ = ["main"]


def _make_executor(kind: str):
    if kind == "events":
        from rclpy.experimental import EventsExecutor

        return EventsExecutor()
    return rclpy.executors.SingleThreadedExecutor()


def main(factory: Callable[[], Node], prog: str, summary: str, specs: Sequence[ParamSpec],
         argv: list[str] | None = None) -> int:
    """Run one graph node (a :class:`~phfdi_base.ros.graph_node.GraphNode` made by ``factory``) as this
    process; returns the exit status."""
    t_main, cpu_main = time.time(), time.process_time()  # the node's module and imports are loaded (start-up trace)
    argv = list(sys.argv if argv is None else argv)
    own = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if "-h" in own or "--help" in own:
        print_parameter_help(prog, summary, common_params(getattr(factory, "RUNTIME_COMMON", ())) + tuple(specs))
        return 0
    if not die_with_launcher():
        print(f"{prog}: the launcher that started this node has ended; not starting", file=sys.stderr)
        return 1
    try:
        ensure_localhost()  # before rclpy creates any DDS participant
        use_discovery_profile()  # a node started by hand discovers its peers as a launched one does
    except UserError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    stop: list[int] = []

    def on_signal(signum, _frame) -> None:
        stop.append(signum)

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    t_init, cpu_init = time.time(), time.process_time()
    name = prog.split(".")[0]
    try:
        node: Any = factory()  # a GraphNode: param, finished, spin_timeout_s, after_spin, drain, close, exit_code
    except NodeStartError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    node._startup_step("main", t_main, cpu_main)
    node._startup_step("init", t_init, cpu_init)
    executor = _make_executor(node.param("executor"))
    executor.add_node(node)
    try:
        while not stop and not node.finished:
            executor.spin_once(timeout_sec=node.spin_timeout_s())
            node.after_spin()
    finally:
        try:
            node.drain(executor)
        finally:
            node.close()
        executor.remove_node(node)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    if stop and not node.finished:
        return 0  # stopped on request: a normal end
    return node.exit_code

