"""Write a fitted model as a scenario file the simulator loads.

The file ``extends:`` the nominal scenario (by preset name, or by absolute
path for a file) and restates only the top-level keys the extension (or a
``--set`` override) changed: a block in ``faults`` or ``sensors.ph.extra``,
a valve's maximum flow, the plant model written inline (``plant:`` mapping)
for a process candidate, a feed schedule. ``phfdi simulate --scenario
FILE`` runs it; :func:`load_model_file` reads it back for the check that
the file reproduces what the diagnosis scored.
"""

from __future__ import annotations

import copy
from pathlib import Path

import yaml

from phfdi.scenario import raw_scenario
from phfdi_base.outputs import write_text

from .model import inline_plant

#: keys the evaluator sets per record; never written
_RECORD_KEYS = ("sample_time_s", "duration_s")


def _parent(model: str) -> str:
    p = Path(model)
    return str(p.resolve()) if p.suffix in (".yaml", ".yml") else model


def changed_keys(model: str, raw: dict) -> dict:
    """Top-level keys of ``raw`` that differ from the scenario ``model`` as written."""
    base = inline_plant(raw_scenario(model))
    base.pop("extends", None)
    out = {}
    for key, value in raw.items():
        if key in _RECORD_KEYS or key == "name":
            continue
        if key == "plant":
            if value != base.get("plant"):
                out[key] = copy.deepcopy(value)
            continue
        if value != base.get(key):
            out[key] = copy.deepcopy(value)
    return out


def write_model(path: str | Path, model: str, raw: dict, header: str, name: str) -> Path:
    """Write ``raw`` (a full scenario mapping) as a file extending ``model``."""
    doc = {"extends": _parent(model), "name": name}
    doc.update(changed_keys(model, raw))
    text = "".join(f"# {line}\n" for line in header.strip().splitlines())
    text += yaml.safe_dump(_plain(doc), sort_keys=False, default_flow_style=None, width=110)
    return write_text(path, text, overwrite=True)


def _plain(o):
    if isinstance(o, dict):
        return {str(k): _plain(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_plain(v) for v in o]
    if hasattr(o, "item"):
        return o.item()
    if isinstance(o, float):
        return float(f"{o:.10g}")
    return o


def load_model_file(path: str | Path) -> dict:
    """The scenario mapping of a written model, plant inline, as the evaluator takes it."""
    raw = inline_plant(raw_scenario(str(path)))
    raw.pop("extends", None)
    return raw
