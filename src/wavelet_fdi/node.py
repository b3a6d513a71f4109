"""ROS 2 node of the fault detector (thin wrapper of :class:`StreamingDetector`): publishes /fault_alarm.

Inputs: /plant/measurement (pH, level of stamp t_k) and /controller/output
(setpoint and valve commands computed for t_k). The reading of t_k is paired
with the controller output stamped t_k. If that output is missing (an output
with a later stamp came, or the output topic fell silent for
``pairing_timeout_s`` while ``pairing_window`` later measurements waited),
the sample goes on with NaN commands, which the core counts and, if it lasts,
answers by holding detection (see :mod:`wavelet_fdi.inputs`). With ``channel_map_file`` (a YAML channel map,
:mod:`wavelet_fdi.channel_map`, as the learned detector node reads) the node reads your plant's own topics instead:
the map names the topic, type and field of each of :data:`PHYSICS_CHANNELS` (a map without one is refused in one
line), :mod:`wavelet_fdi.map_inputs` aligns them onto the scenario's sample grid and each sample goes to the core
as a paired one (stamp k * sample time from the grid's first sample; /fault_alarm stamped so too, the grid's
origin in the ``detector_done`` report; the map's status on /diagnostics, ``detector: channel map``). Not simply "by
the next measurement": two topics from two writers are not delivered in
publication order (in a lock-step run 29 of 1601 controller outputs arrived
after the next measurement, though published before it; :class:`Pairing`).

Outputs: /fault_alarm (phfdi_interfaces/FaultAlarm) on every state change
(alarm raised, diagnosed, cleared, warm-up over, and an input problem that
changes the alarm state: detection held or resumed), input problems at most
once per ``input_problem_period_s`` of wall time (one message with the counts
so far: stamp garbage once gave 313 messages in a second), and as a
heartbeat every ``heartbeat_period_s`` of simulated time (at most one per batch
the worker takes: a backlog worked off at once gives one); /diagnostics
(diagnostic_msgs/DiagnosticArray: the core's input counters, pairing counts,
processing lag, calibration in use) every ``diagnostics_period_s`` and
whenever a problem counter grows.

The node is an observer, never part of the lock-step ring: its callbacks
only queue samples. A worker thread hands everything queued since its last
call to the core in one ``StreamingDetector.process`` call (results are
identical for any chunking), so an isolation (1-3 s, once per alarm) never
stops the executor from taking messages, and nothing is lost (reliable,
keep-all). On SIGINT/SIGTERM it takes what its readers still hold, processes
it, runs pending isolations on the data there is (``flush``), publishes the
result and exits.

    python -m wavelet_fdi.node --ros-args -p scenario:=paper -p graph_nodes:="[detector]"
"""

from __future__ import annotations

import math
import sys
import time
import traceback
from collections import deque
from itertools import islice

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from phfdi_interfaces.msg import ControllerOutput, FaultAlarm, Measurement
from rclpy.clock import Clock, ClockType

from phfdi_base import live_view
from phfdi_base.errors import UserError
from phfdi_base.ros.graph_node import NodeStartError, ParamSpec, main, to_time
from phfdi_base.stamps import finite_or, seconds_to_ns, time_ns, time_on_grid_s, valid_stamp
from phfdi_base.topics import CONTROLLER, MEASUREMENT

from .alarm_messages import severity_of
from .channel_map import load_channel_map
from .config import Calibration, load_default_calibration, setting_specs, settings_from_values
from .detector import StreamingDetector
from .inputs import INPUT_PROBLEMS
from .map_inputs import MappedInputs
from .node_base import MONITOR_PARAMS, STATE_OF_LEVEL, DetectorNodeBase, next_multiple
from .reference import KnownStart

