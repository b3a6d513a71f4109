"""The fault detector's ROS 2 node (thin wrapper of the multichannel detector,
wavelet_fdi.learned_detector.LearnedDetector): the loop graph's topics, /measured/sample or your plant's own topics
in, /fault_alarm out. ``phfdi launch --detector`` starts it with the physics reference shipped for the scenario.

Input, with ``channel_map_file`` (a YAML channel map, :mod:`wavelet_fdi.channel_map`): each channel of the
reference from the topic, message type and field the map names (std_msgs numbers and arrays, sensor_msgs
scalars, the project's messages), stamped by its header where it has one and by the node's clock when it is
received otherwise, put onto the reference's sample grid by :mod:`wavelet_fdi.channel_align` (the map's
``align`` rule); the channel sources, stamp rules, counts and problems on /diagnostics (``detector: channel
map``), the /fault_alarm stamps on the plant's clock (the grid's origin + each sample's time: k * sample time, or
with ``align: sequence`` and stamped messages the samples' own stamps). Without it: /measured/sample
(phfdi_interfaces/MeasuredSample: channel names and values of one row of a measured record, e.g. played from a
bag of ``phfdi bag from-csv``). The channels are matched to the
reference's by name (a channel a message lacks is missing for that row). Output: /fault_alarm
(phfdi_interfaces/FaultAlarm) when an alarm is raised or cleared and when a channel goes missing,
with the channels that carry the alarm (``channels``, ``channel_shares``, ``channel_bands``); for a
reference that names faults (the estimator), once more when the alarm is named (``fault_class``,
``severity`` and ``severity_unit``: the hypothesis that explains it best and its size); every message about an
alarm names its statistic (``statistic_name``). Input problems (a channel missing and back, detection held by the
reference's own rule and resumed) go out at once where they change the state (WARN while one is open, unless an
alarm is up), else at most once per ``input_problem_period_s`` of wall time, in one message that sums up those
held back (a burst of gaps in the stamps would otherwise send two messages per gap). A heartbeat every
``heartbeat_period_s`` of the record's time (at most one per batch, and one at the end) gives the state, the
worst statistic against its threshold and, while an alarm is open, its times and channels.

The reference is the kind the model file names (a learned ARX reference from ``phfdi calibrate --learn``,
the rig's Kalman estimator from ``phfdi calibrate --estimator``, ...). The core takes each row at its
stamp in seconds (:func:`phfdi_base.stamps.stamp_seconds`; ``phfdi bag from-csv`` stamps a row with the
record's own time to the ns), the times the offline ``phfdi replay RECORD --reference REF`` gives it: the
estimator steps by their differences.

Callbacks only queue rows; a worker thread hands everything queued to the core in one call (the
result is the same for any chunking; :mod:`wavelet_fdi.node_base`). The node prints one JSON line per
published change and, on exit, a ``detector_done`` report with every alarm (the launcher and
``phfdi replay --live`` read it).

    python -m wavelet_fdi.learned_node --ros-args -p reference:=ref.json -p graph_nodes:="[detector]"
"""

from __future__ import annotations

import math
import sys
import time
import traceback

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from phfdi_interfaces.msg import FaultAlarm, MeasuredSample
from rclpy.clock import Clock, ClockType

from phfdi_base.errors import UserError
from phfdi_base.ros.graph_node import NodeStartError, ParamSpec, main, to_time
from phfdi_base.stamps import seconds_to_ns, stamp_seconds, time_ns
from phfdi_base.topics import MEASURED_SAMPLE

from .channel_align import grid_period_ns
from .channel_map import ChannelMap, load_channel_map, loop_graph_map
from .healthy_range import RangeWatch, describe_first, healthy_span, span
from .learned_detector import LearnedDetector, LearnedModel
from .map_inputs import MappedInputs, SummedWarnings
from .node_base import MONITOR_PARAMS, STATE_NAMES, DetectorNodeBase, next_multiple
from .reference_physics import follow_scenario

