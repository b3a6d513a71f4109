"""A node's part of a resolved scenario: what the launcher hands each node of the graph.

The launcher (:mod:`phfdi.ros.launcher`) resolves and validates the scenario
once, computes the loop's starting steady state once, and writes one
:class:`NodePart` per node as JSON; each node reads it and builds only its own
part with its core's factory (``ph_plant_sim.build``, ``valve_actuator.build``,
``pi_controllers.build``). A node started by hand (scenario parameters, no
part file) asks the installed resolver for the same thing: the application
registers one under the entry-point group ``phfdi.node_parts``, so the cores
never import the application.

Examples
--------
>>> import json
>>> part = NodePart.from_json(json.loads(EXAMPLE))
>>> part.scenario.name, part.start.valve_command_pct, part.base_scenario
('demo', 40.0, 'demo')
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from .errors import UserError
from .spec import ScenarioSpec, validate_scenario

__all__ = ["ENTRY_POINT_GROUP", "LoopStart", "NodePart", "read_part", "resolve_part", "write_part"]

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


@dataclass
class NodePart:
    """The resolved scenario, its starting point and what a runtime fault change re-resolves from."""

    scenario: ScenarioSpec
    start: LoopStart
    raw_scenario: dict = field(default_factory=dict)  # the scenario before fault, onset and overrides
    fault_library: dict = field(default_factory=dict)  # named faults a node may switch to at runtime
    base_scenario: str = ""  # the scenario's own name (shipped calibrations are per base scenario)

    def to_json(self) -> dict:
        return {"scenario": self.scenario.model_dump(mode="json"), "start": asdict(self.start),
                "raw_scenario": self.raw_scenario, "fault_library": self.fault_library,
                "base_scenario": self.base_scenario}

    @classmethod
    def from_json(cls, data: dict, source: str = "node part") -> "NodePart":
        try:
            return cls(validate_scenario(data["scenario"], source=source), LoopStart(**data["start"]),
                       data.get("raw_scenario", {}), data.get("fault_library", {}), data.get("base_scenario", ""))
        except (KeyError, TypeError) as exc:
            raise UserError(f"{source}: not a node part ({type(exc).__name__}: {exc})") from None


def write_part(path: str | Path, part: NodePart) -> Path:
    """Write a part as JSON (the launcher does, one per node)."""
    path = Path(path)
    path.write_text(json.dumps(part.to_json()), encoding="utf-8")
    return path


def read_part(path: str | Path) -> NodePart:
    """Read a part the launcher wrote; a one-line :class:`UserError` if it is missing or broken."""
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"no such node part file: {path}") from None
    except (OSError, ValueError) as exc:
        raise UserError(f"{path}: cannot read the node part ({exc})") from None
    return NodePart.from_json(data, source=str(path))


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