PARAMS = (
    ParamSpec("calibration", "", "calibration file (.yaml/.json) from phfdi calibrate; '' takes the one shipped "
                                 "for the scenario"),
    # the detector settings exposed to users, from their one declaration (wavelet_fdi.config.DetectorSettings)
    *(ParamSpec(s.name, list(s.default) if s.is_list else s.default, s.help, range=s.range)
      for s in setting_specs(exposed_only=True)),
    ParamSpec("isolate", True, "name the fault class (and estimate its parameter) after an alarm"),
    ParamSpec("loop", "ph", "name of the monitored loop in /fault_alarm"),
    ParamSpec("pairing_window", 1, "measurements that must wait behind a sample before its controller output "
                                   "is given up on a silent output topic (then NaN commands)", range=(1, 1000)),
    ParamSpec("pairing_timeout_s", 10.0, "silence of the controller-output topic (s, wall) after which waiting "
                                        "samples go on without their output (longer than a DDS repair)",
              range=(0.0, 60.0)),
    ParamSpec("heartbeat_period_s", 60.0, "publish the state on /fault_alarm every this many s of simulated "
                                          "time; 0: only on changes", range=(0.0, 1e9), runtime=True),
    ParamSpec("diagnostics_period_s", 60.0, "publish /diagnostics every this many s of simulated time (and "
                                            "whenever an input problem is counted); 0: only then",
              range=(0.0, 1e9), runtime=True),
    # wall time, not simulated: garbage stamps move the simulated clock, they cannot move this one
    ParamSpec("input_problem_period_s", 1.0, "input problems on /fault_alarm at most once per this many s of "
                                             "wall time (one message with the counts; state changes always)",
              range=(0.05, 3600.0), runtime=True),
    *MONITOR_PARAMS,
    ParamSpec("foxglove_port", 0, "serve what this detector sees (inputs, residuals, statistic ratios, alarm "
                                  "state) over the Foxglove WebSocket protocol on this port; 0: no live view",
              range=(0, 65535)),
    ParamSpec("foxglove_host", live_view.LOOPBACK, "address the live view listens on (default: this machine only)"),
    ParamSpec("channel_map_file", "", "YAML channel map: the topic, type and field of each signal the detector "
              "pairs ('' = /plant/measurement and /controller/output; docs/ros_graph.md)"),
    ParamSpec("silent_after_s", 10.0, "channel map: wall time after which a mapped topic that delivers nothing is "
              "reported", range=(0.1, 3600.0)),
)

#: the signals the detector pairs, as channels of a channel map (the core's input names)
PHYSICS_CHANNELS = ("ph_measured", "level_measured_cm", "valve_command_pct", "level_controller_output_pct",
                    "ph_setpoint")
#: wall time between a channel map's checks of waits and silent topics, and between its /diagnostics reports
MAP_TICK_S, MAP_REPORT_S = 0.2, 1.0

#: diagnostics counters that mean bad input (a growth is reported at once)
PROBLEM_COUNTERS = (*INPUT_PROBLEMS, "commands_missing", "late_controller_outputs", "unpaired_controller_outputs",
                    "core_errors")
LAG_WINDOW = 4096  # samples whose processing lag the statistics cover


