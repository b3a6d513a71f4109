"""The catalogue of model extensions a diagnosis tries.

Each candidate is one cause of the shared catalogue
(:data:`phfdi.diagnosis.report.CAUSES`) with its parameters, their search
bounds and start points, and how it extends a model: every extension is an
edit of the scenario mapping (a block in ``faults`` or ``sensors.ph.extra``,
a changed valve or plant-model parameter, an extra feed), so the fitted model
is a file the simulator loads.

* actuator (the pH valve; needs the valve command in the data): stiction
  (Kano), backlash, deadzone (about the first command), saturation,
  coulomb_viscous_friction, leakage (flow blocks of ``valve_actuator``) and
  valve_gain (the valve's maximum flow);
* sensor (the pH probe; blocks of ``ph_plant_sim.sensors`` after the
  model's own): sensor_delay, sensor_lag, sensor_bias, sensor_drift,
  sensor_gain (about pH 7);
* process (the plant model): buffer (a monoprotic weak acid of unknown pKa
  carried by one feed, e.g. carbonate from CO2 absorbed by caustic),
  reagent_concentration (one feed's concentrations scaled), holdup (vessel
  area, or volume of an overflow vessel, scaled) and disturbance_flow (an
  unmeasured extra inflow with one feed's composition, from an onset time).

Candidates whose answer depends on a feed are tried once per feed
("variants"); the best variant stands for the cause.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from phfdi.faults import block_name
from phfdi.faults import catalogue as fault_catalogue
from phfdi_base.errors import UserError
from phfdi_base.faults import Fault

from .report import causes

BUFFER_COMPONENT = "unmodelled_buffer"
BUFFER_COMPOUND = "UNMODELLED_BUFFER"


@dataclass(frozen=True)
class Param:
    """A fitted parameter: physical bounds, linear or logarithmic search scale."""

    name: str
    low: float
    high: float
    unit: str
    log: bool = False

    def to_unit(self, value: float) -> float:
        """Physical value -> [0, 1] search coordinate."""
        if self.log:
            return (math.log(value) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        return (value - self.low) / (self.high - self.low)

    def from_unit(self, u: float) -> float:
        u = min(max(u, 0.0), 1.0)
        if self.log:
            return math.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        return self.low + u * (self.high - self.low)

    def clip(self, value: float) -> float:
        return min(max(value, self.low), self.high)


@dataclass
class Context:
    """What the candidates need to know of the nominal model and the data."""

    feeds: list[str]
    valve_feed: str
    valve_max_flow_ml_s: float
    overflow: bool
    has_command: bool
    command_pct: np.ndarray  # all records' commands, concatenated (empty without)
    ph_range: tuple[float, float]
    duration_s: float
    dt_s: float
    total_inflow_ml_s: float
    feed_strength_mol_l: dict[str, float]  # largest component concentration per feed
    outputs: set[str]
    vessel_volume_ml: float = 1000.0  # liquid volume of the nominal vessel (mixing-zone bounds)
    feed_max_flow_ml_s: dict[str, float] = field(default_factory=dict)  # largest flow of each feed in the data
    basic_feeds: tuple[str, ...] = ()  # feeds above pH 7 (carbonate is carried by caustic)


@dataclass
class Candidate:
    """One cause (or one variant of it) with its parameters and how it edits a model."""

    cause: str
    params: list[Param]
    starts: list[dict[str, float]]
    apply: Callable[[dict, dict[str, float]], None]
    main: str
    variant: str = ""  # e.g. the feed a process candidate acts on
    nonsmooth: bool = False  # piecewise in its parameters: coarser finite differences
    fixed: dict = field(default_factory=dict)  # non-fitted settings reported with the parameters
    #: half-width (% of span) of the band a valve with memory can rest in, from the parameters; the
    #: rest point of each record becomes a nuisance parameter within it
    band: Callable[[dict[str, float]], float] | None = None
    #: parameters that may differ per group of records (a reagent batch, a day, a probe calibration): with
    #: ``--group`` one value per group, and for a group the fit has not seen, the only ones fitted (``--adapt``)
    per_group: tuple[str, ...] = ()
    #: parameters that belong to each record (a property of its start, such as what the vessel held): one value
    #: per record, fitted with its start (a training record on its training samples; a validation record on the
    #: samples that set its start, or on its first --adapt fraction when its group is unseen)
    per_record: tuple[str, ...] = ()
    #: what the variant names in the report's ``fixed`` (a feed, or the species of the vessel's own contents)
    variant_of: str = "feed"
    structural: bool = False  # tried by the structure search (or when named), not by the single-cause catalogue
    polish_evals: int = 20  # least-squares evaluations per parameter when refining the best start
    #: start points polished besides the best one, whatever their cost: for a cost of several narrow basins
    #: whose floors differ less than the start points' costs do (fit._optimise)
    basins: int = 0
    #: parameter (linear) -> the step of the lattice its cost has kinks on, from its low bound: a dead time
    #: interpolated between samples (the sample time); after the polish the fit tries the neighbouring
    #: intervals of the lattice while that lowers the cost (fit._hop)
    lattice: dict[str, float] = field(default_factory=dict)

    @property
    def family(self) -> str:
        return causes()[self.cause]

    @property
    def label(self) -> str:
        return f"{self.cause}[{self.variant}]" if self.variant else self.cause

    @property
    def stage(self) -> str:
        """Which simulation stages the candidate changes (for cost ordering)."""
        if self.family == "sensor":
            return "sensor"
        if self.cause in ("buffer", "reagent_concentration", "carbonate", "mixing_zone", "tanks_in_series",
                          "co2_absorption", "flask_contents"):
            return "chemistry"
        return "flows"


# ---- edits of a scenario mapping --------------------------------------------------
def _add_fault(raw: dict, kind: str, params: dict, where: str = "valve") -> None:
    raw.setdefault("faults", []).append({"type": kind, "where": where, "params": params, "onset_s": 0.0})


def _add_sensor_block(raw: dict, kind: str, params: dict) -> None:
    ph = raw.setdefault("sensors", {}).setdefault("ph", {})
    ph.setdefault("extra", []).append({"type": kind, "params": params})


def _fault(block: str) -> Fault:
    return next(f for f in fault_catalogue().values() if f.block == block)


def _param(block: str, name: str, low: float = -math.inf, high: float = math.inf) -> Param:
    """A catalogued fault parameter over the diagnosis's range of the fault catalogue (:mod:`phfdi_base.faults`),
    narrowed by the data to [low, high]."""
    p = _fault(block).param(name)
    r = p.fit_range("diagnosis")
    return Param(name, max(r.low, low), min(r.high, high), p.unit, r.log)


def _preset(block: str, name: str) -> float:
    value = _fault(block).param(name).paper
    assert value is not None, f"{block}.{name} has no preset value"
    return value


def _spaced(low: float, high: float, n: int, log: bool = False) -> list[float]:
    if log:
        return [float(v) for v in np.geomspace(low, high, n + 2)[1:-1]]
    return [float(v) for v in np.linspace(low, high, n + 2)[1:-1]]


def actuator_candidates(ctx: Context) -> list[Candidate]:
    cmd = ctx.command_pct
    high = _param("saturation", "high_pct")
    sat_low = min(max(float(np.min(cmd)), high.low), 90.0)  # a stop below every command cannot be told from none
    med_cmd = float(np.median(cmd))
    lo_cmd, hi_cmd = float(np.min(cmd)), max(float(np.max(cmd)), float(np.min(cmd)) + 1.0)
    qmax = ctx.valve_max_flow_ml_s
    sat_fixed = {"low_pct": _preset("saturation", "low_pct")}
    out = [
        Candidate("stiction", [_param("stiction", "s_pct"), _param("stiction", "j_pct")],
                  [{"s_pct": s, "j_pct": s * f} for s in _spaced(0.3, 15.0, 6, log=True) for f in (0.1, 0.4, 0.7, 1.0)],
                  lambda raw, p: _add_fault(raw, "stiction", {"s_pct": p["s_pct"], "j_pct": p["j_pct"]}),
                  "s_pct", nonsmooth=True, band=lambda p: 0.5 * p["s_pct"]),
        Candidate("backlash", [_param("backlash", "width_pct")],
                  [{"width_pct": w} for w in _spaced(0.15, 15.0, 8, log=True)],
                  lambda raw, p: _add_fault(raw, "backlash", {"width_pct": p["width_pct"]}),
                  "width_pct", nonsmooth=True, band=lambda p: 0.5 * p["width_pct"]),
        Candidate("deadzone", [_param("deadzone", "width_pct"), _param("deadzone", "center_pct", lo_cmd, hi_cmd)],
                  [{"width_pct": w, "center_pct": c} for w in _spaced(0.5, 60.0, 5, log=True)
                   for c in (float(np.quantile(cmd, 0.25)), med_cmd, float(np.quantile(cmd, 0.75)))],
                  lambda raw, p: _add_fault(raw, "deadzone", {"width_pct": p["width_pct"],
                                                              "center_pct": p["center_pct"]}),
                  "width_pct", nonsmooth=True),
        Candidate("saturation", [_param("saturation", "high_pct", low=sat_low)],
                  # where the commands are: a stop only shows when the data ask for more
                  [{"high_pct": float(np.quantile(cmd, q))} for q in (0.3, 0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.995)]
                  + [{"high_pct": high.high}],
                  lambda raw, p: _add_fault(raw, "saturation", {**sat_fixed, "high_pct": p["high_pct"]}),
                  "high_pct", nonsmooth=True, fixed=dict(sat_fixed)),
        Candidate("coulomb_viscous_friction",
                  [_param("coulomb_viscous_friction", "coulomb_pct"),
                   _param("coulomb_viscous_friction", "mobility_per_s")],
                  [{"coulomb_pct": c, "mobility_per_s": m} for c in _spaced(0.15, 8.0, 5, log=True)
                   for m in (0.02, 0.1, 1.0)],
                  lambda raw, p: _add_fault(raw, "coulomb_viscous_friction",
                                            {"coulomb_pct": p["coulomb_pct"], "mobility_per_s": p["mobility_per_s"]}),
                  "coulomb_pct", nonsmooth=True, band=lambda p: p["coulomb_pct"]),
        # at most half the valve's rated flow
        Candidate("leakage", [_param("leakage", "flow_ml_s", high=0.5 * qmax)],
                  [{"flow_ml_s": f * qmax} for f in (0.0, 0.005, 0.02, 0.08)],
                  lambda raw, p: _add_fault(raw, "leakage", {"flow_ml_s": p["flow_ml_s"]}, "valve_flow"),
                  "flow_ml_s"),
        Candidate("valve_gain", [Param("gain", 0.25, 4.0, "1", log=True)],
                  [{"gain": g} for g in (0.8, 1.25)],
                  lambda raw, p: _scale_valve(raw, p["gain"]), "gain"),
    ]
    return out


def _scale_valve(raw: dict, gain: float) -> None:
    v = raw["valves"]["ph"]
    v["max_flow_ml_s"] = v["max_flow_ml_s"] * gain


def sensor_candidates(ctx: Context) -> list[Candidate]:
    span = ctx.duration_s
    longest = max(5.0 * ctx.dt_s, min(_param("sensor_delay", "delay_s").high, span / 5.0))
    starts_s = sorted({min(longest * 0.9, max(ctx.dt_s, s)) for s in (1.0, 5.0, 20.0, 80.0)})
    gain_fixed = {"reference": _preset("sensor_gain", "reference")}
    return [
        Candidate("sensor_delay", [_param("sensor_delay", "delay_s", high=longest)], [{"delay_s": s} for s in starts_s],
                  lambda raw, p: _add_sensor_block(raw, "sensor_delay", {"delay_s": p["delay_s"]}), "delay_s",
                  lattice={"delay_s": ctx.dt_s}),
        Candidate("sensor_lag", [_param("sensor_lag", "tau_s", high=longest)], [{"tau_s": s} for s in starts_s],
                  lambda raw, p: _add_sensor_block(raw, "sensor_lag", {"tau_s": p["tau_s"]}), "tau_s"),
        Candidate("sensor_bias", [_param("sensor_bias", "bias")], [{"bias": 0.0}],
                  lambda raw, p: _add_sensor_block(raw, "sensor_bias", {"bias": p["bias"]}), "bias",
                  per_group=("bias",)),
        # up to 3 pH over the record, either sign
        Candidate("sensor_drift", [_param("sensor_drift", "rate_per_s", -3.0 / span, 3.0 / span)],
                  [{"rate_per_s": 0.0}],
                  lambda raw, p: _add_sensor_block(raw, "sensor_drift", {"rate_per_s": p["rate_per_s"]}),
                  "rate_per_s"),
        Candidate("sensor_gain", [_param("sensor_gain", "gain")], [{"gain": 1.0}],
                  lambda raw, p: _add_sensor_block(raw, "sensor_gain", {"gain": p["gain"], **gain_fixed}),
                  "gain", fixed=dict(gain_fixed)),
    ]


def _add_buffer(raw: dict, feed: str, conc: float, pka: float) -> None:
    chem = raw["plant"].setdefault("chemistry", {})
    chem.setdefault("components", []).append({"name": BUFFER_COMPONENT, "charge": 0, "pka": [pka]})
    chem.setdefault("compounds", {})[BUFFER_COMPOUND] = {BUFFER_COMPONENT: 1.0}
    raw["plant"]["feeds"][feed]["recipe"][BUFFER_COMPOUND] = conc


def _scale_feed(raw: dict, feed: str, factor: float) -> None:
    recipe = raw["plant"]["feeds"][feed]["recipe"]
    for k in recipe:
        recipe[k] = recipe[k] * factor


def _scale_holdup(raw: dict, factor: float) -> None:
    tank = raw["plant"]["tank"]
    if tank.get("overflow"):
        tank["volume_ml"] = tank["volume_ml"] * factor
    else:
        tank["area_cm2"] = tank["area_cm2"] * factor


def _add_disturbance(raw: dict, feed: str, flow: float, onset: float, dt_s: float) -> None:
    feeds = raw["plant"]["feeds"]
    name = f"{feed}_disturbance"
    feeds[name] = {"recipe": dict(feeds[feed]["recipe"]), "flow_ml_s": 0.0}
    # a ramp over one sample makes the response continuous in the onset time
    raw.setdefault("feeds", {})[name] = {"initial": 0.0, "changes": [{"at_s": onset, "value": flow, "ramp_s": dt_s}]}


def process_candidates(ctx: Context) -> list[Candidate]:
    lo_ph, hi_ph = ctx.ph_range
    pka_lo, pka_hi = max(0.5, lo_ph - 1.0), min(13.5, hi_ph + 1.0)
    pka_starts = _spaced(max(pka_lo, lo_ph - 0.5), min(pka_hi, hi_ph + 0.5), 4)
    out: list[Candidate] = []
    for feed in ctx.feeds:
        strength = ctx.feed_strength_mol_l.get(feed, 0.0) or 1e-3
        out.append(Candidate(
            "buffer", [Param("conc_mol_l", strength * 1e-4, strength * 10.0, "mol/L", log=True),
                       Param("pka", pka_lo, pka_hi, "pH")],
            [{"conc_mol_l": strength * f, "pka": p} for p in pka_starts for f in (0.05, 0.3)],
            lambda raw, p, feed=feed: _add_buffer(raw, feed, p["conc_mol_l"], p["pka"]), "pka", variant=feed,
            per_group=("conc_mol_l",)))
    for feed in ctx.feeds:
        out.append(Candidate(
            "reagent_concentration", [Param("factor", 0.2, 5.0, "1", log=True)],
            [{"factor": f} for f in (0.75, 1.33)],
            lambda raw, p, feed=feed: _scale_feed(raw, feed, p["factor"]), "factor", variant=feed,
            per_group=("factor",)))
    out.append(Candidate(
        "holdup", [Param("factor", 0.2, 5.0, "1", log=True)], [{"factor": f} for f in (0.6, 1.6)],
        lambda raw, p: _scale_holdup(raw, p["factor"]), "factor",
        fixed={"acts_on": "volume_ml" if ctx.overflow else "area_cm2"}))
    q_total = max(ctx.total_inflow_ml_s, 1e-3)
    onsets = [ctx.duration_s * f for f in (0.0, 0.15, 0.3, 0.45, 0.6, 0.75, 0.9)]
    for feed in ctx.feeds:
        out.append(Candidate(
            "disturbance_flow", [Param("flow_ml_s", 0.0, 0.5 * q_total, "mL/s"),
                                 Param("onset_s", 0.0, ctx.duration_s * 0.98, "s")],
            [{"flow_ml_s": 0.0, "onset_s": 0.0}] + [{"flow_ml_s": 0.05 * q_total, "onset_s": t} for t in onsets],
            lambda raw, p, feed=feed: _add_disturbance(raw, feed, p["flow_ml_s"], p["onset_s"], ctx.dt_s),
            "flow_ml_s", variant=feed))
    return out


CARBONATE_COMPONENT = "absorbed_co2"
CARBONATE_COMPOUND = "ABSORBED_CO2"
CARBONATE_PKA = (6.35, 10.33)  # H2CO3*/HCO3-, HCO3-/CO3-- at 25 C


def _add_carbonate(raw: dict, feed: str, conc: float) -> None:
    """CO2 taken up by a caustic feed: carbonate added, its sodium unchanged (2 NaOH + CO2 -> Na2CO3 + H2O)."""
    _carbonate_component(raw)
    raw["plant"]["chemistry"].setdefault("compounds", {})[CARBONATE_COMPOUND] = {CARBONATE_COMPONENT: 1.0}
    raw["plant"]["feeds"][feed]["recipe"][CARBONATE_COMPOUND] = conc


def _carbonate_component(raw: dict) -> None:
    comps = raw["plant"].setdefault("chemistry", {}).setdefault("components", [])
    if not any(c["name"] == CARBONATE_COMPONENT for c in comps):
        comps.append({"name": CARBONATE_COMPONENT, "charge": 0, "pka": list(CARBONATE_PKA)})


def _set_air_exchange(raw: dict, kla: float, equilibrium: float) -> None:
    """CO2 absorbed from the air: the carbonate component relaxes toward an equilibrium level (ph_plant_sim.exchange)."""
    _carbonate_component(raw)
    raw["plant"]["air_exchange"] = {"component": CARBONATE_COMPONENT, "kla_per_s": kla,
                                    "equilibrium_mol_l": equilibrium}


#: the monoprotic weak acid of a vessel's own water (flask_contents[weak_acid]); its pKa is fitted
FLASK_ACID_COMPONENT = "flask_weak_acid"


def _set_contents(raw: dict, species: str, conc: float, pka: float | None = None) -> None:
    """The vessel starts holding ``conc`` mol/L of a weak acid of its own (ph_plant_sim.contents): carbonate
    (the component of ``carbonate``, so it adds to any carbonate a feed carries) or a monoprotic weak acid."""
    if species == "carbonate":
        _carbonate_component(raw)
        component = CARBONATE_COMPONENT
    else:
        comps = raw["plant"].setdefault("chemistry", {}).setdefault("components", [])
        comps[:] = [c for c in comps if c["name"] != FLASK_ACID_COMPONENT]
        comps.append({"name": FLASK_ACID_COMPONENT, "charge": 0, "pka": [pka]})
        component = FLASK_ACID_COMPONENT
    raw["plant"]["initial_contents"] = {"component": component, "conc_mol_l": conc}


def _contents_candidates(ctx: Context) -> list[Candidate]:
    """A weak acid in the vessel's own water at the start (tap-water alkalinity, a phosphate-like buffer),
    washing out with the outflow: carbonate (pKa 6.35, 10.33) and a monoprotic weak acid of fitted pKa.

    Which parameters are whose, by physics: the amount the flask holds at the start is a property of each run's
    history (refilled from the tap, rinsed, or left from the run before), so ``conc_mol_l`` is per record, fitted
    with each record's start like its start pH; the species, and so its pKa, is that of the water supply or of the
    contaminant and is shared by every record.
    """
    strength = max(ctx.feed_strength_mol_l.values(), default=1e-2) or 1e-2
    conc = Param("conc_mol_l", strength * 1e-4, strength, "mol/L", log=True)
    lo_ph, hi_ph = ctx.ph_range
    pka_lo, pka_hi = max(0.5, lo_ph - 1.0), min(13.5, hi_ph + 1.0)
    fractions = (0.003, 0.015, 0.06)
    # the cost is multimodal in pKa (each pKa buffers another stretch of the record): a start every half pH unit
    pkas = _spaced(pka_lo, pka_hi, max(4, int(round(2.0 * (pka_hi - pka_lo)))))
    return [
        Candidate("flask_contents", [conc], [{"conc_mol_l": strength * f} for f in fractions],
                  lambda raw, p: _set_contents(raw, "carbonate", p["conc_mol_l"]), "conc_mol_l",
                  variant="carbonate", variant_of="species", fixed={"pka": list(CARBONATE_PKA)},
                  per_record=("conc_mol_l",), structural=True),
        Candidate("flask_contents", [conc, Param("pka", pka_lo, pka_hi, "pH")],
                  [{"conc_mol_l": strength * f, "pka": p} for p in pkas for f in fractions],
                  lambda raw, p: _set_contents(raw, "weak_acid", p["conc_mol_l"], p["pka"]), "pka",
                  variant="weak_acid", variant_of="species", per_record=("conc_mol_l",), structural=True,
                  polish_evals=40),
    ]


def _set_series(raw: dict, n_tanks: float) -> None:
    raw["plant"]["series"] = {"n_tanks": int(round(n_tanks))}


def _add_line_block(raw: dict, feed: str, kind: str, params: dict) -> None:
    raw["plant"]["feeds"][feed].setdefault("line", []).append({"type": kind, "params": params})


def _set_mixing(raw: dict, feeds: list[str], volume: float, exchange: float) -> None:
    raw["plant"]["mixing"] = {"zone_volume_ml": volume, "exchange_ml_s": exchange, "feeds": list(feeds)}


def _vessel_candidates(ctx: Context, vol: float, q_total: float) -> list[Candidate]:
    """Tanks in series (an overflow vessel) and CO2 absorbed from the air."""
    out: list[Candidate] = []
    if ctx.overflow:
        # a plug-flow-like vessel: integer compartments, fitted by pattern search (the cost is a staircase)
        out.append(Candidate(
            "tanks_in_series", [Param("n_tanks", 1.0, 12.0, "1")],
            [{"n_tanks": float(n)} for n in (2, 3, 5, 8)],
            lambda raw, p: _set_series(raw, p["n_tanks"]), "n_tanks", nonsmooth=True, structural=True))
    # CO2 from the air above the vessel: first-order uptake toward an equilibrium carbonate level
    strength = max(ctx.feed_strength_mol_l.values(), default=1e-2) or 1e-2
    turnover = q_total / vol  # 1/s
    out.append(Candidate(
        "co2_absorption", [Param("kla_per_s", 0.01 * turnover, 100.0 * turnover, "1/s", log=True),
                           Param("equilibrium_mol_l", strength * 1e-3, strength, "mol/L", log=True)],
        # at a fast kla the level is a constant buffer and kla's gradient vanishes: a denser grid, a longer polish
        [{"kla_per_s": k * turnover, "equilibrium_mol_l": c * strength} for k in (0.1, 0.4, 1.5, 6.0)
         for c in (0.01, 0.03, 0.08, 0.2, 0.5)],
        lambda raw, p: _set_air_exchange(raw, p["kla_per_s"], p["equilibrium_mol_l"]), "equilibrium_mol_l",
        fixed={"pka": list(CARBONATE_PKA)}, structural=True, polish_evals=60, basins=4))
    return out


def _pump_lag_candidates(ctx: Context) -> list[Candidate]:
    """Start-up and stop dynamics of each feed's pump (on/off dosing)."""
    out: list[Candidate] = []
    slowest = max(5.0 * ctx.dt_s, min(60.0, ctx.duration_s / 5.0))
    for feed in ctx.feeds:
        out.append(Candidate(
            "pump_lag", [Param("tau_start_s", 0.0, slowest, "s"), Param("tau_stop_s", 0.0, slowest, "s")],
            [{"tau_start_s": a * slowest, "tau_stop_s": b * slowest} for a in (0.05, 0.15, 0.3) for b in (0.02, 0.1, 0.3)],
            lambda raw, p, feed=feed: _add_line_block(raw, feed, "pump_lag", {
                "tau_start_s": p["tau_start_s"], "tau_stop_s": p["tau_stop_s"]}),
            "tau_start_s", variant=feed, structural=True))
    return out


