"""Column maps: which file column holds which signal, in which unit (one format for every command).

A column map is a small YAML file or a dict. Each key is a signal (the project's names, e.g.
``time_s``, ``ph_measured``, ``valve_command_pct``, ``op_pct``, ``pv``, ``sp``, or any name), each
value a column name or ``{column: NAME, unit: UNIT}``::

    time_s: {column: "ElapsedTime (s)", unit: s}
    ph_measured: pH
    valve_command_pct: {column: OP, unit: fraction}
    mode: {column: FIC101.MODE, automatic: [AUTO, CAS]}    # optional: only automatic rows are judged
    quality: {column: FIC101.Q, good: [192], signals: [pv]} # optional: other values mark samples missing
    sample_time_s: 10                                        # when there is no time column
    time_format: "%d.%m.%Y %H:%M:%S"                         # when stamps are not ISO 8601

The older loop-diagnose form ``columns: {time: T, op: OP, pv: PV, sp: SP}`` with ``loop_tag`` reads
the same (``time`` is ``time_s``, ``op`` is ``op_pct``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Self, Sequence

from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping

#: unit -> factor to the project's unit, per kind of signal
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0},
    "pct": {"%": 1.0, "pct": 1.0, "fraction": 100.0},
    "flow": {"mL/s": 1.0, "ml/s": 1.0, "mL/min": 1 / 60, "ml/min": 1 / 60, "L/min": 1000 / 60, "l/min": 1000 / 60,
             "L/h": 1000 / 3600, "l/h": 1000 / 3600, "m3/h": 1e6 / 3600},
    "ph": {"pH": 1.0, "ph": 1.0},
    "level": {"cm": 1.0, "mm": 0.1, "m": 100.0},
}
#: the project's unit of each kind
PROJECT_UNIT = {"time": "s", "pct": "%", "flow": "mL/s", "ph": "pH", "level": "cm"}
#: short names accepted for signals (the loop-diagnose form)
ALIASES = {"time": "time_s", "op": "op_pct"}
OPTION_KEYS = ("sample_time_s", "time_format", "loop_tag", "mode", "quality", "columns")
#: mode texts taken as automatic (case-insensitive); numbers other than 0 are automatic too
AUTO_WORDS = frozenset({"auto", "automatic", "aut", "a", "cas", "cascade", "casc", "rcas", "true", "on"})
#: quality cells taken as good when a quality column gives no ``good`` list
GOOD_WORDS = frozenset({"0", "good", "ok", "g", "false"})


def kind_of(signal: str) -> str | None:
    """Kind of a signal from its name (time, flow, pct, ph, level), None when the name says nothing."""
    if signal == "time_s":
        return "time"
    if signal.endswith("_flow_ml_s"):
        return "flow"
    if signal.endswith("_pct"):
        return "pct"
    if signal.startswith("ph"):
        return "ph"
    if signal.endswith("_cm"):
        return "level"
    return None


#: the measured outputs a plant model is compared with (the model diagnosis's outputs)
OUTPUTS = ("ph_measured", "level_measured_cm")
#: the controller outputs that drive a plant (the model diagnosis's inputs, with every feed's flow)
COMMAND_INPUTS = ("valve_command_pct", "level_controller_output_pct")


def is_input(signal: str) -> bool:
    """True for a signal that drives the plant: a controller output or a feed's flow."""
    return signal in COMMAND_INPUTS or signal.endswith("_flow_ml_s")


def normal_cell(value: object) -> str:
    """A cell as compared with mode and quality lists: stripped, lower case, numbers without '.0'."""
    text = str(value).strip().lower()
    try:
        x = float(text)
    except ValueError:
        return text
    return str(int(x)) if math.isfinite(x) and x == int(x) else text


@dataclass(frozen=True)
class ColumnSpec:
    """One mapped column: its name in the file, its unit there and the factor to the project's unit.

    Examples
    --------
    >>> from phfdi.records import ColumnMap
    >>> ColumnMap.from_mapping({"op_pct": {"column": "OP", "unit": "fraction"}}).signals["op_pct"]
    ColumnSpec(column='OP', unit='fraction', factor=100.0)
    """

    column: str
    unit: str | None = None
    factor: float = 1.0


@dataclass(frozen=True)
class ModeSpec:
    """The controller-mode column; ``automatic`` None: the default words (auto, cascade, numbers != 0).

    Examples
    --------
    >>> from phfdi.records import ModeSpec
    >>> mode = ModeSpec("FIC101.MODE")
    >>> mode.is_automatic("CAS"), mode.is_automatic("MAN")
    (True, False)
    """

    column: str
    automatic: frozenset[str] | None = None

    def is_automatic(self, cell: object) -> bool:
        text = normal_cell(cell)
        if self.automatic is not None:
            return text in self.automatic
        if text in AUTO_WORDS:
            return True
        try:
            return float(text) != 0.0
        except ValueError:
            return False


