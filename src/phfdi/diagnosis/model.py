"""The model under diagnosis, simulated open loop on a measured record.

A model is a scenario mapping (the nominal scenario with its plant model
written inline, plus any extension) validated by :mod:`phfdi.scenario`, so
the file the diagnosis writes is exactly what it simulated. The simulation
is :func:`phfdi.loop.simulate_open_loop` arranged for speed, with the same
cores and blocks:

1. flows: the recorded valve command through the scenario's valve (its
   position and flow blocks, stepped per sample), or the recorded flow;
   other feeds from their recorded flow or their schedule; the outlet
   opening from the recorded level-controller output through the outlet
   valve, else held;
2. volume: :func:`ph_plant_sim.plant.record_sample_maps` (the plant's
   per-sample maps, vectorised over the record);
3. composition and pH: the component amounts from those maps
   (:func:`~ph_plant_sim.plant.affine_recurrence`) and
   :meth:`~ph_plant_sim.chemistry.ChargeBalance.ph_array`;
4. sensors: the scenario's pH and level sensor chains (blocks, stepped per
   sample), without noise: the prediction is the expected measurement.

Each stage's result is cached under the part of the model it depends on, so
a sensor candidate re-runs only stage 4, a buffer candidate stages 3-4. A
test checks the result against :func:`~phfdi.loop.simulate_open_loop`.
"""

from __future__ import annotations

import copy
import json
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ph_plant_sim.build import build_plant, feed_lines, initial_contents, load_plant_model, plant_start, sensor_chain
from ph_plant_sim.contents import contents_vector
from ph_plant_sim.exchange import AirExchange, exchange_recurrence
from ph_plant_sim.mixing import MixingZone, zone_trajectory
from ph_plant_sim.plant import CstrPlant, affine_recurrence, record_sample_maps
from ph_plant_sim.series import TanksInSeries, series_trajectory
from phfdi.records import Record
from phfdi.scenario import raw_scenario
from phfdi_base.blocks import Chain, Injected
from phfdi_base.errors import UserError
from phfdi_base.spec import ScenarioSpec, apply_override, injected_faults, parse_override, profile, validate_scenario
from valve_actuator.build import build_valve


def nominal_raw(model: str, overrides: list[str] = ()) -> dict:
    """Scenario mapping of ``model`` (name or .yaml) with its plant model inline and ``--set`` overrides applied.

    Examples
    --------
    >>> from phfdi.diagnosis import nominal_raw
    >>> model = nominal_raw("paper", ["sensors.ph.noise_std=0.02"])
    >>> model["sensors"]["ph"]["noise_std"], isinstance(model["plant"], dict)
    (0.02, True)
    """
    raw = raw_scenario(model)
    raw = inline_plant(raw)
    raw.pop("extends", None)
    for text in overrides:
        keys, value = parse_override(text)
        try:
            apply_override(raw, keys, value)
        except (KeyError, IndexError, ValueError, TypeError):
            raise UserError(f"--set {text!r}: no such key in model {model!r}") from None
    raw["faults"] = [f for f in raw.get("faults", [])]
    validate_scenario(raw, source=f"model {model}")
    return raw


def inline_plant(raw: dict) -> dict:
    """The scenario mapping with ``plant`` as a mapping (preset loaded) instead of a name."""
    raw = copy.deepcopy(raw)
    if isinstance(raw.get("plant"), str):
        raw["plant"] = load_plant_model(raw["plant"]).model_dump(exclude_defaults=True)
    return raw


def _key(*parts) -> str:
    return json.dumps(parts, sort_keys=True, default=str)


@dataclass(frozen=True)
class Start:
    """What a record leaves unknown about its first sample (nuisances of a fit).

    ``ph``: tank pH (``initial: fit``). ``valve_offset_pct``: where the valve
    stem rests relative to the first command: a valve with backlash, stiction
    or friction can rest anywhere within its band, and that hidden state
    persists until the command travels across the band.
    """

    ph: float | None = None
    valve_offset_pct: float = 0.0


