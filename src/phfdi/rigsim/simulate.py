"""One simulated rig run: an operation on a day, seeded, optionally with a probe fault the controller sees.

Per sample, in the rig's order: the probe reads the flask (zone -> probe lag -> calibration and slow drift ->
noise and the pumps' stroke ripple -> an optional probe fault -> the meter's 0.01 pH), the operation decides
the row's pump commands from that reading, the pumps deliver the fixed table's flow (% x mL/s per %) until the
next sample, and the flask advances (:class:`~phfdi.rigsim.flask.RigFlask`). The sample times carry the
recorded files' jitter.

The random numbers of a run come from its seed alone (the day's from its day number), drawn as whole arrays
before the loop: a run is the same for the same (operation, seed, day, duration, fault) on any machine, and a
probe fault changes only what happens after its onset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import Callable

import numpy as np

from ph_plant_sim.sensors import lag_step
from phfdi.inject_kinds import KINDS, PH_MAX, PH_MIN, PH_RESOLUTION, TRUTH_FORMAT
from phfdi_base.blocks import Block
from phfdi_base.errors import UserError

from .control import build_policy
from .day import FLOW_PER_PCT, RigDay, draw_day
from .flask import RigFlask
from .operations import Operation, OperationSpec, draw_operation, load_catalogue

#: sampling of the recorded files (s): two interleaved intervals and rare long ones (docs/simulation.md)
FAST_DT_S, FAST_SD_S = 0.3390, 0.0020
SLOW_DT_S, SLOW_SD_S = 0.3528, 0.0036
FAST_SHARE = (0.35, 0.5)  # share of fast intervals per run: 0.38-0.48 in the recorded files
GAP_PROBABILITY, GAP_S = 0.004, (0.36, 0.43)  # 0.1-0.6 % of the intervals exceed 0.37 s
#: room temperature: T_Room of the recorded files moves by a few tenths of a degree per run, 0.02 deg C white
ROOM_WALK_C_PER_SQRT_S, ROOM_NOISE_C = 0.006, 0.02
#: the probe faults a run can carry: the sensor faults of ``phfdi inject``, in its units
PROBE_FAULTS = tuple(k for k, spec in KINDS.items() if spec.family == "sensor")

_RUN_STREAM = 0x52_16_51_4D  # a run's random stream, apart from the day's


@dataclass(frozen=True)
class ProbeFault:
    """A probe fault from ``onset_s`` (record time, the file's ElapsedTime) on, on the reading the controller
    sees: ``kind`` one of :data:`PROBE_FAULTS` with ``size`` in ``phfdi inject``'s unit for it (bias pH,
    drift pH/min, noise pH std, lag s, gain fraction; frozen takes none); ``seed`` seeds a noise fault.

    Examples
    --------
    >>> from phfdi.rigsim import ProbeFault, simulate_run
    >>> run = simulate_run("on_off_acid", seed=1, duration_s=200.0, probe_fault=ProbeFault("probe_frozen", 100.0))
    >>> k0 = run.fault["onset_index"]
    >>> len(set(run.ph[k0:].tolist())), run.fault["unit"]
    (1, 'none')
    """

    kind: str
    onset_s: float
    size: float | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.kind not in PROBE_FAULTS:
            raise UserError(f"probe fault {self.kind!r}: one of {', '.join(PROBE_FAULTS)}")
        if not math.isfinite(self.onset_s):
            raise UserError("the probe fault's onset must be a finite time")
        if self.kind != "probe_frozen":
            if self.size is None or not math.isfinite(self.size):
                raise UserError(f"{self.kind} needs a finite size (in {KINDS[self.kind].inject.unit})")
            if self.kind in ("probe_noise", "probe_lag") and not self.size > 0:
                raise UserError(f"{self.kind}: the size must be above 0 ({KINDS[self.kind].inject.unit})")
            if self.kind == "probe_gain" and not self.size > -1:
                raise UserError("probe_gain: the size must be above -1 (fraction)")

    def block(self, dt_s: float):
        """The fault as the project's sensor blocks, switched on at the onset (:class:`phfdi_base.Injected`)."""
        from ph_plant_sim import sensors
        from phfdi_base.blocks import Injected
        from valve_actuator.blocks import Blocking

        size = 0.0 if self.size is None else float(self.size)
        makers: dict[str, Callable[[], Block]] = {
            "probe_bias": lambda: sensors.Bias(size),
            "probe_drift": lambda: sensors.Drift(size / 60.0),  # pH/min -> pH/s
            "probe_frozen": lambda: Blocking(),  # holds the reading where the onset found it
            "probe_noise": lambda: sensors.GaussianNoise(size, seed=self.seed),
            "probe_lag": lambda: sensors.FirstOrderLag(size, dt_s=dt_s),
            "probe_gain": lambda: sensors.Gain(1.0 + size, reference=7.0),
        }
        return Injected(makers[self.kind](), self.onset_s)


