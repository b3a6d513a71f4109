"""The plant's part of a scenario: the vessel, its chemistry, feed lines, sensors and disturbances.

A factory from the validated scenario (:class:`phfdi_base.spec.ScenarioSpec`)
to this core's objects, used alike by the in-process loop (:mod:`phfdi.loop`),
the plant node and the detector's reference model. The valve's side of the
starting point (stem positions for these flows) is the valve core's
(:func:`valve_actuator.build.position_for_opening`).
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, cast

from phfdi_base.blocks import Chain, make_block
from phfdi_base.errors import UserError
from phfdi_base.spec_tools import checked_block, injected_faults, profile
from phfdi_base.yamlfile import read_mapping, resolve_preset

from . import feedlines, sensors  # noqa: F401  (register the feed-line and sensor blocks)
from .chemistry import Chemistry, Component
from .contents import InitialContents
from .exchange import AirExchange, ExchangePlant
from .mixing import MixingZone, ZonedPlant
from .plant import CstrPlant, Feed, GravityOutlet, Tank
from .process import PlantProcess
from .series import SeriesPlant, TanksInSeries

if TYPE_CHECKING:  # the schema (pydantic) only where a plant model file is read: a node gets its model validated
    from phfdi_base.spec import PlantModelSpec, ScenarioSpec, SensorSpec

__all__ = ["PLANT_DIR", "PlantStart", "build_plant", "build_process", "feed_lines", "initial_contents",
           "load_plant_model", "plant_start", "sensor_chain"]

#: the plant-model presets (``plant: <name>`` in a scenario)
PLANT_DIR = Path(str(resources.files("ph_plant_sim"))) / "presets"


def load_plant_model(plant: str | PlantModelSpec) -> PlantModelSpec:
    """A plant model: as given, a preset of :data:`PLANT_DIR` by name, or a .yaml file.

    Parameters
    ----------
    plant : str or PlantModelSpec
        A preset name (``"paper"``), a path to a plant-model .yaml, or a model already validated.

    Returns
    -------
    PlantModelSpec

    Raises
    ------
    UserError
        No such preset or file, or a file that is not a valid plant model (naming the key).

    Examples
    --------
    >>> from ph_plant_sim import load_plant_model
    >>> model = load_plant_model("paper")
    >>> list(model.feeds)
    ['acid', 'buffer', 'base']
    """
    if not isinstance(plant, str):  # a model already validated (the scenario's own, or one a node part carries)
        return plant
    from pydantic import ValidationError

    from phfdi_base.spec import PlantModelSpec, format_validation

    path = resolve_preset(plant, PLANT_DIR, "plant model")
    try:
        return PlantModelSpec.model_validate(read_mapping(path))
    except ValidationError as exc:
        raise UserError(format_validation(exc, str(path))) from None


def build_plant(model: PlantModelSpec) -> CstrPlant:
    """The vessel of a plant model (a :class:`ZonedPlant` when the probe reads a mixing zone).

    Parameters
    ----------
    model : PlantModelSpec
        From :func:`load_plant_model`.

    Returns
    -------
    CstrPlant
        Not yet at a steady state: :func:`build_process` puts it at one.

    Examples
    --------
    >>> from ph_plant_sim import build_plant, load_plant_model
    >>> plant = build_plant(load_plant_model("paper"))
    >>> [f.name for f in plant.feeds]
    ['acid', 'buffer', 'base']
    """
    chem_spec = model.chemistry
    try:
        streams = [dict(f.recipe) for f in model.feeds.values()]
        compounds = dict(chem_spec.compounds)
        if model.air_exchange is not None:  # the exchanged component is in the vessel even if no feed carries it
            air = f"air exchange of {model.air_exchange.component}"
            compounds[air] = {model.air_exchange.component: 1.0}
            streams.append({air: 0.0})
        if model.initial_contents is not None:  # the vessel's own weak acid, carried by no feed
            own = f"initial contents of {model.initial_contents.component}"
            compounds[own] = {model.initial_contents.component: 1.0}
            streams.append({own: 0.0})
        chemistry = Chemistry.for_streams(
            streams,
            extra_components=[Component(c.name, c.charge, tuple(c.pka)) for c in chem_spec.components],
            extra_compounds=compounds,
            pkw=chem_spec.pkw,
        )
    except ValueError as exc:
        raise UserError(f"plant model {model.name!r}: {exc}") from None
    feeds = [Feed(name, dict(f.recipe), f.flow_ml_s) for name, f in model.feeds.items()]
    t = model.tank
    outlet = GravityOutlet(t.outlet.cv, t.outlet.z_cm, t.outlet.n) if t.outlet else None
    plant = CstrPlant(chemistry, feeds, Tank(t.area_cm2, outlet, t.overflow, t.volume_ml))
    if model.mixing is not None:  # the probe reads a zone exchanging with the bulk
        m = model.mixing
        # a ZonedPlant stands in for the CstrPlant it wraps (the same interface, delegating)
        return cast(CstrPlant, ZonedPlant(plant, MixingZone(m.zone_volume_ml, m.exchange_ml_s, tuple(m.feeds))))
    if model.series is not None:  # compartments in series, the probe at the last
        return cast(CstrPlant, SeriesPlant(plant, TanksInSeries(model.series.n_tanks)))
    if model.air_exchange is not None:  # a component exchanging with the air (CO2)
        x = model.air_exchange
        try:
            return cast(CstrPlant, ExchangePlant(plant, AirExchange(x.component, x.kla_per_s, x.equilibrium_mol_l)))
        except ValueError as exc:
            raise UserError(f"plant model {model.name!r}: {exc}") from None
    return plant


def initial_contents(model: PlantModelSpec) -> InitialContents | None:
    """The vessel's own contents at the start (``plant.initial_contents``; :mod:`ph_plant_sim.contents`), or None."""
    c = model.initial_contents
    return InitialContents(c.component, c.conc_mol_l) if c is not None else None


