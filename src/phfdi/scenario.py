"""Scenario and plant-model files: finding, merging and validating them.

A *plant model* (``ph_plant_sim/presets/<name>.yaml``) is the vessel, its
feeds and their chemistry. A *scenario* (``phfdi/scenarios/<name>.yaml``) is
a whole experiment on the loop. A scenario may ``extends:`` another and
override any key. Faults can also come from the fault library
(``phfdi/scenarios/faults.yaml``) by name. The schema itself is
:mod:`phfdi_base.spec` (re-exported here for the application's convenience).

Every error names the key and the problem (:class:`phfdi_base.errors.UserError`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from phfdi_base.errors import UserError
from phfdi_base.spec import (  # noqa: F401
    BlockSpec,
    ChangeSpec,
    ChemistrySpec,
    ComponentSpec,
    ControllersSpec,
    FaultSite,
    FaultSpec,
    FeedSpec,
    MixingSpec,
    OutletSpec,
    PISpec,
    PlantModelSpec,
    ProfileSpec,
    ScenarioSpec,
    SensorSpec,
    SensorsSpec,
    SetpointsSpec,
    TankSpec,
    ValveSpec,
    ValvesSpec,
    deep_merge,
    format_validation,
    load_plugins,
    validate_scenario,
)
from phfdi_base.yamlfile import read_mapping


def _package_dir(package: str, sub: str = "") -> Path:
    return Path(str(resources.files(package))) / sub


SCENARIO_DIR = _package_dir("phfdi", "scenarios")
PLANT_DIR = _package_dir("ph_plant_sim", "presets")


def list_presets(directory: Path) -> dict[str, str]:
    """name -> description of the YAML presets in a directory."""
    out = {}
    for p in sorted(directory.glob("*.yaml")):
        if p.stem == "faults":
            continue
        out[p.stem] = str(read_mapping(p).get("description", "")).strip().splitlines()[0:1]
        out[p.stem] = out[p.stem][0] if out[p.stem] else ""
    return out


def fault_library() -> dict[str, dict]:
    """Named fault presets (the paper's severities), from faults.yaml."""
    return read_mapping(SCENARIO_DIR / "faults.yaml")["faults"]


def _resolve(name_or_path: str, directory: Path, kind: str) -> Path:
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        return p
    candidate = directory / f"{name_or_path}.yaml"
    if not candidate.exists():
        known = ", ".join(list_presets(directory))
        raise UserError(f"unknown {kind} {name_or_path!r}; presets: {known} (or give a .yaml path)")
    return candidate


def _absolutise(data: dict, base: Path) -> None:
    """Relative file references in a scenario are relative to the scenario file."""

    def fix(ref):
        if isinstance(ref, str) and ref.endswith((".yaml", ".yml", ".py")) and not Path(ref).is_absolute():
            return str((base / ref).resolve())
        return ref

    for key in ("extends", "plant"):
        if key in data:
            data[key] = fix(data[key])
    if isinstance(data.get("plugins"), list):
        data["plugins"] = [fix(p) for p in data["plugins"]]


def raw_scenario(name_or_path: str, _seen: tuple = ()) -> dict:
    """Scenario mapping with ``extends`` resolved (not yet validated)."""
    path = _resolve(name_or_path, SCENARIO_DIR, "scenario")
    data = read_mapping(path)
    _absolutise(data, path.parent)
    parent = data.pop("extends", None)
    if parent:
        if parent in _seen:
            raise UserError(f"{path}: 'extends' loops back to {parent!r}")
        data = deep_merge(raw_scenario(parent, _seen + (parent,)), data)
    data.setdefault("name", path.stem)
    return data


def load_plant_model(plant: str | PlantModelSpec) -> PlantModelSpec:
    if isinstance(plant, PlantModelSpec):
        return plant
    path = _resolve(plant, PLANT_DIR, "plant model")
    try:
        return PlantModelSpec.model_validate(read_mapping(path))
    except ValidationError as exc:
        raise UserError(format_validation(exc, str(path))) from None


def parse_override(text: str) -> tuple[list[str], Any]:
    """'a.b.c=value' -> (['a','b','c'], yaml-parsed value)."""
    if "=" not in text:
        raise UserError(f"--set expects key=value, got {text!r}")
    key, value = text.split("=", 1)
    try:
        parsed = yaml.safe_load(value)
    except yaml.YAMLError:
        parsed = value
    return key.strip().split("."), parsed


def apply_override(data: dict, keys: list[str], value: Any) -> None:
    node = data
    for k in keys[:-1]:
        if isinstance(node, list):
            node = node[int(k)]
        else:
            node = node.setdefault(k, {})
    if isinstance(node, list):
        node[int(keys[-1])] = value
    else:
        node[keys[-1]] = value


def load_scenario(name_or_path: str = "paper", fault: str | None = None,
                  overrides: list[str] = (), onset_s: float | None = None) -> ScenarioSpec:
    """Load, apply a named fault and ``key=value`` overrides, validate.

    ``fault`` replaces the scenario's faults with the library fault of that
    name ("none" or "healthy" removes them).
    """
    data = raw_scenario(name_or_path)
    if fault is not None:
        if fault in ("none", "healthy"):
            data["faults"] = []
        else:
            lib = fault_library()
            if fault not in lib:
                raise UserError(f"unknown fault {fault!r}; known: healthy, {', '.join(lib)}")
            entry = dict(lib[fault])
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
    return validate_scenario(data, source=f"scenario {name_or_path}")