@dataclass
class RigRun:
    """A simulated run: the record's columns (as the CSV holds them) and the truth behind them.

    ``time_s`` is the record's ElapsedTime; ``ph`` the recorded reading (0.01 pH, with the probe fault if
    any); ``ph_probe`` what a healthy probe would have read (the same run, no fault); ``ph_zone`` the true pH
    where the probe sits; ``ph_true`` the flask's (bulk) pH; ``setpoint_ph`` the controller's setpoint (NaN
    in open loop).

    Examples
    --------
    >>> from phfdi.rigsim import simulate_run
    >>> run = simulate_run("shared_add_base", seed=0)
    >>> run.operation.name, run.day.number, len(run) == len(run.ph) == len(run.ph_true)
    ('shared_add_base', 0, True)
    >>> rec = run.measured()  # as phfdi.learned.read_measured gives its CSV
    >>> rec.channels, rec.x.shape[0] == len(run)
    (('acid_flow_ml_s', 'base_flow_ml_s', 'ph_measured'), True)
    """

    operation: Operation
    day: RigDay
    seed: int
    time_s: np.ndarray
    acid_pct: np.ndarray
    base_pct: np.ndarray
    acid_flow_ml_s: np.ndarray
    base_flow_ml_s: np.ndarray
    ph: np.ndarray
    ph_probe: np.ndarray
    ph_zone: np.ndarray
    ph_true: np.ndarray
    setpoint_ph: np.ndarray
    room_temp_c: np.ndarray
    clock_start: datetime  # wall clock at ElapsedTime 0
    uptime_s: float  # the logger's clock at the start: its rounding shows in ElapsedTime's last digits
    fault: dict | None = None
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.time_s)

    #: the channels of the ``ph_rig`` column map and where a run holds them
    MAP_CHANNELS = {"acid_flow_ml_s": "acid_flow_ml_s", "base_flow_ml_s": "base_flow_ml_s", "ph_measured": "ph"}

    def recorded(self, name: str) -> np.ndarray:
        """A ``ph_rig`` channel as the CSV holds it (flows and pH at 2 decimals): what reading the file gives."""
        if name not in self.MAP_CHANNELS:
            raise UserError(f"no channel {name!r}; the rig's are {', '.join(self.MAP_CHANNELS)}")
        return np.round(getattr(self, self.MAP_CHANNELS[name]), 2)

    def measured(self, channels=("acid_flow_ml_s", "base_flow_ml_s", "ph_measured")):
        """The run as :func:`phfdi.learned.read_measured` gives its CSV under the ``ph_rig`` map (the same
        numbers, no file): a :class:`phfdi.records.Record` for the detector's and the estimator's code."""
        from phfdi.records import Record

        units = {"acid_flow_ml_s": "mL/s", "base_flow_ml_s": "mL/s", "ph_measured": "pH"}
        return Record(f"rig-sim:{self.operation.name}:seed{self.seed}:day{self.day.number}",
                      np.round(self.time_s, 3), {c: np.asarray(self.recorded(c), dtype=float) for c in channels},
                      {c: units[c] for c in channels}, {c: c for c in channels}, np.arange(2, len(self) + 2), "line")

    def meta(self) -> dict:
        """What made this run (operation drawn, day, seed, fault truth): the OUT.rigsim.json sidecar."""
        return {"format": "phfdi-rig-sim/1", "operation": self.operation.to_dict(), "day": self.day.to_dict(),
                "seed": self.seed, "samples": len(self), "duration_s": float(self.time_s[-1] - self.time_s[0]),
                "probe_fault": self.fault, "notes": list(self.notes)}