@dataclass(frozen=True)
class QualitySpec:
    """A quality-flag column; rows whose flag is not in ``good`` mark ``signals`` (None: all) missing.

    Examples
    --------
    >>> from phfdi.records import ColumnMap
    >>> cmap = ColumnMap.from_mapping({"pv": "FIC101.PV", "quality": {"column": "FIC101.Q", "good": [192]}})
    >>> cmap.quality[0].column, sorted(cmap.quality[0].good)
    ('FIC101.Q', ['192'])
    """

    column: str
    good: frozenset[str] = GOOD_WORDS
    signals: tuple[str, ...] | None = None


@dataclass
class ColumnMap:
    """Signal -> column (with unit), plus the time options and the mode/quality columns.

    Made from a dict or YAML file (:meth:`from_mapping`, :meth:`load`, the module docstring's format) or
    from the command line's ``--column``/``--unit`` (:meth:`from_args`, :meth:`parse`).

    Examples
    --------
    >>> from phfdi.records import ColumnMap
    >>> cmap = ColumnMap.from_mapping({"time_s": "Stamp", "op_pct": {"column": "OP", "unit": "fraction"},
    ...                                "mode": {"column": "MODE", "automatic": ["AUTO"]}})
    >>> cmap.channels(), cmap.columns_used()
    (['op_pct'], ['Stamp', 'OP', 'MODE'])
    >>> ColumnMap.parse("op=FIC1.OP,pv=FIC1.PV,time=Stamp").channels()
    ['op_pct', 'pv']
    """

    signals: dict[str, ColumnSpec]
    sample_time_s: float | None = None
    time_format: str | None = None
    loop_tag: str | None = None
    mode: ModeSpec | None = None
    quality: list[QualitySpec] = field(default_factory=list)
    source: str = "column map"

    @property
    def time(self) -> ColumnSpec | None:
        return self.signals.get("time_s")

    def channels(self) -> list[str]:
        """The mapped signals other than time, in map order."""
        return [s for s in self.signals if s != "time_s"]

    def columns_used(self) -> list[str]:
        """Every file column the map reads."""
        cols = [c.column for c in self.signals.values()]
        cols += [self.mode.column] if self.mode else []
        return cols + [q.column for q in self.quality]

    def to_mapping(self) -> dict:
        """The map as the dict :meth:`from_mapping` reads (stored in a reference file, so a replay reads the
        record the way its calibration did).

        >>> from phfdi.records import ColumnMap
        >>> cmap = ColumnMap.from_args(["time_s=t", "level_cm=L"], ["level_cm=mm"])
        >>> cmap.to_mapping()
        {'time_s': {'column': 't', 'unit': 's'}, 'level_cm': {'column': 'L', 'unit': 'mm'}}
        >>> ColumnMap.from_mapping(cmap.to_mapping()).signals == cmap.signals
        True
        """
        out: dict = {name: {"column": spec.column, **({"unit": spec.unit} if spec.unit is not None else {})}
                     for name, spec in self.signals.items()}
        for key in ("sample_time_s", "time_format", "loop_tag"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.mode is not None:
            out["mode"] = {"column": self.mode.column, **({"automatic": sorted(self.mode.automatic)}
                                                          if self.mode.automatic is not None else {})}
        if self.quality:
            out["quality"] = [{"column": q.column, "good": sorted(q.good),
                               **({"signals": list(q.signals)} if q.signals is not None else {})}
                              for q in self.quality]
        return out

    # ---- constructors --------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> Self:
        """From a YAML file."""
        data = read_mapping(path, "column map", "a mapping 'signal: column' or 'signal: {column:, unit:}'")
        return cls.from_mapping(data, str(path))

    @classmethod
    def from_mapping(cls, data: dict, source: str = "column map") -> Self:
        """From a dict in either form (see the module docstring)."""
        if not isinstance(data, dict):
            raise UserError(f"{source}: expected a mapping 'signal: column'")
        nested = data.get("columns")
        if nested is not None and not isinstance(nested, dict):
            raise UserError(f"{source}: columns: expected a mapping 'signal: column'")
        entries = {**(nested or {}), **{k: v for k, v in data.items() if k not in OPTION_KEYS}}
        signals = {}
        for key, spec in entries.items():
            name = ALIASES.get(str(key), str(key))
            signals[name] = _column_spec(name, spec, source)
        if not signals:
            raise UserError(f"{source}: the map names no column")
        return cls(signals, sample_time_s=_positive(data.get("sample_time_s"), "sample_time_s", source),
                   time_format=_opt_str(data.get("time_format")), loop_tag=_opt_str(data.get("loop_tag")),
                   mode=_mode_spec(data.get("mode"), source), quality=_quality_specs(data.get("quality"), source),
                   source=source)

    @classmethod
    def from_args(cls, columns: Sequence[str], units: Sequence[str] = (), source: str = "--column") -> Self:
        """From ``--column SIGNAL=COLUMN`` items (``mode=COL``, ``quality=COL`` too) and ``--unit SIGNAL=UNIT``."""
        data: dict = {}
        for item in columns:
            sig, col = _pair(item, "--column", "SIGNAL=COLUMN")
            data[ALIASES.get(sig, sig)] = col if sig in ("mode", "quality") else {"column": col}
        for item in units:
            sig, unit = _pair(item, "--unit", "SIGNAL=UNIT")
            sig = ALIASES.get(sig, sig)
            if sig not in data or sig in ("mode", "quality"):
                raise UserError(f"--unit {item!r}: no --column for {sig!r}")
            data[sig]["unit"] = unit
        return cls.from_mapping(data, source)

    @classmethod
    def parse(cls, text: str) -> Self:
        """From ``op=FIC1.OP,pv=FIC1.PV,time=Stamp`` (one argument) or a YAML file name."""
        if text.endswith((".yaml", ".yml")):
            return cls.load(text)
        items = [p.strip() for p in text.split(",") if p.strip()]
        return cls.from_args(items, source=f"--columns {text!r}")


def _pair(item: str, flag: str, form: str) -> tuple[str, str]:
    key, sep, value = item.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise UserError(f"{flag} expects {form}, got {item!r}")
    return key.strip(), value.strip()


def _opt_str(value: object) -> str | None:
    return None if value is None or value == "" else str(value)


def _positive(value: Any, key: str, source: str) -> float | None:  # value: a YAML scalar
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x > 0):
        raise UserError(f"{source}: {key} must be a positive number of seconds, got {value!r}")
    return x


