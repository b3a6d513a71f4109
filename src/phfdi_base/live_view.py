"""The live view: the graph's signals over the Foxglove WebSocket protocol (foxglove-sdk), loopback by default.

One table of channels (topic, JSON schema) for the bridge node that serves them (``phfdi launch --foxglove``, or
started alone: :mod:`phfdi.ros.live_bridge`, every signal of the graph). The channels carry
JSON with units in the field names, stamped with the simulated time of their sample (log time, ns), so
Foxglove's plots run on the graph's own clock. The layout that plots them ships as
``config/foxglove_layout.json`` (docs/ros_graph.md, "Live view in Foxglove").

The message converters read ROS messages by attribute only: no rclpy import here (the base's ROS-free part).
"""

from __future__ import annotations

import math
from typing import Any

from .errors import UserError

#: where the live view listens unless told otherwise: this machine only
LOOPBACK = "127.0.0.1"
DEFAULT_PORT = 8765
#: messages buffered per client before the oldest is dropped: a slow viewer must never slow the graph down
BACKLOG_MESSAGES = 4096
#: the limit the statistic ratios are plotted against: a CUSUM statistic at its threshold raises the alarm
RATIO_LIMIT = 1.0

MEASUREMENT = "/plant/measurement"
CONTROLLER = "/controller/output"
VALVE = "/valve/state"
MONITOR = "/detector/monitor"
ALARM = "/fault_alarm"

ALARM_STATES = {0: "OK", 1: "WARN", 2: "ALARM"}
#: how the detector names its residuals and ratios on the ROS topic /detector/monitor (MeasuredSample.names)
MONITOR_RESIDUALS = ("ph_residual", "level_residual_cm")
RATIO_PREFIX = "ratio:"


#: a number, or null where it is missing (JSON has no NaN)
_NUMBER = {"type": ["number", "null"]}


def _schema(title: str, description: str, numbers: dict[str, str], extra: dict[str, Any] | None = None) -> dict:
    """A JSON schema of an object whose fields are numbers (each with its description) plus ``extra``."""
    props: dict[str, Any] = {name: {**_NUMBER, "description": text} for name, text in numbers.items()}
    props.update(extra or {})
    return {"title": title, "description": description, "type": "object", "properties": props,
            "required": list(props)}


#: topic -> JSON schema of its channel
SCHEMAS: dict[str, dict] = {
    MEASUREMENT: _schema("phfdi.Measurement", "pH probe and level transmitter (phfdi_interfaces/Measurement)", {
        "time_s": "simulated time of the sample (s)", "ph": "measured pH", "level_cm": "measured level (cm)"}),
    CONTROLLER: _schema("phfdi.ControllerOutput", "both PI loops (phfdi_interfaces/ControllerOutput)", {
        "time_s": "simulated time (s)", "ph_setpoint": "pH setpoint", "ph_output_pct": "pH valve command (%)",
        "level_setpoint_cm": "level setpoint (cm)", "level_output_pct": "outlet valve command (%)"}),
    VALVE: _schema("phfdi.ValveState", "both valves (phfdi_interfaces/ValveState)", {
        "time_s": "simulated time (s)", "ph_command_pct": "pH valve command (%)",
        "ph_position_pct": "pH valve stem position (%)", "outlet_command_pct": "outlet valve command (%)",
        "outlet_position_pct": "outlet valve stem position (%)"}),
    MONITOR: _schema("phfdi.DetectorMonitor", "the detector's residuals and CUSUM statistics over their thresholds", {
        "time_s": "simulated time of the last sample the detector processed (s)",
        "ph_residual": "measured minus predicted pH", "level_residual_cm": "measured minus predicted level (cm)",
        "worst_ratio": "the largest statistic / threshold", "limit": "1: a statistic at its threshold alarms"},
        {"ratio": {"type": "object", "description": "statistic / threshold, per statistic (dots written _)",
                   "additionalProperties": _NUMBER}}),
    ALARM: _schema("phfdi.FaultAlarm", "the detector's state (phfdi_interfaces/FaultAlarm)", {
        "time_s": "simulated time (s)", "state": "0 OK, 1 WARN, 2 ALARM", "confidence": "of fault_class, 0..1",
        "severity": "the fault's size in severity_unit (NaN: unknown)", "statistic": "decision statistic",
        "threshold": "its alarm threshold", "ratio": "statistic / threshold"},
        {"state_name": {"type": "string", "enum": list(ALARM_STATES.values())},
         "fault_class": {"type": "string"}, "severity_unit": {"type": "string"}, "message": {"type": "string"},
         "statistic_name": {"type": "string", "description": "which statistic, e.g. ph.R.mean_down"}}),
}


def statistic_key(name: str) -> str:
    """A statistic's name as a JSON key Foxglove's message paths can address (``ph.R.mean_up`` -> ``ph_R_mean_up``)."""
    return name.replace(".", "_")