@dataclass
class Prediction:
    """The model's expected measurements on a record, and what produced them."""

    outputs: dict[str, np.ndarray]  # ph_measured, level_measured_cm: (N,)
    ph_true: np.ndarray  # (N,)
    flows_ml_s: np.ndarray  # (N, n_feeds)
    feed_names: list[str]


class _LRU(OrderedDict):
    def __init__(self, size: int) -> None:
        super().__init__()
        self.size = size

    def put(self, key, value):
        self[key] = value
        self.move_to_end(key)
        while len(self) > self.size:
            self.popitem(last=False)
        return value

    def take(self, key):
        if key in self:
            self.move_to_end(key)
            return self[key]
        return None


class Evaluator:
    """Simulates model variants on one record (open loop from the recorded inputs).

    ``initial``: ``steady`` starts the plant at the steady state of the
    first sample's inputs (a record taken from a plant at rest); ``fit``
    starts it at a given tank pH (:class:`Start` ``ph``), the
    composition a mix of the most acidic and the most basic feed giving
    that pH (a record that starts mid-transient, such as a titration).
    """

    def __init__(self, record: Record, nominal: dict, initial: str = "steady", level_from_data: bool = True) -> None:
        if initial not in ("steady", "fit"):
            raise UserError(f"initial state {initial!r}: use steady or fit")
        self.record = record
        self.initial = initial
        # a gravity tank's level at the first sample: the measured one (a plant under level control is never
        # exactly at the steady state of its first sample's inputs), averaged over the first samples
        level = record.outputs.get("level_measured_cm")
        self.level0_cm = float(np.mean(level[:10])) if level is not None and level_from_data else None
        self.dt_s = record.dt_s
        self.t_rel = record.time_s - record.time_s[0]
        self._stage: dict[str, _LRU] = {s: _LRU(6) for s in ("spec", "plant", "flows", "maps", "states")}
        self._nominal_volume: np.ndarray | None = None
        self._ph_guess: np.ndarray | None = None
        self._derived: dict[int, tuple[ScenarioSpec, dict]] = {}
        spec = self.spec(nominal)
        self.nominal_spec = spec
        self._check_inputs(spec)
        self.nominal_opening = self._held_opening(spec)

    # ---- model ----------------------------------------------------------------
    def spec(self, raw: dict) -> ScenarioSpec:
        key = _key(raw)
        hit = self._stage["spec"].take(key)
        if hit is not None:
            return hit
        data = copy.deepcopy(raw)
        data["sample_time_s"] = self.dt_s
        data["duration_s"] = max(float(self.t_rel[-1]), self.dt_s)
        data["faults"] = [dict(f, onset_s=min(f.get("onset_s", 0.0), data["duration_s"] * 0.999))
                          for f in data.get("faults", [])]
        for p in (data.get("setpoints") or {}).values():
            if isinstance(p, dict):
                p["changes"] = [c for c in p.get("changes", []) if c["at_s"] < data["duration_s"]]
        spec = validate_scenario(data, source="model")
        return self._stage["spec"].put(key, spec)

    def _of_spec(self, spec: ScenarioSpec) -> dict:
        """What a prediction derives from a (validated, never modified) spec: its plant model, the plant, the
        cache keys; worked out once per spec object instead of at every stage of every prediction."""
        hit = self._derived.get(id(spec))
        if hit is not None and hit[0] is spec:
            return hit[1]
        model = load_plant_model(spec.plant)
        model_dump = model.model_dump()
        # the plant (its chemistry) depends on which component the vessel starts holding, not on how much
        own = model.initial_contents.component if model.initial_contents is not None else None
        key = _key({k: v for k, v in model_dump.items() if k != "initial_contents"}, own)
        plant = self._stage["plant"].take(key)
        if plant is None:
            plant = self._stage["plant"].put(key, build_plant(model))
        out = {"model": model, "model_dump": model_dump, "plant": plant}
        out["flows_key"] = self._flows_key(spec, plant, model)
        if len(self._derived) > 32:
            self._derived.clear()
        self._derived[id(spec)] = (spec, out)  # the spec is held here, so its id is not reused meanwhile
        return out

    def plant(self, spec: ScenarioSpec) -> CstrPlant:
        return self._of_spec(spec)["plant"]

    def _check_inputs(self, spec: ScenarioSpec) -> None:
        rec = self.record
        feed = spec.valves.ph.feed
        plant = self.plant(spec)
        names = [f.name for f in plant.feeds]
        if "valve_command_pct" not in rec.inputs and f"{feed}_flow_ml_s" not in rec.inputs:
            raise UserError(f"{rec.name}: the model's pH valve drives feed {feed!r}: the data needs "
                            f"valve_command_pct or {feed}_flow_ml_s")
        unknown = [k for k in rec.inputs if k.endswith("_flow_ml_s") and k[:-10] not in names]
        if unknown:
            raise UserError(f"{rec.name}: {unknown[0]} is not a feed of the model (feeds: {', '.join(names)})")

    def _held_opening(self, spec: ScenarioSpec) -> float:
        """Outlet opening when the data has no outlet command: the model's start (level setpoint)."""
        plant = self.plant(spec)
        if plant.tank.overflow or "level_controller_output_pct" in self.record.inputs:
            return 1.0
        return plant_start(spec, plant).outlet_opening

    # ---- stages -----------------------------------------------------------------
    def flows(self, spec: ScenarioSpec, start: Start = Start()) -> tuple[np.ndarray, np.ndarray]:
        """Feed flows (N, n_feeds) in mL/s and outlet openings (N,)."""
        derived = self._of_spec(spec)
        plant = derived["plant"]
        key = _key(derived["flows_key"], start.valve_offset_pct)
        hit = self._stage["flows"].take(key)
        if hit is not None:
            return hit
        rec = self.record
        n = len(rec)
        names = [f.name for f in plant.feeds]
        feed = spec.valves.ph.feed
        flows = np.empty((n, len(names)))
        for j, f in enumerate(plant.feeds):
            col = f"{f.name}_flow_ml_s"
            if f.name == feed and "valve_command_pct" in rec.inputs:
                flows[:, j] = self._valve_flows(spec, rec.inputs["valve_command_pct"], start.valve_offset_pct)
            elif col in rec.inputs:
                flows[:, j] = rec.inputs[col]
            elif f.name in spec.feeds:
                prof = profile(spec.feeds[f.name])
                flows[:, j] = [prof.value(t) for t in self.t_rel.tolist()]
            else:
                flows[:, j] = f.flow_ml_s
        lines = feed_lines(derived["model"], self.dt_s)
        for j, f in enumerate(plant.feeds):  # commanded flow -> flow entering the vessel
            if f.name in lines:
                flows[:, j] = np.maximum(_run_chain(lines[f.name], flows[:, j], self.t_rel.tolist()), 0.0)
        if np.any(flows < 0) or not np.all(np.isfinite(flows)):
            raise UserError("model: a feed flow went negative or non-finite")
        openings = self._openings(spec)
        return self._stage["flows"].put(key, (flows, openings))

    @staticmethod
    def _flows_key(spec: ScenarioSpec, plant: CstrPlant, model) -> str:
        return _key(spec.valves.model_dump(), [f.model_dump() for f in spec.faults if not f.where.endswith("sensor")],
                    {k: v.model_dump() for k, v in spec.feeds.items()}, [(f.name, f.flow_ml_s) for f in plant.feeds],
                    {k: [b.model_dump() for b in v.line] for k, v in model.feeds.items()})

    def _valve_flows(self, spec: ScenarioSpec, command: np.ndarray, offset_pct: float = 0.0) -> np.ndarray:
        valve = build_valve(spec.valves.ph, spec, "valve")
        # the faults of a diagnosis model act from the start: step the blocks themselves
        pos_blocks = [_bare(b) for b in valve.position_blocks.blocks]
        flow_blocks = [_bare(b) for b in valve.flow_blocks.blocks]
        cmd = command.tolist()
        for b in pos_blocks:  # at rest offset from the first command (a stem held by its dead band)
            b.reset(cmd[0] + offset_pct)
        t = self.t_rel.tolist()
        pos = np.array(cmd)
        for b in pos_blocks:  # block by block over the record: the same sequence as a chain stepped per sample
            step = b.step
            pos = np.array([step(x, tk) for x, tk in zip(pos.tolist(), t)])
        pos = np.clip(pos, 0.0, 100.0)
        if valve.characteristic == "linear":
            opening = pos / 100.0
        else:
            opening = np.where(pos > 0.0, valve.rangeability ** (pos / 100.0 - 1.0), 0.0)
        flow = opening * valve.max_flow_ml_s
        for b in flow_blocks:
            b.reset(float(flow[0]))
            step = b.step
            flow = np.array([step(x, tk) for x, tk in zip(flow.tolist(), t)])
        return flow

    def _openings(self, spec: ScenarioSpec) -> np.ndarray:
        rec = self.record
        n = len(rec)
        if spec.valves.outlet is None or "level_controller_output_pct" not in rec.inputs:
            return np.full(n, self.nominal_opening if hasattr(self, "nominal_opening") else 1.0)
        key = _key(spec.valves.outlet.model_dump(), [f.model_dump() for f in spec.faults
                                                     if f.where.startswith("outlet_valve")])
        if key == getattr(self, "_openings_key", None):
            return self._openings_cached
        outlet = build_valve(spec.valves.outlet, spec, "outlet_valve")
        cmd = rec.inputs["level_controller_output_pct"].tolist()
        outlet.reset(cmd[0])
        t = self.t_rel.tolist()
        self._openings_key = key
        self._openings_cached = np.array([outlet.step(c, tk).opening for c, tk in zip(cmd, t)])
        return self._openings_cached

    def states(self, spec: ScenarioSpec, start: Start = Start()) -> dict:
        """True pH (N + 1,), volume (N + 1,) and level (N + 1,) of the tank."""
        derived = self._of_spec(spec)
        plant = derived["plant"]
        flows, openings = self.flows(spec, start)
        fkey = _key(derived["flows_key"], start.valve_offset_pct)
        model = derived["model"]
        initial_ph = start.ph if self.initial == "fit" else None
        key = _key(fkey, derived["model_dump"], initial_ph)
        hit = self._stage["states"].take(key)
        if hit is not None:
            return hit
        tank = plant.tank
        q0 = flows[0].tolist()
        if tank.overflow:
            v0 = tank.volume_ml
        elif self.level0_cm is not None:
            v0 = self.level0_cm * tank.area_cm2
        else:
            if sum(q0) <= 0:
                raise UserError(f"{self.record.name}: no inflow at the first sample: no steady state to start from")
            v0 = tank.outlet.level_for_flow(sum(q0), float(openings[0])) * tank.area_cm2
        mkey = _key(fkey, model.tank.model_dump(), v0)
        maps = self._stage["maps"].take(mkey)
        if maps is None:
            try:
                maps = record_sample_maps(tank, v0, flows.sum(axis=1), openings, self.dt_s,
                                          volume_guess_ml=self._nominal_volume)
            except FloatingPointError as exc:
                raise UserError(f"{self.record.name}: open-loop simulation failed: {exc}") from None
            self._stage["maps"].put(mkey, maps)
            if self._nominal_volume is None:
                self._nominal_volume = maps[0]
        volume, coef = maps
        contents = initial_contents(model)  # the vessel's own weak acid at the start (ph_plant_sim.contents)
        extra = contents_vector(plant, contents) if contents is not None else None
        conc0 = self._initial_conc(plant, q0, initial_ph, extra)
        feed_conc = np.asarray(plant.feed_conc, dtype=float)
        inflow = flows @ feed_conc  # mmol/s per component
        if model.air_exchange is not None:  # the exchanging component at its own steady level (inflow and air)
            x = model.air_exchange
            exch = AirExchange(x.component, x.kla_per_s, x.equilibrium_mol_l)
            j = [c.name for c in plant.chemistry.components].index(x.component)
            conc0 = list(conc0)
            conc0[j] = exch.steady_conc(float(inflow[0, j]), float(sum(q0)), v0) + (extra[j] if extra else 0.0)
        amounts = affine_recurrence(coef[:, 0], coef[:, 1:2] * inflow, np.asarray(conc0) * v0)
        if model.air_exchange is not None:  # ph_plant_sim.exchange: the flow map, then the relaxation
            gain, drive = exchange_recurrence(exch, coef, inflow[:, j], volume, self.dt_s)
            amounts[:, j] = affine_recurrence(gain, drive, conc0[j] * v0)
        conc = amounts / volume[:, None]
        if model.series is not None:  # the probe reads the last compartment (ph_plant_sim.series)
            conc = series_trajectory(TanksInSeries(model.series.n_tanks), feed_conc, flows, float(volume[0]),
                                     self.dt_s, np.asarray(conc0, dtype=float))
        if model.mixing is not None:  # the probe reads the zone (ph_plant_sim.mixing)
            m = model.mixing
            conc, _ = zone_trajectory(MixingZone(m.zone_volume_ml, m.exchange_ml_s, tuple(m.feeds)),
                                      [f.name for f in plant.feeds], feed_conc, flows, volume, self.dt_s,
                                      np.asarray(conc0, dtype=float))
        ph0 = plant.balance.ph(conc0)
        # a nearby trajectory (the first one simulated) saves Newton iterations; the root does not depend on it
        guess = self._ph_guess if self._ph_guess is not None and len(self._ph_guess) == len(conc) else ph0
        ph = plant.balance.ph_array(conc, guess=guess)
        if self._ph_guess is None:
            self._ph_guess = ph
        out = {"ph": ph, "volume_ml": volume, "level_cm": volume / tank.area_cm2, "flows": flows}
        return self._stage["states"].put(key, out)

    def _initial_conc(self, plant: CstrPlant, q0: list[float], initial_ph: float | None,
                      extra: list[float] | None = None) -> list[float]:
        """The start composition: the steady state of the first flows plus ``extra`` (the vessel's own contents,
        as :meth:`ph_plant_sim.process.PlantProcess.rest` adds them), or with ``initial: fit`` a mix of the feeds
        that, with ``extra``, has the start pH."""
        if self.initial == "steady":
            if sum(q0) <= 0:
                raise UserError(f"{self.record.name}: no inflow at the first sample: no steady state to start "
                                f"from (use --initial fit for a record that starts mid-transient)")
            mixed = plant.mixed_inflow(q0)
            return [c + e for c, e in zip(mixed, extra)] if extra else mixed
        if initial_ph is None:
            raise ValueError("initial 'fit' needs initial_ph")
        return mix_for_ph(plant, initial_ph, extra)

    def predict(self, raw: dict, start: Start = Start()) -> Prediction:
        spec = self.spec(raw)
        states = self.states(spec, start)
        n = len(self.record)
        outputs = {}
        t = self.t_rel.tolist()
        no_noise = {"noise_std": 0.0}
        if "ph_measured" in self.record.outputs:
            chain = sensor_chain(spec.sensors.ph.model_copy(update=no_noise), self.dt_s, 0, "ph",
                                 _sensor_faults(spec, "ph_sensor", self.dt_s))
            outputs["ph_measured"] = _run_chain(chain, states["ph"][:n], t)
        if "level_measured_cm" in self.record.outputs:
            chain = sensor_chain(spec.sensors.level.model_copy(update=no_noise), self.dt_s, 0, "level",
                                 _sensor_faults(spec, "level_sensor", self.dt_s))
            outputs["level_measured_cm"] = _run_chain(chain, states["level_cm"][:n], t)
        plant = self.plant(spec)
        return Prediction(outputs, states["ph"][:n], states["flows"], [f.name for f in plant.feeds])


