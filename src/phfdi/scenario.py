"""Scenario and plant-model files: finding, merging and validating them.

A *plant model* (``ph_plant_sim/presets/<name>.yaml``) is the vessel, its
feeds and their chemistry. A *scenario* (``phfdi/scenarios/<name>.yaml``) is
a whole experiment on the loop. A scenario may ``extends:`` another and
override any key. Faults can also come from the fault library by name: the
presets of the fault catalogue (:func:`phfdi.faults.fault_library`). The schema itself is
:mod:`phfdi_base.spec`.

Every error names the key and the problem (:class:`phfdi_base.errors.UserError`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from phfdi_base.errors import UserError
from phfdi_base.spec import ScenarioSpec, deep_merge, load_plugins, resolve_scenario
from phfdi_base.yamlfile import read_mapping, resolve_preset

from .faults import fault_library, preset_name


def _package_dir(package: str, sub: str = "") -> Path:
    return Path(str(resources.files(package))) / sub


SCENARIO_DIR = _package_dir("phfdi", "scenarios")


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
    path = resolve_preset(name_or_path, SCENARIO_DIR, "scenario")
    data = read_mapping(path)
    _absolutise(data, path.parent)
    parent = data.pop("extends", None)
    if parent:
        if parent in _seen:
            raise UserError(f"{path}: 'extends' loops back to {parent!r}")
        data = deep_merge(raw_scenario(parent, _seen + (parent,)), data)
    data.setdefault("name", path.stem)
    return data


def load_scenario(name_or_path: str = "paper", fault: str | None = None,
                  overrides: list[str] = (), onset_s: float | None = None) -> ScenarioSpec:
    """Load, apply a named fault and ``key=value`` overrides, validate.

    ``fault`` replaces the scenario's faults with the library fault of that
    name, or of that block ("none" or "healthy" removes them).
    """
    raw = raw_scenario(name_or_path)
    library = {}
    if fault not in (None, "none", "healthy"):
        load_plugins(raw.get("plugins") or [])  # a plugin's blocks may declare the named fault
        fault = preset_name(fault)
        library = fault_library()
    return resolve_scenario(raw, fault, library, overrides, onset_s, source=f"scenario {name_or_path}")
