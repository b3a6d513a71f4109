"""The live view's bridge node: the graph's signals to Foxglove (WebSocket protocol, foxglove-sdk), loopback by default.

Subscribes to /plant/measurement, /controller/output, /valve/state, /detector/monitor (the detector's residuals
and statistic ratios, published when ``phfdi launch --foxglove`` turns on its ``monitor_topic``) and
/fault_alarm, and logs each message as JSON on a Foxglove channel of the same name
(:mod:`phfdi_base.live_view`: schemas, units in the field names, simulated time as log time).

One node for the whole graph, not Foxglove in every node: the loop nodes stay as they are, and a viewer that
cannot keep up costs only its own messages. Its readers are best effort (:data:`VIEWER_QOS`): no writer ever
waits for them or keeps samples for them, so the lock-step ring runs as without it; they are matched at the
start barrier, so a viewer that keeps up sees the run from sample 0. Clients that read too slowly lose the
oldest messages (foxglove's backlog per client), never the graph.

    python -m phfdi.ros.live_bridge --ros-args -p scenario:=paper -p graph_nodes:="[foxglove]" -p port:=8765
"""

from __future__ import annotations

import json
import sys
from typing import Any, Callable

from phfdi_interfaces.msg import ControllerOutput, FaultAlarm, MeasuredSample, Measurement, ValveState

from phfdi_base import live_view
from phfdi_base.errors import UserError
from phfdi_base.ros.barrier import VIEWER_QOS
from phfdi_base.ros.graph_node import GraphNode, NodeStartError, ParamSpec, main, time_ns
from phfdi_base.topics import CONTROLLER, DETECTOR_MONITOR, FAULT_ALARM, LIVE_VIEW, MEASUREMENT, VALVE_STATE

PARAMS = (
    ParamSpec("port", live_view.DEFAULT_PORT, "port of the Foxglove WebSocket server", range=(1, 65535)),
    ParamSpec("host", live_view.LOOPBACK, "address it listens on (default: this machine only)"),
)


def _monitor(msg: MeasuredSample) -> dict:
    return live_view.monitor(msg.stamp.sec + msg.stamp.nanosec * 1e-9, dict(zip(msg.names, msg.values)))


#: ROS topic -> (message type, converter to the channel's JSON)
ROUTES: dict[str, tuple[Any, Callable[[Any], dict]]] = {
    MEASUREMENT.name: (Measurement, live_view.measurement),
    CONTROLLER.name: (ControllerOutput, live_view.controller_output),
    VALVE_STATE.name: (ValveState, live_view.valve_state),
    DETECTOR_MONITOR.name: (MeasuredSample, _monitor),
    FAULT_ALARM.name: (FaultAlarm, live_view.fault_alarm),
}


class LiveBridge(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(LIVE_VIEW)
        self.errors = 0  # messages that could not be sent (a bug in a converter): counted, logged, never fatal
        try:
            self.live = live_view.LiveView(self.param("port"), self.param("host"), name="phfdi graph")
        except UserError as exc:
            raise NodeStartError(str(exc)) from None
        for topic, (msg_type, convert) in ROUTES.items():
            self.data_subscription(msg_type, topic, self._forward(topic, convert), qos=VIEWER_QOS)
        # the launcher prints where to connect (phfdi launch --foxglove)
        self.report({"event": "live_view", "url": self.live.url, "channels": list(self.live.channels)})
        self.start_barrier()

    def _forward(self, topic: str, convert: Callable[[Any], dict]) -> Callable[[Any], None]:
        def on_message(msg) -> None:
            try:
                self.live.log(topic, convert(msg), time_ns(msg.stamp))
            except Exception as exc:  # noqa: BLE001 - the view loses this message; the graph must go on
                self.errors += 1
                if self.errors == 1 or self.errors % 1000 == 0:
                    self.get_logger().error(f"live view: {topic} message not sent ({self.errors} so far): "
                                            f"{type(exc).__name__}: {exc}")

        return on_message

    @staticmethod
    def report(event: dict) -> None:
        """One JSON line on stdout (the launcher follows them)."""
        print(json.dumps(event), flush=True)

    def close(self) -> None:
        self.report({"event": "live_view_done", "logged": self.live.logged, "errors": self.errors})
        self.live.stop()
        super().close()


def run() -> int:
    return main(LiveBridge, "phfdi.ros.live_bridge", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