PARAMS = (
    ParamSpec("reference", "", "reference file (.json) from phfdi calibrate (--learn, --estimator, or a physics reference), or "
                               "a shipped one by name (paper_physics: the paper loop's physics)"),
    ParamSpec("loop", "measured", "name of the monitored plant or loop in /fault_alarm"),
    ParamSpec("name_faults", True, "name the fault behind each alarm where the reference can (false: detection "
                                   "only; phfdi replay --live --no-isolation)"),
    ParamSpec("channel_map_file", "", "YAML channel map: each reference channel's topic, type and field "
              "('' = /measured/sample, or the loop graph's topics with loop_graph_topics; docs/ros_graph.md)"),
    ParamSpec("loop_graph_topics", False, "without a channel map: read the loop graph's own topics "
              "(/plant/measurement, /controller/output) for a reference of its signals (a physics reference: phfdi calibrate); "
              "phfdi launch sets it"),
    ParamSpec("silent_after_s", 10.0, "wall time after which a mapped topic that delivers nothing is reported",
              (0.1, 3600.0)),
    # wall time: a topic that went silent moves no record time (the physics nodes' diagnostics_period_s counts
    # simulated time, so this one has a name of its own)
    ParamSpec("channel_map_report_period_s", 5.0, "wall time between the channel map's /diagnostics reports",
              (0.1, 3600.0)),
    ParamSpec("diagnostics_period_s", 0.0, "the old name of channel_map_report_period_s (before 2026-12-06): a value "
                                           "above 0 is taken for it, with a warning; 0: not set", (0.0, 3600.0)),
    # on the stream's own time, so a replay faster than real time gives the heartbeats the plant's time would have
    *MONITOR_PARAMS,
    ParamSpec("input_problem_period_s", 1.0, "input problems on /fault_alarm at most once per this many s of "
                                             "wall time (one message summing those held back; state changes always)",
              range=(0.05, 3600.0), runtime=True),
    ParamSpec("heartbeat_period_s", 60.0, "publish the state on /fault_alarm every this many s of the record's time "
                                          "(at most one per batch the worker takes); 0: only on changes",
              range=(0.0, 1e9), runtime=True),
)
#: what a heartbeat during an alarm repeats from the alarm's last message (its statistic is the heartbeat's own)
ALARM_FIELDS = ("fault_class", "confidence", "severity", "severity_unit", "detection_time", "onset_time", "channels",
                "channel_shares", "channel_bands", "wavelet_level")
#: the live view's names of the physics kind's residuals (phfdi_base.live_view.MONITOR_RESIDUALS), in its units
LIVE_RESIDUALS = {"ph_measured": "ph_residual", "level_measured_cm": "level_residual_cm"}
#: input events an input message gives in words (the others are counted)
INPUT_TEXTS = 3
#: wall time between the checks of a channel map's waits and silent topics
TICK_S = 0.2
STATE_OF_KIND = {"alarm": FaultAlarm.ALARM, "cleared": FaultAlarm.OK}
#: a confirming reference's deviations take the state their level says (WARN while being checked or outside
#: calibration; OK when one ended before its verdict)
STATE_OF_LEVEL = {"ERROR": FaultAlarm.ALARM, "WARN": FaultAlarm.WARN, "OK": FaultAlarm.OK}


