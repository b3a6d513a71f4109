"""Simulated pH neutralization plant: chemistry by reaction invariants, a CSTR with level dynamics, feed
lines and sensor blocks. ROS-free; the node lives in :mod:`ph_plant_sim.node`.

Build the plant's part of a scenario with :func:`load_plant_model`, :func:`build_plant`,
:func:`plant_start` and :func:`build_process`; step it with :func:`advance_plant`. The names in
``__all__`` are imported from their modules on first use (:mod:`phfdi_base.lazy`).
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["CstrPlant", "PlantProcess", "PlantStart", "advance_plant", "build_plant", "build_process",
           "load_plant_model", "plant_start"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .build import PlantStart, build_plant, build_process, load_plant_model, plant_start
    from .plant import CstrPlant
    from .process import PlantProcess, advance_plant
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