def _column_spec(signal: str, spec: object, source: str) -> ColumnSpec:
    if isinstance(spec, (str, int, float)) and not isinstance(spec, bool):
        column, unit = str(spec), None
    elif isinstance(spec, dict) and spec.get("column") not in (None, ""):
        unknown = sorted(set(map(str, spec)) - {"column", "unit"})
        if unknown:
            raise UserError(f"{source}: {signal}: unknown key {unknown[0]!r} (use column, unit)")
        column, unit = str(spec["column"]), _opt_str(spec.get("unit"))
    else:
        raise UserError(f"{source}: {signal}: expected a column name or {{column: NAME, unit: UNIT}}")
    kind = kind_of(signal)
    if kind is None:
        return ColumnSpec(column, unit, 1.0)
    unit = unit or PROJECT_UNIT[kind]
    if unit not in UNITS[kind]:
        raise UserError(f"{source}: {signal}: unit {unit!r} not known for a {kind} signal; "
                        f"use one of {', '.join(UNITS[kind])}")
    return ColumnSpec(column, unit, UNITS[kind][unit])


def _cells(values: object, key: str, source: str) -> frozenset[str]:
    if not isinstance(values, (list, tuple)) or not values:
        raise UserError(f"{source}: {key}: expected a list of values, got {values!r}")
    return frozenset(normal_cell(v) for v in values)


def _mode_spec(spec: object, source: str) -> ModeSpec | None:
    if spec is None:
        return None
    if isinstance(spec, str):
        return ModeSpec(spec)
    if isinstance(spec, dict) and isinstance(spec.get("column"), str):
        auto = spec.get("automatic")
        return ModeSpec(spec["column"], None if auto is None else _cells(auto, "mode.automatic", source))
    raise UserError(f"{source}: mode: expected a column name or {{column: NAME, automatic: [VALUES]}}")


def _quality_specs(spec: object, source: str) -> list[QualitySpec]:
    if spec is None:
        return []
    items = spec if isinstance(spec, list) else [spec]
    out = []
    for item in items:
        if isinstance(item, str):
            out.append(QualitySpec(item))
        elif isinstance(item, dict) and isinstance(item.get("column"), str):
            good = item.get("good")
            sigs = item.get("signals")
            if sigs is not None and not (isinstance(sigs, list) and all(isinstance(s, str) for s in sigs)):
                raise UserError(f"{source}: quality.signals: expected a list of signal names")
            out.append(QualitySpec(item["column"], GOOD_WORDS if good is None else _cells(good, "quality.good", source),
                                   None if sigs is None else tuple(ALIASES.get(str(s), str(s)) for s in sigs)))
        else:
            raise UserError(f"{source}: quality: expected a column name or {{column: NAME, good: [VALUES]}}")
    return out
