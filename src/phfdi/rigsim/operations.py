"""The operations catalogue: what the simulated rig is asked to do (data: ``operations.yaml`` beside this file).

An *operation* is how the pumps are commanded over a run: a recorded profile replayed, an open-loop addition
or ramp, an on/off (bang-bang) controller with hysteresis, or a PI controller (:mod:`pi_controllers`) on one
pump. Its parameters (start pH, duration, settings, setpoints, tuning) are numbers, ranges ``{min: a, max:
b}`` (uniform) or ``{choices: [...]}``, drawn per run seed by :func:`draw_operation`, so one operation gives
many distinct runs. The schema (:class:`OperationSpec`) refuses unknown keys, missing ones, out-of-range
values and operations the rig cannot perform on some day of :data:`~phfdi.rigsim.day.DAY_RANGES` (a switched
pump too weak to overpower the steady one, a setpoint its pumps cannot reach): :func:`load_catalogue`.

Groups: ``shared`` replays or mimics the five recorded runs (for calibrating a detector on their simulated
counterparts); ``unseen`` are operations none of the recorded runs contains (for measuring false alarms on
operations a calibration never saw).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from phfdi_base.errors import UserError
from phfdi_base.spec import format_validation
from phfdi_base.yamlfile import read_mapping

from .day import DAY_RANGES, FLOW_PER_PCT

CATALOGUE_FORMAT = "phfdi-rig-operations/1"
#: the rig's command resolution (%): the recorded ramp of the March titration moves in steps of 0.1 %
COMMAND_STEP_PCT = 0.1
#: the longest run an operation may ask for (s)
MAX_DURATION_S = 4 * 3600.0
#: margin a switched pump needs over the steady one in the weakest day (ratio of delivered charge)
FEASIBLE_MARGIN = 1.2


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class Uniform(_Strict):
    """A parameter drawn uniformly between ``min`` and ``max`` (an integer parameter: floor of the draw + 1)."""

    min: float
    max: float

    @model_validator(mode="after")
    def _ordered(self) -> "Uniform":
        if self.min > self.max:
            raise ValueError(f"min {self.min:g} is above max {self.max:g}")
        return self


class Choice(_Strict):
    """A parameter drawn among ``choices`` (equally likely)."""

    choices: list[float] = Field(min_length=1)


class TextChoice(_Strict):
    choices: list[str] = Field(min_length=1)


Param = Union[float, Uniform, Choice]
TextParam = Union[str, TextChoice]


def _bounds(p: Param) -> tuple[float, float]:
    if isinstance(p, Uniform):
        return p.min, p.max
    if isinstance(p, Choice):
        return min(p.choices), max(p.choices)
    return float(p), float(p)


def _texts(p: TextParam) -> list[str]:
    return list(p.choices) if isinstance(p, TextChoice) else [p]


def _check_within(name: str, p: Param | None, low: float, high: float) -> None:
    if p is None:
        return
    lo, hi = _bounds(p)
    if lo < low or hi > high:
        raise ValueError(f"{name} must lie within [{low:g}, {high:g}], got {lo:g}..{hi:g}")


class OperationSpec(_Strict):
    """One operation of the catalogue (see the module docstring; units in the key names).

    Examples
    --------
    >>> from phfdi.rigsim import OperationSpec, simulate_run
    >>> op = OperationSpec(name="hold_ph9", group="unseen", kind="on_off", description="on/off about pH 9",
    ...                    duration_s=300.0, start_ph=8.0, switched="base", on_pct=40.0, other_pct=20.0,
    ...                    setpoint_ph=9.0, band_ph=0.3)
    >>> float(simulate_run(op, seed=1).setpoint_ph[0])
    9.0
    >>> OperationSpec(name="x", group="unseen", kind="pi", description="d", duration_s=60.0, start_ph=7.0)
    Traceback (most recent call last):
    ...
    pydantic_core._pydantic_core.ValidationError: 1 validation error for OperationSpec
    ...
    """

    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$")
    group: Literal["shared", "unseen"]
    kind: Literal["profile", "open_loop", "on_off", "pi"]
    description: str = Field(min_length=1)
    duration_s: Param
    start_ph: Param
    start_elapsed_s: Param = Uniform(min=0.85, max=1.3)  # the recorded files start 0.88-1.25 s into the log
    # profile: change points (s from the start, acid %, base %)
    profile: list[tuple[float, float, float]] | None = None
    # open loop: each pump's command, ramped to *_end over the run when given
    acid_pct: Param | None = None
    base_pct: Param | None = None
    acid_end_pct: Param | None = None
    base_end_pct: Param | None = None
    # controllers
    setpoint_ph: Param | None = None
    setpoint_changes: Param = 0.0
    band_ph: Param | None = None  # on/off: half-width of the hysteresis (0: switch at the setpoint)
    switched: TextParam | None = None  # on/off: base, acid or both
    on_pct: Param | None = None  # on/off: the switched pump's command when on
    pump: TextParam | None = None  # PI: the pump it drives
    kp_pct_per_ph: Param | None = None
    ti_s: Param | None = None
    other_pct: Param | None = None  # the pump nobody switches: its steady command

    @field_validator("profile")
    @classmethod
    def _profile(cls, v):
        if v is None:
            return v
        if not v or v[0][0] != 0.0:
            raise ValueError("a profile starts with a change point at 0 s")
        times = [p[0] for p in v]
        if any(b <= a for a, b in zip(times, times[1:])):
            raise ValueError("profile times must increase")
        if any(not (0.0 <= p[1] <= 100.0 and 0.0 <= p[2] <= 100.0) for p in v):
            raise ValueError("profile commands must lie within [0, 100] %")
        return v

    @model_validator(mode="after")
    def _kind_fields(self) -> "OperationSpec":
        need = {"profile": ["profile"], "open_loop": ["acid_pct", "base_pct"],
                "on_off": ["setpoint_ph", "band_ph", "switched", "on_pct"],
                "pi": ["setpoint_ph", "pump", "kp_pct_per_ph", "ti_s", "other_pct"]}[self.kind]
        allowed = set(need) | {"on_off": {"other_pct", "setpoint_changes"}, "pi": {"setpoint_changes"},
                               "open_loop": {"acid_end_pct", "base_end_pct"}, "profile": set()}[self.kind]
        optional = {"profile", "acid_pct", "base_pct", "acid_end_pct", "base_end_pct", "setpoint_ph", "band_ph",
                    "switched", "on_pct", "pump", "kp_pct_per_ph", "ti_s", "other_pct"}
        missing = [k for k in need if getattr(self, k) is None]
        if missing:
            raise ValueError(f"a {self.kind} operation needs {', '.join(missing)}")
        stray = [k for k in sorted(optional - allowed) if getattr(self, k) is not None]
        if stray:
            raise ValueError(f"a {self.kind} operation takes no {', '.join(stray)}")
        if self.kind != "profile" and "setpoint_changes" not in allowed and self.setpoint_changes != 0.0:
            raise ValueError(f"a {self.kind} operation takes no setpoint_changes")
        _check_within("duration_s", self.duration_s, 10.0, MAX_DURATION_S)
        _check_within("start_ph", self.start_ph, 1.0, 13.0)
        _check_within("start_elapsed_s", self.start_elapsed_s, 0.0, 1e6)
        for name in ("acid_pct", "base_pct", "acid_end_pct", "base_end_pct", "on_pct", "other_pct"):
            _check_within(name, getattr(self, name), 0.0, 100.0)
        _check_within("setpoint_ph", self.setpoint_ph, 2.0, 12.0)
        _check_within("setpoint_changes", self.setpoint_changes, 0.0, 20.0)
        _check_within("band_ph", self.band_ph, 0.0, 5.0)
        _check_within("kp_pct_per_ph", self.kp_pct_per_ph, 1e-3, 1e4)
        _check_within("ti_s", self.ti_s, 0.1, 1e5)
        for name, allowed_texts in (("switched", {"base", "acid", "both"}), ("pump", {"base", "acid"})):
            value = getattr(self, name)
            bad = [t for t in (_texts(value) if value is not None else []) if t not in allowed_texts]
            if bad:
                raise ValueError(f"{name} must be one of {', '.join(sorted(allowed_texts))}, got {bad[0]!r}")
        if self.profile is not None:
            lo, _ = _bounds(self.duration_s)
            if self.profile[-1][0] > lo:
                raise ValueError("the profile's last change point must come before the end of the run")
        return self


class CatalogueSpec(_Strict):
    format: Literal["phfdi-rig-operations/1"]
    operations: list[OperationSpec] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique(self) -> "CatalogueSpec":
        names = [op.name for op in self.operations]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"operation {dup[0]!r} is listed twice")
        return self


# ---- feasibility: can the rig do it on every day of DAY_RANGES? ------------------------------------------
def _charge_rate(pump: str, pct: float, strength_mM: float) -> float:
    """Charge a pump delivers (umol/s) at ``pct`` of command with a reagent of ``strength_mM``."""
    return pct * FLOW_PER_PCT[pump] * strength_mM


def _steady_ph(acid_pct: float, base_pct: float, acid_mM: float, base_mM: float) -> float:
    """The pH the flask tends to under steady commands (strong acid and base only)."""
    q = acid_pct * FLOW_PER_PCT["acid"] + base_pct * FLOW_PER_PCT["base"]
    if q <= 0.0:
        return 7.0
    x = (_charge_rate("acid", acid_pct, acid_mM) + _charge_rate("base", base_pct, base_mM)) / q * 1e-3  # mol/L
    h = (-x + math.sqrt(x * x + 4e-14)) / 2.0  # x = Kw/h - h
    return -math.log10(h)


def _corners(*params: Param | None) -> list[tuple[float, ...]]:
    return list(itertools.product(*[_bounds(p) if p is not None else (0.0,) for p in params]))


def check_feasible(op: OperationSpec) -> None:
    """Refuse (ValueError) an operation that some day of :data:`DAY_RANGES` cannot perform: an on/off or PI
    pump that cannot push the flask past its setpoint band against the steady pump, or a steady flow that
    cannot bring it back. Checked at the corners of the parameter and day ranges."""
    acid_r, base_r, vol_r = DAY_RANGES["acid_per_litre"], DAY_RANGES["base_per_litre"], DAY_RANGES["volume_ml"]
    days = [(-a * v / 1000.0, b * v / 1000.0) for a in (acid_r.low, acid_r.high) for b in (base_r.low, base_r.high)
            for v in (vol_r.low, vol_r.high)]
    if op.kind == "on_off":
        lo_sp, hi_sp = _bounds(op.setpoint_ph)  # type: ignore[arg-type]
        _, band = _bounds(op.band_ph)  # type: ignore[arg-type]
        for mode in _texts(op.switched):  # type: ignore[arg-type]
            for (on, other), (a_mM, b_mM) in itertools.product(_corners(op.on_pct, op.other_pct), days):
                if mode == "base":
                    up, down = _steady_ph(other, on, a_mM, b_mM), _steady_ph(other, 0.0, a_mM, b_mM)
                    margin = _charge_rate("base", on, b_mM) / max(1e-9, -_charge_rate("acid", other, a_mM))
                elif mode == "acid":
                    up, down = _steady_ph(0.0, other, a_mM, b_mM), _steady_ph(on, other, a_mM, b_mM)
                    margin = -_charge_rate("acid", on, a_mM) / max(1e-9, _charge_rate("base", other, b_mM))
                else:  # both switched, nothing steady
                    up, down, margin = _steady_ph(0.0, on, a_mM, b_mM), _steady_ph(on, 0.0, a_mM, b_mM), math.inf
                if margin < FEASIBLE_MARGIN or up < hi_sp + band + 0.3 or down > lo_sp - band - 0.3:
                    raise ValueError(f"operation {op.name!r}: with {mode} switched at {on:g} % against {other:g} % "
                                     f"the flask reaches only pH {down:.1f}..{up:.1f} on a day of acid "
                                     f"{a_mM:g} / base {b_mM:g} mM, short of the setpoints {lo_sp:g}..{hi_sp:g} "
                                     f"+- {band:g} (or the switched pump is not {FEASIBLE_MARGIN}x the steady one)")
    if op.kind == "pi":
        lo_sp, hi_sp = _bounds(op.setpoint_ph)  # type: ignore[arg-type]
        for pump in _texts(op.pump):  # type: ignore[arg-type]
            for (other,), (a_mM, b_mM) in itertools.product(_corners(op.other_pct), days):
                if pump == "base":
                    up, down = _steady_ph(other, 100.0, a_mM, b_mM), _steady_ph(other, 0.0, a_mM, b_mM)
                else:
                    up, down = _steady_ph(0.0, other, a_mM, b_mM), _steady_ph(100.0, other, a_mM, b_mM)
                if up < hi_sp + 0.3 or down > lo_sp - 0.3:
                    raise ValueError(f"operation {op.name!r}: the PI on the {pump} pump against {other:g} % reaches "
                                     f"only pH {down:.1f}..{up:.1f} on a day of acid {a_mM:g} / base {b_mM:g} mM, "
                                     f"short of the setpoints {lo_sp:g}..{hi_sp:g}")


# ---- loading ---------------------------------------------------------------------------------------------
def catalogue_path() -> Path:
    """The shipped catalogue, ``phfdi/rigsim/operations.yaml``."""
    return Path(str(resources.files("phfdi.rigsim"))) / "operations.yaml"


_LOADED: dict[str, dict[str, OperationSpec]] = {}


def load_catalogue(path: str | Path | None = None) -> dict[str, OperationSpec]:
    """The operations of a catalogue file (the shipped one by default), by name, validated and checked
    feasible; one :class:`UserError` naming the file, the operation and the problem otherwise.

    Examples
    --------
    >>> from phfdi.rigsim import load_catalogue
    >>> ops = load_catalogue()
    >>> ops["on_off_base"].kind, ops["on_off_base"].group
    ('on_off', 'unseen')
    >>> sorted({op.group for op in ops.values()})
    ['shared', 'unseen']
    """
    source = Path(path) if path is not None else catalogue_path()
    key = str(source.resolve())
    if key in _LOADED:
        return _LOADED[key]
    raw = read_mapping(source, "operations catalogue")
    try:
        spec = CatalogueSpec.model_validate(raw)
    except ValidationError as exc:
        raise UserError(_where(format_validation(exc, str(source)), raw)) from None
    for op in spec.operations:
        try:
            check_feasible(op)
        except ValueError as exc:
            raise UserError(f"{source}: {exc}") from None
    out = _LOADED[key] = {op.name: op for op in spec.operations}
    return out


def _where(message: str, raw: dict) -> str:
    """Name the operation (not only its index) in a validation message about ``operations.N``."""
    import re

    m = re.search(r"operations\.(\d+)", message)
    ops = raw.get("operations") if isinstance(raw, dict) else None
    if m and isinstance(ops, list) and int(m.group(1)) < len(ops) and isinstance(ops[int(m.group(1))], dict):
        name = ops[int(m.group(1))].get("name")
        if name:
            return message.replace(m.group(0), f"{m.group(0)} ({name})", 1)
    return message


def operation_names(group: str | None = None, path: str | Path | None = None) -> list[str]:
    """The catalogue's operation names, of one group (``shared``, ``unseen``) or all.

    Examples
    --------
    >>> from phfdi.rigsim import operation_names
    >>> operation_names("shared")[:2]
    ['shared_add_base', 'shared_control_ph7']
    """
    ops = load_catalogue(path)
    if group not in (None, "shared", "unseen"):
        raise UserError(f"group {group!r}: one of shared, unseen")
    return [n for n, op in ops.items() if group is None or op.group == group]


# ---- drawing one run's operation ------------------------------------------------------------------------
@dataclass
class Operation:
    """An operation with every parameter drawn: what one run does (``values``: name -> number or text;
    ``setpoints``: (time from the start in s, pH) change points of a controller, empty for open loop).

    Examples
    --------
    >>> from phfdi.rigsim import simulate_run
    >>> op = simulate_run("pi_base", seed=2, duration_s=120.0).operation
    >>> op.kind, op.duration_s, sorted(op.values)[:3]
    ('pi', 120.0, ['duration_s', 'kp_pct_per_ph', 'other_pct'])
    >>> op.setpoints[0][0]
    0.0
    """

    name: str
    group: str
    kind: str
    description: str
    values: dict[str, object]
    profile: list[tuple[float, float, float]] = field(default_factory=list)
    setpoints: list[tuple[float, float]] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return float(self.values["duration_s"])  # type: ignore[arg-type]

    def to_dict(self) -> dict:
        return {"name": self.name, "group": self.group, "kind": self.kind, "description": self.description,
                "values": dict(self.values), "profile": [list(p) for p in self.profile],
                "setpoints": [list(s) for s in self.setpoints]}


def _draw(p: Param | TextParam, rng: np.random.Generator) -> float | str:
    if isinstance(p, Uniform):
        return float(rng.uniform(p.min, p.max))
    if isinstance(p, (Choice, TextChoice)):
        return p.choices[int(rng.integers(len(p.choices)))]
    return p


def draw_operation(spec: OperationSpec, rng: np.random.Generator, duration_s: float | None = None) -> Operation:
    """One run's operation: every parameter of ``spec`` drawn from ``rng`` (``duration_s`` overrides the
    drawn duration; a profile is cut there or its last commands held).

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.rigsim import draw_operation, load_catalogue
    >>> spec = load_catalogue()["add_base_new_setting"]
    >>> op = draw_operation(spec, np.random.default_rng(0))
    >>> op.values["base_pct"] in (10.0, 30.0, 45.0, 80.0), 300.0 <= op.duration_s <= 900.0
    (True, True)
    """
    values: dict[str, object] = {}
    for name in ("duration_s", "start_ph", "start_elapsed_s", "acid_pct", "base_pct", "acid_end_pct",
                 "base_end_pct", "band_ph", "switched", "on_pct", "pump", "kp_pct_per_ph", "ti_s", "other_pct"):
        p = getattr(spec, name)
        if p is not None:
            values[name] = _draw(p, rng)
    if duration_s is not None:
        if not (math.isfinite(duration_s) and 10.0 <= duration_s <= MAX_DURATION_S):
            raise UserError(f"--duration-s {duration_s:g}: must lie within [10, {MAX_DURATION_S:g}] s")
        values["duration_s"] = float(duration_s)
    for name in ("acid_pct", "base_pct", "acid_end_pct", "base_end_pct", "on_pct", "other_pct"):
        if name in values:
            values[name] = quantise_command(float(values[name]))  # type: ignore[arg-type]
    setpoints: list[tuple[float, float]] = []
    if spec.setpoint_ph is not None:
        changes = int(math.floor(float(_draw(spec.setpoint_changes, rng)) + 1e-9))  # type: ignore[arg-type]
        values["setpoint_changes"] = changes
        hold = float(values["duration_s"]) / (changes + 1)  # type: ignore[arg-type]
        previous = None
        for i in range(changes + 1):
            sp = float(_draw(spec.setpoint_ph, rng))  # type: ignore[arg-type]
            for _ in range(20):  # a change changes the setpoint (when the choices allow)
                if sp != previous:
                    break
                sp = float(_draw(spec.setpoint_ph, rng))  # type: ignore[arg-type]
            setpoints.append((i * hold, sp))
            previous = sp
    profile = [tuple(map(float, p)) for p in spec.profile] if spec.profile else []
    return Operation(spec.name, spec.group, spec.kind, spec.description, values, profile,  # type: ignore[arg-type]
                     setpoints)


def quantise_command(pct: float) -> float:
    """A command (%) on the rig's 0.1 % resolution, within [0, 100]."""
    return min(100.0, max(0.0, round(round(pct / COMMAND_STEP_PCT) * COMMAND_STEP_PCT, 6)))
