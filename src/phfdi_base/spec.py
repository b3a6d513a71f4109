"""The schema of scenarios and plant models: what a validated experiment on the loop is.

A *plant model* is the vessel, its feeds and their chemistry. A *scenario* is
a whole experiment on the loop: which plant, valves, sensors, controller
tuning, setpoint profile, faults, duration, noise and seed. Finding the files
(presets, ``extends:``, the fault library, ``--set`` overrides) is the
application's business (:mod:`phfdi.scenario`); this module only says what a
valid one is, so that the cores can take a :class:`ScenarioSpec` without
depending on the application.

Every error names the key and the problem (:class:`phfdi_base.errors.UserError`).
"""

from __future__ import annotations

import copy
from typing import Any, Literal, Sequence

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .errors import UserError
from .spec_tools import checked_block, injected_faults, load_plugins, profile
from .yamlfile import DuplicateKeyError, load_yaml

__all__ = [
    "AirExchangeSpec", "BlockSpec", "ChangeSpec", "ChemistrySpec", "ComponentSpec", "ControllersSpec", "FaultSite",
    "FaultSpec", "FeedSpec", "InitialContentsSpec", "MixingSpec", "OutletSpec", "PISpec", "PlantModelSpec",
    "ProfileSpec", "ScenarioSpec",
    "SensorSpec", "SeriesSpec",
    "SensorsSpec", "SetpointsSpec", "TankSpec", "ValveSpec", "ValvesSpec", "deep_merge", "format_validation",
    "apply_override", "checked_block", "injected_faults", "load_plugins", "parse_override", "profile",
    "resolve_scenario", "validate_scenario",
]


class Strict(BaseModel):
    # no unknown keys; no inf or NaN anywhere in a scenario or plant model (a number is a finite number)
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


#: the longest run a scenario may ask for, in samples (about 10 minutes of the in-process loop on this
#: project's 2-core machine at 60 us per sample; 116 days at 1 s sampling)
MAX_SAMPLES = 10_000_000


# ---- plant model ----------------------------------------------------------------
class ComponentSpec(Strict):
    name: str
    charge: int
    pka: list[float] = []


class ChemistrySpec(Strict):
    pkw: float = Field(14.0, gt=10.0, lt=18.0)
    components: list[ComponentSpec] = []
    compounds: dict[str, dict[str, float]] = {}


class BlockSpec(Strict):
    type: str
    params: dict[str, Any] = {}


class FeedSpec(Strict):
    recipe: dict[str, float] = Field(description="compound -> concentration (mol/L)")
    flow_ml_s: float = Field(0.0, ge=0.0, description="nominal flow when no valve drives the feed (mL/s)")
    line: list[BlockSpec] = Field([], description=(
        "blocks between the commanded flow and the vessel (ph_plant_sim.feedlines: line_delay, pump_curve, "
        "pump_lag), stepped per sample on the flow in mL/s"))

    @field_validator("recipe")
    @classmethod
    def _nonnegative(cls, v: dict[str, float]) -> dict[str, float]:
        for k, c in v.items():
            if not c >= 0.0:
                raise ValueError(f"concentration of {k} must be non-negative, got {c}")
        return v


class OutletSpec(Strict):
    cv: float = Field(gt=0.0, description="drain coefficient, mL/s per cm^n")
    z_cm: float = Field(0.0, description="outlet head offset (cm)")
    n: float = Field(0.5, gt=0.0, le=1.0)


class TankSpec(Strict):
    area_cm2: float = Field(gt=0.0)
    outlet: OutletSpec | None = None
    overflow: bool = False
    volume_ml: float | None = Field(None, gt=0.0)

    @model_validator(mode="after")
    def _consistent(self) -> "TankSpec":
        if self.overflow and self.volume_ml is None:
            raise ValueError("an overflow vessel needs volume_ml")
        if not self.overflow and self.outlet is None:
            raise ValueError("a vessel without overflow needs an outlet")
        return self


class MixingSpec(Strict):
    """A zone around the inlets and the probe exchanging with the bulk (ph_plant_sim.mixing)."""

    zone_volume_ml: float = Field(gt=0.0)
    exchange_ml_s: float = Field(ge=0.0, allow_inf_nan=False)
    feeds: list[str] = Field(description="feeds dosed into the zone; the others enter the bulk")


class SeriesSpec(Strict):
    """The vessel as equal, perfectly mixed compartments in series, probe at the last (ph_plant_sim.series)."""

    n_tanks: int = Field(ge=1, le=50)