def _sample_times(duration_s: float, start_s: float, rng: np.random.Generator) -> np.ndarray:
    """Record times (s) with the recorded files' jitter: fast and slow intervals interleaved, rare long
    ones, on the logger's millisecond clock."""
    n = int(duration_s / FAST_DT_S) + 8
    fast = rng.random(n) < rng.uniform(*FAST_SHARE)
    dt = np.where(fast, rng.normal(FAST_DT_S, FAST_SD_S, n), rng.normal(SLOW_DT_S, SLOW_SD_S, n))
    gaps = rng.random(n) < GAP_PROBABILITY
    dt = np.where(gaps, rng.uniform(*GAP_S, n), dt)
    dt_ms = np.maximum(np.round(dt * 1000.0), 320.0)
    t_ms = np.round(start_s * 1000.0) + np.concatenate([[0.0], np.cumsum(dt_ms)])
    return t_ms[t_ms <= t_ms[0] + duration_s * 1000.0] / 1000.0


def _ripple(t_s: np.ndarray, period_s: float, coherence_s: float, std_ph: float,
            rng: np.random.Generator) -> np.ndarray:
    """A pump's stroke ripple at the reading: a narrowband Gaussian process at the stroke frequency (the
    real part of z_k = exp(-dt/tc + i w dt) z_k-1 + innovation, a stochastic oscillator whose autocorrelation
    is std^2 cos(w tau) exp(-tau/tc): strokes that drift in timing lose coherence over ``coherence_s``), of
    standard deviation ``std_ph``, at the sample times (exact for any interval)."""
    from ph_plant_sim.plant import affine_recurrence

    dt = np.diff(t_s, prepend=t_s[0])
    rho = np.exp(-dt / coherence_s)
    theta = np.cumsum(2.0 * np.pi * dt / period_s)  # the oscillation's phase, factored out of the recursion
    xi = rng.standard_normal((len(t_s), 2)) * std_ph * np.sqrt(1.0 - rho**2)[:, None]  # complex, E|.|^2 = 2 std^2
    rot = np.column_stack([np.cos(theta), np.sin(theta)])
    # w_k = rho_k w_k-1 + xi_k e^{-i theta_k}: real gains, so the core's vectorised recurrence applies
    drive = np.column_stack([xi[:, 0] * rot[:, 0] + xi[:, 1] * rot[:, 1], xi[:, 1] * rot[:, 0] - xi[:, 0] * rot[:, 1]])
    w0 = rng.standard_normal(2) * std_ph  # started stationary
    w = affine_recurrence(rho, drive, w0)[1:]
    return w[:, 0] * rot[:, 0] - w[:, 1] * rot[:, 1]  # Re(w e^{i theta})


def resolve_operation(operation: str | OperationSpec, catalogue=None) -> OperationSpec:
    if isinstance(operation, OperationSpec):
        return operation
    ops = load_catalogue(catalogue)
    if operation not in ops:
        raise UserError(f"no operation {operation!r}; the catalogue has {', '.join(ops)}")
    return ops[operation]