def structural_candidates(ctx: Context) -> list[Candidate]:
    """Structure a stirred-tank model of a real plant often lacks: imperfect mixing, feed lines, reagent
    carbonate, probe dynamics and calibration."""
    out: list[Candidate] = []
    vol = max(ctx.vessel_volume_ml, 1.0)
    q_total = max(ctx.total_inflow_ml_s, 1e-3)
    zone_sets = [[f] for f in ctx.feeds] + ([list(ctx.feeds)] if len(ctx.feeds) > 1 else [])
    for feeds in zone_sets:
        out.append(Candidate(
            "mixing_zone", [Param("zone_volume_ml", 0.002 * vol, 0.5 * vol, "mL", log=True),
                            Param("exchange_ml_s", 0.05 * q_total, 300.0 * q_total, "mL/s", log=True)],
            [{"zone_volume_ml": v * vol, "exchange_ml_s": x * q_total} for v in (0.005, 0.015, 0.04, 0.1, 0.25)
             for x in (0.3, 1.0, 3.0, 10.0, 40.0)],
            lambda raw, p, feeds=feeds: _set_mixing(raw, feeds, p["zone_volume_ml"], p["exchange_ml_s"]),
            # ill-conditioned (volume and exchange trade off along a valley): polish, then the simplex along it
            "zone_volume_ml", variant="+".join(feeds), structural=True, polish_evals=100))
    longest = max(5.0 * ctx.dt_s, min(120.0, ctx.duration_s / 5.0))
    delay_step = max(ctx.dt_s, longest / 120.0)
    for feed in ctx.feeds:
        out.append(Candidate(
            "feed_delay", [Param("delay_s", 0.0, longest, "s")],
            # every sample interval's middle (at most 120: every second of the rig's 0.35 s sampling): the truth's
            # basin is about a pulse edge wide (+-1 s), and between basins the cost can be lower far away than
            # next to it (seed 1416186938: 17.7 s true, 40 s the best of starts 1, 4, 15 and 40 s, then 20.8 s
            # fitted at 340 x the truth's training error)
            [{"delay_s": (k + 0.5) * delay_step} for k in range(int(longest / delay_step))],
            lambda raw, p, feed=feed: _add_line_block(raw, feed, "line_delay", {"delay_s": p["delay_s"]}),
            "delay_s", variant=feed, structural=True, lattice={"delay_s": ctx.dt_s}))
    for feed in ctx.feeds:
        qmax = max(ctx.feed_max_flow_ml_s.get(feed, 0.0), 1e-3)
        out.append(Candidate(
            "pump_curve", [Param("gain", 0.4, 2.5, "1", log=True), Param("threshold_ml_s", 0.0, 0.6 * qmax, "mL/s")],
            # a narrow valley (the pH near equivalence is steep in the delivered flow): a dense start grid
            [{"gain": g, "threshold_ml_s": t * qmax} for g in (0.7, 0.8, 0.9, 1.0, 1.1, 1.2, 1.35)
             for t in (0.0, 0.05, 0.1, 0.17, 0.25, 0.35)],
            lambda raw, p, feed=feed: _add_line_block(raw, feed, "pump_curve", {
                "gain": p["gain"], "threshold_ml_s": p["threshold_ml_s"]}),
            "threshold_ml_s", variant=feed, structural=True, polish_evals=100, basins=4))
    out += _vessel_candidates(ctx, vol, q_total) + _pump_lag_candidates(ctx) + _contents_candidates(ctx)
    for feed in ctx.basic_feeds:
        strength = ctx.feed_strength_mol_l.get(feed, 0.0) or 1e-2
        out.append(Candidate(
            "carbonate", [Param("conc_mol_l", strength * 1e-3, strength * 2.0, "mol/L", log=True)],
            [{"conc_mol_l": strength * f} for f in (0.01, 0.05, 0.2, 0.6)],
            lambda raw, p, feed=feed: _add_carbonate(raw, feed, p["conc_mol_l"]), "conc_mol_l", variant=feed,
            fixed={"pka": list(CARBONATE_PKA)}, per_group=("conc_mol_l",), structural=True))
    if "ph_measured" in ctx.outputs:
        longest = max(5.0 * ctx.dt_s, min(300.0, ctx.duration_s / 5.0))
        out.append(Candidate(
            "probe_asymmetric_lag", [Param("tau_up_s", 0.0, longest, "s"), Param("tau_down_s", 0.0, longest, "s")],
            [{"tau_up_s": a, "tau_down_s": b} for a in (1.0, 10.0, 40.0) for b in (1.0, 10.0, 40.0) if a != b],
            lambda raw, p: _add_sensor_block(raw, "sensor_asymmetric_lag", {
                "tau_up_s": p["tau_up_s"], "tau_down_s": p["tau_down_s"]}), "tau_up_s", structural=True))
        # two lags in series, the slower first (tau2 = ratio tau1 <= tau1: the two are interchangeable otherwise)
        out.append(Candidate(
            "sensor_second_order", [Param("tau1_s", 0.0, longest, "s"), Param("tau2_ratio", 0.05, 1.0, "1", log=True)],
            [{"tau1_s": a, "tau2_ratio": r} for a in (3.0, 15.0, 50.0) for r in (0.1, 0.5, 1.0)],
            lambda raw, p: _add_sensor_block(raw, "sensor_second_order", {
                "tau1_s": p["tau1_s"], "tau2_s": p["tau1_s"] * p["tau2_ratio"]}), "tau1_s", structural=True))
        out.append(Candidate(
            "two_point_calibration", [Param("slope", 0.6, 1.5, "1", log=True), Param("offset", -1.5, 1.5, "pH")],
            [{"slope": s_, "offset": o} for s_ in (0.9, 1.1) for o in (-0.2, 0.2)],
            lambda raw, p: _add_sensor_block(raw, "two_point_calibration", {
                "slope": p["slope"], "offset": p["offset"]}), "slope", per_group=("offset",), structural=True))
    return out