class AirExchangeSpec(Strict):
    """First-order exchange of one component with the air, e.g. CO2 absorbed (ph_plant_sim.exchange)."""

    component: str = Field(description="a chemistry component, e.g. a carbonate with pKa 6.35 and 10.33")
    kla_per_s: float = Field(ge=0.0, allow_inf_nan=False, description="mass-transfer coefficient (1/s)")
    equilibrium_mol_l: float = Field(ge=0.0, allow_inf_nan=False, description="level it relaxes to (mol/L)")


class InitialContentsSpec(Strict):
    """A weak acid the vessel's own water holds at the start, washing out with the outflow (ph_plant_sim.contents)."""

    component: str = Field(description=(
        "a chemistry component: a library one (carbonate, phosphate, acetate, ...) or one declared in "
        "chemistry.components"))
    conc_mol_l: float = Field(ge=0.0, allow_inf_nan=False, description=(
        "its total concentration at t = 0 (mol/L), on top of the start composition"))


class PlantModelSpec(Strict):
    name: str
    description: str = ""
    chemistry: ChemistrySpec = ChemistrySpec()
    feeds: dict[str, FeedSpec]
    tank: TankSpec
    mixing: MixingSpec | None = None
    series: SeriesSpec | None = None
    air_exchange: AirExchangeSpec | None = None
    initial_contents: InitialContentsSpec | None = None

    @model_validator(mode="after")
    def _zone_feeds(self) -> "PlantModelSpec":
        for f in (self.mixing.feeds if self.mixing else []):
            if f not in self.feeds:
                raise ValueError(f"mixing.feeds: no feed {f!r} (feeds: {', '.join(self.feeds)})")
        structures = [k for k in ("mixing", "series", "air_exchange") if getattr(self, k) is not None]
        if len(structures) > 1:
            raise ValueError(f"{' and '.join(structures)} together are not modelled (one of them per vessel)")
        if self.series is not None and not self.tank.overflow:
            raise ValueError("series: tanks in series are modelled for an overflow vessel (constant volume) only")
        return self


# ---- loop ------------------------------------------------------------------------
class ChangeSpec(Strict):
    at_s: float = Field(ge=0.0)
    value: float
    ramp_s: float = Field(0.0, ge=0.0)


class ProfileSpec(Strict):
    initial: float
    changes: list[ChangeSpec] = []


class PISpec(Strict):
    kp: float = Field(gt=0.0, description="% per PV unit")
    ti_s: float = Field(gt=0.0)
    action: Literal["direct", "reverse"] = "reverse"
    antiwindup: Literal["back_calculation", "conditional", "none"] = "back_calculation"
    tt_s: float | None = Field(None, gt=0.0)
    u_min: float = 0.0
    u_max: float = 100.0
    setpoint_weight: float = Field(1.0, ge=0.0, le=1.0)


class ValveSpec(Strict):
    feed: str | None = Field(None, description="feed the valve manipulates; none for the outlet valve")
    max_flow_ml_s: float | None = Field(None, gt=0.0, le=1e6)  # up to 1 m3/s
    characteristic: Literal["linear", "equal_percentage"] = "linear"
    rangeability: float = Field(50.0, gt=1.0)


class SensorSpec(Strict):
    delay_s: float = Field(0.0, ge=0.0)
    lag_s: float = Field(0.0, ge=0.0)
    noise_std: float = Field(0.0, ge=0.0)
    extra: list[BlockSpec] = Field([], description="further sensor effects (blocks), after delay and lag")


FaultSite = Literal["valve", "valve_flow", "outlet_valve", "ph_sensor", "level_sensor"]


class FaultSpec(Strict):
    type: str
    where: FaultSite = "valve"
    params: dict[str, Any] = {}
    onset_s: float = Field(0.0, ge=0.0)
    ramp_s: float = Field(0.0, ge=0.0)


class SetpointsSpec(Strict):
    ph: ProfileSpec
    level_cm: ProfileSpec | None = None


class ControllersSpec(Strict):
    ph: PISpec
    level: PISpec | None = None


class ValvesSpec(Strict):
    ph: ValveSpec = Field(description="the valve the pH controller drives (the actuator under study)")
    outlet: ValveSpec | None = Field(None, description="outlet valve the level controller drives")


class SensorsSpec(Strict):
    ph: SensorSpec = SensorSpec()
    level: SensorSpec = SensorSpec()


