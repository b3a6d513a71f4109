"""PI controllers with anti-windup and setpoint profiles. ROS-free; the node lives in
:mod:`pi_controllers.node`.

:class:`PIController` is one loop's controller, :class:`ControllerBank` the loop's pH and level controllers
with their setpoint profiles, :func:`build_controllers` makes them from a scenario. The names in ``__all__``
are imported from their modules on first use (:mod:`phfdi_base.lazy`).
"""

from typing import TYPE_CHECKING

from phfdi_base.lazy import lazy_exports

__all__ = ["ControllerBank", "ControllerOutputs", "PIController", "build_controllers", "pi_controller"]

if TYPE_CHECKING:  # the public names, for type checkers; lazy_exports reads them too
    from .build import build_controllers, pi_controller
    from .loops import ControllerBank, ControllerOutputs
    from .pi import PIController
else:
    __getattr__, __dir__ = lazy_exports(__name__, __file__)