class Pairing:
    """Pairs measurements with the controller output of the same stamp, in measurement arrival order.

    Rows: (stamp_ns, ph, level_cm, (ph_output_pct, level_output_pct, ph_setpoint) or None, arrival).
    Each topic arrives in its writer's order, but the two topics are not ordered with each other
    (measured: outputs overtaken by the next measurement in a lock-step run; in full-speed replays
    one topic stalled for 2.7 to 5.2 s in 5 of 9 runs, about 1100 samples, while the other flowed:
    lost shared-memory packets wait for the reliable writer's repair). So a measurement leaves with
    its output, or without it (NaN commands) once

    * the last output received has a later stamp (its own will not come: one writer, in order; the last,
      not the newest ever, so that one stray output stamped in the future does not give up every
      measurement after it), or
    * two of the next measurements behind it are older (a stray stamped in the future at the head of the
      queue; one writer's measurements only go forward); if it also jumps ahead of the stream by more than
      1.5 steps it is dropped and counted (``stray_measurements``), never passed on to become the detector's
      clock (a row that jumps ahead so waits for two measurements behind it even when its output has come: a
      stray output can carry the same future stamp), or
    * ``window`` later measurements have arrived and no output has come for ``timeout_s``
      (wall, monotonic clock) since it arrived: a silent controller-output topic, or
    * ``MAX_PENDING`` measurements wait (memory and delay stay bounded whatever the stamps).

    Bad stamps are not judged here: the core does (duplicates, order, gaps).
    """

    EARLY_LIMIT = 4096  # outputs kept waiting for their measurement
    MAX_PENDING = 4096

    def __init__(self, window: int = 1, timeout_s: float = 0.0) -> None:
        self.window = window
        self.timeout_s = timeout_s
        self.pending: deque[list] = deque()
        self.early: dict[int, tuple] = {}
        self.missed: deque[int] = deque(maxlen=256)  # stamps passed on without an output (late or unpaired)
        self.last_passed_ns: int | None = None  # the newest stamp passed on (_passed)
        self.last_step_ns: int | None = None  # the step to it from the one before
        self.last_output_ns = -math.inf  # stamp of the last output received
        self.last_output_at = -math.inf  # wall time of the last output received
        self.max_wait_s = 0.0  # longest a measurement waited for its output (wall)
        self.counts = {"measurements": 0, "controller_outputs": 0, "commands_missing": 0,
                       "late_controller_outputs": 0, "unpaired_controller_outputs": 0, "stray_measurements": 0,
                       "invalid_stamps": 0}

    def measurement(self, ns: int, ph: float, level_cm: float, arrival: float) -> list[tuple]:
        self.counts["measurements"] += 1
        self.pending.append([ns, ph, level_cm, self.early.pop(ns, None), arrival])
        return self._ready(arrival)

    def output(self, ns: int, values: tuple, now: float) -> list[tuple]:
        self.counts["controller_outputs"] += 1
        self.last_output_at = now
        self.last_output_ns = ns
        for row in reversed(self.pending):
            if row[0] == ns and row[3] is None:
                row[3] = values
                return self._ready(now)
        if ns in self.missed:
            self.counts["late_controller_outputs"] += 1
        else:
            self.early[ns] = values
            if len(self.early) > self.EARLY_LIMIT:
                del self.early[next(iter(self.early))]
                self.counts["unpaired_controller_outputs"] += 1
        return self._ready(now)

    def expire(self, now: float) -> list[tuple]:
        """Samples whose controller output is given up by now."""
        return self._ready(now)

    def _given_up(self, row: list, now: float) -> bool:
        pending = self.pending
        return (row[0] < self.last_output_ns or len(pending) > self.MAX_PENDING
                or (len(pending) > self.window and now - max(row[4], self.last_output_at) >= self.timeout_s)
                or (len(pending) > 2 and sum(r[0] <= row[0] for r in islice(pending, 1, 9)) >= 2))

    def _jumps(self, row: list) -> bool:
        """The row's stamp is ahead of the last one passed on by more than 1.5 of the last step."""
        return self.last_step_ns is not None and row[0] - self.last_passed_ns > 1.5 * self.last_step_ns

    def _held(self, row: list, now: float) -> bool:
        """A row that jumps ahead waits, even with its output, until two later measurements can say whether it
        is a stray: a stray output with the stray measurement's future stamp would else pair with it and pass
        it on (seen once in CI, six times in one run, when the two topics' strays arrived interleaved). Costs
        two samples of delay at a real gap; a stream that pauses after one releases it after ``timeout_s``."""
        return (self._jumps(row) and len(self.pending) < 3 and len(self.pending) <= self.MAX_PENDING
                and now - row[4] < self.timeout_s)

    def _stray(self, row: list) -> bool:
        """The head measurement is a stray from the future: it jumps ahead of the last one passed on by more than
        1.5 of the last step, and two of the next ones are strictly older (one writer's stamps only go forward).
        Passed on, its stamp would become the detector's clock: the jump reads as a gap and the time after it as
        a reset, each restarting the warm-up (600 samples without detection). The jump condition keeps a real
        next sample that strays from the past happen to follow."""
        if not self._jumps(row):
            return False
        return len(self.pending) > 2 and sum(r[0] < row[0] for r in islice(self.pending, 1, 9)) >= 2

    def _passed(self, ns: int) -> None:
        """Follow the stream's time: the last stamp passed on and the step to it (for :meth:`_stray`)."""
        if self.last_passed_ns is not None and ns > self.last_passed_ns:
            self.last_step_ns = ns - self.last_passed_ns
        if self.last_passed_ns is None or ns > self.last_passed_ns:
            self.last_passed_ns = ns

    def _ready(self, now: float, all_: bool = False) -> list[tuple]:
        out = []
        pending = self.pending
        while pending and (all_ or pending[0][3] is not None or self._given_up(pending[0], now)):
            if not all_ and self._held(pending[0], now):
                break
            if not all_ and self._stray(pending[0]):
                pending.popleft()
                self.counts["stray_measurements"] += 1
                continue
            row = pending.popleft()
            self._passed(row[0])
            if now < math.inf:
                self.max_wait_s = max(self.max_wait_s, now - row[4])
            if row[3] is None:
                self.counts["commands_missing"] += 1
                self.missed.append(row[0])
            out.append(tuple(row))
        return out

    def drain(self) -> list[tuple]:
        """Everything still waiting (the end of a stream)."""
        return self._ready(math.inf, all_=True)