class ScenarioSpec(Strict):
    """A validated scenario: plant, valves, sensors, controller tuning, setpoints, faults, duration, seed.

    Build one with :func:`validate_scenario` (a one-line :class:`~phfdi_base.errors.UserError` for bad
    input) or, from a preset or file, with the application's ``phfdi.scenario.load_scenario``. Each core
    builds its part from it (``ph_plant_sim.build``, ``valve_actuator.build``, ``pi_controllers.build``).

    Examples
    --------
    >>> from phfdi_base import validate_scenario
    >>> spec = validate_scenario({
    ...     "name": "demo", "plant": "paper", "duration_s": 600.0,
    ...     "setpoints": {"ph": {"initial": 8.0}},
    ...     "controllers": {"ph": {"kp": 6.0, "ti_s": 10.0, "action": "direct"}},
    ...     "valves": {"ph": {"feed": "acid", "max_flow_ml_s": 40.0}}})
    >>> spec.sample_time_s, spec.valves.ph.characteristic
    (1.0, 'linear')
    """

    name: str
    description: str = ""
    plant: str | PlantModelSpec
    sample_time_s: float = Field(1.0, gt=0.0)
    duration_s: float = Field(gt=0.0)
    seed: int = Field(0, ge=0)
    setpoints: SetpointsSpec
    controllers: ControllersSpec
    valves: ValvesSpec
    sensors: SensorsSpec = SensorsSpec()
    feeds: dict[str, ProfileSpec] = Field({}, description="flow schedules (mL/s) of feeds no valve drives")
    faults: list[FaultSpec] = []
    plugins: list[str] = Field([], description=(
        "modules or .py files (relative to the scenario file) that register user blocks before the loop is built"))
    min_actuator_margin_pct: float = Field(0.0, ge=0.0, lt=50.0, description=(
        "each pH setpoint must be reachable with the valve between margin and 100 - margin %"))

    @model_validator(mode="after")
    def _consistent(self) -> "ScenarioSpec":
        if (self.controllers.level is None) != (self.setpoints.level_cm is None):
            raise ValueError("setpoints.level_cm and controllers.level go together")
        if self.controllers.level is not None and self.valves.outlet is None:
            raise ValueError("controllers.level needs valves.outlet")
        if self.valves.ph.feed is None or self.valves.ph.max_flow_ml_s is None:
            raise ValueError("valves.ph needs feed and max_flow_ml_s")
        if self.duration_s / self.sample_time_s > MAX_SAMPLES:
            raise ValueError(f"duration_s / sample_time_s = {self.duration_s / self.sample_time_s:.3g} samples: at "
                             f"most {MAX_SAMPLES:.0e} per run (split a longer study into runs)")
        for i, f in enumerate(self.faults):
            if f.onset_s >= self.duration_s:
                raise ValueError(f"faults.{i}.onset_s = {f.onset_s} s is not before the end of the run "
                                 f"(duration_s = {self.duration_s} s)")
        for key, prof in (("setpoints.ph", self.setpoints.ph), ("setpoints.level_cm", self.setpoints.level_cm)):
            for j, c in enumerate(prof.changes if prof else []):
                if c.at_s >= self.duration_s:
                    raise ValueError(f"{key}.changes.{j}.at_s = {c.at_s} s is not before the end of the run")
        return self


# ---- helpers ---------------------------------------------------------------------
def deep_merge(base: dict, over: dict) -> dict:
    """``base`` with ``over`` laid on top, mappings merged key by key (neither is changed)."""
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = deep_merge(out[k], v)
        else:
            out[k] = copy.deepcopy(v)
    return out




def format_validation(exc: ValidationError, source: str) -> str:
    """One line naming the source, the key and the problem of a pydantic validation error."""
    errors = exc.errors()
    # a mapping given where a key accepts a name or a mapping (plant: preset | inline): the mapping's problem, not
    # "should be a valid string"
    err = next((e for e in errors if not e["type"].endswith("_type")), errors[0])
    loc = ".".join(str(x) for x in err["loc"] if "[" not in str(x)) or "(top level)"  # not pydantic's union tags
    msg = err["msg"]
    if err["type"] == "extra_forbidden":
        msg = "unknown key"
    elif msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    more = f" (and {len(exc.errors()) - 1} more problem(s))" if len(exc.errors()) > 1 else ""
    return f"{source}: {loc}: {msg}{more}"


