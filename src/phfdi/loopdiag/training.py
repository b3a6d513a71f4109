"""Synthetic loops for training and checking the stiction classifier (the project's own simulator).

:func:`draw_loops` draws closed loops from :func:`phfdi.loopdiag.synthetic.simulate_loop` across the
conditions a refinery historian shows, the same for loops with a sticky valve (Kano et al. 2004
model, :class:`valve_actuator.blocks.Stiction`) and with a healthy one, so that no condition tells
the label by itself:

* process: self-regulating (first order plus dead time, time constant 0.3 to 20 samples, dead
  time 0 to 8 samples, dead-time dominant included) or integrating (a level, with a short lag);
* tuning: SIMC-style (Skogestad 2003) with the closed-loop time constant 0.3 to 3 times the dead
  time or lag, i.e. from aggressive (oscillating) to sluggish;
* disturbances: a random-walk load, a first-order filtered load, load steps, a sinusoidal
  disturbance on PV, setpoint steps (each loop gets none, one or two of these), each about as
  large in % of valve travel as the valve faults (loads of 0.1 to 1 %, steps and sinusoids of 0.2 to
  3 %): a record whose PV is dominated by a disturbance many times the valve's stiction shows no
  stiction to any method, and its label would only be noise;
* measurement: white noise of 0.02 to 0.3 % of span in PV units, and in a third of the loops PV
  rounded to the historian's resolution;
* stiction (ranges in :mod:`.vocabulary`): half of the sticky valves follow Kano et al.'s model (S from 0.3 to 6 % of span, J from
  0 to 1.2 S), half He et al.'s (2007: fs from 0.3 to 6 %, fd from 0 to fs), which sticks again
  after every slip; the Hammerstein features fit Kano's model only, so the He valves check that
  the classifier does not merely recognise its own model.

Records are 751 samples at 10 s, like the shared refinery records. Every draw is reproducible from
its seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phfdi.records.record import Record

from .synthetic import SyntheticLoop, simulate_loop
from .vocabulary import OTHER_NONLINEARITIES
from .vocabulary import TRAINING_DRAWS as DRAWS

DT_S = 10.0
SAMPLES = 751
CONDITIONS = ("load_walk", "load_ar", "load_steps", "sine_disturbance", "setpoint_steps")
#: a loop drawn with no disturbance condition is listed under this one
QUIET = "quiet"


@dataclass(frozen=True)
class DrawnLoop:
    spec: SyntheticLoop
    stiction: bool
    conditions: tuple[str, ...]
    process_type: str
    #: the loop's class in :data:`LOOP_CLASSES` ("" for :func:`draw_spec`'s loops)
    loop_class: str = ""

    @property
    def group(self) -> str:
        return self.spec.loop_tag


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def draw_spec(rng: np.random.Generator, stiction: bool, tag: str) -> DrawnLoop:
    """One loop (see the module docstring for the ranges)."""
    dt = DT_S
    duration = SAMPLES * dt
    integrating = rng.random() < 0.35
    theta_n = int(rng.integers(0, 9)) if not integrating else int(rng.integers(0, 4))
    aggr = _logu(rng, 0.3, 3.0)  # closed-loop time constant over the dead time / lag
    if integrating:
        gain = _logu(rng, 0.0005, 0.01)  # PV units per % per s
        tau = _logu(rng, 0.3, 3.0) * dt
        theta = theta_n * dt
        lam = aggr * (theta + tau + dt)
        kp = 1.0 / (gain * (lam + theta + tau))
        ti = 4.0 * (lam + theta + tau) * _logu(rng, 0.6, 1.6)
    else:
        gain = _logu(rng, 0.3, 3.0)  # PV units per %
        tau = _logu(rng, 0.3, 20.0) * dt
        theta = theta_n * dt
        lam = aggr * max(theta + dt, 0.3 * tau)
        kp = tau / (gain * (lam + theta + 0.5 * dt)) * _logu(rng, 0.7, 1.4)
        ti = min(tau, 4.0 * (lam + theta + dt)) * _logu(rng, 0.5, 2.0)
        ti = max(ti, dt)
    pv_scale = gain * (1.0 if not integrating else 30.0 * dt)  # PV units per % of travel (over ~30 samples)
    n_cond = int(rng.integers(0, 3))
    conditions = tuple(sorted(rng.choice(CONDITIONS, size=n_cond, replace=False).tolist())) or (QUIET,)
    kw: dict = {}
    if "load_walk" in conditions:
        kw["load_walk_std"] = _logu(rng, 0.005, 0.05)
    if "load_ar" in conditions:
        kw["load_ar_std"] = _logu(rng, 0.1, 1.0)
        kw["load_ar_pole"] = float(rng.uniform(0.8, 0.99))
    if "load_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 5)))) * duration
        kw["load_steps"] = [(float(t), float(rng.choice([-1, 1]) * rng.uniform(0.5, 3.0))) for t in times]
    if "sine_disturbance" in conditions:
        kw["disturbance_amplitude"] = float(pv_scale * rng.uniform(0.2, 1.5))
        kw["disturbance_period_s"] = float(rng.uniform(10, 80) * dt)
    sp_steps = []
    if "setpoint_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 4)))) * duration
        sp = 50.0
        for t in times:
            sp = 50.0 + float(rng.choice([-1, 1]) * pv_scale * rng.uniform(0.5, 3.0))
            sp_steps.append((float(t), sp))
    else:
        # a loop at rest with a sticky valve never slips: historian records start mid-operation
        sp_steps.append((float(rng.uniform(0.0, 0.05) * duration), 50.0 + float(pv_scale * rng.uniform(0.2, 1.0))))
    noise = float(pv_scale * _logu(rng, 0.02, 0.3))
    quantum = float(noise * rng.uniform(0.5, 3.0)) if rng.random() < 0.33 else 0.0
    valve = None
    if stiction:
        valve = _sticky_valve(rng)
    spec = SyntheticLoop(process="integrating" if integrating else "foptd", gain=gain, time_constant_s=tau,
                         dead_time_s=theta, dt_s=dt, duration_s=duration, kp=kp, ti_s=ti, valve=valve,
                         setpoint_steps=sp_steps, noise_std=noise, pv_quantum=quantum,
                         seed=int(rng.integers(0, 2 ** 31 - 1)), loop_tag=tag, **kw)
    return DrawnLoop(spec, stiction, conditions, "integrating" if integrating else "self_regulating")


def usable(run: Record) -> bool:
    """A loop an operator would run: OP not pinned at a limit for more than a fifth of the record,
    PV not diverging."""
    op = run["op_pct"]
    at_limit = float(np.mean((op <= 0.01) | (op >= 99.99)))
    return at_limit < 0.2 and bool(np.all(np.isfinite(run["pv"])))


def _at_limits(run: Record) -> float:
    op = run["op_pct"]
    return float(np.mean((op <= 0.01) | (op >= 99.99)))


def draw_loops(n: int, seed: int, prefix: str = "SYN") -> list[tuple[DrawnLoop, Record]]:
    """n loops, half with stiction (alternating), each simulated; unusable draws are redrawn."""
    rng = np.random.default_rng(seed)
    out: list[tuple[DrawnLoop, Record]] = []
    i = 0
    while len(out) < n:
        stiction = len(out) % 2 == 0
        loop = draw_spec(rng, stiction, f"{prefix}{seed}_{len(out):04d}")
        i += 1
        run = simulate_loop(loop.spec)
        run.metadata["process_type"] = loop.process_type
        if usable(run):
            out.append((loop, run))
        if i > 20 * n:
            raise RuntimeError("the generator keeps drawing unusable loops")
    return out


# ---- loops by class: the generator with the conditions users see false alarms under ----------
#: healthy valves: answering load steps and ramps, tuned to oscillate, under other disturbances;
#: sticky valves (Kano or He); other valve nonlinearities (dead-zone, quantisation, saturation:
#: not stiction); backlash (a dead-band, Kano's model with J = 0: reported apart, not scored)
LOOP_CLASSES = ("healthy_load_steps", "healthy_oscillatory_tuning", "healthy_other", "stiction",
                "other_nonlinearity", "backlash")
CONDITIONS_BY_CLASS = CONDITIONS + ("load_ramps",)


def _tuning(rng: np.random.Generator, integrating: bool, gain: float, tau: float, theta: float,
            oscillatory: bool) -> tuple[float, float]:
    """(Kp, Ti): SIMC-style (Skogestad 2003) as in :func:`draw_spec`; ``oscillatory``: a loop tuned
    tighter than SIMC allows, the common industrial fault - proportional gain 1.5 to 3 times and
    integral time 0.25 to 1 times the rule's at an aggressive closed-loop time constant, so the
    loop rings or cycles on its own (an underdamped, healthy loop)."""
    dt = DT_S
    aggr = _logu(rng, 0.3, 1.0) if oscillatory else _logu(rng, 0.3, 3.0)
    if integrating:
        lam = aggr * (theta + tau + dt)
        kp = 1.0 / (gain * (lam + theta + tau))
        ti = 4.0 * (lam + theta + tau) * _logu(rng, 0.6, 1.6)
    else:
        lam = aggr * max(theta + dt, 0.3 * tau)
        kp = tau / (gain * (lam + theta + 0.5 * dt)) * _logu(rng, 0.7, 1.4)
        ti = max(min(tau, 4.0 * (lam + theta + dt)) * _logu(rng, 0.5, 2.0), dt)
    if oscillatory:
        kp *= _logu(rng, 1.5, 3.0)
        ti = max(ti * _logu(rng, 0.25, 1.0), dt)
    return kp, ti


def _draw_class_conditions(rng: np.random.Generator, loop_class: str) -> tuple[str, ...]:
    """The disturbances and setpoint moves a loop of ``loop_class`` sees (names of
    :data:`CONDITIONS_BY_CLASS`, ``load_steps`` always for ``healthy_load_steps``)."""
    if loop_class == "healthy_load_steps":
        extra = rng.choice(("load_walk", "load_ar", "setpoint_steps", "load_ramps"), size=int(rng.integers(0, 2)),
                           replace=False).tolist()
        return tuple(sorted({"load_steps", *extra}))
    if loop_class == "healthy_oscillatory_tuning":
        pool = ("load_walk", "load_ar", "load_steps", "load_ramps", "setpoint_steps")
        return tuple(sorted(rng.choice(pool, size=int(rng.integers(1, 3)), replace=False).tolist()))
    n_cond = int(rng.integers(0, 3))
    return tuple(sorted(rng.choice(CONDITIONS_BY_CLASS, size=n_cond, replace=False).tolist())) or (QUIET,)


def _draw_class_valve(rng: np.random.Generator, loop_class: str) -> tuple[str, dict] | None:
    """The valve model of a loop of ``loop_class`` as (block name, parameters in % of travel);
    None for a healthy valve."""
    if loop_class == "stiction":
        return _sticky_valve(rng)
    if loop_class == "other_nonlinearity":
        kind = str(rng.choice(OTHER_NONLINEARITIES))
        d = DRAWS[kind]
        if kind == "deadzone":
            return (kind, {"width_pct": _logu(rng, *d["width_pct"])})
        if kind == "quantization":
            return (kind, {"step_pct": _logu(rng, *d["step_pct"])})
        # the stem cannot open past a limit a little above where the loop works
        return (kind, {"low_pct": d["low_pct"], "high_pct": d["high_pct"]["base"] + _logu(rng, *d["high_pct"]["above"])})
    if loop_class == "backlash":
        return ("backlash", {"width_pct": _logu(rng, *DRAWS["backlash"]["width_pct"])})
    return None


def _sticky_valve(rng: np.random.Generator) -> tuple[str, dict]:
    """Kano's stiction or He's, half each, S (fs) and J/S (fd/fs) drawn over the vocabulary's ranges."""
    s = _logu(rng, *DRAWS["stiction"]["s_pct"])
    if rng.random() < 0.5:
        return ("stiction", {"s_pct": s, "j_pct": s * float(rng.uniform(*DRAWS["stiction"]["j_over_s"]))})
    return ("stiction_he", {"fs_pct": s, "fd_pct": s * float(rng.uniform(*DRAWS["stiction_he"]["fd_over_fs"]))})