class LagStats:
    """Processing lag (s, wall) of the last samples: arrival of a measurement to the core's result."""

    def __init__(self) -> None:
        self.lags: deque[float] = deque(maxlen=LAG_WINDOW)
        self.calls = 0
        self.samples = 0
        self.core_s = 0.0
        self.max_lag_s = 0.0
        self.max_queue = 0
        self.max_call_samples = 0

    def add(self, arrivals: list[float], done: float, core_s: float, queued: int) -> None:
        lags = [done - a for a in arrivals]
        self.lags.extend(lags)
        self.calls += 1
        self.samples += len(arrivals)
        self.core_s += core_s
        self.max_lag_s = max(self.max_lag_s, max(lags, default=0.0))
        self.max_queue = max(self.max_queue, queued)
        self.max_call_samples = max(self.max_call_samples, len(arrivals))

    def summary(self) -> dict:
        q = np.percentile(np.asarray(self.lags), [50, 99]) if self.lags else [math.nan, math.nan]
        return {"lag_median_s": float(q[0]), "lag_p99_s": float(q[1]), "lag_max_s": self.max_lag_s,
                "core_calls": self.calls, "samples_per_call": self.samples / self.calls if self.calls else 0.0,
                "max_samples_per_call": self.max_call_samples, "max_queue": self.max_queue,
                "core_s_per_sample": self.core_s / self.samples if self.samples else math.nan}


