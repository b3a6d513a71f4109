"""Control valve with composable nonlinearity blocks (backlash, dead-zone, friction, stiction, saturation,
leakage, blocking). ROS-free; the node lives in :mod:`valve_actuator.node`.

:class:`Valve` maps a command to a stem position, an opening and a flow; :func:`build_valves` makes the
scenario's valves with their injected faults; :func:`step_valves` moves them for one sample. The blocks
register under their names (``make_block("backlash", ...)``) in :mod:`valve_actuator.blocks`. The names in
``__all__`` are imported from their modules on first use (:mod:`phfdi_base.lazy`).
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["Valve", "ValveOutput", "ValveStep", "build_valve", "build_valves", "inherent_characteristic",
           "position_for_opening", "step_valves"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .build import ValveStep, build_valve, build_valves, position_for_opening, step_valves
    from .valve import Valve, ValveOutput, inherent_characteristic
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