def draw_class_spec(rng: np.random.Generator, loop_class: str, tag: str) -> DrawnLoop:
    """One loop of ``loop_class`` (:data:`LOOP_CLASSES`). Process, noise, historian resolution and
    setpoint as in :func:`draw_spec`; in addition

    * loads enter as steps of 0.5 to 5 % of valve travel (a feed or a pressure changing upstream)
      and ramps of 0.5 to 5 % over 10 to 150 samples (a feed being moved); a healthy loop answering
      them moves OP to a new level while PV returns, the response that widens the PV-OP ellipse;
    * the historian compresses PV and OP in a quarter of the loops (step-hold dead-band of 0.5 to 2
      noise levels for PV, 0.02 to 0.2 % for OP), which flattens PV like a stuck valve does;
    * ``healthy_oscillatory_tuning`` loops are tuned too tight (:func:`_tuning`), a fifth of the
      sticky valves too.
    """
    if loop_class not in LOOP_CLASSES:
        raise ValueError(f"unknown loop class {loop_class!r}; one of {LOOP_CLASSES}")
    dt = DT_S
    duration = SAMPLES * dt
    integrating = rng.random() < 0.35
    theta_n = int(rng.integers(0, 9)) if not integrating else int(rng.integers(0, 4))
    if integrating:
        gain = _logu(rng, 0.0005, 0.01)
        tau = _logu(rng, 0.3, 3.0) * dt
    else:
        gain = _logu(rng, 0.3, 3.0)
        tau = _logu(rng, 0.3, 20.0) * dt
    theta = theta_n * dt
    oscillatory = loop_class == "healthy_oscillatory_tuning" or (loop_class == "stiction" and rng.random() < 0.2)
    kp, ti = _tuning(rng, integrating, gain, tau, theta, oscillatory)
    pv_scale = gain * (1.0 if not integrating else 30.0 * dt)
    conditions = _draw_class_conditions(rng, loop_class)
    kw: dict = {}
    if "load_walk" in conditions:
        kw["load_walk_std"] = _logu(rng, 0.005, 0.05)
    if "load_ar" in conditions:
        kw["load_ar_std"] = _logu(rng, 0.1, 1.0)
        kw["load_ar_pole"] = float(rng.uniform(0.8, 0.99))
    if "load_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 6)))) * duration
        kw["load_steps"] = [(float(t), float(rng.choice([-1, 1]) * _logu(rng, 0.5, 5.0))) for t in times]
    if "load_ramps" in conditions:
        starts = np.sort(rng.uniform(0.05, 0.8, int(rng.integers(1, 4)))) * duration
        kw["load_ramps"] = [(float(t), float(_logu(rng, 10, 150) * dt), float(rng.choice([-1, 1]) * _logu(rng, 0.5, 5.0)))
                            for t in starts]
    if "sine_disturbance" in conditions:
        kw["disturbance_amplitude"] = float(pv_scale * rng.uniform(0.2, 1.5))
        kw["disturbance_period_s"] = float(rng.uniform(10, 80) * dt)
    sp_steps = []
    if "setpoint_steps" in conditions:
        times = np.sort(rng.uniform(0.05, 0.9, int(rng.integers(1, 4)))) * duration
        for t in times:
            sp_steps.append((float(t), 50.0 + float(rng.choice([-1, 1]) * pv_scale * rng.uniform(0.5, 3.0))))
    else:
        sp_steps.append((float(rng.uniform(0.0, 0.05) * duration), 50.0 + float(pv_scale * rng.uniform(0.2, 1.0))))
    noise = float(pv_scale * _logu(rng, 0.02, 0.3))
    quantum = float(noise * rng.uniform(0.5, 3.0)) if rng.random() < 0.33 else 0.0
    if rng.random() < 0.25:
        kw["pv_compression"] = float(noise * _logu(rng, 0.5, 2.0))
        kw["op_compression"] = _logu(rng, 0.02, 0.2)
    valve = _draw_class_valve(rng, loop_class)
    spec = SyntheticLoop(process="integrating" if integrating else "foptd", gain=gain, time_constant_s=tau,
                         dead_time_s=theta, dt_s=dt, duration_s=duration, kp=kp, ti_s=ti, valve=valve,
                         setpoint_steps=sp_steps, noise_std=noise, pv_quantum=quantum,
                         seed=int(rng.integers(0, 2 ** 31 - 1)), loop_tag=tag, **kw)
    return DrawnLoop(spec, loop_class == "stiction", conditions, "integrating" if integrating else "self_regulating",
                     loop_class)


def draw_class_loops(classes: list[str], seed: int, prefix: str) -> list[tuple[DrawnLoop, Record]]:
    """One usable loop per entry of ``classes`` (in that order), each simulated; unusable draws
    are redrawn from the same random stream."""
    rng = np.random.default_rng(seed)
    out = []
    tries = 0
    for k, cls in enumerate(classes):
        while True:
            tries += 1
            if tries > 20 * max(len(classes), 1):
                raise RuntimeError("the generator keeps drawing unusable loops")
            loop = draw_class_spec(rng, cls, f"{prefix}{seed}_{k:04d}")
            run = simulate_loop(loop.spec)
            run.metadata["process_type"] = loop.process_type
            if usable(run) and _at_limits(run) < 0.05:  # a healthy loop does not bang between limits
                out.append((loop, run))
                break
    return out


def class_round_robin(per_class: int) -> list[str]:
    """Every class of :data:`LOOP_CLASSES` ``per_class`` times, round robin (the fresh test set)."""
    return [c for _ in range(per_class) for c in LOOP_CLASSES]