def feed_lines(model: PlantModelSpec, dt_s: float) -> dict[str, Chain]:
    """Each feed's line blocks (``feeds.<name>.line``) as a chain; feeds without a line are left out."""
    out = {}
    for name, f in model.feeds.items():
        if f.line:
            out[name] = Chain([_line_block(b.type, b.params, f"plant.feeds.{name}.line.{i}", dt_s)
                               for i, b in enumerate(f.line)])
    return out


def _line_block(kind: str, params: dict, where: str, dt_s: float):
    try:
        return make_block(kind, params, dt_s=dt_s)
    except (ValueError, TypeError) as exc:
        raise UserError(f"{where}: {exc}") from None


def sensor_chain(spec: SensorSpec, dt_s: float, seed: int, where: str, faults: list) -> Chain:
    """delay -> lag -> extra effects -> injected faults -> noise."""
    blocks: list = []
    if spec.delay_s > 0:
        blocks.append(checked_block("sensor_delay", {"delay_s": spec.delay_s}, f"sensors.{where}", dt_s))
    if spec.lag_s > 0:
        blocks.append(checked_block("sensor_lag", {"tau_s": spec.lag_s}, f"sensors.{where}", dt_s))
    for i, b in enumerate(spec.extra):
        blocks.append(checked_block(b.type, b.params, f"sensors.{where}.extra.{i}", dt_s))
    blocks.extend(faults)
    if spec.noise_std > 0:
        blocks.append(checked_block("sensor_noise", {"std": spec.noise_std, "seed": seed}, f"sensors.{where}", dt_s))
    return Chain(blocks)


@dataclass
class PlantStart:
    """The plant's side of the loop's starting steady state (at the t=0 setpoints), from :func:`plant_start`.

    Attributes
    ----------
    flows_ml_s : list of float
        Every feed's flow (mL/s), in the plant's feed order.
    valve_feed_index : int
        The feed the pH valve drives.
    outlet_opening : float
        Fraction of full outlet flow that holds the level setpoint (1 without one).

    Examples
    --------
    >>> from ph_plant_sim import PlantStart
    >>> PlantStart([9.8, 2.0, 15.6], 0, 0.43).flows_ml_s[0]
    9.8
    """

    flows_ml_s: list[float]  # every feed, plant feed order
    valve_feed_index: int  # the feed the pH valve drives
    outlet_opening: float  # fraction of full outlet flow that holds the level setpoint (1 without one)


