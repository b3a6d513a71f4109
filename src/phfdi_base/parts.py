"""A node's part of a resolved scenario: what the launcher hands each node of the graph.

The launcher (:mod:`phfdi.ros.launcher`) resolves and validates the scenario
once, computes the loop's starting steady state once, and writes one
:class:`NodePart` per node as JSON; each node reads it and builds only its own
part with its core's factory (``ph_plant_sim.build``, ``valve_actuator.build``,
``pi_controllers.build``). The launcher has validated the scenario; a node
reads it back as a :class:`SpecView` (attribute access as on the pydantic
models, without importing pydantic: about 0.2 s of CPU less per node at
start-up); ``read_part(path, validate=True)`` validates it again. A node started by hand (scenario parameters, no
part file) asks the installed resolver for the same thing: the application
registers one under the entry-point group ``phfdi.node_parts``, so the cores
never import the application.

Examples
--------
>>> import json
>>> part = NodePart.from_json(json.loads(EXAMPLE))
>>> part.scenario.name, part.start.valve_command_pct, part.base_scenario
('demo', 40.0, 'demo')
>>> view = NodePart.from_json(json.loads(json.dumps(part.to_json())), validate=False).scenario
>>> type(view).__name__, view.valves.ph.feed, view.model_dump() == part.scenario.model_dump(mode="json")
('SpecView', 'base', True)
"""

from __future__ import annotations

import copy
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any, cast

from .errors import UserError

if TYPE_CHECKING:  # the schema (pydantic) only where a part is validated, not when a node reads its part
    from .spec import PlantModelSpec, ScenarioSpec

__all__ = ["ENTRY_POINT_GROUP", "LoopStart", "NodePart", "SpecView", "read_part", "resolve_part", "write_part"]

#: the key that marks a schema object (a pydantic model) in a part file, with its class name
MODEL_KEY = "__spec__"

#: the entry-point group of the resolver a node started by hand uses (scenario, fault, overrides, onset_s)
ENTRY_POINT_GROUP = "phfdi.node_parts"


@dataclass
class LoopStart:
    """The loop's starting steady state (at the t=0 setpoints), computed once for every node."""

    valve_command_pct: float
    outlet_command_pct: float
    outlet_opening: float  # fraction of full outlet flow
    flows_ml_s: list[float]  # every feed, plant feed order
    ph: float  # the plant's pH at rest there
    level_cm: float  # the plant's level at rest there


class SpecView(SimpleNamespace):
    """A validated scenario or plant model read back from a part file: the fields of the pydantic model
    as attributes (nested models as views, lists and mappings as they are), without pydantic.

    What the cores read of a :class:`~phfdi_base.spec.ScenarioSpec` reads the same here; ``model_dump``
    and ``model_copy`` do what the model's do for the JSON data a view holds.
    """

    def model_dump(self, mode: str = "python") -> dict:
        """The plain data (as ``ScenarioSpec.model_dump(mode="json")`` gave it to the launcher)."""
        return _plain(self)

    def model_copy(self, update: dict | None = None) -> "SpecView":
        """A copy with some fields replaced (nested views shared, as pydantic's shallow copy)."""
        return SpecView(**{**vars(self), **(update or {})})


def _plain(value: Any) -> Any:
    if isinstance(value, SpecView):
        return {k: _plain(v) for k, v in vars(value).items()}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return copy.copy(value)


def _marked(model: Any, dumped: Any) -> Any:
    """``dumped`` (a model's JSON dump) with each object that was a model marked with :data:`MODEL_KEY`."""
    fields = getattr(type(model), "model_fields", None)
    if fields is not None and isinstance(dumped, dict):
        return {MODEL_KEY: type(model).__name__, **{k: _marked(getattr(model, k), v) for k, v in dumped.items()}}
    if isinstance(model, dict) and isinstance(dumped, dict):
        return {k: _marked(model.get(k), v) for k, v in dumped.items()}
    if isinstance(model, (list, tuple)) and isinstance(dumped, list):
        return [_marked(m, d) for m, d in zip(model, dumped)]
    return dumped


def _unmarked(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _unmarked(v) for k, v in value.items() if k != MODEL_KEY}
    if isinstance(value, list):
        return [_unmarked(v) for v in value]
    return value


def _view(value: Any) -> Any:
    if isinstance(value, dict):
        items = {k: _view(v) for k, v in value.items() if k != MODEL_KEY}
        return SpecView(**items) if MODEL_KEY in value else items
    if isinstance(value, list):
        return [_view(v) for v in value]
    return value


