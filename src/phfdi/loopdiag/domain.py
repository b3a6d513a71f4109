"""Domain-randomised closed loops: the only labelled training data of the stiction verdict.

The refinery records are a test set; nothing is fitted on them. So the simulator has to cover what a plant's
historian shows, wide enough that a real loop looks like one more draw (domain randomisation, Tobin et al. 2017;
for stiction, Damarla et al. train on simulation and test on industrial loops). Every loop of
:func:`draw_domain_loops` is a PI loop of :func:`.synthetic.simulate_loop` with every property drawn at random,
the same way for every class, so that no property but the valve tells the label:

* **process**: self-regulating (first order, time constant 0.2 to 40 samples: fast flows and pressures to slow
  temperatures; a second lag in 30 %) or integrating (a level, 35 %; a short lag); dead time 0 to about 10
  samples; gain of either sign (direct-acting loops); sample time 1 to 60 s and any PV level;
* **tuning**: SIMC (Skogestad 2003) with the closed-loop time constant 0.5 to 10 times the rule's (aggressive
  to sluggish, as plant loops mostly are), in 30 % of the loops stretched 2 to 8 times more (detuned: OP creeps
  for minutes after an upset), then Kp and Ti each off the rule by up to 2 and 3 times (irregular tuning);
* **disturbances**, each with its own probability: a first-order filtered load (coloured, any bandwidth), a
  random-walk load, load steps, load ramps, an operator's setpoint steps (half the loops), a setpoint wandering
  like a cascade master's output;
* **measurement**: white or coloured (AR(1)) noise of 0.01 to 0.5 % of travel in PV units, PV rounded to the
  historian's resolution, OP rounded, and exception-based storage (PV and OP held flat until they move past a
  dead-band) in a quarter of the loops.

Classes (:data:`CLASS_SHARES`): half the loops have a sticky valve (Kano et al. 2004 or He et al. 2007, S from
0.3 to 8 % of travel); of the other half, half are the **hard negatives** the earlier classifier called sticky:
loops tuned too tight (gain margin 1.1 to 1.8: they ring and cycle on their own) and loops cycling with an
external oscillation (an upstream loop's: a sine, a soft square wave, a triangle or a sawtooth, entering ahead
of the valve or at PV); the rest are healthy loops answering load steps and ramps, healthy loops under the
background disturbances, and valves with another nonlinearity (dead-zone, quantisation, saturation: not
stiction). Sticky loops get the same external oscillations and tight tunings now and then, so neither tells
the label.

**A sticky valve must show.** A valve that never broke away in the record (OP never travelled S) leaves no trace
in OP and PV, and its label would only be noise: a sticky loop is kept only when its stem (known in simulation)
slipped at least :data:`MIN_SLIPS` times, each a break-away after it stood still while OP moved, or once after
standing :data:`LONG_STAND` samples or more (a detuned loop's OP creeping through the dead-band after a setpoint
step, then one slip: a pattern of plant records); the others are redrawn and counted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from phfdi.records.record import Record

from .synthetic import WAVEFORMS, SyntheticLoop, simulate_loop
from .training import DrawnLoop, _logu
from .vocabulary import DOMAIN_DRAWS, OTHER_NONLINEARITIES

SAMPLES = 751
#: sample times drawn (s): the indicators read time in samples; the sample time only names the seconds
SAMPLE_TIMES_S = (1.0, 2.0, 5.0, 10.0, 30.0, 60.0)
#: the classes and their shares of the loops drawn (the hard negatives, tuning and external, half the negatives)
CLASS_SHARES = {"stiction": 0.5, "tight_tuning": 0.125, "external_oscillation": 0.125, "load_steps": 0.1,
                "healthy_other": 0.1, "other_nonlinearity": 0.05}
CLASSES = tuple(CLASS_SHARES)
#: a sticky valve must have slipped this many times in the record to be labelled (module docstring) ...
MIN_SLIPS = 3
#: ... or at least once after standing this many samples while OP travelled (one long stand and slip shows)
LONG_STAND = 30
#: share of the loops (of every class but the tight ones) detuned beyond SIMC's sluggish end, and by how much
#: their closed-loop time constant is stretched further
DETUNED_SHARE = 0.3
DETUNED_FACTOR = (2.0, 8.0)
#: share of the loops whose operator moves the setpoint during the record
SETPOINT_STEP_SHARE = 0.5


@dataclass(frozen=True)
class Process:
    """A process in samples: gain (PV units per % of travel, per % per sample when integrating), lags and dead
    time in samples."""

    integrating: bool
    gain: float
    tau_n: float
    tau2_n: float
    theta_n: int


def _draw_process(rng: np.random.Generator) -> Process:
    integrating = rng.random() < 0.35
    sign = -1.0 if rng.random() < 0.3 else 1.0
    theta_n = min(int(_logu(rng, 0.5, 12.0)) if rng.random() < 0.8 else 0, 10)
    if integrating:
        return Process(True, sign * _logu(rng, 0.002, 0.05), _logu(rng, 0.2, 5.0), 0.0, min(theta_n, 5))
    tau_n = _logu(rng, 0.2, 40.0)
    tau2_n = tau_n * rng.uniform(0.1, 0.5) if rng.random() < 0.3 else 0.0
    return Process(False, sign * _logu(rng, 0.2, 5.0), tau_n, tau2_n, theta_n)


def simc(p: Process, ratio: float) -> tuple[float, float]:
    """SIMC PI tuning (Skogestad 2003) in samples: (Kc in % per PV unit, Ti in samples) for a closed-loop time
    constant ``ratio`` times the effective dead time (the second lag counted half as dead time)."""
    theta = p.theta_n + 1.0 + 0.5 * p.tau2_n  # the simulator's one-sample input delay included
    lam = ratio * max(theta, 0.3 * p.tau_n if not p.integrating else theta)
    g = abs(p.gain)
    if p.integrating:
        return 1.0 / (g * (lam + theta)), 4.0 * (lam + theta)
    return p.tau_n / (g * (lam + theta)), max(min(p.tau_n, 4.0 * (lam + theta)), 1.0)


def loop_frequency_response(p: Process, kc: float, ti_n: float, w: np.ndarray) -> np.ndarray:
    """L(e^jw) = C G of the simulated loop (PI in position form, zero-order hold, the one-sample input delay)."""
    z1 = np.exp(-1j * w)  # z^-1
    c = kc * (1.0 + (1.0 / ti_n) * z1 / (1.0 - z1))
    if p.integrating:
        g = abs(p.gain) * z1 / (1.0 - z1)
        if p.tau_n > 0:
            a = math.exp(-1.0 / p.tau_n)
            g = g * (1.0 - a) / (1.0 - a * z1)
    else:
        a = math.exp(-1.0 / p.tau_n)
        g = abs(p.gain) * (1.0 - a) * z1 / (1.0 - a * z1)
        if p.tau2_n > 0:
            a2 = math.exp(-1.0 / p.tau2_n)
            g = g * (1.0 - a2) / (1.0 - a2 * z1)
    return c * g * z1 ** p.theta_n


def gain_margin(p: Process, kc: float, ti_n: float) -> float:
    """1 / |L| where the loop's phase first crosses -180 degrees (inf when it never does)."""
    w = np.linspace(1e-3, math.pi, 4000)
    phase = np.unwrap(np.angle(loop_frequency_response(p, kc, ti_n, w)))
    cross = np.flatnonzero(phase <= -math.pi)
    if cross.size == 0:
        return math.inf
    return float(1.0 / abs(loop_frequency_response(p, kc, ti_n, w[cross[:1]])[0]))