def _bare(block):
    """The block inside an :class:`~phfdi_base.blocks.Injected` that is fully on from t = 0 (one call less per sample)."""
    if isinstance(block, Injected) and block.onset_s <= 0.0 and block.ramp_s <= 0.0:
        if hasattr(block.block, "severity"):
            block.block.severity = 1.0
        return block.block
    return block


def _sensor_faults(spec: ScenarioSpec, site: str, dt_s: float) -> list:

    return [_bare(b) for b in injected_faults(spec, site)]


def _run_chain(chain: Chain, x: np.ndarray, t: list[float]) -> np.ndarray:
    """The chain stepped over a record, block by block (a chain of causal single-input blocks gives the same
    outputs stepped sample by sample); blocks with ``step_many`` (the vectorised ``step``) run in one call."""
    if not chain.blocks:
        return np.array(x, dtype=float)
    values = np.asarray(x, dtype=float)
    chain.reset(float(values[0]))
    t_arr = None
    for b in chain.blocks:
        many = getattr(b, "step_many", None)
        if many is not None:
            if t_arr is None:
                t_arr = np.asarray(t, dtype=float)
            values = many(values, t_arr)
        else:
            step = b.step
            values = np.array([step(v, tk) for v, tk in zip(values.tolist(), t)])
    return values