def simulate_run(operation: str | OperationSpec, seed: int, day: int | RigDay | None = None, *,
                 duration_s: float | None = None, probe_fault: ProbeFault | None = None,
                 catalogue=None) -> RigRun:
    """Simulate one run of ``operation`` (a catalogue name or spec) with run ``seed`` on ``day`` (a day
    number, a :class:`RigDay`, or None for day number ``seed``).

    Examples
    --------
    >>> from phfdi.rigsim import ProbeFault, simulate_run
    >>> run = simulate_run("on_off_base", seed=5, duration_s=120.0)
    >>> len(run) > 300, float(run.time_s[1] - run.time_s[0]) < 0.45
    (True, True)
    >>> faulty = simulate_run("on_off_base", seed=5, duration_s=120.0, probe_fault=ProbeFault("probe_bias", 60.0, 0.5))
    >>> bool((faulty.ph[:100] == run.ph[:100]).all()), faulty.fault["kind"]
    (True, 'probe_bias')
    """
    spec = resolve_operation(operation, catalogue)
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UserError(f"seed must be a non-negative integer, got {seed!r}")
    rig_day = day if isinstance(day, RigDay) else draw_day(int(seed if day is None else day))
    rng = np.random.default_rng([_RUN_STREAM, int(seed)])
    op = draw_operation(spec, rng, duration_s)
    start_elapsed = float(op.values["start_elapsed_s"])  # type: ignore[arg-type]
    t = _sample_times(op.duration_s, start_elapsed, rng)
    if probe_fault is not None and not t[0] <= probe_fault.onset_s <= t[-1]:
        raise UserError(f"the probe fault's onset {probe_fault.onset_s:g} s is outside the run ({t[0]:g} to "
                        f"{t[-1]:g} s of ElapsedTime)")
    n = len(t)
    # every random number of the run, drawn before the loop (a fault changes nothing before its onset)
    white = rig_day.white_noise_ph * rng.standard_normal(n)
    ripple_acid = _ripple(t, rig_day.acid_stroke_s, rig_day.stroke_coherence_s, rig_day.acid_ripple_ph, rng)
    ripple_base = _ripple(t, rig_day.base_stroke_s, rig_day.stroke_coherence_s, rig_day.base_ripple_ph, rng)
    room = (rig_day.room_temp_c + ROOM_WALK_C_PER_SQRT_S * np.cumsum(np.sqrt(np.diff(t, prepend=t[0]))
                                                                   * rng.standard_normal(n))
            + ROOM_NOISE_C * rng.standard_normal(n))
    clock_start = (datetime(2025, 5, 5) + timedelta(days=rig_day.number, seconds=float(rng.uniform(9, 16) * 3600)))
    uptime_s = float(rng.uniform(1e3, 5e4))

    flask = RigFlask(rig_day)
    policy = build_policy(op)
    acid, base, acid_flow, base_flow, ph, ph_probe, ph_zone, ph_true, setpoint = \
        _loop(flask, policy, t, white, ripple_acid, ripple_base, op, probe_fault)
    fault = _truth(probe_fault, t, op) if probe_fault is not None else None
    return RigRun(op, rig_day, int(seed), t, acid, base, acid_flow, base_flow, ph, ph_probe, ph_zone, ph_true,
                  setpoint, room, clock_start, uptime_s, fault)


def draw_runs(hours: float, group: str | None = "unseen", first_seed: int = 0, *, operations=None,
              days=None, catalogue=None):
    """Runs until ``hours`` of record are simulated: the operations of ``group`` (or the names in
    ``operations``) in turn, seed ``first_seed``, ``first_seed + 1``, ... (each on day = its seed, or on the
    day numbers ``days`` cycled). A generator: each :class:`RigRun` as it is made.

    Examples
    --------
    >>> from phfdi.rigsim import draw_runs
    >>> runs = list(draw_runs(0.2, operations=["shared_add_base", "shared_add_acid"], first_seed=10))
    >>> [r.operation.name for r in runs][:3], sum(float(r.time_s[-1] - r.time_s[0]) for r in runs) >= 720
    (['shared_add_base', 'shared_add_acid', 'shared_add_base'], True)
    """
    from .operations import operation_names

    names = list(operations) if operations is not None else operation_names(group, catalogue)
    day_list = None if days is None else [int(d) for d in days]
    if not names or day_list == []:
        raise UserError("no operation to run (or an empty list of days)")
    if not (math.isfinite(hours) and hours > 0):
        raise UserError(f"hours must be positive, got {hours}")
    total_s, i = 0.0, 0
    while total_s < hours * 3600.0:
        seed = first_seed + i
        day = None if day_list is None else day_list[i % len(day_list)]
        run = simulate_run(names[i % len(names)], seed, day, catalogue=catalogue)
        total_s += float(run.time_s[-1] - run.time_s[0])
        i += 1
        yield run


