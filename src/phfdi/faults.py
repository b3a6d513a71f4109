"""The fault catalogue as the application sees it (:mod:`phfdi_base.faults`, filled by the cores).

Importing this module imports the cores' block modules, so every built-in fault is registered; a
plugin a scenario names registers its own when the scenario is loaded. The presets (``--fault NAME``),
``phfdi scenarios``, the isolation, the diagnosis, the evaluation and ``--help`` all read it.
"""

from __future__ import annotations

import ph_plant_sim.feedlines  # noqa: F401  (registers the dosing pumps' faults)
import ph_plant_sim.sensors  # noqa: F401  (registers the probe's faults)
import valve_actuator.blocks  # noqa: F401  (registers the valve's faults)
from phfdi_base.faults import Fault, faults

__all__ = ["EXTENDED_MARK", "base_scenario", "block_name", "catalogue", "fault_library", "preset_name", "preset_names"]


def catalogue() -> dict[str, Fault]:
    """Every registered fault, valve faults first (see :func:`phfdi_base.faults.faults`).

    >>> catalogue()["backlash"].main.name
    'width_pct'
    """
    return faults()


def fault_library() -> dict[str, dict]:
    """Named fault presets (the paper's severities): a scenario ``faults:`` entry per catalogued fault.

    >>> fault_library()["backlash"]["params"]
    {'width_pct': 0.7}
    """
    return {name: f.preset_entry() for name, f in faults().items() if f.preset}


def preset_names() -> list[str]:
    """``--fault`` choices: healthy and each preset."""
    return ["healthy"] + [name for name, f in faults().items() if f.preset]


def preset_name(name: str) -> str:
    """The preset named by a fault's name or its block's (``coulomb_viscous_friction`` -> ``friction``).

    >>> preset_name("sensor_delay"), preset_name("backlash"), preset_name("healthy")
    ('probe_delay', 'backlash', 'healthy')
    """
    return next((n for n, f in faults().items() if f.preset and f.block == name and n != name), name)


def block_name(name: str) -> str:
    """The block of a fault named by its preset name (``friction`` -> ``coulomb_viscous_friction``), as the
    diagnosis names causes; other names unchanged.

    >>> block_name("friction"), block_name("sensor_lag")
    ('coulomb_viscous_friction', 'sensor_lag')
    """
    f = faults().get(name)
    return f.block if f is not None else name


#: what phfdi diagnose puts after a model's name for the extended model it writes ("paper-extended-valve_gain")
EXTENDED_MARK = "-extended"


def base_scenario(name: str) -> str:
    """The scenario a resolved scenario's name comes from: the name without the ``-<fault>`` that naming a
    preset fault added (:func:`phfdi_base.spec.resolve_scenario`) and without the :data:`EXTENDED_MARK` and
    cause that ``phfdi diagnose`` adds to the model it extends; other names unchanged. Decided from the
    catalogue's names and that mark, never by splitting on '-', so a scenario whose own name holds '-' keeps
    it. The one rule (shipped calibrations and a recording's base scenario are per base scenario).

    >>> base_scenario("paper-backlash"), base_scenario("my-plant-probe_delay"), base_scenario("my-plant")
    ('paper', 'my-plant', 'my-plant')
    >>> base_scenario("paper-extended-valve_gain"), base_scenario("my-plant-extended-stiction-backlash")
    ('paper', 'my-plant')
    """
    names = sorted({n for f in faults().values() if f.preset for n in (f.name, f.block)}, key=len, reverse=True)
    base = next((name[: -len(n) - 1] for n in names if name.endswith(f"-{n}") and len(name) > len(n) + 1), name)
    mark = base.find(EXTENDED_MARK)
    return base[:mark] if mark > 0 and base[mark + len(EXTENDED_MARK):][:1] in ("", "-") else base