def _dump(model: Any) -> Any:
    return _marked(model, model.model_dump(mode="json"))


@dataclass
class NodePart:
    """The resolved scenario, its starting point and what a runtime fault change re-resolves from."""

    scenario: ScenarioSpec
    start: LoopStart
    raw_scenario: dict = field(default_factory=dict)  # the scenario before fault, onset and overrides
    fault_library: dict = field(default_factory=dict)  # named faults a node may switch to at runtime
    base_scenario: str = ""  # the scenario's own name (shipped calibrations are per base scenario)
    #: the scenario's plant model (its preset file read and validated once; None: read ``scenario.plant``)
    plant_model: PlantModelSpec | None = None

    def to_json(self) -> dict:
        """JSON data; schema objects carry :data:`MODEL_KEY` so that a node can read them without the schema."""
        return {"scenario": _dump(self.scenario), "start": asdict(self.start),
                "raw_scenario": self.raw_scenario, "fault_library": self.fault_library,
                "base_scenario": self.base_scenario,
                "plant_model": None if self.plant_model is None else _dump(self.plant_model)}

    @classmethod
    def from_json(cls, data: dict, source: str = "node part", validate: bool = True) -> "NodePart":
        """``validate=False``: the scenario and plant model as :class:`SpecView` (trusting the launcher that
        validated them); data without the marks is validated anyway."""
        try:
            scenario, plant = data["scenario"], data.get("plant_model")
            if validate or MODEL_KEY not in scenario:
                from .spec import PlantModelSpec, format_validation, validate_scenario

                spec = validate_scenario(_unmarked(scenario), source=source)
                try:
                    model = None if plant is None else PlantModelSpec.model_validate(_unmarked(plant))
                except ValueError as exc:  # pydantic's ValidationError
                    raise UserError(format_validation(cast(Any, exc), f"{source}: plant_model")) from None
            else:
                spec, model = cast("ScenarioSpec", _view(scenario)), cast("PlantModelSpec | None", _view(plant))
            return cls(spec, LoopStart(**data["start"]), data.get("raw_scenario", {}), data.get("fault_library", {}),
                       data.get("base_scenario", ""), model)
        except (KeyError, TypeError) as exc:
            raise UserError(f"{source}: not a node part ({type(exc).__name__}: {exc})") from None


def write_part(path: str | Path, part: NodePart) -> Path:
    """Write a part as JSON (the launcher does, one per node)."""
    path = Path(path)
    path.write_text(json.dumps(part.to_json()), encoding="utf-8")
    return path


def read_part(path: str | Path, validate: bool = True) -> NodePart:
    """Read a part the launcher wrote; a one-line :class:`UserError` if it is missing or broken.

    ``validate=False`` (a node of a launched graph): the scenario as the launcher validated it, as
    :class:`SpecView` objects, without importing the schema."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"no such node part file: {path}") from None
    except (OSError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the node part ({exc})") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: not a node part (a JSON object expected)")
    return NodePart.from_json(data, source=str(path), validate=validate)


def resolve_part(scenario: str, fault: str | None, overrides: list[str], onset_s: float | None) -> NodePart:
    """A part from scenario parameters, through the installed resolver (a node started by hand)."""
    from importlib import metadata  # only here: it costs a launched node's start-up about 0.1 s

    found = metadata.entry_points(group=ENTRY_POINT_GROUP)
    if not found:
        raise UserError(f"no scenario resolver installed (entry point group {ENTRY_POINT_GROUP}): "
                        "start the graph with phfdi launch, or run bash scripts/setup.sh")
    resolver = sorted(found, key=lambda e: e.name)[0].load()
    return resolver(scenario, fault, overrides, onset_s)


EXAMPLE = json.dumps({
    "scenario": {"name": "demo", "plant": "paper", "duration_s": 100, "setpoints": {"ph": {"initial": 7}},
                 "controllers": {"ph": {"kp": 1, "ti_s": 10}}, "valves": {"ph": {"feed": "base",
                                                                                 "max_flow_ml_s": 2}}},
    "start": {"valve_command_pct": 40.0, "outlet_command_pct": 100.0, "outlet_opening": 1.0,
              "flows_ml_s": [1.0, 0.8], "ph": 7.0, "level_cm": 10.0},
    "base_scenario": "demo"})
