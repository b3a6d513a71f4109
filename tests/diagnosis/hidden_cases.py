"""Measured data with a hidden effect, for the diagnosis tests and benchmarks/diagnose_hidden.py.

The effect is drawn at random from the catalogue within the identifiability
bounds below, simulated with the project's simulator (closed loop, or open
loop from a random valve-command sequence) with measurement noise, and the
data are written to a neutral file name (``record.csv``) with only what a
plant historian holds: time, valve command, outlet (level controller)
command, measured pH, measured level. The answer stays in the returned
:class:`HiddenCase`; nothing of it (seed, name, metadata) is in the file.

Bounds are stated for this excitation: the paper's plant at 1 s, pH noise
0.01, level noise 0.02 cm; closed loop: setpoint steps every 400 s between
pH 8 and 11.5, pH 8 and one of 10.5 to 11.5 among them; open loop: a valve
test staircase (reversals of 0.5 to 6 % in 0.5 % steps, 20 s each, 480 s)
then valve command steps between 28 and 62 %, 60 % of them 0.3 to 6 % and
the others 6 to 25 %, held 60 to 250 s. A 600 s warm-up that the data leave
out puts the plant in the steady state of the effect.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ph_plant_sim.build import load_plant_model
from phfdi.loop import simulate, simulate_open_loop
from phfdi.records.record import Record
from phfdi.scenario import raw_scenario
from phfdi_base.blocks import register_block
from phfdi_base.spec import validate_scenario

WARMUP_S = 600.0
COLUMNS = ["time_s", "valve_command_pct", "level_controller_output_pct", "ph_measured", "level_measured_cm"]


def _two_sided(rng, lo: float, hi: float, centre: float) -> float:
    """Uniform in [centre - hi, centre - lo] U [centre + lo, centre + hi]."""
    return centre + rng.choice([-1.0, 1.0]) * rng.uniform(lo, hi)


#: cause -> (bounds text, sampler rng -> params, main parameter, tolerance as (relative, absolute))
BOUNDS = {
    "stiction": ("S 1.5..5 %, J 0.3..0.7 S", lambda r: (lambda s: {"s_pct": s, "j_pct": s * r.uniform(0.3, 0.7)})(
        r.uniform(1.5, 5.0)), "s_pct", (0.2, 0.2)),
    "backlash": ("width 0.5..5 %", lambda r: {"width_pct": r.uniform(0.5, 5.0)}, "width_pct", (0.15, 0.1)),
    "deadzone": ("width 2..20 % about the operating point", lambda r: {"width_pct": r.uniform(2.0, 20.0)},
                 "width_pct", (0.15, 0.5)),
    "saturation": ("high limit 45..58 % (the loop needs 65 % at pH 8)", lambda r: {"high_pct": r.uniform(45.0, 58.0)},
                   "high_pct", (0.0, 1.5)),
    "coulomb_viscous_friction": ("Coulomb 0.5..3 %, mobility 0.02..0.2 1/s",
                                 lambda r: {"coulomb_pct": r.uniform(0.5, 3.0),
                                            "mobility_per_s": math.exp(r.uniform(math.log(0.02), math.log(0.2)))},
                                 "coulomb_pct", (0.2, 0.1)),
    "leakage": ("1..6 mL/s (of 40 mL/s)", lambda r: {"flow_ml_s": r.uniform(1.0, 6.0)}, "flow_ml_s", (0.15, 0.2)),
    "valve_gain": ("gain 0.7..0.9 or 1.1..1.4", lambda r: {"gain": _two_sided(r, 0.1, 0.3, 1.0)}, "gain",
                   (0.05, 0.0)),
    "sensor_delay": ("10..30 s", lambda r: {"delay_s": r.uniform(10.0, 30.0)}, "delay_s", (0.15, 1.0)),
    "sensor_lag": ("time constant 12..60 s", lambda r: {"tau_s": r.uniform(12.0, 60.0)}, "tau_s", (0.2, 1.0)),
    "sensor_bias": ("0.1..0.5 pH either sign", lambda r: {"bias": _two_sided(r, 0.1, 0.5, 0.0)}, "bias",
                    (0.0, 0.03)),
    "sensor_drift": ("0.5..2 pH over the record, either sign", None, "rate_per_s", (0.15, 0.0)),
    "sensor_gain": ("slope 0.85..0.95 or 1.05..1.15 about pH 7", lambda r: {"gain": _two_sided(r, 0.05, 0.15, 1.0)},
                    "gain", (0.0, 0.02)),
    "buffer": ("monoprotic weak acid in the base feed, pKa 8.5..11, 0.005..0.02 mol/L",
               lambda r: {"pka": r.uniform(8.5, 11.0), "conc_mol_l": r.uniform(0.005, 0.02)}, "pka", (0.0, 0.3)),
    "reagent_concentration": ("acid (titrant) concentration x 0.8..0.9 or 1.1..1.25",
                              lambda r: {"factor": (r.uniform(0.8, 0.9) if r.random() < 0.5 else r.uniform(1.1, 1.25))},
                              "factor", (0.05, 0.0)),
    "holdup": ("vessel area x 0.6..0.8 or 1.25..1.6",
               lambda r: {"factor": (r.uniform(0.6, 0.8) if r.random() < 0.5 else r.uniform(1.25, 1.6))},
               "factor", (0.1, 0.0)),
    "disturbance_flow": ("extra base inflow 1..3 mL/s from 20..70 % of the record",
                         None, "flow_ml_s", (0.15, 0.1)),
}

CATALOGUE_CAUSES = tuple(BOUNDS)


@dataclass
class HiddenCase:
    """The answer (for the test only) and where the data are."""

    cause: str
    params: dict
    main: str
    value: float
    tolerance: float
    excitation: str
    path: Path

    def main_ok(self, fitted: dict) -> bool:
        return self.main in fitted and abs(fitted[self.main] - self.value) <= self.tolerance


@register_block("test_alkaline_error")
@dataclass
class AlkalineError:
    """Not in the catalogue: a glass electrode's alkaline (sodium) error, reading low above pH 10.

        y = x - a (x - 10)^2 for x > 10
    """

    a: float
    severity: float = 1.0

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        return x - self.severity * self.a * max(0.0, x - 10.0) ** 2


@register_block("test_periodic_flow")
@dataclass
class PeriodicFlow:
    """Not in the catalogue: a flow that pulses with the valve's supply, q + A sin(2 pi t / P)."""

    amplitude_ml_s: float
    period_s: float
    max_flow_ml_s: float = 1.0
    severity: float = 1.0

    def reset(self, x0: float) -> None:
        pass

    def step(self, x: float, t_s: float) -> float:
        return max(0.0, x + self.severity * self.amplitude_ml_s * math.sin(2 * math.pi * t_s / self.period_s))