def ratio(value: float, limit: float) -> float:
    """value / limit; NaN when the limit is not a positive finite number (no threshold known)."""
    return value / limit if math.isfinite(limit) and limit > 0 else math.nan


def _seconds(stamp: Any) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def finite(x: float) -> float | None:
    """JSON has no NaN: a missing number is null."""
    return float(x) if math.isfinite(x) else None


# ---- ROS messages -> channel messages (attribute access only) -----------------------------------------------
def measurement(msg: Any) -> dict:
    return {"time_s": _seconds(msg.stamp), "ph": finite(msg.ph), "level_cm": finite(msg.level_cm)}


def controller_output(msg: Any) -> dict:
    return {"time_s": _seconds(msg.stamp), "ph_setpoint": finite(msg.ph_setpoint),
            "ph_output_pct": finite(msg.ph_output_pct), "level_setpoint_cm": finite(msg.level_setpoint_cm),
            "level_output_pct": finite(msg.level_output_pct)}


def valve_state(msg: Any) -> dict:
    return {"time_s": _seconds(msg.stamp), "ph_command_pct": finite(msg.ph_command_pct),
            "ph_position_pct": finite(msg.ph_position_pct), "outlet_command_pct": finite(msg.outlet_command_pct),
            "outlet_position_pct": finite(msg.outlet_position_pct)}


def fault_alarm(msg: Any) -> dict:
    return {"time_s": _seconds(msg.stamp), "state": int(msg.state), "state_name": ALARM_STATES.get(msg.state, "?"),
            "fault_class": msg.fault_class, "confidence": finite(msg.confidence), "severity": finite(msg.severity),
            "severity_unit": msg.severity_unit, "statistic": finite(msg.statistic),
            "threshold": finite(msg.threshold), "ratio": finite(ratio(msg.statistic, msg.threshold)),
            "statistic_name": getattr(msg, "statistic_name", ""), "message": msg.message}


def monitor(time_s: float, values: dict[str, float]) -> dict:
    """The /detector/monitor message of a sample: ``values`` as the detector names them
    (:data:`MONITOR_RESIDUALS` and ``ratio:<statistic>``)."""
    ratios = {statistic_key(k[len(RATIO_PREFIX):]): finite(v) for k, v in values.items() if k.startswith(RATIO_PREFIX)}
    known = [v for v in ratios.values() if v is not None]
    return {"time_s": time_s, "ph_residual": finite(values.get("ph_residual", math.nan)),
            "level_residual_cm": finite(values.get("level_residual_cm", math.nan)),
            "worst_ratio": max(known) if known else None, "limit": RATIO_LIMIT, "ratio": ratios}


# ---- the server -------------------------------------------------------------------------------------------------
class LiveView:
    """A Foxglove WebSocket server with the live view's channels; ``log`` sends to every subscribed client.

    Every instance has a foxglove context of its own (its channels are its server's only). A port that is
    taken gives a :class:`UserError` of one line."""

    def __init__(self, port: int = DEFAULT_PORT, host: str = LOOPBACK, name: str = "phfdi",
                 topics: tuple[str, ...] = tuple(SCHEMAS)) -> None:
        import foxglove  # only where a live view is asked for: the nodes do not pay for it otherwise

        check_port(port)
        self.context = foxglove.Context()
        self.channels = {t: foxglove.Channel(t, schema=SCHEMAS[t], context=self.context) for t in topics}
        try:
            self.server = foxglove.start_server(name=name, host=host, port=port, context=self.context,
                                                message_backlog_size=BACKLOG_MESSAGES)
        except RuntimeError as exc:  # foxglove: "FoxgloveError: Failed to bind port: Address already in use ..."
            raise UserError(f"cannot serve the Foxglove live view on {host}:{port}: {_bind_reason(exc)}") from None
        self.host, self.port = host, self.server.port
        self.logged: dict[str, int] = dict.fromkeys(self.channels, 0)

    @property
    def url(self) -> str:
        return f"ws://{self.host}:{self.port}"

    def log(self, topic: str, message: dict, time_ns: int) -> None:
        """Send one message (simulated time ``time_ns`` as its log time) to the clients subscribed to ``topic``."""
        self.channels[topic].log(message, log_time=max(int(time_ns), 0))
        self.logged[topic] += 1

    def stop(self) -> None:
        self.server.stop()


def check_port(port: int) -> None:
    """A port the live view can ask for: 1..65535 (0, any free port, for tests)."""
    if not (isinstance(port, int) and 0 <= port <= 65535):
        raise UserError(f"Foxglove port {port!r}: use 1 .. 65535")


def _bind_reason(exc: Exception) -> str:
    text = str(exc)
    if "Address already in use" in text:
        return "the port is already in use (another live view or program); choose another port"
    return text.removeprefix("FoxgloveError: ")
