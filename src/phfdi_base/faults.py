"""The fault catalogue: each fault a block models, defined once, where the block is registered.

A core declares the fault its block models next to the block itself::

    @register_block("backlash", fault=Fault(
        "backlash", site="valve", description="backlash (dead-band) of 0.7 % of span on the acid valve stem",
        params=(FaultParam("width_pct", "% of span", bounds=(0.0, 100.0), paper=0.7,
                           search=Range(0.05, 20.0, log=True)),),
        severities=(0.35, 0.7, 1.4)))
    @dataclass
    class Backlash: ...

and everything else reads it from :data:`FAULTS`: the named presets (``--fault NAME``), the isolation's
hypotheses, the diagnosis's candidates, the evaluation's severities, the paper set, the loop diagnosis's
training draws and the command line's help. Adding a block with a ``fault=`` of one's own makes it show up in
all of them with no other edit.

Each parameter has one physical range (``bounds``: what the device can have) and the sub-range a fit
searches (``search``, within ``bounds``; the data may narrow it further, e.g. a delay shorter than a fifth
of the record). Where the diagnosis fits a parameter differently from the isolation (another scale, or
a range that must include "no fault"), its sub-range is declared in the same entry as ``diagnosis``.
A fault the loop diagnosis (plant historian loops) draws declares those draws in the same entry too
(``loop=LoopDraws(...)``): there a valve's size is relative to the loop's OP travel, not the pH valve's.

This module imports nothing of the project: the cores fill the registry, the application reads it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["FAULTS", "SITES", "SITE_FAMILY", "Fault", "FaultParam", "Injection", "LoopDraws", "Range", "SizeRange",
           "faults", "register_fault"]

#: where a fault acts: the valve stem position, the valve's flow, the pH probe (as in a scenario's
#: ``faults: - where:``; the plant and its feeds are extended by the diagnosis's process candidates), or a
#: dosing pump of a feed (the rig's; faults only ``phfdi inject`` and the rig estimator name)
SITES = ("valve", "valve_flow", "ph_sensor", "pump")
#: a fault's family by where it acts: a valve's or a pump's is the actuator's, the probe's the sensor's
SITE_FAMILY = {"valve": "actuator", "valve_flow": "actuator", "ph_sensor": "sensor", "pump": "actuator"}


@dataclass(frozen=True)
class Range:
    """A search range of a parameter, in its unit.

    Parameters
    ----------
    low, high : float
        The range's ends (``high`` may be infinite: the data narrow it).
    log : bool
        Search it on a logarithmic scale (``low`` must then be positive).

    Examples
    --------
    >>> from phfdi_base import Range
    >>> Range(0.05, 20.0, log=True).contains(0.7)
    True
    """

    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        if not self.low < self.high or (self.log and self.low <= 0.0):
            raise ValueError(f"bad range [{self.low}, {self.high}] (log={self.log})")

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high


@dataclass(frozen=True)
class FaultParam:
    """One parameter of a fault: its unit, physical bounds, the preset's value and its search range.

    Parameters
    ----------
    name : str
        The block's keyword (``width_pct``).
    unit : str
        Its unit (``% of span``).
    bounds : tuple of float
        The physical range: what the device can have.
    paper : float, optional
        The value of the named preset: the paper's where it gives one (Section 5.B).
    search : Range, optional
        What the isolation and the diagnosis fit over (default: ``bounds``), within ``bounds``.
    diagnosis : Range, optional
        Replaces ``search`` for the diagnosis where that fits differently (declared here, never elsewhere).

    Examples
    --------
    >>> from phfdi_base import FaultParam, Range
    >>> p = FaultParam("width_pct", "% of span", bounds=(0.0, 100.0), paper=0.7, search=Range(0.05, 20.0, log=True))
    >>> p.fit_range("diagnosis")
    Range(low=0.05, high=20.0, log=True)
    """

    name: str
    unit: str
    bounds: tuple[float, float]
    paper: float | None = None
    search: Range | None = None
    diagnosis: Range | None = None

    def __post_init__(self) -> None:
        lo, hi = self.bounds
        if not lo < hi:
            raise ValueError(f"{self.name}: bounds {self.bounds} are empty")
        for r in (self.search, self.diagnosis):
            if r is not None and not (lo <= r.low and r.high <= hi):
                raise ValueError(f"{self.name}: search range [{r.low}, {r.high}] outside its bounds {self.bounds}")
        if self.paper is not None and not lo <= self.paper <= hi:
            raise ValueError(f"{self.name}: preset value {self.paper} outside its bounds {self.bounds}")

    def fit_range(self, consumer: str = "isolation") -> Range:
        """The range ``consumer`` ("isolation" or "diagnosis") searches."""
        if consumer == "diagnosis" and self.diagnosis is not None:
            return self.diagnosis
        if self.search is not None:
            return self.search
        return Range(*self.bounds)  # an unbounded one is narrowed by the data (e.g. a valve's rated flow)


@dataclass(frozen=True)
class LoopDraws:
    """The fault as the loop diagnosis's simulated training loops draw it (:mod:`phfdi.loopdiag`): each
    parameter in % of the loop's OP travel, not in the pH valve's units, because a historian loop's valve
    has no other scale.

    Parameters
    ----------
    training, domain : dict
        parameter -> a (low, high) drawn log-uniform, a ratio to the main parameter (``*_over_*``, (low, high)
        drawn uniform), a fixed value, or a dict of such (a limit ``above`` a base or the working point), for
        the per-class generator (``training``: :mod:`phfdi.loopdiag.training`) and the domain-randomised one
        that trains the stiction verdict (``domain``: :mod:`phfdi.loopdiag.domain`).

    Examples
    --------
    >>> from phfdi_base import LoopDraws
    >>> LoopDraws(training={"width_pct": (0.3, 6.0)}, domain={"width_pct": (0.3, 8.0)}).domain["width_pct"]
    (0.3, 8.0)
    """

    training: dict = field(default_factory=dict)
    domain: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SizeRange:
    """The sizes an injected fault takes: from ``low`` to ``high`` in its unit, each end in or out of the range.

    Examples
    --------
    >>> from phfdi_base import SizeRange
    >>> SizeRange(0.0, 1.0, low_in=False, high_in=False).says("fraction")
    'above 0 and below 1 (a fraction)'
    >>> 1e308 in SizeRange(-14.0, 14.0)
    False
    """

    low: float
    high: float
    low_in: bool = True
    high_in: bool = True

    def __contains__(self, size: float) -> bool:
        above = size >= self.low if self.low_in else size > self.low
        below = size <= self.high if self.high_in else size < self.high
        return above and below

    def says(self, unit: str) -> str:
        """The range in words, with its unit."""
        unit = "(a fraction)" if unit == "fraction" else unit
        if self.low_in and self.high_in:
            return f"from {self.low:g} to {self.high:g} {unit}"
        low = f"at least {self.low:g}" if self.low_in else f"above {self.low:g}"
        high = f"at most {self.high:g}" if self.high_in else f"below {self.high:g}"
        return f"{low} and {high} {unit}"


@dataclass(frozen=True)
class Injection:
    """The fault as ``phfdi inject`` hides it in a measured record, and the rig estimator's names for it.

    Parameters
    ----------
    unit : str
        The size's unit in a record (a probe drift in pH per minute, as a rig's engineer states it; its block
        takes pH per second).
    what : str
        What it does to the record, ``SIZE`` standing for the size.
    sizes : SizeRange or None
        The sizes where the size still means the fault (None: it takes no size).
    isolated_as : tuple of str
        The classes the rig estimator's isolation (``wavelet_fdi.estimator_isolation``) names it by when it names
        it right, the exact one first; ``{pump}`` stands for the pump the fault is on (``pump:acid_flow_ml_s``).

    Examples
    --------
    >>> from phfdi_base import Injection, SizeRange
    >>> i = Injection("fraction", "delivers SIZE less", SizeRange(0.0, 1.0, low_in=False), ("pump:{pump}_flow_ml_s",))
    >>> i.isolation_classes("acid"), i.size_text()
    (['pump:acid_flow_ml_s'], 'above 0 and at most 1 (a fraction)')
    """

    unit: str
    what: str
    sizes: SizeRange | None
    isolated_as: tuple[str, ...] = ()

    def isolation_classes(self, pump: str | None = None) -> list[str]:
        """The classes a right name gives this fault (on ``pump``'s flow for a pump fault)."""
        return [c.format(pump=pump) for c in self.isolated_as]

    def size_text(self) -> str:
        """'from -14 to 14 pH' (--help): the range and its unit."""
        return "none" if self.sizes is None else self.sizes.says(self.unit)


@dataclass(frozen=True)
class Fault:
    """A fault a block models: preset name, site, parameters (main first), severities.

    Parameters
    ----------
    name : str
        The preset's name (``--fault NAME``) and the isolation's class.
    site : str
        Where it acts, one of :data:`SITES`.
    description : str
        One line for ``phfdi scenarios``.
    params : tuple of FaultParam
        Its parameters, the main one first.
    severities : tuple of float, optional
        The main parameter's mild, preset and strong values for the evaluation.
    scale_with_main : tuple of str
        Parameters that scale along with the main one across severities.
    onset_s : float
        The preset's onset (the paper's Section 7: 7000 s).
    isolate : bool
        False keeps it out of the online isolation (a fault its bank cannot re-simulate).
    preset : bool
        False keeps it out of ``--fault``.
    candidate : bool
        False keeps it out of the model diagnosis's causes and candidates (``phfdi diagnose``): a fault only
        the loop diagnosis draws (``stiction_he``, ``quantization``), or only injection and the rig simulator
        use.
    loop : LoopDraws, optional
        How the loop diagnosis's training loops draw it (None: they do not).
    inject : Injection, optional
        How ``phfdi inject`` hides it in a measured record and the rig estimator names it (None: it does not).

    ``block``, the registered block type (the diagnosis's cause), is filled in by
    :func:`phfdi_base.blocks.register_block`.

    Examples
    --------
    >>> from phfdi_base import Fault, FaultParam
    >>> f = Fault("sticky", site="valve", description="a sticky stem",
    ...           params=(FaultParam("s_pct", "% of span", (0.0, 100.0), paper=1.5),))
    >>> f.main.name, f.preset_params()
    ('s_pct', {'s_pct': 1.5})
    """

    name: str
    site: str
    description: str
    params: tuple[FaultParam, ...] = ()
    severities: tuple[float, float, float] | None = None
    scale_with_main: tuple[str, ...] = ()
    onset_s: float = 7000.0
    isolate: bool = True
    preset: bool = True
    candidate: bool = True
    loop: LoopDraws | None = field(default=None, compare=False)
    inject: Injection | None = field(default=None, compare=False)
    block: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        if self.site not in SITES:
            raise ValueError(f"fault {self.name}: site {self.site!r} not one of {', '.join(SITES)}")
        if self.severities is not None and self.main is None:
            raise ValueError(f"fault {self.name}: severities need a parameter")

    @property
    def family(self) -> str:
        """``actuator`` or ``sensor``, by where it acts (:data:`SITE_FAMILY`)."""
        return SITE_FAMILY[self.site]

    @property
    def main(self) -> FaultParam | None:
        """The main parameter (the first), which severities and fits are about."""
        return self.params[0] if self.params else None

    def param(self, name: str) -> FaultParam:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(f"fault {self.name} has no parameter {name!r}")

    def preset_params(self) -> dict[str, float]:
        """The preset's parameters (those with a ``paper`` value)."""
        return {p.name: p.paper for p in self.params if p.paper is not None}

    def preset_entry(self) -> dict:
        """The scenario ``faults:`` entry of the named preset."""
        entry: dict = {"description": self.description, "type": self.block}
        if self.site != "valve":
            entry["where"] = self.site
        params = self.preset_params()
        if params:
            entry["params"] = params
        entry["onset_s"] = self.onset_s
        return entry

    def severity_params(self) -> list[dict[str, float]]:
        """Parameters of the mild, preset and strong severities (others scaled along, see the class)."""
        if self.severities is None or self.main is None:
            return []
        main = self.main.paper
        along = {name: self.param(name).paper for name in self.scale_with_main}
        out = []
        for value in self.severities:
            d = {self.main.name: value}
            for name, v in along.items():
                if v is None or not main:
                    raise ValueError(f"fault {self.name}: {name} scales with {self.main.name}: both need a preset value")
                d[name] = v * (value / main)
            out.append(d)
        return out


#: name -> fault, in registration order
FAULTS: dict[str, Fault] = {}


def register_fault(fault: Fault, block: str) -> Fault:
    """Enter ``fault`` (modelled by the registered block ``block``) in :data:`FAULTS`; returns it."""
    if not block:
        raise ValueError(f"fault {fault.name}: needs its block's name")
    object.__setattr__(fault, "block", block)
    FAULTS[fault.name] = fault
    return fault


def faults() -> dict[str, Fault]:
    """The registered faults by site (valve, valve flow, pH probe), in registration order within a site.

    Only what has been imported is registered: the application imports the cores' block modules
    (``valve_actuator.blocks``, ``ph_plant_sim.sensors``) before it asks.
    """
    order = {s: i for i, s in enumerate(SITES)}
    return dict(sorted(FAULTS.items(), key=lambda kv: order[kv[1].site]))