class LearnedDetectorNode(DetectorNodeBase):
    PARAMS = PARAMS
    WORKER_NAME = "learned-detector-core"

    def __init__(self) -> None:
        super().__init__()
        path = self.param("reference")
        if not path:
            raise NodeStartError("parameter reference: give a reference file (phfdi calibrate --learn, --estimator "
                                 "or neither: a physics reference) or a shipped one by name (paper_physics)")
        try:
            self.model = LearnedModel.load(path)
        except UserError as exc:
            raise NodeStartError(f"parameter reference = {path!r}: {exc}") from None
        if self.param("loop_graph_topics"):  # in the loop graph: a physics reference runs the launch's own plant
            self.model, note = follow_scenario(self.model, self.spec, "launch")
            if note:
                self.get_logger().warning(note)
        self.core = LearnedDetector(self.model, name_faults=self.param("name_faults"))
        self.quiet_events = 0  # deviations (and their verdicts) kept but not published: the hold of the last one
        # where the inputs leave what the reference's healthy runs had (a reference file from before: nothing)
        self.range_watch = RangeWatch(self.model.source.get("healthy_ranges") or {}, self.model.channels)
        self._index = {c: i for i, c in enumerate(self.model.channels)}
        self._t_last = 0.0
        self._heartbeat_s = self.param("heartbeat_period_s")
        self._last_heartbeat_t = -math.inf
        self._alarm_said: FaultAlarm | None = None
        self._alarm_state = FaultAlarm.OK  # the state the alarms and deviations alone give (inputs aside)
        self._input_period_s = self.param("input_problem_period_s")
        self._inputs_held: list = []  # input events not yet on /fault_alarm (the rate limit)
        self._inputs_sent_at = -math.inf  # monotonic time of the last input message
        self.open_alarm_output()
        self._pub_range = self.diagnostics_publisher()
        self._range_warnings = SummedWarnings(self.get_logger(), f"/diagnostics ('{self.get_name()}: healthy range')")
        self._received = 0
        self.open_monitor_output()
        self.inputs: MappedInputs | None = None
        path = self.param("channel_map_file")
        if path:
            try:
                self._subscribe_map(load_channel_map(path, self.model.channels))
            except UserError as exc:
                raise NodeStartError(f"parameter channel_map_file = {path!r}: {exc}") from None
        elif self.param("loop_graph_topics"):
            # the paper loop's signals from the loop graph's own topics
            try:
                self._subscribe_map(loop_graph_map(self.model.channels))
            except UserError as exc:
                raise NodeStartError(f"parameter loop_graph_topics: {exc}") from None
        else:
            self.data_subscription(MeasuredSample, MEASURED_SAMPLE.name, self._on_sample)
        self.start_worker()
        self.start_barrier()

    def _subscribe_map(self, cmap: ChannelMap) -> None:
        """The plant's own topics, as the channel map names them, aligned onto the reference's sample grid."""
        try:
            dt_ns = grid_period_ns(self.model.settings.sample_time_s)
        except ValueError as exc:
            raise NodeStartError(f"parameter reference: {exc}") from None
        inputs = self.inputs = MappedInputs(self, cmap, dt_ns, self.enqueue, self.param("silent_after_s"))
        self._pub_map_diag = self.diagnostics_publisher()
        steady = Clock(clock_type=ClockType.STEADY_TIME)  # waits are wall time, also under use_sim_time
        self.create_timer(TICK_S, inputs.tick, clock=steady)
        self.create_timer(self._report_period_s(), self._report_map, clock=steady)
        self._problems_said = 0

    def _report_period_s(self) -> float:
        """channel_map_report_period_s, or the old name's value (set by a launch file written before the rename)."""
        old = float(self.param("diagnostics_period_s"))
        if old > 0.0:
            self.get_logger().warning(f"parameter diagnostics_period_s = {old:g} is now channel_map_report_period_s "
                                      f"(wall time between the channel map's reports); taken as that")
            return old
        return float(self.param("channel_map_report_period_s"))

    def _report_map(self) -> None:
        """The channel map's status on /diagnostics (periodically; at once when a new problem is seen)."""
        assert self.inputs is not None
        status = self.inputs.status()
        status.values.append(KeyValue(key="reference", value=str(self.param("reference"))))  # what it watches with
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._pub_map_diag.publish(array)
        self._problems_said = len(self.inputs.problems)

    def after_spin(self) -> None:
        if self.inputs is not None and len(self.inputs.problems) > self._problems_said:
            self._report_map()
        if self._inputs_held and self._inputs_due():  # held-back input problems go out even if nothing follows
            self.poke()

    # ---- executor thread: queue only ----------------------------------------------------------
    def _on_sample(self, msg: MeasuredSample) -> None:
        row = np.full(len(self._index), np.nan)
        for name, value in zip(msg.names, msg.values):
            i = self._index.get(name)
            if i is not None:
                row[i] = value
        self._received += 1
        self.enqueue([(stamp_seconds(time_ns(msg.stamp)), row)])

    def _publish_monitor(self) -> None:
        """The last row's residuals and statistics on /detector/monitor when due (worker thread): the physics
        kind's residuals in the measurements' units under the live view's names, every other kind's in its
        sigmas (``residual:<channel>``)."""
        if self.pub_monitor is None:
            return
        t_s, values = self.core.monitor()
        if not math.isfinite(t_s) or not self.monitor_due(t_s):
            return
        noise = getattr(self.model.reference, "noise", None) if self.model.reference.kind == "physics" else None
        if noise is not None:
            for channel, unit in zip(self.model.residual_channels, noise):
                values[LIVE_RESIDUALS[channel]] = values.pop(f"residual:{channel}") * float(unit)
        self.publish_monitor(t_s, values, self._stamp(t_s))

    def received(self) -> int:
        return self._received + (self.inputs.received if self.inputs is not None else 0)

    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers hold; a mapped node then hands every sample begun to the core."""
        super().drain(executor, idle_s, limit_s)
        if self.inputs is not None:
            self.inputs.flush()
            self._report_map()

    # ---- worker thread: the core and the publisher --------------------------------------------
    def process(self, rows: list[tuple[float, np.ndarray]]) -> None:
        if not rows:  # poked: only the input problems held back by the rate limit
            if self._inputs_held and self._inputs_due():
                self._publish_inputs()
            return
        t = np.array([r[0] for r in rows])
        x = np.vstack([r[1] for r in rows])
        try:
            events, _ = self.core.process(t, x)
        except Exception:  # noqa: BLE001 - a bug must not take the observer down: report, keep going
            self.core_errors += 1
            self.get_logger().error(f"learned detector failed on {len(rows)} rows:\n" + traceback.format_exc())
            return
        self._t_last = float(t[-1])
        for ev in events:
            if ev.kind == "input":  # rate-limited below
                self._inputs_held.append(ev)
            else:
                self._publish(ev)
        # an input problem that changes the state (a channel missing or back, detection held or resumed) goes
        # out at once, the others when due
        if self._inputs_held and (self._combined_state() != self._state or self._inputs_due()):
            self._publish_inputs()
        self._state = self._combined_state()
        if self._t_last < self._last_heartbeat_t:  # the record's clock went back: the schedule follows it
            self._last_heartbeat_t = self._t_last
        if self._heartbeat_s > 0 and self._t_last >= next_multiple(self._last_heartbeat_t, self._heartbeat_s):
            self._publish_heartbeat()
        self._publish_monitor()
        new = self.range_watch.update(x)
        for o in new:  # once per channel: the reference extrapolates from here on (beyond a few: summed up)
            self._range_warnings.warn("range", o["channel"], describe_first(o))
        self._range_warnings.flush({"range": "channels beyond the reference's healthy runs"})
        if new:
            self._report_range()

    def _report_range(self) -> None:
        """'detector: healthy range' on /diagnostics: WARN with each channel outside it so far (at its first
        leaving and at the end), OK at the end when none left it."""
        outside = self.range_watch.summary()
        values = [KeyValue(key=o["channel"], value=f"{100 * o['share']:.1f} % of {self.range_watch.rows} samples "
                                                    f"outside ({span(o)}; healthy: {healthy_span(o['healthy'])})")
                  for o in outside]
        msg = "inputs beyond the reference's healthy runs: " + ", ".join(o["channel"] for o in outside) if outside \
            else "inputs within the reference's healthy runs"
        status = DiagnosticStatus(level=DiagnosticStatus.WARN if outside else DiagnosticStatus.OK,
                                  name=f"{self.get_name()}: healthy range", message=msg,
                                  hardware_id=self.param("reference"), values=values)
        array = DiagnosticArray(status=[status])
        array.header.stamp = self.get_clock().now().to_msg()
        self._pub_range.publish(array)

    def _publish(self, ev) -> None:
        if not ev.announce:  # a repeat within the hold of the last deviation outside calibration: kept, not shown
            self.quiet_events += 1
            return
        if ev.kind in ("deviation", "outside_calibration"):
            self._alarm_state = STATE_OF_LEVEL[ev.level]
        else:
            self._alarm_state = STATE_OF_KIND.get(ev.kind, self._alarm_state if self._alarm_state == FaultAlarm.ALARM
                                                  else FaultAlarm.WARN)
        state = self._combined_state()
        msg = FaultAlarm(loop=self._loop, state=state, message=ev.message, severity=math.nan, wavelet_level=-1)
        msg.stamp = self._stamp(ev.time_s)
        a = ev.alarm
        if a:
            iso = a.get("isolation") or {}
            # named NAMING_AFTER samples after the detection; a deviation no fault explains is no fault class
            # not named yet: "pending" where the reference names faults (the physics kind, 300 s after the
            # detection), "unknown" where it never does
            msg.fault_class = {"pending": "pending", "outside calibration": "outside_calibration"}.get(
                a.get("verdict", ""), iso.get("fault_class", "pending" if self.core.namer is not None else "unknown"))
            if a.get("verdict") == "outside calibration":
                iso = {}
            if iso:
                msg.severity, msg.severity_unit = float(iso["size"]), str(iso["unit"])
                msg.confidence = float(iso.get("confidence", 0.0))
            msg.detection_time = self._stamp(a["detection_time"])
            if a.get("onset_time") is not None:
                msg.onset_time = self._stamp(a["onset_time"])
            msg.statistic_name = str(a["statistic"])
            msg.statistic, msg.threshold = float(a["statistic_value"]), float(a["threshold"])
            cont = a["contributions"] if ev.kind in ("alarm", "deviation") \
                else a.get("episode_contributions") or a["contributions"]
            msg.channels = list(cont)
            msg.channel_shares = [float(v["share"]) for v in cont.values()]
            msg.channel_bands = [max(v["bands"], key=v["bands"].get) for v in cont.values()]
            band = msg.channel_bands[0] if msg.channel_bands else ""
            msg.wavelet_level = int(band[1:]) if band.startswith("D") else 0 if band.startswith("A") else -1
        self.publish_alarm(msg, ev.kind, ev.time_s, a)
        self._state = state
        self._alarm_said = msg if a else self._alarm_said  # what the heartbeat repeats of an open alarm

    def _combined_state(self) -> int:
        """The state to publish: the alarms' (ALARM wins), else WARN while an input problem is open."""
        if self._alarm_state == FaultAlarm.ALARM:
            return FaultAlarm.ALARM
        return FaultAlarm.WARN if self.core.input_problem else self._alarm_state

    def _inputs_due(self) -> bool:
        return time.monotonic() - self._inputs_sent_at >= self._input_period_s

    def _publish_inputs(self) -> None:
        """One /fault_alarm message for the input events held since the last one: the first few in words, the
        number of the others, and what is still open (worker thread)."""
        held, self._inputs_held = self._inputs_held, []
        texts = list(dict.fromkeys(ev.message for ev in held))[:INPUT_TEXTS]
        text = "; ".join(texts)
        if len(held) > len(texts):
            text += f" ({len(held)} input events since the last report)"
        open_now = self.core.input_problem
        text += f"; still: {open_now}" if open_now else "; inputs complete"
        state = self._combined_state()
        msg = FaultAlarm(loop=self._loop, state=state, message=text, severity=math.nan, wavelet_level=-1)
        msg.stamp = self._stamp(held[-1].time_s)
        self.publish_alarm(msg, "input", held[-1].time_s, None)
        self._state = state
        self._inputs_sent_at = time.monotonic()

    def _publish_heartbeat(self) -> None:
        """The state now on /fault_alarm (no JSON line: not a change): the worst statistic against its threshold,
        and the open alarm's times and channels while there is one."""
        core = self.core
        ratio = core.cusum.value / core.h
        worst = int(np.argmax(ratio)) if len(ratio) else -1
        name, value, h = (core.stat_names[worst], float(core.cusum.value[worst]), float(core.h[worst])) \
            if worst >= 0 else ("", math.nan, math.nan)
        text = (f"{STATE_NAMES[self._state]}: worst statistic {name} {value:.1f} of threshold {h:.1f}; "
                f"{core.samples_processed} samples")
        msg = FaultAlarm(loop=self._loop, state=self._state, message=text, severity=math.nan, wavelet_level=-1,
                         statistic=value, threshold=h, statistic_name=name)
        msg.stamp = self._stamp(self._t_last)
        if core.in_alarm and self._alarm_said is not None:  # the open alarm's class, times and channels as last said
            for field in ALARM_FIELDS:
                setattr(msg, field, getattr(self._alarm_said, field))
        self.publish_alarm(msg, "state", self._t_last, None, report=False)
        self._last_heartbeat_t = self._t_last

    def apply_parameters(self, params) -> None:
        self._heartbeat_s = self.param("heartbeat_period_s")  # from the next batch the worker takes
        self._input_period_s = self.param("input_problem_period_s")

    def _stamp(self, t_s: float):
        """A core time as a ROS time: with a channel map on the plant's clock (the grid's origin added)."""
        origin = self.inputs.aligner.origin_ns if self.inputs is not None else None
        return to_time((origin or 0) + seconds_to_ns(t_s))

    # ---- the end ---------------------------------------------------------------------------------
    def finish(self) -> None:
        """The stream ended: name the alarms still waiting for their window (as the offline replay does)."""
        for ev in self.core.finish():
            self._publish(ev)
        if self._inputs_held:  # the last ones held back by the rate limit
            self._publish_inputs()
        if self.core.samples_processed:
            self._publish_heartbeat()  # the state at the end
        self._report_range()

    def done_report(self) -> dict:
        report = {"samples": self.core.samples_processed, "alarms": self.core.alarms,
                  "core_errors": self.core_errors, "quiet_events": self.quiet_events, "reference": self.param("reference"),
                  "outside_healthy_range": self.range_watch.summary()}
        if self.inputs is not None:
            report["channel_map"] = {**self.inputs.report(), "file": self.param("channel_map_file")}
        return report


def run() -> int:
    return main(LearnedDetectorNode, "wavelet_fdi.learned_node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