#: the faults of the fault catalogue tried with a search of their own (above)
TAILORED = ("stiction", "backlash", "deadzone", "saturation", "coulomb_viscous_friction", "leakage", "sensor_delay",
            "sensor_lag", "sensor_bias", "sensor_drift", "sensor_gain")


def _others(sites: tuple[str, ...]) -> tuple[str, ...]:
    """Blocks of catalogued faults at ``sites`` with no tailored candidate (a block of one's own)."""
    return tuple(f.block for f in fault_catalogue().values()
                 if f.candidate and f.site in sites and f.params and f.block not in TAILORED)


def catalogued_candidates(ctx: Context, sites: tuple[str, ...]) -> list[Candidate]:
    """A candidate for each catalogued fault at ``sites`` without a tailored one: every parameter over its
    diagnosis range (an unbounded one up to ten times its preset value), started from its preset value and
    the main parameter spread over its range."""
    out = []
    for block in _others(sites):
        f = _fault(block)
        params, base = [], {}
        for p in f.params:
            r = p.fit_range("diagnosis")
            high = r.high if math.isfinite(r.high) else 10.0 * (p.paper or 1.0)
            params.append(Param(p.name, r.low, high, p.unit, r.log))
            base[p.name] = params[-1].clip(p.paper) if p.paper is not None else params[-1].from_unit(0.5)
        main = params[0]
        starts = [dict(base, **{main.name: main.from_unit(u)}) for u in (0.2, 0.5, 0.8)] + [base]
        where = f.site if f.site != "ph_sensor" else ""
        apply = (lambda raw, p, block=block: _add_sensor_block(raw, block, dict(p))) if not where else \
            (lambda raw, p, block=block, where=where: _add_fault(raw, block, dict(p), where))
        out.append(Candidate(block, params, starts, apply, main.name, nonsmooth=f.site != "ph_sensor"))
    return out


