"""The block protocol: composable discrete-time elements of the loop model.

Valve nonlinearities, sensor effects and user extensions are all *blocks*: a
single-input single-output element stepped once per sample. Extending the
model is adding a block to a chain, not editing the plant.

A block implements two methods::

    class MyBlock:
        def reset(self, x0: float) -> None:
            '''Put the block at rest with input x0 (a pass-through rest: output x0).'''

        def step(self, x: float, t_s: float) -> float:
            '''Consume the input of the sample at time t_s, return the output.'''

and may expose ``severity`` (float in [0, 1], default 1): the fraction of its
effect that is switched on. Blocks that scale their main parameter by
``severity`` support incipient (ramped) faults exactly; for blocks without it,
:class:`Injected` blends input and output. Register a block under a name with
:func:`register_block` to use it in scenario files (``type: <name>``); its
constructor keywords become the scenario's ``params``, and it should raise
``ValueError`` naming the parameter for bad values.

Example (a sensor that reads 2 % high, see docs/extending.md)::

    @register_block("sensor_gain_example")
    @dataclass
    class Gain:
        gain: float = 1.02
        severity: float = 1.0
        def reset(self, x0): pass
        def step(self, x, t_s): return x * (1.0 + self.severity * (self.gain - 1.0))
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Protocol, runtime_checkable

from .faults import Fault, register_fault


@runtime_checkable
class Block(Protocol):
    """A single-input single-output element stepped once per sample (see the module docstring).

    Methods
    -------
    reset(x0)
        Put the block at rest with input ``x0`` (a pass-through rest: output ``x0``).
    step(x, t_s)
        Consume the input ``x`` of the sample at time ``t_s`` (s) and return the output.

    Examples
    --------
    >>> from phfdi_base import Block
    >>> class Doubler:
    ...     def reset(self, x0): pass
    ...     def step(self, x, t_s): return 2.0 * x
    >>> isinstance(Doubler(), Block)
    True
    """

    def reset(self, x0: float) -> None: ...

    def step(self, x: float, t_s: float) -> float: ...


BLOCKS: dict[str, type] = {}


def register_block(name: str, fault: Fault | None = None) -> Callable[[type], type]:
    """Class decorator: make a block available to scenario files as ``type: name``.

    Parameters
    ----------
    name : str
        The block's name in scenario files and in :func:`make_block`.
    fault : Fault, optional
        The fault the block models, entered in the catalogue (:mod:`phfdi_base.faults`): presets,
        isolation, diagnosis, evaluation and ``--help`` then know it.

    Examples
    --------
    >>> from dataclasses import dataclass
    >>> from phfdi_base import make_block, register_block
    >>> @register_block("gain_example")
    ... @dataclass
    ... class Gain:
    ...     gain: float = 1.02
    ...     def reset(self, x0): pass
    ...     def step(self, x, t_s): return self.gain * x
    >>> make_block("gain_example", {"gain": 1.5}).step(2.0, 0.0)
    3.0
    >>> from phfdi_base.blocks import BLOCKS
    >>> del BLOCKS["gain_example"]  # leave the registry as it was
    """

    def deco(cls: type) -> type:
        BLOCKS[name] = cls
        setattr(cls, "block_name", name)  # noqa: B010  (a new attribute of any class)
        if fault is not None:
            register_fault(fault, name)
        return cls

    return deco


def make_block(name: str, params: dict | None = None, **context: float) -> Block:
    """Instantiate a registered block.

    Parameters
    ----------
    name : str
        A name given to :func:`register_block` (the cores register theirs when imported).
    params : dict, optional
        The block's constructor keywords (a scenario's ``params``).
    **context : float
        Passed when the block takes it (e.g. ``dt_s``, the sample time in s).

    Returns
    -------
    Block

    Raises
    ------
    ValueError
        An unknown block or parameter (the message lists the known ones), or a bad value.

    Examples
    --------
    >>> import valve_actuator.blocks  # registers the valve blocks
    >>> from phfdi_base import make_block
    >>> backlash = make_block("backlash", {"width_pct": 2.0})
    >>> backlash.reset(50.0)
    >>> [backlash.step(x, t) for t, x in enumerate([50.0, 52.0, 51.0, 49.0])]
    [50.0, 51.0, 51.0, 50.0]
    """
    if name not in BLOCKS:
        raise ValueError(f"unknown block type {name!r}; known: {', '.join(sorted(BLOCKS))}")
    cls = BLOCKS[name]
    kwargs = dict(params or {})
    fields = getattr(cls, "__dataclass_fields__", {})
    for key, value in context.items():
        if key in fields and key not in kwargs:
            kwargs[key] = value
    unknown = [k for k in kwargs if fields and k not in fields]
    if unknown:
        allowed = [k for k in fields if k not in ("severity",) and k not in context]
        raise ValueError(f"{name}: unknown parameter {unknown[0]!r}; allowed: {', '.join(allowed)}")
    return cls(**kwargs)


@dataclass
class Chain:
    """Blocks in series; itself a block.

    Examples
    --------
    >>> import valve_actuator.blocks  # registers the valve blocks
    >>> from phfdi_base import Chain, make_block
    >>> chain = Chain([make_block("backlash", {"width_pct": 2.0}), make_block("saturation", {"high_pct": 80.0})])
    >>> chain.reset(50.0)
    >>> chain.step(95.0, 0.0)
    80.0
    """

    blocks: list = field(default_factory=list)

    def reset(self, x0: float) -> None:
        # each block at rest passes its input through, so x0 propagates unchanged
        for b in self.blocks:
            b.reset(x0)

    def step(self, x: float, t_s: float) -> float:
        for b in self.blocks:
            x = b.step(x, t_s)
        return x


@dataclass
class Injected:
    """A block switched on at ``onset_s``, abruptly or ramped over ``ramp_s``.

    Before the onset the output equals the input and the inner block is held
    at rest on the input, so switching on is bumpless and state such as a
    stuck position or a dead-zone centre is taken at the onset.
    """

    block: Block
    onset_s: float
    ramp_s: float = 0.0

    def severity_at(self, t_s: float) -> float:
        if t_s < self.onset_s:
            return 0.0
        if self.ramp_s <= 0.0:
            return 1.0
        return min(1.0, (t_s - self.onset_s) / self.ramp_s)

    def reset(self, x0: float) -> None:
        self.block.reset(x0)

    def step(self, x: float, t_s: float) -> float:
        s = self.severity_at(t_s)
        if s <= 0.0:
            self.block.reset(x)
            return x
        if hasattr(self.block, "severity"):
            self.block.severity = s
            return self.block.step(x, t_s)
        y = self.block.step(x, t_s)
        return x + s * (y - x)