def _tuning(rng: np.random.Generator, p: Process, tight: bool) -> tuple[float, float]:
    """(Kc, Ti in samples): irregular SIMC; ``tight``: Ti 0.2 to 1 times the aggressive rule's and Kc raised
    until the gain margin is 1.1 to 1.8 (a loop that rings or cycles on its own)."""
    if not tight:
        ratio = _logu(rng, 0.5, 10.0)
        if rng.random() < DETUNED_SHARE:  # detuned for safety, as many plant loops are (OP creeps for minutes)
            ratio *= _logu(rng, *DETUNED_FACTOR)
        kc, ti = simc(p, ratio)
        return kc * _logu(rng, 0.5, 2.0), max(ti * _logu(rng, 0.33, 3.0), 1.0)
    kc, ti = simc(p, 0.5)
    ti = max(ti * _logu(rng, 0.2, 1.0), 1.0)
    gm = gain_margin(p, kc, ti)
    target = rng.uniform(1.1, 1.8)
    return (kc * gm / target if math.isfinite(gm) else kc * 3.0), ti


def _background(rng: np.random.Generator, p: Process, n: int, pv_scale: float, kw: dict) -> list[str]:
    """The disturbances every class draws from (added to ``kw``); their names."""
    dt = kw["dt_s"]
    names = []
    if rng.random() < 0.5:
        kw["load_ar_std"], kw["load_ar_pole"] = _logu(rng, 0.05, 2.0), 1.0 - _logu(rng, 0.005, 0.2)
        names.append("load_ar")
    if rng.random() < 0.25:
        kw["load_walk_std"] = _logu(rng, 0.002, 0.05)
        names.append("load_walk")
    if rng.random() < 0.25:
        _load_steps(rng, n, dt, kw)
        names.append("load_steps")
    if rng.random() < 0.15:
        _load_ramps(rng, n, dt, kw)
        names.append("load_ramps")
    sp = kw["pv0"]
    steps = [(float(rng.uniform(0.0, 0.05) * n * dt), sp + float(pv_scale * rng.uniform(-1.0, 1.0)))]
    if rng.random() < SETPOINT_STEP_SHARE:
        for t in np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 5)))) * n * dt:
            steps.append((float(t), sp + float(rng.choice([-1, 1]) * pv_scale * _logu(rng, 0.3, 5.0))))
        names.append("setpoint_steps")
    kw["setpoint_steps"] = steps
    if rng.random() < 0.15:
        kw["sp_ar_std"], kw["sp_ar_pole"] = pv_scale * _logu(rng, 0.2, 3.0), float(rng.uniform(0.8, 0.99))
        names.append("cascade_setpoint")
    return names