def _setpoints(rng, duration_s: float, step_s: float = 400.0,
               high: tuple[float, ...] = (10.5, 11.0, 11.5)) -> dict:
    """Setpoint steps every 400 s, visiting pH 8 (the valve near 65 %) and one of ``high`` (near 30 %)."""
    levels = [8.0, 8.5, 9.0, 9.5, 10.0, 10.5, 11.0, 11.5]
    n = max(1, int((duration_s - 100.0) // step_s))
    seq = [8.0, float(rng.choice(list(high)))][:n]
    while len(seq) < n:
        seq.append(float(rng.choice([v for v in levels if v != seq[-1]])))
    order = rng.permutation(n)
    seq = [seq[i] for i in order]
    for i in range(1, n):  # no two equal neighbours
        if seq[i] == seq[i - 1]:
            seq[i] = 9.5 if seq[i] != 9.5 else 10.0
    # the first change 100 s into the data: the data start in a steady state
    changes = [{"at_s": WARMUP_S + 100.0 + i * step_s, "value": v} for i, v in enumerate(seq)]
    return {"initial": 10.0, "changes": changes}


def _command_sequence(rng, n: int) -> np.ndarray:
    """Open-loop valve test: hold through the warm-up, a staircase of reversals, a stroke to both ends of the
    range, then random steps.

    The staircase (a valve-test pattern: up and back down by 0.5, 1.0, ..., 6 %, each held 20 s) puts command
    moves on both sides of any dead or stick band in the bounds; the stroke (62 % then 28 %, 60 s each) shows
    any stop within the range (without it the random walk stayed below a drawn saturation limit in about one
    1700 s record in four); the random steps (between 28 and 62 %, 60 % of them 0.3 to 6 % and the others 6 to
    25 %, held 60 to 250 s) excite the process.
    """
    level = 45.0
    cmd = [level] * (int(WARMUP_S) + 100)
    for size in np.arange(0.5, 6.01, 0.5):
        cmd += [level + size] * 20 + [level] * 20
    cmd += [62.0] * 60 + [28.0] * 60 + [level] * 60
    while len(cmd) < n:
        size = rng.uniform(0.3, 6.0) if rng.random() < 0.6 else math.exp(rng.uniform(math.log(6.0), math.log(25.0)))
        move = size * rng.choice([-1.0, 1.0])
        level = level + move
        if not 28.0 <= level <= 62.0:
            level = level - 2.0 * move
        level = min(max(level, 28.0), 62.0)
        cmd += [level] * int(rng.uniform(60, 250))
    return np.asarray(cmd[:n], dtype=float)


#: narrower bounds where open-loop excitation cannot see the whole range: its command steps keep the pH above
#: about 9.4, so a buffer's pKa below that shows only its tail (benchmark: pKa 8.8 read as 9.5)
OPEN_LOOP_BOUNDS = {
    "buffer": ("pKa 9.5..11 (open loop), 0.005..0.02 mol/L",
               lambda r: {"pka": r.uniform(9.5, 11.0), "conc_mol_l": r.uniform(0.005, 0.02)}),
}


def true_model(rng, cause: str, duration_s: float, excitation: str = "closed") -> tuple[dict, dict, str, float]:
    """Scenario mapping of the plant with the hidden effect, its parameters, main parameter and value."""
    raw = raw_scenario("paper")
    raw["plant"] = load_plant_model("paper").model_dump(exclude_defaults=True)
    raw["min_actuator_margin_pct"] = 0.0
    raw["faults"] = []
    if cause == "sensor_drift":
        p = {"rate_per_s": _two_sided(rng, 0.5, 2.0, 0.0) / duration_s}
    elif cause == "disturbance_flow":
        p = {"flow_ml_s": float(rng.uniform(1.0, 3.0)), "onset_s": float(rng.uniform(0.2, 0.7) * duration_s)}
    elif excitation == "open" and cause in OPEN_LOOP_BOUNDS:
        p = OPEN_LOOP_BOUNDS[cause][1](rng)
    elif cause in BOUNDS:
        p = BOUNDS[cause][1](rng)
    else:
        p = {}
    p = {k: float(v) for k, v in p.items()}
    main = BOUNDS[cause][2] if cause in BOUNDS else ""
    if cause in ("stiction", "backlash", "deadzone", "coulomb_viscous_friction"):
        raw["faults"] = [{"type": cause, "params": dict(p), "onset_s": 0.0}]
    elif cause == "saturation":
        raw["faults"] = [{"type": "saturation", "params": {"low_pct": 0.0, "high_pct": p["high_pct"]}, "onset_s": 0.0}]
    elif cause == "leakage":
        raw["faults"] = [{"type": "leakage", "where": "valve_flow", "params": dict(p), "onset_s": 0.0}]
    elif cause == "valve_gain":
        raw["valves"]["ph"]["max_flow_ml_s"] *= p["gain"]
    elif cause in ("sensor_delay", "sensor_lag", "sensor_bias", "sensor_gain"):
        raw["faults"] = [{"type": cause, "where": "ph_sensor", "params": dict(p), "onset_s": 0.0}]
    elif cause == "sensor_drift":  # drifting from the first sample of the data
        raw["faults"] = [{"type": cause, "where": "ph_sensor", "params": dict(p), "onset_s": WARMUP_S}]
    elif cause == "buffer":
        chem = raw["plant"].setdefault("chemistry", {})
        chem["components"] = [{"name": "hidden_weak_acid", "charge": 0, "pka": [p["pka"]]}]
        chem["compounds"] = {"HIDDEN_ACID": {"hidden_weak_acid": 1.0}}
        raw["plant"]["feeds"]["base"]["recipe"]["HIDDEN_ACID"] = p["conc_mol_l"]
    elif cause == "reagent_concentration":
        raw["plant"]["feeds"]["acid"]["recipe"]["HNO3"] *= p["factor"]
    elif cause == "holdup":
        raw["plant"]["tank"]["area_cm2"] *= p["factor"]
    elif cause == "disturbance_flow":
        raw["plant"]["feeds"]["base_extra"] = {"recipe": dict(raw["plant"]["feeds"]["base"]["recipe"]),
                                               "flow_ml_s": 0.0}
        raw["feeds"] = {"base_extra": {"initial": 0.0, "changes": [{"at_s": WARMUP_S + p["onset_s"],
                                                                    "value": p["flow_ml_s"]}]}}
    elif cause == "alkaline_error":
        p = {"a": float(rng.uniform(0.15, 0.3))}
        raw["sensors"]["ph"]["extra"] = [{"type": "test_alkaline_error", "params": p}]
    elif cause == "periodic_flow":
        p = {"amplitude_ml_s": float(rng.uniform(1.5, 3.0)), "period_s": float(rng.uniform(150.0, 400.0))}
        raw["faults"] = [{"type": "test_periodic_flow", "where": "valve_flow", "params": p, "onset_s": 0.0}]
    elif cause != "none":
        raise ValueError(f"unknown hidden cause {cause!r}")
    return raw, p, main, p.get(main, math.nan)


def make_case(rng: np.random.Generator, cause: str, excitation: str, out_dir: Path,
              duration_s: float = 2400.0, fresh: np.random.Generator | None = None) -> HiddenCase:
    """Simulate data with ``cause`` hidden (or ``none``, or an effect outside the catalogue) into out_dir/record.csv.

    ``fresh``: draw the noise seed and the excitation from it instead of ``rng`` (the effect's parameters still
    come from ``rng``): a generator in the same state as an earlier call's gives another record of that effect."""
    raw, params, main, value = true_model(rng, cause, duration_s, excitation)
    rng = fresh or rng
    raw["seed"] = int(rng.integers(1, 2**31 - 1))
    raw["duration_s"] = WARMUP_S + duration_s
    raw["sample_time_s"] = 1.0
    if excitation == "closed":
        # an alkaline error reads a (x - 10)^2 low above pH 10: at a pH 10.5 step it is 0.04 pH or less, which a
        # buffer with a probe gain error matches to the noise floor; the experiment has to go where it shows
        high = (11.0, 11.5) if cause == "alkaline_error" else (10.5, 11.0, 11.5)
        raw["setpoints"]["ph"] = _setpoints(rng, duration_s, high=high)
        run = simulate(validate_scenario(raw))
    elif excitation == "open":
        raw["setpoints"]["ph"] = {"initial": 10.0}
        n = int(raw["duration_s"]) + 1
        t = np.arange(n, dtype=float)
        inputs = Record.of({"time_s": t, "valve_command_pct": _command_sequence(rng, n),
                      "level_controller_output_pct": np.full(n, 50.0)})
        run = simulate_open_loop(validate_scenario(raw), inputs)
    else:
        raise ValueError(excitation)
    keep = run.time_s >= WARMUP_S
    data = {c: np.asarray(run[c])[keep] for c in COLUMNS}
    data["time_s"] = data["time_s"] - data["time_s"][0]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = Record.of(data, {}).to_csv(out_dir / "record.csv")
    if cause in BOUNDS:
        rel, absolute = BOUNDS[cause][3]
        tol = max(rel * abs(value), absolute)
    else:
        tol = math.nan
    return HiddenCase(cause, params, main, value, tol, excitation, path)


#: independent draws a seeded hidden-effect test may take: it passes at the first draw that passes. With a
#: per-draw failure rate p (benchmarks/hidden_flake_rates.py measures it with PHFDI_HIDDEN_DRAWS=1) a suite run
#: fails by chance with probability p^3 per test (p = 5 %: 1.3e-4); a method that no longer finds the effect
#: fails every draw. The failure message gives every draw's reason.
HIDDEN_DRAWS = max(1, int(os.environ.get("PHFDI_HIDDEN_DRAWS", "3")))


def fresh_draws(test):
    """Run a test taking ``hidden_rng`` on up to HIDDEN_DRAWS independent draws (children of the seed's generator:
    the first draw is the seed's own, as before; the others reproducible from the same seed). A test taking
    ``tmp_path`` gets a fresh folder for each draw: a draw must not meet the files an earlier draw left."""

    @functools.wraps(test)
    def run(*args, **kwargs):
        rng = kwargs["hidden_rng"]
        base_dir = kwargs.get("tmp_path")
        draws = [rng, *rng.spawn(HIDDEN_DRAWS - 1)]  # spawning leaves the first draw's stream as it was
        failures = []
        for k, draw in enumerate(draws):
            kwargs["hidden_rng"] = draw
            if base_dir is not None:
                kwargs["tmp_path"] = Path(base_dir) / f"draw{k + 1}"
                kwargs["tmp_path"].mkdir(parents=True, exist_ok=False)
            try:
                return test(*args, **kwargs)
            except AssertionError as exc:
                failures.append(f"draw {k + 1} of {len(draws)}: {str(exc).splitlines()[0] if str(exc) else exc!r}")
        raise AssertionError("every draw failed:\n" + "\n".join(failures))

    return run