def _loop(flask: RigFlask, policy, t: np.ndarray, white: np.ndarray, ripple_acid: np.ndarray,
          ripple_base: np.ndarray, op: Operation, fault: ProbeFault | None):
    day = flask.day
    n = len(t)
    t0 = float(t[0])
    start_ph = float(op.values["start_ph"])  # type: ignore[arg-type]
    x = np.vstack([flask.start_composition(start_ph)] * 2)  # rows: zone, bulk (mol/L per component)
    balance, carb = flask.balance, flask.carbonate
    ceq = flask.air.equilibrium_mol_l
    bulk = np.empty((n, x.shape[1]))
    out_ph, out_probe, out_zone, out_sp = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    acid_cmd, base_cmd = np.empty(n), np.empty(n)
    ph_zone = balance.ph(x[0].tolist(), guess=start_ph)
    probe = ph_zone
    previous = policy.start(ph_zone)
    block = fault.block(float(np.mean(np.diff(t))) if n > 1 else 0.35) if fault is not None else None
    if block is not None:
        block.reset(0.0)
    inflow: dict[tuple[float, float], np.ndarray] = {}
    slope, offset, drift = day.probe_slope, day.probe_offset_ph, day.probe_drift_ph_per_h / 3600.0
    tau = day.probe_tau_s
    idle = day.idle_ripple_ph / day.base_ripple_ph
    for k in range(n):
        tk = float(t[k])
        if k:
            probe = lag_step(probe, ph_zone, tau, tk - float(t[k - 1]))
        noise = float(white[k])
        if previous[0] > 0.0:
            noise += float(ripple_acid[k])
        if previous[1] > 0.0:
            noise += float(ripple_base[k])
        if previous[0] <= 0.0 and previous[1] <= 0.0:
            noise += idle * float(ripple_base[k])  # neither pump: the band's noise at the day's idle level
        healthy = 7.0 + slope * (probe - 7.0) + offset + drift * (tk - t0) + noise
        seen = block.step(healthy, tk) if block is not None else healthy
        reading = _meter(seen)
        out_probe[k] = _meter(healthy)
        out_ph[k] = reading
        out_zone[k] = ph_zone
        bulk[k] = x[1]
        command = policy.command(tk - t0, reading)
        acid_cmd[k], base_cmd[k] = command
        out_sp[k] = policy.setpoint(tk - t0)
        previous = command
        if k + 1 < n:
            dt = float(t[k + 1]) - tk
            f = inflow.get(command)
            if f is None:
                flows = np.array([command[0] * FLOW_PER_PCT["acid"], command[1] * FLOW_PER_PCT["base"]])
                f = inflow[command] = flask.inflow_per_volume(flows)
                f.flags.writeable = False
            q = command[0] * FLOW_PER_PCT["acid"] + command[1] * FLOW_PER_PCT["base"]
            tr = flask.transition(q, dt)
            x = tr.e @ x + np.outer(tr.p[:, 1], f)
            x[1, carb] = ceq + (x[1, carb] - ceq) * flask.air_factor(dt)
            ph_zone = balance.ph(x[0].tolist(), guess=ph_zone)
    ph_true = balance.ph_array(bulk, guess=out_zone)
    acid_flow = acid_cmd * FLOW_PER_PCT["acid"]
    base_flow = base_cmd * FLOW_PER_PCT["base"]
    return acid_cmd, base_cmd, acid_flow, base_flow, out_ph, out_probe, out_zone, ph_true, out_sp


def _meter(ph: float) -> float:
    """The meter's reading: 0.01 pH steps, within 0..14."""
    return min(PH_MAX, max(PH_MIN, math.floor(ph / PH_RESOLUTION + 0.5) * PH_RESOLUTION))


def _truth(fault: ProbeFault, t: np.ndarray, op: Operation) -> dict:
    spec = KINDS[fault.kind]
    k0 = int(np.searchsorted(t, fault.onset_s, side="left"))
    closed = op.kind in ("on_off", "pi")
    amount = "" if fault.kind == "probe_frozen" else f" of {fault.size:g} {spec.inject.unit}"
    seen = "the reading the controller acts on" if closed else "the recorded reading (open loop: no controller)"
    return {
        "format": TRUTH_FORMAT, "kind": fault.kind, "family": spec.family, "channels": ["pH"], "pump": None,
        "onset_s": float(fault.onset_s), "onset_index": k0, "onset_line": k0 + 2,
        "size": 0.0 if fault.size is None else float(fault.size), "unit": spec.inject.unit, "seed": int(fault.seed),
        "closed_loop": closed,
        "description": f"{fault.kind}{amount} on {seen} from {fault.onset_s:g} s (record time): "
                       f"{spec.inject.what.replace('SIZE', f'{fault.size if fault.size is not None else 0:g}')}",
        "source": f"phfdi rig-sim --operation {op.name}",
        "resolution": {"value": PH_RESOLUTION, "unit": "pH", "clipped_to": [PH_MIN, PH_MAX]},
    }
