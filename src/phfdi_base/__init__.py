"""phfdi_base: the ground floor every other package of the project stands on.

The block protocol and its registry (:mod:`phfdi_base.blocks`), the fault catalogue
(:mod:`phfdi_base.faults`), piecewise profiles (:mod:`phfdi_base.profiles`), the scenario schema
(:mod:`phfdi_base.spec`), the run's signal catalogue (:mod:`phfdi_base.signals`), the graph's topic table
and time base (:mod:`phfdi_base.topics`, :mod:`phfdi_base.stamps`), the YAML reader
(:mod:`phfdi_base.yamlfile`) and the user error (:mod:`phfdi_base.errors`). It imports nothing of the
project: the four cores (ph_plant_sim, valve_actuator, pi_controllers, wavelet_fdi) stand on it and the
application (phfdi) on top of them; see docs/architecture.md.

The names in ``__all__`` are imported from their modules on first use (:mod:`phfdi_base.lazy`), so
``import phfdi_base`` stays cheap.
"""

from typing import TYPE_CHECKING

from .lazy import lazy_exports

__all__ = ["Block", "Chain", "Change", "Fault", "FaultParam", "Injection", "LoopDraws", "Profile", "Range", "ScenarioSpec",
           "Signal", "SizeRange", "UserError", "label", "make_block", "read_mapping", "register_block", "unit_of",
           "validate_scenario"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .blocks import Block, Chain, make_block, register_block
    from .errors import UserError
    from .faults import Fault, FaultParam, Injection, LoopDraws, Range, SizeRange
    from .profiles import Change, Profile
    from .signals import Signal, label, unit_of
    from .spec import ScenarioSpec, validate_scenario
    from .yamlfile import read_mapping
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