def validate_scenario(data: dict, source: str = "scenario") -> ScenarioSpec:
    """A validated scenario; a :class:`UserError` naming ``source``, the key and the problem otherwise.

    Parameters
    ----------
    data : dict
        The scenario mapping (as read from YAML, ``extends:`` already resolved).
    source : str
        What the data came from, for the error message (a file name).

    Returns
    -------
    ScenarioSpec

    Examples
    --------
    >>> from phfdi_base import UserError, validate_scenario
    >>> try:
    ...     validate_scenario({"name": "demo", "plant": "paper", "duration_s": 0.0}, "demo.yaml")
    ... except UserError as exc:
    ...     print(str(exc).split(" (and")[0])
    demo.yaml: duration_s: Input should be greater than 0
    """
    try:
        return ScenarioSpec.model_validate(data)
    except ValidationError as exc:
        raise UserError(format_validation(exc, source)) from None


def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b.c=value' -> (['a','b','c'], yaml-parsed value)."""
    if "=" not in text:
        raise UserError(f"--set expects key=value, got {text!r}")
    key, value = text.split("=", 1)
    try:
        parsed = load_yaml(value, f"--set {key.strip()}")
    except DuplicateKeyError:
        raise
    except UserError:  # not YAML: the text itself (a name such as 'a: b' stays a string)
        parsed = value
    return key.strip().split("."), parsed


def apply_override(data: dict, keys: list[str], value: Any) -> None:
    """Set ``data[k0][k1]...`` (list items by index) to ``value`` in place; a path through something that is
    neither a mapping nor a list (or a list index that is not there) is a UserError naming the key."""
    node = data
    for i, k in enumerate(keys[:-1]):
        if isinstance(node, dict) and node.get(k) is None:
            node[k] = {}  # an empty YAML key (``setpoints:``) or a new one
        node = _step(node, k, keys, i)
    if isinstance(node, list):
        node[_index(node, keys[-1], keys, len(keys) - 1)] = value
    elif isinstance(node, dict):
        node[keys[-1]] = value
    else:
        _step(node, keys[-1], keys, len(keys) - 1)  # raises: not a mapping


def _step(node: Any, key: str, keys: list[str], i: int) -> Any:
    if isinstance(node, list):
        return node[_index(node, key, keys, i)]
    if isinstance(node, dict):
        return node[key]
    raise UserError(f"--set {'.'.join(keys)}: {'.'.join(keys[:i]) or 'the scenario'} is "
                    f"{type(node).__name__} {node!r}, not a mapping")


def _index(node: list, key: str, keys: list[str], i: int) -> int:
    try:
        k = int(key)
        node[k]
    except (ValueError, IndexError):
        raise UserError(f"--set {'.'.join(keys)}: {'.'.join(keys[:i])} is a list of {len(node)}; "
                        f"{key!r} is not an index of it") from None
    return k


def resolve_scenario(raw: dict, fault: str | None, library: dict[str, dict], overrides: Sequence[str] = (),
                     onset_s: float | None = None, source: str = "scenario") -> ScenarioSpec:
    """A scenario mapping (``extends`` already resolved) made into a validated scenario.

    ``fault`` replaces the scenario's faults with the entry of that name in
    ``library`` ("none" or "healthy" removes them; None keeps them); ``onset_s``
    moves every fault's onset; then the ``key=value`` overrides apply. The
    application calls this with the files it found; a node re-resolves with
    the same inputs when its fault changes at runtime.

    Examples
    --------
    >>> raw = {"name": "demo", "plant": "paper", "duration_s": 100, "setpoints": {"ph": {"initial": 7}},
    ...        "controllers": {"ph": {"kp": 1, "ti_s": 10}},
    ...        "valves": {"ph": {"feed": "base", "max_flow_ml_s": 2}}}
    >>> spec = resolve_scenario(raw, "stuck", {"stuck": {"type": "stiction", "params": {"s_pct": 2}}},
    ...                         onset_s=50)
    >>> spec.name, spec.faults[0].type, spec.faults[0].onset_s
    ('demo-stuck', 'stiction', 50.0)
    """
    data = copy.deepcopy(raw)
    if fault is not None:
        if fault in ("none", "healthy"):
            data["faults"] = []
        else:
            if fault not in library:
                raise UserError(f"unknown fault {fault!r}; known: healthy, {', '.join(library)}")
            entry = dict(library[fault])
            entry.pop("description", None)
            data["faults"] = [entry]
    if onset_s is not None:
        for f in data.get("faults", []):
            f["onset_s"] = onset_s
    for text in overrides:
        keys, value = parse_override(text)
        apply_override(data, keys, value)
    if fault is not None and fault not in ("none", "healthy"):
        data["name"] = f"{data.get('name', 'scenario')}-{fault}"
    return validate_scenario(data, source=source)





