"""What the cores build from a validated scenario, without pydantic: profiles, fault blocks, user plugins.

:mod:`phfdi_base.spec` says what a valid scenario is (pydantic models); these
functions only read one, by attribute, so a node that takes the scenario the
launcher already validated (:func:`phfdi_base.parts.read_part`) never imports
pydantic (about 0.2 s of CPU per process at start-up).

Examples
--------
>>> from types import SimpleNamespace as NS
>>> profile(NS(initial=7.0, changes=[NS(at_s=10.0, value=8.0, ramp_s=0.0)])).value(20.0)
8.0
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path
from typing import Any, Collection

from .blocks import Block, Injected, make_block
from .errors import UserError
from .profiles import Change, Profile

#: a validated scenario: a :class:`phfdi_base.spec.ScenarioSpec` or its view (:class:`phfdi_base.parts.SpecView`)
Scenario = Any

__all__ = ["checked_block", "injected_faults", "load_plugins", "profile"]


def load_plugins(plugins: list[str]) -> None:
    """Import user modules (dotted names or .py files) so their blocks register."""
    for ref in plugins:
        try:
            if ref.endswith(".py"):
                name = f"phfdi_plugin_{Path(ref).stem}"
                if name in sys.modules:
                    continue
                spec = importlib.util.spec_from_file_location(name, ref)
                if spec is None or spec.loader is None or not Path(ref).exists():
                    raise FileNotFoundError(ref)
                module = importlib.util.module_from_spec(spec)
                sys.modules[name] = module
                spec.loader.exec_module(module)
            else:
                importlib.import_module(ref)
        except Exception as exc:  # a user's plugin: report it as bad input, whatever it raised
            raise UserError(f"plugins: cannot load {ref!r}: {type(exc).__name__}: {exc}") from None


def profile(spec: Any) -> Profile:
    """The piecewise signal a profile spec (:class:`phfdi_base.spec.ProfileSpec` or its view) describes."""
    return Profile(spec.initial, [Change(c.at_s, c.value, c.ramp_s) for c in spec.changes])


def checked_block(kind: str, params: dict, where: str, dt_s: float, max_flow_ml_s: float | None = None) -> Block:
    """A registered block made from a spec; a :class:`UserError` naming ``where`` if it refuses its parameters."""
    try:
        return make_block(kind, params, dt_s=dt_s, max_flow_ml_s=max_flow_ml_s or 1.0)
    except (TypeError, ValueError) as exc:
        raise UserError(f"{where}: {kind}: {exc}") from None


def injected_faults(spec: Scenario, site: str, max_flow_ml_s: float | None = None,
                    flow_blocks: Collection[str] = ()) -> list[Injected]:
    """The scenario's faults acting at ``site``, each switched on at its onset.

    A fault of a type in ``flow_blocks`` given at ``valve`` acts on the valve's
    flow (``valve_flow``): the valve core names those types.
    """
    out = []
    for i, f in enumerate(spec.faults):
        f_site = "valve_flow" if f.type in flow_blocks and f.where == "valve" else f.where
        if f_site == site:
            block = checked_block(f.type, f.params, f"faults.{i}", spec.sample_time_s, max_flow_ml_s)
            out.append(Injected(block, f.onset_s, f.ramp_s))
    return out
