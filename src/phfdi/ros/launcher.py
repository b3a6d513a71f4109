"""Start the graph as processes and stop it cleanly, whatever happens (no rclpy here).

A graph is a list of :class:`NodeSpec` (the detector is one more, an observer). Each
node runs as ``python -m <module> --ros-args --params-file <file>`` in a
process group of its own, on a ROS domain reserved for this launch, with
LOCALHOST discovery. The plant prints JSON lines (connected, progress, done)
that the launcher follows.

Stopping, always in this order so that nothing published is lost: the plant
(no new samples), then the loop nodes (they deliver what they published to
their reliable readers before exiting), then the observers (the detector
processes what it holds and publishes its last alarms), then the recorder
(takes what its readers hold and finishes the bag). A node that does not stop within
``stop_timeout_s`` is killed. Afterwards: no process of the graph is left
(each node asks the kernel for SIGTERM when the launcher dies: ``PHFDI_LAUNCHER_PID``,
:func:`phfdi_base.ros.run.main`), a killed node's
Fast DDS shared-memory files are removed (``fastdds shm clean``), and a bag
whose recorder could not finish it is recovered in place.

When things go wrong (docs/ros_graph.md, "When things go wrong"):

- A bag another process is recording (its writer's lock) stops the launch
  before any node starts (:func:`phfdi.bagio.check_not_recording`); should two
  launches pass that check at once, the second recorder refuses the file and
  its launcher fails without touching it (the launcher finishes or recovers
  only the files its own recorder reported taking).
- The recorder's write failure (a full disk) is named in one line
  (``recorder: cannot write bags/x.mcap: No space left on device``), the graph
  stopped; the in-place recovery writes through a staged file, so a disk still
  full leaves the unfinished bag as it was (readable up to its last complete
  chunk), never a 0-byte or half-written one.
- Watchdog: once the graph is connected, the clock node reports progress at
  least every ``progress_period_s`` (it says so in its ``connected`` event);
  no progress for ``watchdog_s`` (at least :data:`WATCHDOG_SAMPLE_PERIODS`
  sample periods of wall time at the current pace) stops the graph the
  SIGTERM way and names the stall. Stopping sends SIGCONT after SIGTERM, so a
  stopped (SIGSTOP) node ends cleanly too.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import yaml

from phfdi import bagio
from phfdi_base.errors import UserError
from phfdi_base.parts import NodePart, write_part
from phfdi_base.ros.env import LAUNCHER_PID_VAR, graph_env, reserve_domain_id
from phfdi_base.topics import CONTROLLER as CONTROLLER_OUTPUT
from phfdi_base.topics import (
    CONTROLLERS,
    DETECTOR,
    LIVE_VIEW,
    MEASUREMENT,
    PLANT,
    PLANT_STATE,
    RECORDER,
    VALVE,
    VALVE_STATE,
)

from .parts import make_part

LOOP, OBSERVER = "loop", "observer"

#: default of ``Launcher(watchdog_s=...)`` and ``phfdi launch --watchdog-s``: seconds of wall time without progress
#: after which a connected graph counts as stalled
WATCHDOG_S = 30.0
#: the watchdog never fires sooner than this many sample periods of wall time (dt / pace in paced runs)
WATCHDOG_SAMPLE_PERIODS = 5.0


@dataclass
class NodeSpec:
    """One node of a graph: its name, the module it runs and its parameters."""

    name: str
    module: str
    params: dict = field(default_factory=dict)
    role: str = LOOP  # loop: in the lock-step ring; observer: only listens (stopped last)
    #: the resolved scenario and starting point (written once for the graph, handed over as ``part``)
    part: NodePart | None = None


def loop_graph(scenario: str = "paper", fault: str | None = None, onset_s: float | None = None,
               overrides: list[str] = (), record: str | Path | None = None, pace: float = 0.0,
               executor: str = "events", connect_timeout_s: float = 60.0,
               extra: list[NodeSpec] = (), detector: dict | None = None,
               split_after_s: float = 0.0, overwrite: bool = False, live: dict | None = None) -> list[NodeSpec]:
    """The loop graph: plant, valve, controllers (+ recorder, a new file every ``split_after_s`` of
    simulated time if > 0, replacing an existing ``record`` file only if ``overwrite``, + the fault detector
    with these parameters, + the live view's bridge with these (port, host), + extra nodes)."""
    if Path(scenario).suffix in (".yaml", ".yml"):
        scenario = str(Path(scenario).resolve())
    common = {"scenario": scenario, "fault": fault or "", "fault_onset_s": -1.0 if onset_s is None else float(onset_s),
              "executor": executor, "connect_timeout_s": float(connect_timeout_s)}
    if overrides:
        common["overrides"] = list(overrides)
    nodes = [NodeSpec(CONTROLLERS, "pi_controllers.node"), NodeSpec(VALVE, "valve_actuator.node"),
             NodeSpec(PLANT, "ph_plant_sim.node", {"pace": float(pace)})]
    part = make_part(scenario, fault or None, list(overrides), onset_s)  # resolved and validated once for every node
    if record is not None:
        from .recorder import graph_run_metadata

        rec = {"path": str(Path(record).resolve()), "run_metadata": graph_run_metadata(part.scenario),
               "overwrite": bool(overwrite)}
        if split_after_s > 0:
            rec["split_after_s"] = float(split_after_s)
        nodes.append(NodeSpec(RECORDER, "phfdi.ros.recorder", rec, OBSERVER))
    if detector is not None:
        detector = with_default_reference(detector, part.scenario)
        # the live view plots the detector's residuals and statistics: it asks the detector to publish them
        nodes.append(detector_spec({**detector, "monitor_topic": True} if live is not None else detector))
    if live is not None:
        nodes.append(live_view_spec(live))
    nodes += list(extra)
    names = [n.name for n in nodes]
    for n in nodes:
        n.params = {**common, "graph_nodes": names, **n.params}
    for n in nodes:
        n.part = part
    return nodes


#: parameters of the physics detector's own node (wavelet_fdi.node, retired on 2026-12-07: one detector node, issue
#: 37), and what does their work now
RETIRED_NODE_PARAMS = {
    "calibration": "a physics reference of your calibration: phfdi calibrate --out REF.json, then "
                   "reference=REF.json",
    "isolate": "the physics reference always names the fault",
    "level": "a setting of phfdi calibrate (its reference file carries it)",
    "wavelet": "a setting of phfdi calibrate (its reference file carries it)",
    "arl0_samples": "a setting of phfdi calibrate (its reference file carries it)",
    "channels": "a reference of the channels you want (phfdi calibrate) or channel_map_file",
    "pairing_window": "the channel map's align rule and max_wait_s (channel_map_file)",
    "pairing_timeout_s": "the channel map's align rule and max_wait_s (channel_map_file)",
    "foxglove_host": "phfdi launch --foxglove PORT --foxglove-host ADDRESS, or python -m phfdi.ros.live_bridge",
    "foxglove_port": "phfdi launch --foxglove PORT, or python -m phfdi.ros.live_bridge",
}


def with_default_reference(params: dict, spec) -> dict:
    """The loop graph's detector: the multichannel detector with the physics reference shipped for the scenario
    (``<scenario>_physics``; its model runs the launch's own plant, ``reference_physics.follow_scenario``) unless
    the parameters name a reference. A parameter of the retired physics detector node is refused in one line that
    says what does its work now (:data:`RETIRED_NODE_PARAMS`)."""
    retired = [name for name in params if name in RETIRED_NODE_PARAMS]
    if retired:
        name = retired[0]
        raise UserError(f"detector parameter {name!r} belonged to the physics detector's own node, retired on "
                        f"2026-12-07 (one detector node: python -m wavelet_fdi.learned_node --help); instead: "
                        f"{RETIRED_NODE_PARAMS[name]}")
    if "reference" in params:
        return params
    from phfdi.replay import shipped_physics_name

    return {"loop": "ph", **params, "reference": shipped_physics_name(spec)}  # the loop's name, as before


def detector_spec(params: dict) -> NodeSpec:
    """The fault detector, an observer outside the lock-step ring: the multichannel detector's node
    (wavelet_fdi.learned_node) with ``params["reference"]`` (a file or a shipped name); a physics reference reads
    the graph's own topics unless a channel map is given."""
    params = dict(params)
    if Path(str(params["reference"])).exists():  # a file: the node may start elsewhere; else a shipped name
        params["reference"] = str(Path(str(params["reference"])).resolve())
    if not params.get("channel_map_file"):
        params.setdefault("loop_graph_topics", True)
    return NodeSpec(DETECTOR, "wavelet_fdi.learned_node", params, OBSERVER)


def live_view_spec(params: dict | None = None) -> NodeSpec:
    """The live view's bridge (phfdi.ros.live_bridge: the graph's signals to Foxglove): an observer."""
    return NodeSpec(LIVE_VIEW, "phfdi.ros.live_bridge", dict(params or {}), OBSERVER)


@dataclass
class LaunchResult:
    status: int  # 0 done, 1 a node failed (or the recorder could not write, or the graph stalled), 128 + signal
    samples: int  # of the scenario
    samples_done: int
    connect_s: float  # start of the processes -> graph connected (wall)
    run_wall_s: float  # sample 0 -> last sample (wall, as the plant measured it)
    domain_id: int
    bag: dict | None = None  # phfdi.bagio.bag_info of the recorded bag
    failure: str | None = None
    notes: list[str] = field(default_factory=list)
    log_dir: str | None = None
    scenario: str = ""
    sample_time_s: float = 1.0
    interrupted_by: str | None = None  # signal that stopped the launch
    published: dict[str, int] = field(default_factory=dict)  # messages per topic, as the nodes counted them
    #: JSON lines the nodes other than the clock node printed (e.g. the detector's fault_alarm events)
    node_events: dict[str, list[dict]] = field(default_factory=dict)
    #: per node, seconds after the launcher started the processes: spawned, main (interpreter and imports
    #: done), init (rclpy.init), built (node made), matched (own endpoints matched), connected; startup_cpu:
    #: the node's CPU seconds at the same steps
    startup: dict[str, dict[str, float]] = field(default_factory=dict)
    startup_cpu: dict[str, dict[str, float]] = field(default_factory=dict)
    #: the watchdog stopped the graph: samples done when it fired (None: it did not)
    stalled_at: int | None = None

    @property
    def simulated_s(self) -> float:
        return max(self.samples_done - 1, 0) * self.sample_time_s

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.run_wall_s if self.run_wall_s > 0 else float("nan")


class _Proc:
    def __init__(self, spec: NodeSpec, popen: subprocess.Popen, log_dir: Path) -> None:
        self.spec, self.popen, self.log_dir = spec, popen, log_dir
        self.expected_exit = False
        self.stdout_pos = 0
        self.killed_by_us = False
        self.spawned = 0.0  # s after the launcher's t0

    @property
    def name(self) -> str:
        return self.spec.name

    def stderr_tail(self, n: int = 8) -> list[str]:
        try:
            lines = (self.log_dir / f"{self.name}.stderr").read_text(errors="replace").splitlines()
        except OSError:
            return []
        return [ln for ln in lines if ln.strip()][-n:]

    def events(self) -> list[dict]:
        """Every JSON event the node printed so far (read from the start; leaves ``stdout_pos`` alone)."""
        try:
            data = (self.log_dir / f"{self.name}.stdout").read_bytes()
        except OSError:
            return []
        lines = data[: data.rfind(b"\n") + 1].decode(errors="replace").splitlines()
        return [e for e in map(_json_event, lines) if e is not None]

    def run_state(self) -> str:
        """The process's state letter from /proc (R, S, D, T stopped, t traced...); '' if unknown."""
        try:
            stat = Path(f"/proc/{self.popen.pid}/stat").read_text()
        except OSError:
            return ""
        return stat[stat.rfind(")") + 2:][:1]

    def new_stdout_lines(self) -> list[str]:
        try:
            with open(self.log_dir / f"{self.name}.stdout", "rb") as f:
                f.seek(self.stdout_pos)
                data = f.read()
        except OSError:
            return []
        end = data.rfind(b"\n") + 1
        self.stdout_pos += end
        return data[:end].decode(errors="replace").splitlines()

    def describe_exit(self) -> str:
        rc = self.popen.returncode
        if rc is None:
            return "is still running"
        if rc < 0:
            try:
                return f"was killed by {signal.Signals(-rc).name}"
            except ValueError:
                return f"was killed by signal {-rc}"
        return f"exited with status {rc}"


class Launcher:
    """Runs a graph to its end (or to a failure or a stop request) and cleans up."""

    def __init__(self, nodes: list[NodeSpec], domain_id: int | None = None, log_dir: str | Path | None = None,
                 progress: Callable[[float], None] | None = None, stop_timeout_s: float = 15.0,
                 status: Callable[[str], None] | None = None, clock_node: str = PLANT,
                 on_event: Callable[[str, dict], None] | None = None,
                 watchdog_s: float | None = WATCHDOG_S) -> None:
        """``clock_node``: the node that owns simulated time (prints connected/progress/done);
        ``on_event(node, event)`` gets the JSON lines the other nodes print, as they come;
        ``watchdog_s``: stop a connected graph whose clock node reports no progress for this long (wall s,
        at least :data:`WATCHDOG_SAMPLE_PERIODS` sample periods; None or 0: never). It needs a clock node
        that announces ``progress_period_s`` in its connected event (the plant does)."""
        names = [n.name for n in nodes]
        if len(set(names)) != len(names):
            raise UserError(f"node names must be unique, got {names}")
        if clock_node not in names:
            raise UserError(f"a graph needs the {clock_node} node (it owns simulated time)")
        self.clock_node = clock_node
        self.on_event = on_event
        self.nodes = nodes
        self.requested_domain = domain_id
        self.keep_logs = log_dir is not None
        self.log_dir = Path(log_dir) if log_dir else None
        self.progress = progress
        self.status = status or (lambda text: None)
        self.stop_timeout_s = stop_timeout_s
        self.procs: dict[str, _Proc] = {}
        self._parts_written: dict[int, str] = {}  # one file per distinct part (loop_graph: one for the graph)
        self._signals: list[int] = []
        self.t_connected: float | None = None
        if watchdog_s is not None and not (math.isfinite(watchdog_s) and watchdog_s >= 0):
            raise UserError(f"watchdog_s = {watchdog_s}: use a positive number of seconds, or 0 for none")
        self.watchdog_s = watchdog_s or 0.0
        self._armed = False  # the clock node promised regular progress events (connected event)
        self._last_progress = 0.0  # monotonic time of its last one
        self._pace = 0.0  # the clock node's pace, as it last reported it (for the watchdog's sample period)
        self._stall: dict = {}  # what the watchdog saw when it fired
        self.t0 = self.t_stop = time.monotonic()  # reset when the nodes start (_spawn_all)
        self.t0_wall = time.time()
        self.wall_t0 = self.t0_wall - 1.0

    # ---- public ---------------------------------------------------------------------------
    def run(self) -> LaunchResult:
        # signals first: a Ctrl-C while the domain is reserved or the nodes start is a stop request like any other
        # (an interrupted reservation or a half-made log folder would be left behind otherwise)
        previous = self._catch_signals()
        try:
            self._check_bags_free()  # before anything starts: a refusal costs nothing and touches nothing
            lease = reserve_domain_id(self.requested_domain)
        except BaseException:
            self._restore_signals(previous)
            raise
        result = LaunchResult(status=0, samples=0, samples_done=0, connect_s=float("nan"), run_wall_s=float("nan"),
                              domain_id=lease.domain_id)
        try:
            self.log_dir = Path(tempfile.mkdtemp(prefix="phfdi-launch-")) if self.log_dir is None else self.log_dir
            self.log_dir.mkdir(parents=True, exist_ok=True)
            if not self._signals:  # stopped before any node started: none is started
                self._spawn_all(lease.domain_id)
            self._watch(result)
        finally:
            self._stop_all(result)
            self._restore_signals(previous)
            self._cleanup(result)
            lease.release()
        return result

    def _recorded_paths(self) -> list[Path]:
        return [Path(spec.params["path"]) for spec in self.nodes
                if spec.module == "phfdi.ros.recorder" and spec.params.get("path")]

    def _check_bags_free(self) -> None:
        """:class:`phfdi.bagio.BagBusyError` (one line) if another process records a bag this graph would write."""
        for path in self._recorded_paths():
            for part in bagio.bag_parts(path) or [path]:  # every existing file of a split bag of that name
                bagio.check_not_recording(part)

    # ---- processes ---------------------------------------------------------------------------
    def _spawn_all(self, domain_id: int) -> None:
        env = graph_env(domain_id)
        env[LAUNCHER_PID_VAR] = str(os.getpid())  # each node asks for SIGTERM when this process dies
        self.t0 = time.monotonic()
        self.t0_wall = time.time()  # start-up trace: nodes report wall clock times
        self.wall_t0 = self.t0_wall - 1.0  # for file times (coarse clocks)
        cmds = {spec.name: self._write_params(spec) for spec in self.nodes}
        # the observers first: the detector has the most to import, so it is the last to connect
        for spec in sorted(self.nodes, key=lambda s: s.role != OBSERVER):
            with open(self.log_dir / f"{spec.name}.stdout", "wb") as out, \
                 open(self.log_dir / f"{spec.name}.stderr", "wb") as err:
                # no preexec_fn: the child is started by vfork, about 10 ms sooner per node than a fork of
                # this large process
                popen = subprocess.Popen(cmds[spec.name], stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                         env=env, start_new_session=True)
            self.procs[spec.name] = _Proc(spec, popen, self.log_dir)
            self.procs[spec.name].spawned = time.monotonic() - self.t0
        self.procs = {spec.name: self.procs[spec.name] for spec in self.nodes}  # graph order for what follows
        self.status(f"started {len(self.nodes)} nodes on ROS domain {domain_id}: "
                    + ", ".join(f"{p.name} (pid {p.popen.pid})" for p in self.procs.values()))

    def _write_params(self, spec: NodeSpec) -> list[str]:
        """Write the node's parameter file (and its part, once per distinct part); its command line."""
        params = dict(spec.params)
        if spec.part is not None:
            if id(spec.part) not in self._parts_written:
                path = self.log_dir / f"part{len(self._parts_written)}.json"
                self._parts_written[id(spec.part)] = str(write_part(path, spec.part))
            params["part"] = self._parts_written[id(spec.part)]
        params_file = self.log_dir / f"{spec.name}.params.yaml"
        params_file.write_text(params_document(spec.name, params))
        return [sys.executable, "-m", spec.module, "--ros-args", "--params-file", str(params_file)]

    def _watch(self, result: LaunchResult) -> None:
        if not self.procs:  # a stop request came before any node started
            self._interrupted(result)
            return
        plant = self.procs[self.clock_node]
        done = False
        while True:
            for line in plant.new_stdout_lines():
                done = self._on_plant_event(line, result) or done
            self._follow_others()
            if self._signals:
                self._interrupted(result)
                return
            for p in self.procs.values():
                if p.popen.poll() is None:
                    continue
                if p is plant and p.popen.returncode == 0 and done:
                    p.expected_exit = True
                    return
                result.status = 1
                result.failure = self._describe_failure(p, result)
                return
            if self._armed and not done and self.watchdog_s > 0:
                silent_s = time.monotonic() - self._last_progress
                limit_s = self.watchdog_limit_s(result.sample_time_s)
                if silent_s > limit_s:
                    result.status = 1
                    result.stalled_at = result.samples_done
                    self._stall = {"silent_s": silent_s, "limit_s": limit_s, "stopped": [
                        f"{p.name} (pid {p.popen.pid})" for p in self.procs.values()
                        if p.popen.poll() is None and p.run_state() in ("T", "t")]}
                    result.failure = self._describe_stall(result)  # told again with the nodes' counts after the stop
                    return
            time.sleep(0.05)

    def _interrupted(self, result: LaunchResult) -> None:
        sig = self._signals[0]
        result.status = 128 + sig
        result.interrupted_by = signal.Signals(sig).name

    def watchdog_limit_s(self, sample_time_s: float) -> float:
        """Wall seconds without progress that count as a stall: ``watchdog_s``, but never less than
        :data:`WATCHDOG_SAMPLE_PERIODS` sample periods at the pace the clock node last reported."""
        period_s = sample_time_s / self._pace if self._pace > 0 else 0.0
        return max(self.watchdog_s, WATCHDOG_SAMPLE_PERIODS * period_s)

    def _describe_stall(self, result: LaunchResult) -> str:
        """One line: where the graph stands and, if it can be seen, which node holds it up: a stopped
        process (seen in /proc while it stalls), else the first node of the ring whose published count
        (the nodes' own, reported when stopped) is behind the node before it."""
        st = self._stall
        k = result.published.get(PLANT_STATE.name, result.samples_done)  # exact once the nodes reported
        text = (f"graph stalled: no progress from the {self.clock_node} for {st['silent_s']:.1f} s "
                f"(watchdog {st['limit_s']:g} s) at sample {k} of {result.samples}")
        if st["stopped"]:
            text += "; stopped processes (SIGSTOP or a debugger): " + ", ".join(st["stopped"])
        elif self.clock_node == PLANT and result.published:
            n = [result.published.get(t.name, 0) for t in (MEASUREMENT, CONTROLLER_OUTPUT, VALVE_STATE)]
            if n[1] < n[0]:
                text += f"; the controllers did not answer /plant/measurement of sample {n[0] - 1}"
            elif n[2] < n[1]:
                text += f"; the valve did not answer /controller/output of sample {n[1] - 1}"
            elif k < n[2]:
                text += f"; the plant did not take /valve/state of sample {n[2] - 1}"
        return text + "; graph stopped"

    def _describe_failure(self, p: _Proc, result: LaunchResult) -> str:
        """One line for a node that ended while the graph ran (the recorder names a write failure itself)."""
        failed = [e for e in p.events() if e["event"] == "write_failed"]
        if failed:
            e = failed[-1]
            if e.get("errno"):
                return f"{p.name}: cannot write {_shown(e['path'])}: {e['error']}"
            return f"{p.name}: {e.get('message') or e['error']}"
        where = f"node {p.name} (python -m {p.spec.module}, pid {p.popen.pid})"
        tail = p.stderr_tail()
        if p.popen.returncode == 2 and tail and ": error: " in tail[-1]:  # a NodeStartError: its one line
            return f"{where} refused to start: {tail[-1].split(': error: ', 1)[1]}"
        return (f"{where} {p.describe_exit()}"
                + (" at sample " + str(result.samples_done) if result.samples else "")
                + ("; last lines of its stderr:\n    " + "\n    ".join(tail) if tail else ""))

    def _follow_others(self) -> None:
        if self.on_event is None:
            return
        for p in self.procs.values():
            if p.name == self.clock_node:
                continue
            for line in p.new_stdout_lines():
                event = _json_event(line)
                if event is not None:
                    self.on_event(p.name, event)

    def _on_plant_event(self, line: str, result: LaunchResult) -> bool:
        try:
            event = json.loads(line)
        except json.JSONDecodeError:
            return False
        kind = event.get("event")
        if kind == "connected":
            self.t_connected = time.monotonic()
            result.connect_s = self.t_connected - self.t0
            result.samples = event["samples"]
            result.sample_time_s = event["sample_time_s"]
            result.scenario = event.get("scenario", "")
            self._pace = float(event.get("pace", 0.0))
            self._armed = bool(event.get("progress_period_s"))  # the watchdog needs a node that reports regularly
            self._last_progress = time.monotonic()
            self.status(f"graph connected after {result.connect_s:.1f} s; running {result.samples} samples")
        elif kind == "progress":
            result.samples_done = event["sample"]
            self._last_progress = time.monotonic()
            self._pace = float(event.get("pace", self._pace))
            if self.progress is not None and result.samples:
                self.progress(event["sample"] / result.samples)
        elif kind == "done":
            result.samples_done = event["samples"]
            result.run_wall_s = event["wall_s"]
            if self.progress is not None:
                self.progress(1.0)
            return True
        return False

    def _stop(self, procs: list[_Proc]) -> None:
        alive = [p for p in procs if p.popen.poll() is None]
        for p in alive:
            p.expected_exit = True
            try:
                p.popen.send_signal(signal.SIGTERM)
                # a stopped node (SIGSTOP, a stalled graph) acts on SIGTERM only once continued (bash's kill does
                # the same for stopped jobs); a running one ignores SIGCONT
                p.popen.send_signal(signal.SIGCONT)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + self.stop_timeout_s
        while any(p.popen.poll() is None for p in alive):
            # too slow, or asked twice (a second Ctrl-C): kill what is left
            if time.monotonic() > deadline or len(self._signals) > 1:
                for p in alive:
                    if p.popen.poll() is None:
                        p.killed_by_us = True
                        p.popen.kill()
                        p.popen.wait()
                break
            time.sleep(0.05)

    def _stop_all(self, result: LaunchResult) -> None:
        self.t_stop = time.monotonic()
        if not self.procs:
            return
        plant = [p for p in self.procs.values() if p.name == self.clock_node]
        loop = [p for p in self.procs.values() if p.spec.role == LOOP and p.name != self.clock_node]
        # observers that publish (the detector) deliver their last messages before the recorder closes
        observers = [p for p in self.procs.values() if p.spec.role == OBSERVER and p.name != RECORDER]
        recorder = [p for p in self.procs.values() if p.spec.role == OBSERVER and p.name == RECORDER]
        for group in (plant, loop, observers, recorder):
            self._stop(group)
        self._follow_others()
        for p in recorder:
            # a write that failed while the recorder drained or closed (the messages it had not yet taken when the
            # run ended, its last chunk, the summary): the bag is cut short as surely as during the run
            failed = any(e["event"] == "write_failed" for e in p.events())
            if failed and result.status == 0 and result.failure is None:
                result.status = 1
                result.failure = self._describe_failure(p, result)
        for p in self.procs.values():
            if p.killed_by_us:
                result.notes.append(f"node {p.name} did not stop within {self.stop_timeout_s:g} s and was killed")
            elif p.popen.returncode == -signal.SIGTERM and self.t_connected is None:
                pass  # stopped by our SIGTERM while it was still starting (before its handler): nothing to say
            elif p.popen.returncode not in (0, None) and p.expected_exit and result.failure is None:
                result.notes.append(f"node {p.name} {p.describe_exit()} while stopping: "
                                    + " | ".join(p.stderr_tail(3)))

    # ---- after the processes are gone ---------------------------------------------------------------
    def _collect_published(self, result: LaunchResult) -> None:
        for p in self.procs.values():
            p.stdout_pos = 0
            for line in p.new_stdout_lines():
                event = _json_event(line)
                if event is None:
                    continue
                if event["event"] == "startup":
                    result.startup[p.name] = {"spawned": round(p.spawned, 4), **{
                        k: round(t - self.t0_wall, 4) for k, t in event.get("times", {}).items()}}
                    result.startup_cpu[p.name] = {k: round(c, 4) for k, c in event.get("cpu", {}).items()}
                elif event["event"] == "published":
                    for topic, n in event.get("counts", {}).items():
                        result.published[topic] = result.published.get(topic, 0) + n
                elif p.name != self.clock_node:
                    result.node_events.setdefault(p.name, []).append(event)

    def _cleanup(self, result: LaunchResult) -> None:
        self._collect_published(result)
        if result.failure or any(p.popen.returncode not in (0, None) for p in self.procs.values()):
            # a node that died while the others ran leaves shared memory behind
            time.sleep(1.0)
            result.notes.append(clean_shared_memory(result.domain_id, self.wall_t0))
        else:
            # a clean stop too: the nodes still running write to the ports of those already stopped (the
            # recorder last), re-creating them without an owner
            remove_ownerless_ports(result.domain_id, self.wall_t0)
        if result.stalled_at is not None and result.published:
            result.failure = self._describe_stall(result)
            result.notes.append("messages published per topic when the stalled graph was stopped: " + ", ".join(
                f"{topic} {n}" for topic, n in result.published.items()))
        recorder = self.procs.get(RECORDER)
        if recorder is not None:
            path = Path(recorder.spec.params["path"])
            result.bag = self._finish_bag(path, recorder, result)
            if result.bag is not None:  # the bag knows best how far the run got
                counts = {t["topic"]: t["count"] for t in result.bag["topics"]}
                result.samples_done = counts.get(PLANT_STATE.name, result.samples_done)
        if result.run_wall_s != result.run_wall_s and self.t_connected is not None:  # NaN: stopped early
            result.run_wall_s = self.t_stop - self.t_connected
        if result.status == 0 and not self.keep_logs:
            shutil.rmtree(self.log_dir, ignore_errors=True)
        else:
            result.log_dir = str(self.log_dir)

    def _finish_bag(self, path: Path, recorder: _Proc, result: LaunchResult) -> dict | None:
        """bag_info of the recorded bag (of all its files when split), recovered if unfinished.

        Only the files the recorder reported taking (its ``recording`` events, printed once it holds a file's
        lock): a recorder refused because another process records that path leaves that file alone."""

        split = recorder.spec.params.get("split_after_s", 0) > 0
        events = recorder.events()
        taken = [Path(e["path"]) for e in events if e["event"] == "recording"]
        parts = [p for p in dict.fromkeys(taken) if p.exists()]
        if not parts:
            return None
        failed = next((e for e in events if e["event"] == "write_failed"), None)
        infos = [self._finish_part(p, recorder, result, failed) for p in parts]
        if not split:
            return infos[0]
        info = dict(infos[0], parts=[i["path"] for i in infos], size_bytes=sum(i["size_bytes"] for i in infos),
                    messages=sum(i["messages"] for i in infos), chunks=sum(i.get("chunks", 0) for i in infos),
                    end_s=infos[-1]["end_s"], finished=all(i["finished"] for i in infos))
        counts: dict[str, int] = {}
        for i in infos:
            for t in i["topics"]:
                counts[t["topic"]] = counts.get(t["topic"], 0) + t["count"]
        info["topics"] = [dict(t, count=counts[t["topic"]]) for t in infos[0]["topics"]]
        return info

    def _finish_part(self, path: Path, recorder: _Proc, result: LaunchResult, failed: dict | None) -> dict:
        """The file's bag_info; an unfinished one is first recovered in place, through a staged file: if that
        cannot be written (the disk still full) the unfinished file stays as it was, never a 0-byte one."""
        info = bagio.bag_info(path)
        if info["finished"]:
            return info
        why = (f"the recorder stopped at a write failure ({failed['error']})" if failed
               else f"the recorder {recorder.describe_exit()}")
        try:
            with bagio.bag_lock(path):  # a recorder that took this path since keeps it
                unfinished = path.with_name(f".{path.stem}.{os.getpid()}.unfinished.mcap")
                os.replace(path, unfinished)
                try:
                    rec = bagio.recover(unfinished, path, caller_holds_lock=True)  # staged: all or nothing
                except (UserError, OSError) as exc:
                    os.replace(unfinished, path)
                    result.notes.append(
                        f"{why} before finishing {path.name}: it holds {info['messages']} messages up to its last "
                        f"complete chunk (phfdi bag info reads it) but could not be recovered in place "
                        f"({_one_line(exc)}); run phfdi bag recover {path} FIXED.mcap where there is room")
                    return bagio.bag_info(path)
                unfinished.unlink()
        except bagio.BagBusyError as exc:
            result.notes.append(f"{path.name} left unfinished, not recovered: {exc}")
            return info
        except OSError as exc:
            result.notes.append(f"{path.name} left unfinished, not recovered: {_one_line(exc)}")
            return info
        result.notes.append(f"{why} before finishing {path.name}: recovered {rec['messages']} messages up to its "
                            f"last complete chunk")
        return bagio.bag_info(path)

    # ---- signals -----------------------------------------------------------------------------
    def _catch_signals(self):
        import threading

        if threading.current_thread() is not threading.main_thread():
            return None

        def on_signal(signum, _frame) -> None:
            self._signals.append(signum)  # a second one kills the nodes still stopping (see _stop)

        return {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}

    @staticmethod
    def _restore_signals(previous) -> None:
        if previous:
            for s, handler in previous.items():
                signal.signal(s, handler)


def params_document(node: str, params: dict) -> str:
    """A node's parameter file (rclpy's ``--params-file`` format, ``node: ros__parameters: ...``), as the launcher
    writes it for each node (and as config/*.params.yaml ship it: :mod:`phfdi.ros.shipped_config`)."""
    return yaml.safe_dump({node: {"ros__parameters": params}}, sort_keys=False)


def _shown(path: str | Path) -> str:
    """A path as the user likely wrote it: relative to the working folder when inside it."""
    try:
        return str(Path(path).relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.strerror:
        return f"{str(exc.filename) + ': ' if exc.filename else ''}{exc.strerror}"
    return " ".join(str(exc).split())


def _json_event(line: str) -> dict | None:
    """A node's JSON line ({"event": ...}); None for anything else (log lines)."""
    if not line.startswith("{"):
        return None
    try:
        event = json.loads(line)
    except json.JSONDecodeError:
        return None
    return event if isinstance(event, dict) and "event" in event else None


SHM_DIR = Path("/dev/shm")


def ownerless_port_segments(domain_id: int, since: float) -> list[Path]:
    """Fast DDS port segments of this graph that no live process owns.

    A listening participant holds ``fastrtps_portN_el`` locked while it lives.
    When a node is killed, the others keep sending to its ports for a while
    and re-create the segments without that lock file, which ``fastdds shm
    clean`` does not look at. Ours: the domain's port range, or the
    per-participant ports below it (7000 + i) created during this launch.
    """
    lo = 7400 + 250 * domain_id
    out = []
    for f in SHM_DIR.glob("fastrtps_port*"):
        name = f.name
        if name.endswith(("_el", "_sl")) or not name[len("fastrtps_port"):].isdigit():
            continue
        port = int(name[len("fastrtps_port"):])
        if (SHM_DIR / f"{name}_el").exists() or (SHM_DIR / f"{name}_sl").exists():
            continue
        try:
            recent = f.stat().st_mtime >= since
        except FileNotFoundError:
            continue
        if lo <= port < lo + 250 or (port < 7400 and recent):
            out.append(f)
    return out


def remove_ownerless_ports(domain_id: int, since: float) -> int:
    """Remove this graph's ownerless port segments (:func:`ownerless_port_segments`); how many."""
    ports = ownerless_port_segments(domain_id, since)
    for f in ports:
        for path in (f, SHM_DIR / f"sem.{f.name}_mutex"):
            try:
                path.unlink()
            except FileNotFoundError:
                pass
    return len(ports)


def clean_shared_memory(domain_id: int, since: float) -> str:
    """Remove the Fast DDS shared memory a killed node left: zombie segments and ownerless ports."""
    tool = Path(sys.prefix) / "tools" / "fastdds" / "fastdds.py"
    summary = []
    if tool.exists():  # segments whose lock file is no longer held ("fastdds shm clean" checks the locks)
        out = subprocess.run([sys.executable, str(tool), "shm", "clean"], capture_output=True, text=True,
                             timeout=60)
        summary += [ln.strip() for ln in out.stdout.splitlines() if "cleaned" in ln]
    summary.append(f"{remove_ownerless_ports(domain_id, since)} ownerless port segments removed")
    return "shared memory of the stopped graph cleaned (" + ", ".join(summary) + ")"