def _load_steps(rng: np.random.Generator, n: int, dt: float, kw: dict) -> None:
    times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 7)))) * n * dt
    kw["load_steps"] = [(float(t), float(rng.choice([-1, 1]) * _logu(rng, 0.3, 6.0))) for t in times]


def _load_ramps(rng: np.random.Generator, n: int, dt: float, kw: dict) -> None:
    starts = np.sort(rng.uniform(0.05, 0.8, int(rng.integers(1, 4)))) * n * dt
    kw["load_ramps"] = [(float(t), float(_logu(rng, 10, 200) * dt), float(rng.choice([-1, 1]) * _logu(rng, 0.3, 6.0)))
                        for t in starts]


def _external(rng: np.random.Generator, pv_scale: float, kw: dict) -> str:
    """An oscillation from outside the loop: at the process input (an upstream loop cycling; any waveform) or
    added to PV (a sine), period 5 to 200 samples, 0.3 to 5 % of travel."""
    period_s = _logu(rng, 5.0, 200.0) * kw["dt_s"]
    amp = _logu(rng, 0.3, 5.0)
    if rng.random() < 0.7:
        wave = str(rng.choice(WAVEFORMS))
        kw["input_oscillation"] = (amp, period_s, wave, float(rng.uniform(0, 2 * math.pi)))
        return f"external_{wave}"
    kw["disturbance_amplitude"], kw["disturbance_period_s"] = pv_scale * amp, period_s
    return "external_pv_sine"


def _measurement(rng: np.random.Generator, pv_scale: float, kw: dict) -> None:
    noise = pv_scale * _logu(rng, 0.01, 0.5)
    kw["noise_std"] = noise
    if rng.random() < 0.4:
        kw["noise_pole"] = float(rng.uniform(0.3, 0.9))
    if rng.random() < 0.25:
        kw["pv_quantum"] = noise * rng.uniform(0.5, 3.0)
    if rng.random() < 0.15:
        kw["op_quantum"] = _logu(rng, 0.01, 0.1)
    if rng.random() < 0.25:
        kw["pv_compression"] = noise * _logu(rng, 0.5, 2.0)
        kw["op_compression"] = _logu(rng, 0.02, 0.2)