def catalogue(ctx: Context, only: list[str] | None = None,
              structure: bool = False) -> tuple[list[Candidate], dict[str, str]]:
    """Candidates that apply to this model and data, and why the others do not.

    ``structure``: add the structural candidates (:func:`structural_candidates`); they are also added when
    ``only`` names one of them.
    """
    if only:
        only = [block_name(c) for c in only]  # a fault's preset name (friction) names its block's cause
    skipped: dict[str, str] = {}
    cands: list[Candidate] = []
    if ctx.has_command:
        cands += actuator_candidates(ctx) + catalogued_candidates(ctx, ("valve", "valve_flow"))
    else:
        for c in ("stiction", "backlash", "deadzone", "saturation", "coulomb_viscous_friction", "leakage",
                  "valve_gain") + _others(("valve", "valve_flow")):
            skipped[c] = f"the data has the {ctx.valve_feed} flow, not the valve command: the valve is not modelled"
    if "ph_measured" in ctx.outputs:
        cands += sensor_candidates(ctx) + catalogued_candidates(ctx, ("ph_sensor",))
    else:
        for c in ("sensor_delay", "sensor_lag", "sensor_bias", "sensor_drift", "sensor_gain") + _others(("ph_sensor",)):
            skipped[c] = "no pH measurement in the data"
    cands += process_candidates(ctx)
    structural = structural_candidates(ctx)
    if structure or (only and any(c.cause in only for c in structural)):
        cands += structural
    else:
        for c in dict.fromkeys(c.cause for c in structural):
            skipped.setdefault(c, "structural: tried by --structure (or name it with --candidates)")
    if only:
        known = causes()
        unknown = [c for c in only if c not in known or c == "none"]
        if unknown:

            raise UserError(f"unknown candidate {unknown[0]!r}; catalogue: "
                            f"{', '.join(c for c in known if c != 'none')}")
        for c in {c.cause for c in cands} - set(only):
            skipped.setdefault(c, "not requested (--candidates)")
        cands = [c for c in cands if c.cause in only]
    return cands, skipped