def plant_start(spec: ScenarioSpec, plant: CstrPlant, ph_target: float | None = None) -> PlantStart:
    """Feed flows that hold the plant at the pH (default: the initial setpoint) and the outlet opening that
    holds the level setpoint.

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario (valves, setpoints, feed schedules).
    plant : CstrPlant
        From :func:`build_plant`.
    ph_target : float, optional
        The pH to hold instead of the initial setpoint.

    Returns
    -------
    PlantStart

    Raises
    ------
    UserError
        The pH or the level cannot be held with these feeds and this valve.

    Examples
    --------
    >>> from ph_plant_sim import build_plant, load_plant_model, plant_start
    >>> from phfdi.scenario import load_scenario
    >>> spec = load_scenario("paper")
    >>> start = plant_start(spec, build_plant(load_plant_model(spec.plant)))
    >>> [round(q, 2) for q in start.flows_ml_s], round(start.outlet_opening, 3)
    ([9.82, 2.0, 15.6], 0.427)
    """
    vspec = spec.valves.ph
    names = [f.name for f in plant.feeds]
    if vspec.feed not in names:
        raise UserError(f"valves.ph.feed: plant has no feed {vspec.feed!r} (feeds: {', '.join(names)})")
    k = names.index(vspec.feed)
    flows = [profile(spec.feeds[n]).value(0.0) if n in spec.feeds else f.flow_ml_s
             for n, f in zip(names, plant.feeds)]
    target = spec.setpoints.ph.initial if ph_target is None else ph_target
    assert vspec.max_flow_ml_s is not None  # the scenario schema requires it for the pH valve
    try:
        flows[k] = plant.flow_for_ph(target, k, flows, vspec.max_flow_ml_s)
    except ValueError as exc:
        raise UserError(f"setpoints.ph: {exc}") from None
    opening = 1.0
    if spec.setpoints.level_cm is not None and not plant.tank.overflow:
        level = spec.setpoints.level_cm.initial
        opening = sum(flows) / plant.tank.gravity_outlet.flow(level, 1.0)
        if not 0.0 < opening <= 1.0:
            raise UserError(f"setpoints.level_cm: level {level} cm needs an outlet opening of "
                            f"{100 * opening:.0f} % of full flow, outside 0..100 %")
    return PlantStart(flows, k, opening)


def build_process(spec: ScenarioSpec, plant: CstrPlant, model: PlantModelSpec, flows_ml_s: list[float],
                  outlet_opening: float) -> PlantProcess:
    """The plant with its sensors, schedules and feed lines, at rest at these flows and outlet opening (plus the
    vessel's own initial contents, if the model has them: :meth:`PlantProcess.rest`).

    Parameters
    ----------
    spec : ScenarioSpec
        The scenario (sensors and their faults, feed schedules, sample time, seed).
    plant : CstrPlant
        From :func:`build_plant`; put at the steady state of ``flows_ml_s``.
    model : PlantModelSpec
        The plant model (its feed lines).
    flows_ml_s : list of float
        Every feed's flow (mL/s) at rest, e.g. ``plant_start(...).flows_ml_s``.
    outlet_opening : float
        Fraction of full outlet flow at rest.

    Returns
    -------
    PlantProcess

    Examples
    --------
    >>> from ph_plant_sim import build_plant, build_process, load_plant_model, plant_start
    >>> from phfdi.scenario import load_scenario
    >>> spec = load_scenario("paper")
    >>> model = load_plant_model(spec.plant)
    >>> plant = build_plant(model)
    >>> start = plant_start(spec, plant)
    >>> process = build_process(spec, plant, model, start.flows_ml_s, start.outlet_opening)
    >>> round(process.measure(0.0).ph_true, 2), round(plant.level_cm, 2)
    (12.0, 14.0)
    """
    dt = spec.sample_time_s
    # independent noise streams per sensor, derived from the scenario seed
    process = PlantProcess(
        plant,
        sensor_chain(spec.sensors.ph, dt, spec.seed * 2 + 0, "ph", injected_faults(spec, "ph_sensor")),
        sensor_chain(spec.sensors.level, dt, spec.seed * 2 + 1, "level", injected_faults(spec, "level_sensor")),
        {name: profile(p) for name, p in spec.feeds.items()},
        dt,
        feed_lines(model, dt),
        initial_contents(model),
    )
    process.rest(flows_ml_s, outlet_opening)
    return process
