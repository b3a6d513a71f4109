"""The scenario resolved once for a whole graph: one :class:`phfdi_base.parts.NodePart` for every node.

The launcher calls :func:`make_part` once and writes the result for each node;
a node started by hand reaches the same function through the entry point
``phfdi.node_parts`` (pyproject.toml), so every node starts from the same
resolved scenario and the same starting steady state.
"""

from __future__ import annotations

from dataclasses import asdict

from ph_plant_sim.build import load_plant_model
from phfdi.faults import base_scenario, fault_library
from phfdi.loop import build_parts
from phfdi.scenario import raw_scenario
from phfdi_base.parts import LoopStart, NodePart
from phfdi_base.spec import ScenarioSpec, resolve_scenario

__all__ = ["make_part", "part_for", "recorded_part"]


def make_part(scenario: str, fault: str | None = None, overrides: list[str] = (),
              onset_s: float | None = None) -> NodePart:
    """Resolve and validate the scenario, build the loop once (every check of the in-process loop) and keep
    what the nodes need: the spec, the starting steady state and what a runtime fault change re-resolves from.

    Examples
    --------
    >>> part = make_part("paper", fault="backlash")
    >>> part.scenario.name, part.base_scenario, 0 < part.start.valve_command_pct < 100
    ('paper-backlash', 'paper', True)
    """
    raw = raw_scenario(scenario)
    library = fault_library()
    spec = resolve_scenario(raw, fault, library, list(overrides), onset_s, source=f"scenario {scenario}")
    return part_for(spec, raw, library, str(raw.get("name", scenario)))


def part_for(spec: ScenarioSpec, raw: dict, library: dict, base_scenario: str) -> NodePart:
    """The part of an already resolved scenario (the loop built once for its starting steady state)."""
    parts = build_parts(spec)
    plant = parts.process.plant
    start = LoopStart(**asdict(parts.start), ph=plant.ph, level_cm=plant.level_cm)
    return NodePart(spec, start, raw, library, base_scenario, load_plant_model(spec.plant))


def recorded_part(spec: ScenarioSpec) -> NodePart:
    """The part of a scenario read back from a recording (a bag's metadata): its base scenario is its name
    without the ``-<fault>`` suffix that naming a library fault added (:func:`phfdi.faults.base_scenario`).

    Examples
    --------
    >>> from phfdi.scenario import load_scenario
    >>> recorded_part(load_scenario("paper", fault="backlash")).base_scenario
    'paper'
    """
    return part_for(spec, spec.model_dump(mode="json"), fault_library(), base_scenario(spec.name))