class DetectorNode(DetectorNodeBase):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__()
        self.core, self.calibration_source = self._build_core()
        self.pairing = Pairing(self.param("pairing_window"), self.param("pairing_timeout_s"))
        self.lag = LagStats()
        self._heartbeat_s = self.param("heartbeat_period_s")
        self._diagnostics_s = self.param("diagnostics_period_s")
        self._input_period_s = self.param("input_problem_period_s")
        self.open_alarm_output()
        self.pub_diag = self.diagnostics_publisher()
        self.inputs: MappedInputs | None = None
        if self.param("channel_map_file"):
            self._subscribe_map(self.param("channel_map_file"))
        else:
            self.data_subscription(Measurement, MEASUREMENT.name, self._on_measurement)
            self.data_subscription(ControllerOutput, CONTROLLER.name, self._on_output)
        # the worker (DetectorNodeBase) is the only thread that touches the core and the two publishers
        self._core_state = "starting"
        self._last_heartbeat_t = -math.inf
        self._last_diag_t = -math.inf
        self._reported_problems: dict[str, int] = {}
        self._last_ns = 0
        # input problems not yet on /fault_alarm (rate limit): how many, their distinct texts, the last one's time
        self._inputs_held = 0
        self._inputs_texts: list[str] = []
        self._inputs_t = math.nan
        self._inputs_sent_at = -math.inf  # wall (monotonic) time of the last input-problem message
        self._resets_seen = 0  # window resets (gaps, clock jumps) the heartbeat schedule has followed
        self._open_monitor()
        self.start_worker()
        self.start_barrier()

    def _open_monitor(self) -> None:
        """The live-view outputs asked for: the /detector/monitor topic and/or a Foxglove server of its own."""
        self.open_monitor_output()
        self.live: live_view.LiveView | None = None
        self.live_errors = 0  # messages the live view could not send: counted, logged, never fatal
        if self.param("foxglove_port"):
            try:
                self.live = live_view.LiveView(self.param("foxglove_port"), self.param("foxglove_host"),
                                               name="phfdi detector",
                                               topics=(live_view.MEASUREMENT, live_view.CONTROLLER,
                                                       live_view.MONITOR, live_view.ALARM))
            except UserError as exc:
                raise NodeStartError(str(exc)) from None
            self.get_logger().info(f"live view (Foxglove): {self.live.url}")

    def _subscribe_map(self, path: str) -> None:
        """The plant's own topics, as the channel map names them, aligned onto the scenario's sample grid."""
        try:
            cmap = load_channel_map(path, PHYSICS_CHANNELS)
        except UserError as exc:
            raise NodeStartError(f"parameter channel_map_file = {path!r}: {exc}") from None
        self.inputs = MappedInputs(self, cmap, self.dt_ns, self._on_mapped, self.param("silent_after_s"))
        steady = Clock(clock_type=ClockType.STEADY_TIME)  # waits are wall time, also under use_sim_time
        self.create_timer(MAP_TICK_S, self.inputs.tick, clock=steady)
        self.create_timer(MAP_REPORT_S, self._report_map, clock=steady)
        self._map_problems_said = 0

    def _on_mapped(self, samples: list[tuple[float, np.ndarray]]) -> None:
        """Aligned samples (s from the grid's first, values in PHYSICS_CHANNELS order) as paired rows."""
        now = time.monotonic()
        self.enqueue([(seconds_to_ns(t_s), float(x[0]), float(x[1]), (float(x[2]), float(x[3]), float(x[4])), now)
                      for t_s, x in samples])

    def _report_map(self) -> None:
        """The channel map's status on /diagnostics (periodically; at once when a new problem is seen)."""
        assert self.inputs is not None
        array = DiagnosticArray(status=[self.inputs.status()])
        array.header.stamp = self.get_clock().now().to_msg()
        self.pub_diag.publish(array)  # executor thread (the worker publishes its own arrays)
        self._map_problems_said = len(self.inputs.problems)

    # ---- parameters -----------------------------------------------------------------------
    def _build_core(self):
        try:
            settings = settings_from_values({s.name: self.param(s.name) for s in setting_specs(exposed_only=True)})
            path = self.param("calibration")
            if path:
                cal, source = Calibration.load(path), path
            else:
                base = self.part.base_scenario or self.spec.name  # the scenario the shipped calibrations name
                cal = load_default_calibration(base, settings)
                source = f"shipped {base}_{settings.wavelet}_L{settings.level}"
            known = KnownStart(self.part.start, self.part.plant_model)  # solved once by the launcher
            core = StreamingDetector(self.spec, cal, settings, isolate=self.param("isolate"), known=known)
        except UserError as exc:
            raise NodeStartError(str(exc)) from None
        return core, source

    def apply_parameters(self, params) -> None:
        # runtime changes take effect at the next sample the worker processes
        self._heartbeat_s = self.param("heartbeat_period_s")
        self._diagnostics_s = self.param("diagnostics_period_s")
        self._input_period_s = self.param("input_problem_period_s")

    # ---- executor thread: queue only ------------------------------------------------------
    def _on_measurement(self, msg: Measurement) -> None:
        if not valid_stamp(msg.stamp.sec, msg.stamp.nanosec):  # garbage would read as a clock reset
            self.pairing.counts["invalid_stamps"] += 1  # reported with the pairing counts on /diagnostics
            return
        self.enqueue(self.pairing.measurement(time_ns(msg.stamp), msg.ph, msg.level_cm, time.monotonic()))

    def _on_output(self, msg: ControllerOutput) -> None:
        if not valid_stamp(msg.stamp.sec, msg.stamp.nanosec):  # garbage would read as a clock reset
            self.pairing.counts["invalid_stamps"] += 1  # reported with the pairing counts on /diagnostics
            return
        self.enqueue(self.pairing.output(time_ns(msg.stamp),
                                          (msg.ph_output_pct, msg.level_output_pct, msg.ph_setpoint),
                                          time.monotonic()))

    def after_spin(self) -> None:
        if self.inputs is not None and len(self.inputs.problems) > self._map_problems_said:
            self._report_map()
        if self.pairing.pending:
            self.enqueue(self.pairing.expire(time.monotonic()))
        if self._inputs_held and self._inputs_due():  # held-back input problems go out even if nothing follows
            self.poke()

    def received(self) -> int:
        counts = self.pairing.counts
        return counts["measurements"] + counts["controller_outputs"] + (self.inputs.received if self.inputs else 0)

    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers hold; a mapped node then hands every sample begun to the core."""
        super().drain(executor, idle_s, limit_s)
        if self.inputs is not None:
            self.inputs.flush()
            self._report_map()

    # ---- worker thread: the core and the publishers ----------------------------------------

    def _chunk(self, rows: list[tuple]) -> dict[str, np.ndarray]:
        nan = (math.nan, math.nan, math.nan)
        t = [time_on_grid_s(r[0], self.dt_ns, self.dt_s) for r in rows]
        cmds = [r[3] or nan for r in rows]
        return {"time_s": np.array(t), "ph_measured": np.array([r[1] for r in rows], dtype=float),
                "level_measured_cm": np.array([r[2] for r in rows], dtype=float),
                "valve_command_pct": np.array([c[0] for c in cmds], dtype=float),
                "level_controller_output_pct": np.array([c[1] for c in cmds], dtype=float),
                "ph_setpoint": np.array([c[2] for c in cmds], dtype=float)}

    def process(self, rows: list[tuple], flush: bool = False) -> None:
        before = self._state
        if not rows and not flush:  # poked: only the input problems held back by the rate limit
            if self._inputs_held and self._inputs_due():
                self._publish_inputs(before, self._problems())
            return
        t0 = time.perf_counter()
        try:
            events = self.core.process(self._chunk(rows)) if rows else []
            if flush:
                events += self.core.flush()
        except Exception:  # noqa: BLE001 - a bug must not take the observer down: report, start over
            self._core_failed(rows)
            return
        core_s = time.perf_counter() - t0
        self.lag.add([r[4] for r in rows], time.monotonic(), core_s, len(rows))
        self._last_ns = max([self._last_ns] + [r[0] for r in rows if r[0] > 0])
        status = self.core.status()
        state = before
        published = False
        for ev in events:
            if ev.kind == "input":  # rate-limited below
                self._hold_input(ev)
            else:  # alarm, diagnosis, cleared: always
                state = self._publish_event(ev, state)
                published = True
        self._state = STATE_OF_LEVEL[status["level"]]
        problems = self._problems()
        # an input problem that changes the alarm state (detection held, resumed) goes out at once
        if self._inputs_held and (self._state != before or self._inputs_due()):
            state = self._publish_inputs(state, problems)
            published = True
        core_state = status["state"]
        changed = core_state != self._core_state and not published
        self._core_state = core_state
        t_now = self._t_last()
        self._follow_clock(t_now, problems)
        self._live_outputs(rows, t_now)
        if changed or (self._heartbeat_s > 0 and t_now >= next_multiple(self._last_heartbeat_t, self._heartbeat_s)):
            self._publish_heartbeat(status, t_now, changed)
        grew = any(v > self._reported_problems.get(k, 0) for k, v in problems.items())
        if grew or events or changed or (self._diagnostics_s > 0 and t_now >= next_multiple(self._last_diag_t,
                                                                                              self._diagnostics_s)):
            self._publish_diagnostics(t_now, problems, grew)

    def _follow_clock(self, t_now: float, problems: dict[str, int]) -> None:
        """After a window reset (a gap, a clock jump) or a clock that went back, the periodic messages go on
        from the new time without one of their own: else a stray far-future stamp would stop heartbeats until
        the real clock caught up with it, and every jump forward and back would bring one."""
        resets = problems.get("gap_resets", 0) + problems.get("time_resets", 0)
        if resets != self._resets_seen or t_now < self._last_heartbeat_t:
            self._last_heartbeat_t = t_now
        if resets != self._resets_seen or t_now < self._last_diag_t:
            self._last_diag_t = t_now
        self._resets_seen = resets

    # ---- live view ---------------------------------------------------------------------------
    def _live_outputs(self, rows: list[tuple], t_now: float) -> None:
        """The inputs of these rows to the live view, and the monitor sample when it is due (worker thread)."""
        if self.live is not None:
            for ns, ph, level_cm, outputs, _ in rows:
                t_s = ns * 1e-9
                self._to_live(live_view.MEASUREMENT, {"time_s": t_s, "ph": live_view.finite(ph),
                                                      "level_cm": live_view.finite(level_cm)}, ns)
                if outputs is not None:  # (ph_output_pct, level_output_pct, ph_setpoint), as paired
                    self._to_live(live_view.CONTROLLER, {
                        "time_s": t_s, "ph_setpoint": live_view.finite(outputs[2]),
                        "ph_output_pct": live_view.finite(outputs[0]), "level_setpoint_cm": None,
                        "level_output_pct": live_view.finite(outputs[1])}, ns)
        if (self.pub_monitor is None and self.live is None) or not rows:
            return
        if not self.monitor_due(t_now):
            return
        t_s, values = self.core.monitor()
        if not math.isfinite(t_s):
            return
        ns = seconds_to_ns(t_s)
        self.publish_monitor(t_s, values, self._ros_time(ns))
        if self.live is not None:
            self._to_live(live_view.MONITOR, live_view.monitor(t_s, values), ns)

    def _to_live(self, topic: str, message: dict, ns: int) -> None:
        """One message to the detector's own live view; a failure costs the view that message, never detection
        (this runs on the worker thread, which must not die)."""
        assert self.live is not None
        try:
            self.live.log(topic, message, ns)
        except Exception as exc:  # noqa: BLE001
            self.live_errors += 1
            if self.live_errors == 1 or self.live_errors % 1000 == 0:
                self.get_logger().error(f"live view: {topic} message not sent ({self.live_errors} so far): "
                                        f"{type(exc).__name__}: {exc}")

    def publish_alarm(self, msg: FaultAlarm, kind: str, time_s: float, alarm: dict | None,
                      report: bool = True) -> None:
        super().publish_alarm(msg, kind, time_s, alarm, report)
        if self.live is not None:
            self._to_live(live_view.ALARM, live_view.fault_alarm(msg), time_ns(msg.stamp))

    # ---- input problems on /fault_alarm: rate-limited -----------------------------------
    def _inputs_due(self) -> bool:
        return time.monotonic() - self._inputs_sent_at >= self._input_period_s

    def _hold_input(self, ev) -> None:
        self._inputs_held += 1
        if ev.message not in self._inputs_texts and len(self._inputs_texts) < 3:  # bounded text
            self._inputs_texts.append(ev.message)
        self._inputs_t = ev.time_s

    def _publish_inputs(self, state: int, problems: dict[str, int]) -> int:
        """One /fault_alarm message for the input problems held since the last one, with the counts so far."""
        n = self._inputs_held
        text = "; ".join(self._inputs_texts)
        if n > len(self._inputs_texts):
            text += f" ({n} input problem events since the last report)"
        counted = ", ".join(f"{k} {v}" for k, v in problems.items() if v)
        if counted:
            text += f"; input counts so far: {counted}"
        if state != FaultAlarm.ALARM:  # an input problem does not hide an active alarm
            state = FaultAlarm.WARN
        msg = FaultAlarm(loop=self._loop, state=state, message=text)
        msg.stamp = self._ros_time(finite_or(self._inputs_t, self._last_ns))
        self._alarm_fields(msg, None)
        self.publish_alarm(msg, "input", self._inputs_t, None)
        self._inputs_held, self._inputs_texts = 0, []
        self._inputs_sent_at = time.monotonic()
        return state

    def _ros_time(self, ns: int):
        """A core time (ns) as a ROS time on the plant's clock: with a channel map the grid's origin (the plant's
        first stamp) is added, as the learned detector does; else simulated time as it is."""
        origin = self.inputs.aligner.origin_ns if self.inputs is not None else None
        return to_time(ns + (origin or 0))

    def _t_last(self) -> float:
        """Time (s) of the last sample the core took; else of the newest stamp received."""
        hist = self.core.history
        t = hist.read(hist.end - 1, hist.end, "t")
        return float(t[0]) if len(t) and math.isfinite(t[0]) else self._last_ns * 1e-9

    def _core_failed(self, rows: list[tuple]) -> None:
        self.core_errors += 1
        self.get_logger().error(f"detector core failed on {len(rows)} samples; starting over (warm-up):\n"
                                + traceback.format_exc())
        try:
            self.core, _ = self._build_core()
        except NodeStartError as exc:  # the calibration file went away meanwhile: keep the old core
            self.get_logger().error(f"cannot start over: {exc}")
        self._state = FaultAlarm.WARN
        self._publish_diagnostics(self._last_ns * 1e-9, self._problems(), True)

    # ---- messages -------------------------------------------------------------------------
    def _alarm_fields(self, msg: FaultAlarm, alarm: dict | None) -> None:
        if not alarm:
            msg.severity = math.nan
            msg.wavelet_level = -1
            return
        msg.fault_class = alarm["fault_class"]
        msg.confidence = float(alarm["confidence"])
        msg.onset_time = self._ros_time(seconds_to_ns(alarm["onset_time"]))
        msg.detection_time = self._ros_time(seconds_to_ns(alarm["detection_time"]))
        msg.severity, msg.severity_unit = severity_of(alarm)
        band = alarm.get("dominant_level") or ""
        msg.wavelet_level = int(band[1:]) if band.startswith("D") else 0 if band.startswith("A") else -1

    def _publish_event(self, ev, state: int) -> int:
        """Publish one core event on /fault_alarm; returns the state after it."""
        if ev.kind in ("alarm", "diagnosis"):
            state = FaultAlarm.ALARM
        elif ev.kind == "cleared":
            state = FaultAlarm.OK
        elif state != FaultAlarm.ALARM:  # an input problem does not hide an active alarm
            state = STATE_OF_LEVEL[ev.level]
        msg = FaultAlarm(loop=self._loop, state=state, message=ev.message)
        msg.stamp = self._ros_time(finite_or(ev.time_s, self._last_ns))
        self._alarm_fields(msg, ev.alarm)
        if ev.alarm:
            msg.statistic, msg.threshold = float(ev.alarm["statistic_value"]), float(ev.alarm["threshold"])
            msg.statistic_name = str(ev.alarm["statistic"])
        self.publish_alarm(msg, ev.kind, ev.time_s, ev.alarm)
        return state

    def _publish_heartbeat(self, status: dict, t_s: float, changed: bool) -> None:
        state = STATE_OF_LEVEL[status["level"]]
        text = (f"{status['state']}: worst statistic {status['worst_statistic']} "
                f"{status['worst_statistic_value']:.1f} of threshold {status['worst_threshold']:.1f}; "
                f"{status['samples_processed']} samples")
        msg = FaultAlarm(loop=self._loop, state=state, message=("state now " if changed else "") + text,
                         statistic=status["worst_statistic_value"], threshold=status["worst_threshold"],
                         statistic_name=str(status["worst_statistic"]))
        msg.stamp = self._ros_time(finite_or(t_s, self._last_ns))
        self._alarm_fields(msg, status["alarm"])
        self.publish_alarm(msg, "state", t_s, status["alarm"], report=changed)
        self._last_heartbeat_t = t_s

    def _problems(self) -> dict[str, int]:
        d = self.core.diagnostics()
        d.update(self.pairing.counts)
        d["core_errors"] = self.core_errors
        return {k: int(d[k]) for k in PROBLEM_COUNTERS if k in d}

    def _publish_diagnostics(self, t_s: float, problems: dict[str, int], grew: bool) -> None:
        d = self.core.diagnostics()
        d.update(self.pairing.counts)
        d["pairing_wait_max_s"] = self.pairing.max_wait_s
        d.update(self.lag.summary())
        d.update(core_errors=self.core_errors, calibration=self.calibration_source)
        counted = {k: v for k, v in problems.items() if v}
        stale = bool(d.get("command_stale"))
        level = DiagnosticStatus.WARN if grew or stale or d.get("sample_rate_mismatch") else DiagnosticStatus.OK
        if self.core_errors and grew:
            level = DiagnosticStatus.ERROR
        text = ", ".join(f"{k} {v}" for k, v in counted.items()) if counted else "no input problem so far"
        held = int(problems.get("nonfinite_ph", 0)) + int(problems.get("out_of_range_ph", 0))
        d["ph_samples_held"] = held
        if held:
            text = f"{held} pH samples missing or out of range: held (no residual; statistics not fed); " + text
        if stale:
            text = "valve command missing: detection held; " + text
        inputs = DiagnosticStatus(level=level, name=f"{self.get_name()}: {self._loop} loop inputs",
                                  hardware_id=f"{self._loop}_loop", message=text,
                                  values=[KeyValue(key=k, value=_text(v)) for k, v in d.items()])
        state = DiagnosticStatus(level={FaultAlarm.OK: DiagnosticStatus.OK, FaultAlarm.WARN: DiagnosticStatus.WARN,
                                        FaultAlarm.ALARM: DiagnosticStatus.ERROR}[self._state],
                                 name=f"{self.get_name()}: {self._loop} loop state", hardware_id=f"{self._loop}_loop",
                                 message=f"{d['state']}; {d['alarms']} alarm(s); calibration {self.calibration_source}")
        array = DiagnosticArray(status=[inputs, state])
        array.header.stamp = self._ros_time(finite_or(t_s, self._last_ns))
        self.pub_diag.publish(array)
        self._last_diag_t = t_s
        self._reported_problems = problems

    # ---- the end ---------------------------------------------------------------------------
    def close(self) -> None:
        """Process everything queued, run pending isolations, publish, then deliver and report."""
        self.enqueue(self.pairing.drain())
        super().close()

    def finish(self) -> None:
        self.process([], flush=True)
        if self._inputs_held:  # the last input problems, whatever the rate limit
            self._publish_inputs(self._state, self._problems())
        self._publish_heartbeat(self.core.status(), self._t_last(), False)
        self._publish_diagnostics(self._t_last(), self._problems(), False)
        if self.live is not None:
            self.live.stop()

    def done_report(self) -> dict:
        alarms = [{"alarm_id": a.alarm_id, **a.summary()} for a in self.core.alarms]
        report = {"samples": self.core.samples_processed, "alarms": alarms,
                  "diagnostics": self.core.diagnostics() | self.pairing.counts,
                  "lag": self.lag.summary() | {"pairing_wait_max_s": self.pairing.max_wait_s},
                  "calibration": self.calibration_source}
        if self.inputs is not None:
            report["channel_map"] = {**self.inputs.report(), "file": self.param("channel_map_file")}
        return report


def _text(v) -> str:
    return repr(v) if isinstance(v, float) else str(v)


def run() -> int:
    return main(DetectorNode, "wavelet_fdi.node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