def _valve(rng: np.random.Generator, loop_class: str, op0: float) -> tuple[str, dict] | None:
    """The valve of a loop of ``loop_class`` (block name, parameters in % of travel); None: a healthy valve. A
    saturating valve cannot open past a limit a little above the loop's working point ``op0``."""
    d = DOMAIN_DRAWS
    if loop_class == "stiction":
        s = _logu(rng, *d["stiction"]["s_pct"])
        if rng.random() < 0.5:
            return ("stiction", {"s_pct": s, "j_pct": s * float(rng.uniform(*d["stiction"]["j_over_s"]))})
        return ("stiction_he", {"fs_pct": s, "fd_pct": s * float(rng.uniform(*d["stiction_he"]["fd_over_fs"]))})
    if loop_class != "other_nonlinearity":
        return None
    kind = str(rng.choice(OTHER_NONLINEARITIES))
    if kind == "deadzone":
        return (kind, {"width_pct": _logu(rng, *d["deadzone"]["width_pct"])})
    if kind == "quantization":
        return (kind, {"step_pct": _logu(rng, *d["quantization"]["step_pct"])})
    return (kind, {"low_pct": d["saturation"]["low_pct"], "high_pct": op0 + _logu(rng, *d["saturation"]["above"])})


def draw_domain_spec(rng: np.random.Generator, loop_class: str, tag: str) -> DrawnLoop:
    """One loop of ``loop_class`` (:data:`CLASSES`); see the module docstring."""
    if loop_class not in CLASSES:
        raise ValueError(f"unknown loop class {loop_class!r}; one of {CLASSES}")
    p = _draw_process(rng)
    dt = float(rng.choice(SAMPLE_TIMES_S))
    tight = loop_class == "tight_tuning" or (loop_class == "stiction" and rng.random() < 0.15)
    kc, ti_n = _tuning(rng, p, tight)
    pv_scale = abs(p.gain) * (30.0 if p.integrating else 1.0)
    op0 = float(rng.uniform(20.0, 80.0))
    kw: dict = {"dt_s": dt, "pv0": _logu(rng, 1.0, 1000.0), "op0_pct": op0}
    conditions = _background(rng, p, SAMPLES, pv_scale, kw)
    if loop_class == "load_steps":
        _load_steps(rng, SAMPLES, dt, kw)
        if rng.random() < 0.4:
            _load_ramps(rng, SAMPLES, dt, kw)
        conditions = sorted({*conditions, "load_steps"})
    if loop_class == "external_oscillation" or (loop_class != "tight_tuning" and rng.random() < 0.1):
        conditions.append(_external(rng, pv_scale, kw))
    _measurement(rng, pv_scale, kw)
    valve = _valve(rng, loop_class, op0)
    spec = SyntheticLoop(process="integrating" if p.integrating else "foptd", gain=p.gain / (dt if p.integrating else 1.0),
                         time_constant_s=p.tau_n * dt, time_constant2_s=p.tau2_n * dt, dead_time_s=p.theta_n * dt,
                         duration_s=SAMPLES * dt, kp=kc, ti_s=ti_n * dt, valve=valve,
                         seed=int(rng.integers(0, 2 ** 31 - 1)), loop_tag=tag, **kw)
    return DrawnLoop(spec, loop_class == "stiction", tuple(conditions) or ("quiet",),
                     "integrating" if p.integrating else "self_regulating", loop_class)


def stands(stem: np.ndarray, op: np.ndarray) -> list[int]:
    """Lengths (samples) of the stands of a simulated stem that ended in a break-away: it stood still for at
    least two samples while OP moved, then moved."""
    still = np.abs(np.diff(stem)) == 0.0
    out, run, travel = [], 0, 0.0
    dop = np.abs(np.diff(op))
    for k in range(len(still)):
        if still[k]:
            run += 1
            travel += dop[k]
            continue
        if run >= 2 and travel > 0:
            out.append(run)
        run, travel = 0, 0.0
    return out