def mix_for_ph(plant: CstrPlant, ph: float, extra: list[float] | None = None) -> list[float]:
    """Composition (mol/L) of a mix of the most acidic and the most basic feed with the given pH.

    ``extra``: a vessel's own contents (mol/L per component, :mod:`ph_plant_sim.contents`) held besides the
    mix; the mix is then the one that has the given pH together with them (the strong ions under a buffer of
    the vessel's own water are whatever its start pH says). Beyond the reachable range: the nearer end.
    """
    acid, base, lo, hi = _mix_ends(plant)
    if extra is not None and any(extra):
        add = np.asarray(extra, dtype=float)
        acid, base = acid + add, base + add
        lo, hi = plant.balance.ph(acid.tolist()), plant.balance.ph(base.tolist())
    if ph <= lo:
        return acid.tolist()
    if ph >= hi:
        return base.tolist()

    def ph_of(x: float) -> float:
        return plant.balance.ph(((1.0 - x) * acid + x * base).tolist())

    x = brentq(lambda x: ph_of(x) - ph, 0.0, 1.0, xtol=1e-14)
    return ((1.0 - x) * acid + x * base).tolist()


_MIX_ENDS: dict[int, tuple] = {}


def _mix_ends(plant: CstrPlant) -> tuple:
    """(most acidic feed, most basic feed, their pH) of a plant, cached per plant object."""
    hit = _MIX_ENDS.get(id(plant))
    if hit is not None and hit[0] is plant:
        return hit[1]
    conc = [np.asarray(c, dtype=float) for c in plant.feed_conc]
    phs = [plant.balance.ph(c.tolist()) for c in conc]
    acid, base = conc[int(np.argmin(phs))], conc[int(np.argmax(phs))]
    ends = (acid, base, min(phs), max(phs))
    if len(_MIX_ENDS) > 256:
        _MIX_ENDS.clear()
    _MIX_ENDS[id(plant)] = (plant, ends)
    return ends
