"""The faults :mod:`phfdi.inject` hides in measured records: the fault catalogue's entries with an injection form.

Each is one entry of the fault catalogue (:mod:`phfdi_base.faults`), declared once where its block is: a probe fault
in :mod:`ph_plant_sim.sensors` (``probe_bias``, simulated by the block ``sensor_bias``), a dosing pump's in
:mod:`ph_plant_sim.feedlines` (``pump_low``, the delivery curve ``pump_curve``). Its ``inject`` form
(:class:`phfdi_base.faults.Injection`) carries the size's unit in a record (a drift per minute here, per second in
its block), what it does, the sizes it takes and the rig estimator's classes that name it right.
"""

from __future__ import annotations

from phfdi.faults import catalogue
from phfdi_base.faults import Fault

#: the pH meter's resolution (pH): an injected pH is rounded to it
PH_RESOLUTION = 0.01
PH_MIN, PH_MAX = 0.0, 14.0
#: the calibration point a probe_gain turns about (pH)
PH_CAL_POINT = 7.0
PUMPS = ("acid", "base")
TRUTH_FORMAT = "phfdi-fault/1"

#: name -> catalogue entry, for every fault with an injection form: the probe's first, then the pumps'
KINDS: dict[str, Fault] = {name: f for name, f in catalogue().items() if f.inject is not None}