def slips(stem: np.ndarray, op: np.ndarray) -> int:
    """Break-aways of a simulated stem: it moves after standing still for at least two samples while OP moved."""
    return len(stands(stem, op))


def sticking_shows(stem: np.ndarray, op: np.ndarray) -> bool:
    """A sticky valve that shows in the record: :data:`MIN_SLIPS` break-aways, or one after a stand of
    :data:`LONG_STAND` samples or more (a detuned loop's OP creeping through the dead-band, then a slip)."""
    st = stands(stem, op)
    return len(st) >= MIN_SLIPS or (len(st) >= 1 and max(st) >= LONG_STAND)


def valve_effect_on_pv(spec: SyntheticLoop, run: Record | None = None) -> float:
    """How far the loop's valve moves PV, in units of PV's measurement noise: the standard deviation of PV's
    difference from the same loop with a linear valve (the same loads, setpoint moves and noise draws, so the
    difference is the valve's doing, through the loop's dynamics and its controller), divided by
    ``spec.noise_std``. 0 for a linear valve; inf for a noiseless loop whose valve moves PV at all. Which
    stiction a diagnosis can find depends on this more than on the valve's size (docs/loop_diagnosis.md).
    ``run``: the loop's simulated record, when already at hand."""
    if spec.valve is None:
        return 0.0
    with_valve = simulate_loop(spec) if run is None else run
    linear = simulate_loop(replace(spec, valve=None))
    effect = float(np.std(np.asarray(with_valve["pv"], float) - np.asarray(linear["pv"], float)))
    if spec.noise_std > 0:
        return effect / spec.noise_std
    return 0.0 if effect == 0.0 else math.inf


def usable(run: Record) -> bool:
    """An operable loop: OP pinned at a limit for under 5 % of the record, PV finite."""
    op = run["op_pct"]
    return float(np.mean((op <= 0.01) | (op >= 99.99))) < 0.05 and bool(np.all(np.isfinite(run["pv"])))


def class_sequence(n: int) -> list[str]:
    """``n`` classes in the shares of :data:`CLASS_SHARES`, interleaved (stiction every other loop)."""
    others = [c for c in CLASSES if c != "stiction"]
    weights = np.array([CLASS_SHARES[c] for c in others])
    counts = np.floor(weights / weights.sum() * (n - n // 2 - (n % 2))).astype(int)
    neg_total = n - (n + 1) // 2
    counts[0] += neg_total - counts.sum()
    negatives = [c for c, k in zip(others, counts) for _ in range(k)]
    order = np.random.default_rng(len(negatives)).permutation(len(negatives))
    negatives = [negatives[i] for i in order]
    out = []
    for i in range(n):
        out.append("stiction" if i % 2 == 0 else negatives[i // 2])
    return out


def draw_domain_loops(n: int, seed: int, prefix: str = "DOM",
                      limit: int | None = None) -> tuple[list[tuple[DrawnLoop, Record]], dict]:
    """``n`` usable loops in the class shares (:func:`class_sequence`), each simulated; sticky valves that did not
    show (:func:`sticking_shows`) are redrawn. Also returns counts of what was redrawn and why. ``limit``: only the
    first that many of the ``n`` (the same loops, drawn from the same stream)."""
    rng = np.random.default_rng(seed)
    out, redrawn = [], {"unusable": 0, "sticky_valve_never_slipped": 0}
    for k, cls in enumerate(class_sequence(n)[:limit]):
        for _ in range(200):
            loop = draw_domain_spec(rng, cls, f"{prefix}{seed}_{k:05d}")
            run = simulate_loop(loop.spec)
            run.metadata["process_type"] = loop.process_type
            if not usable(run):
                redrawn["unusable"] += 1
                continue
            if loop.stiction and not sticking_shows(run["stem_pct"], run["op_pct"]):
                redrawn["sticky_valve_never_slipped"] += 1
                continue
            out.append((loop, run))
            break
        else:
            raise RuntimeError(f"the generator keeps drawing unusable {cls} loops")
    return out, redrawn
