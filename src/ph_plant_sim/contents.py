"""What the vessel holds at the start besides the steady mix of its feeds: a weak acid of its own water.

A flask refilled from the tap, rinsed, or left from an earlier run holds at the start of a run a weak acid or
buffer that no feed carries: tap-water alkalinity (carbonate, pKa 6.35 and 10.33), phosphate (pKa near 7.2), or
any other species of the vessel's own history. Nothing feeds it afterwards, so it washes out with the outflow:
its total concentration C (mol/L) in an overflow vessel of volume V (mL) with inflow q (mL/s) falls as

    C(t) = C0 exp(-integral q dt / V)

which the vessel's own component balance already does (the component enters with no feed: dn/dt = -q_out n / V).
So the only new thing is the start: the composition at t = 0 is the vessel's start composition (the steady state
of the first flows, or in the diagnosis's ``initial: fit`` a mix of the feeds) plus ``conc_mol_l`` of the
component. The component enters in the form of its declared charge (a ``charge: 0`` weak acid as HA): at a steady
start the pH shifts accordingly. A diagnosis that fits the start pH (``initial: fit``) keeps the fitted pH and
adjusts the feed mix under it instead (:func:`phfdi.diagnosis.model.mix_for_ph`): there the strong ions the
water held with its buffer are whatever the start pH says.

Scenario key: ``plant.initial_contents: {component, conc_mol_l}`` (:class:`phfdi_base.spec.InitialContentsSpec`);
the component is a chemistry component (a library one such as ``carbonate`` or ``phosphate``, or one declared in
``plant.chemistry.components``). :meth:`ph_plant_sim.process.PlantProcess.rest` adds it wherever the plant is put
at rest (the closed loop's start, an open-loop run's first inputs); the diagnosis adds the same vector to its
start composition (``phfdi.diagnosis.model``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .plant import CstrPlant

__all__ = ["InitialContents", "add_contents", "contents_vector"]


@dataclass(frozen=True)
class InitialContents:
    """``conc_mol_l`` (mol/L) of chemistry component ``component`` in the vessel at the start, on top of its
    start composition, washing out with the outflow."""

    component: str
    conc_mol_l: float

    def __post_init__(self) -> None:
        if not (self.conc_mol_l >= 0.0 and math.isfinite(self.conc_mol_l)):
            raise ValueError(f"initial contents: conc_mol_l must be non-negative and finite, got {self.conc_mol_l}")


def contents_vector(plant: CstrPlant, contents: InitialContents) -> list[float]:
    """The contents as a concentration vector (mol/L) over the plant's components.

    Examples
    --------
    >>> from ph_plant_sim import build_plant, load_plant_model
    >>> from ph_plant_sim.contents import InitialContents, contents_vector
    >>> plant = build_plant(load_plant_model("paper"))  # nitrate, sodium, carbonate
    >>> contents_vector(plant, InitialContents("carbonate", 1e-3))
    [0.0, 0.0, 0.001]
    """
    names = [c.name for c in plant.chemistry.components]
    if contents.component not in names:
        raise ValueError(f"initial contents: no component {contents.component!r} (components: {', '.join(names)})")
    out = [0.0] * len(names)
    out[names.index(contents.component)] = contents.conc_mol_l
    return out


def add_contents(plant: CstrPlant, contents: InitialContents) -> None:
    """Add the contents to the plant's present composition (every compartment of a composed plant alike: call it
    on a plant at rest, where they are equal), its volume unchanged, and solve the pH."""
    extra = contents_vector(plant, contents)
    conc = [c + e for c, e in zip(plant.concentrations, extra)]
    plant.set_state(conc, None if plant.tank.overflow else plant.level_cm)
