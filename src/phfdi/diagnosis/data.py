"""Measured records for diagnosis: read, map columns, check, resample.

A record is what the diagnosis may see of a plant: a uniform time base,
the *inputs* it was driven with and the *outputs* it measured, in the
project's signal names (:mod:`phfdi.run`):

* inputs: ``valve_command_pct`` (the pH controller's output), ``<feed>_flow_ml_s``
  (measured feed flows), ``level_controller_output_pct`` (outlet valve command);
* outputs: ``ph_measured``, ``level_measured_cm``.

Nothing else is read from a project run (``ph_true``, valve position, fault
severity and the run's metadata would tell the answer), so a diagnosis sees
the same as it would on a plant historian.

Sources: a run of the project (.csv, .parquet, or a .mcap bag through
``phfdi.bagio.load_run``), or any CSV with a column mapping (a small YAML
file or ``--column SIGNAL=COLUMN``; units converted to the project's).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping

OUTPUTS = ("ph_measured", "level_measured_cm")
COMMAND_INPUTS = ("valve_command_pct", "level_controller_output_pct")

#: unit -> factor to the project's unit, per kind of signal
UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3, "min": 60.0, "h": 3600.0},
    "pct": {"%": 1.0, "pct": 1.0, "fraction": 100.0},
    "flow": {"mL/s": 1.0, "ml/s": 1.0, "mL/min": 1 / 60, "ml/min": 1 / 60, "L/min": 1000 / 60, "l/min": 1000 / 60,
             "L/h": 1000 / 3600, "l/h": 1000 / 3600, "m3/h": 1e6 / 3600},
    "ph": {"pH": 1.0, "ph": 1.0},
    "level": {"cm": 1.0, "mm": 0.1, "m": 100.0},
}

#: longest stretch of missing samples filled by interpolation (samples)
MAX_GAP_SAMPLES = 5
#: relative spread of sampling intervals still taken as uniform
UNIFORM_TOLERANCE = 0.01


def kind_of(signal: str) -> str:
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
    raise UserError(f"column map: cannot map onto {signal!r}: use time_s, valve_command_pct, "
                    f"level_controller_output_pct, <feed>_flow_ml_s, ph_measured or level_measured_cm")


def is_input(signal: str) -> bool:
    return signal in COMMAND_INPUTS or signal.endswith("_flow_ml_s")


@dataclass
class Record:
    """One measured record on a uniform time base."""

    name: str
    time_s: np.ndarray
    inputs: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    notes: list[str] = field(default_factory=list)

    @property
    def dt_s(self) -> float:
        return float(self.time_s[1] - self.time_s[0])

    def __len__(self) -> int:
        return len(self.time_s)

    def slice(self, start: int, stop: int, name: str | None = None) -> "Record":
        sl = slice(start, stop)
        return Record(name or self.name, self.time_s[sl].copy(), {k: v[sl].copy() for k, v in self.inputs.items()},
                      {k: v[sl].copy() for k, v in self.outputs.items()}, list(self.notes))

    def constant_inputs(self) -> bool:
        """True when no input moves (nothing excites the plant)."""
        for v in self.inputs.values():
            scale = max(1.0, float(np.max(np.abs(v))))
            if float(np.max(v) - np.min(v)) > 1e-6 * scale:
                return False
        return True


@dataclass
class ColumnMap:
    """Project signal -> (source column, unit of the source)."""

    columns: dict[str, tuple[str, str]]

    @classmethod
    def from_yaml(cls, path: str | Path) -> "ColumnMap":
        data = read_mapping(path, "column map", "a mapping 'signal: column' or 'signal: {column:, unit:}'")
        return cls.from_dict(data, str(path))

    @classmethod
    def from_dict(cls, data: dict, source: str = "column map") -> "ColumnMap":
        cols = {}
        for signal, spec in data.items():
            kind = kind_of(str(signal))
            if isinstance(spec, str):
                column, unit = spec, None
            elif isinstance(spec, dict) and "column" in spec:
                column, unit = str(spec["column"]), spec.get("unit")
                unknown = set(spec) - {"column", "unit"}
                if unknown:
                    raise UserError(f"{source}: {signal}: unknown key {sorted(unknown)[0]!r} (use column, unit)")
            else:
                raise UserError(f"{source}: {signal}: expected a column name or {{column: NAME, unit: UNIT}}")
            unit = unit or next(iter(UNITS[kind]))
            if unit not in UNITS[kind]:
                raise UserError(f"{source}: {signal}: unit {unit!r} not known for a {kind} signal; "
                                f"use one of {', '.join(UNITS[kind])}")
            cols[str(signal)] = (column, unit)
        if "time_s" not in cols:
            raise UserError(f"{source}: the map needs time_s (the column holding time)")
        if not any(s in OUTPUTS for s in cols):
            raise UserError(f"{source}: the map needs an output: ph_measured or level_measured_cm")
        if not any(is_input(s) for s in cols):
            raise UserError(f"{source}: the map needs an input: valve_command_pct, <feed>_flow_ml_s "
                            f"or level_controller_output_pct")
        return cls(cols)

    @classmethod
    def from_args(cls, items: list[str], units: list[str]) -> "ColumnMap":
        data: dict = {}
        for item in items:
            if "=" not in item:
                raise UserError(f"--column expects SIGNAL=COLUMN, got {item!r}")
            sig, col = item.split("=", 1)
            data[sig.strip()] = {"column": col.strip()}
        for item in units:
            if "=" not in item:
                raise UserError(f"--unit expects SIGNAL=UNIT, got {item!r}")
            sig, unit = item.split("=", 1)
            if sig.strip() not in data:
                raise UserError(f"--unit {item!r}: no --column for {sig.strip()!r}")
            data[sig.strip()]["unit"] = unit.strip()
        return cls.from_dict(data, "--column")


def _read_table(path: Path) -> dict[str, list[str]]:
    """All columns of a CSV as strings (header names stripped; empty trailing columns ignored)."""
    with open(path, encoding="utf-8-sig", newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows:
        raise UserError(f"{path}: empty file")
    header = [h.strip() for h in rows[0]]
    cols: dict[str, list[str]] = {h: [] for h in header if h}
    for row in rows[1:]:
        if not any(c.strip() for c in row):
            continue
        for h, c in zip(header, row):
            if h:
                cols[h].append(c.strip())
        for h in header[len(row):]:
            if h:
                cols[h].append("")
    return cols


def _numeric(path: Path, column: str, values: list[str]) -> np.ndarray:
    out = np.empty(len(values))
    for i, v in enumerate(values):
        if v == "" or v.lower() in ("nan", "na", "null"):
            out[i] = math.nan
            continue
        try:
            out[i] = float(v)
        except ValueError:
            raise UserError(f"{path}: column {column!r} row {i + 2}: {v!r} is not a number") from None
    return out


def read_mapped_csv(path: Path, cmap: ColumnMap) -> dict[str, np.ndarray]:
    table = _read_table(path)
    out = {}
    for signal, (column, unit) in cmap.columns.items():
        if column not in table:
            close = [h for h in table if h.lower().replace(" ", "") == column.lower().replace(" ", "")]
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise UserError(f"{path}: no column {column!r} for {signal}{hint}; columns: "
                            f"{', '.join(repr(h) for h in table)}")
        out[signal] = _numeric(path, column, table[column]) * UNITS[kind_of(signal)][unit]
    return out


def read_project_run(path: Path) -> dict[str, np.ndarray]:
    """The signals of a project run (CSV, Parquet or bag) that a plant would have measured."""
    if path.suffix.lower() == ".mcap" or path.is_dir():
        try:
            from phfdi.bagio import load_run
        except ImportError:
            raise UserError(f"{path}: reading bags needs phfdi.bagio, not in this installation") from None
        run = load_run(path)
    else:
        from phfdi.run import Run

        try:
            run = Run.load(path)
        except UserError as exc:
            raise UserError(f"{exc} - for a CSV that is not a phfdi run, give a column map (--map or --column)") \
                from None
    sig = run.signals
    out = {"time_s": np.asarray(sig["time_s"], dtype=float)}
    if "valve_command_pct" in sig:
        out["valve_command_pct"] = sig["valve_command_pct"]
    elif "ph_controller_output_pct" in sig:
        out["valve_command_pct"] = sig["ph_controller_output_pct"]
    for name, values in sig.items():
        if name == "outlet_flow_ml_s" or not name.endswith("_flow_ml_s"):
            continue
        out[name] = values
    if "level_controller_output_pct" in sig and np.isfinite(sig["level_controller_output_pct"]).any():
        out["level_controller_output_pct"] = sig["level_controller_output_pct"]
    for name in OUTPUTS:
        if name in sig and np.isfinite(sig[name]).any():
            out[name] = sig[name]
    if not any(n in out for n in OUTPUTS):
        raise UserError(f"{path}: no measured output (ph_measured or level_measured_cm)")
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}


def _fill_gaps(name: str, values: np.ndarray, time_s: np.ndarray, label: str, notes: list[str]) -> np.ndarray:
    bad = ~np.isfinite(values)
    if not bad.any():
        return values
    if bad.all():
        raise UserError(f"{label}: {name} has no finite value")
    edges = np.diff(np.concatenate([[0], bad.astype(int), [0]]))
    starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
    longest = int(np.argmax(stops - starts))
    if stops[longest] - starts[longest] > MAX_GAP_SAMPLES or starts[0] == 0 or stops[-1] == len(values):
        a, b = starts[longest], stops[longest] - 1
        where = "at the start" if starts[0] == 0 else "at the end" if stops[-1] == len(values) else \
            f"of {stops[longest] - starts[longest]} samples"
        raise UserError(f"{label}: {name} is missing (NaN) {where}, from t = {time_s[a]:g} s to {time_s[b]:g} s; "
                        f"gaps of up to {MAX_GAP_SAMPLES} samples are filled, longer ones must be cut out")
    good = ~bad
    filled = values.copy()
    filled[bad] = np.interp(time_s[bad], time_s[good], values[good])
    notes.append(f"{name}: {int(bad.sum())} missing samples in {len(starts)} gap(s) filled by linear interpolation")
    return filled


def _check_ranges(name: str, values: np.ndarray, time_s: np.ndarray, label: str) -> None:
    kind = kind_of(name)
    limits = {"ph": (0.0, 14.0, "pH must lie in 0..14: is this column pH?"),
              "flow": (0.0, math.inf, "a flow cannot be negative"),
              "pct": (-5.0, 105.0, "a command in % of span lies in 0..100: is the unit right (--unit)?"),
              "level": (0.0, math.inf, "a level cannot be negative")}
    if kind not in limits:
        return
    lo, hi, why = limits[kind]
    out = (values < lo) | (values > hi)
    if out.any():
        i = int(np.argmax(out))
        raise UserError(f"{label}: {name} = {values[i]:g} at t = {time_s[i]:g} s: {why}")


def _resample(time_s: np.ndarray, signals: dict[str, np.ndarray], dt_s: float) -> tuple[np.ndarray, dict]:
    """Uniform grid from the first sample: outputs interpolated linearly, inputs held (zero-order hold)."""
    n = int(math.floor((time_s[-1] - time_s[0]) / dt_s + 1e-9)) + 1
    grid = time_s[0] + dt_s * np.arange(n)
    out = {}
    for name, v in signals.items():
        if is_input(name):
            idx = np.clip(np.searchsorted(time_s, grid + 1e-9 * dt_s, side="right") - 1, 0, len(v) - 1)
            out[name] = v[idx]
        else:
            out[name] = np.interp(grid, time_s, v)
    return grid, out


def make_record(signals: dict[str, np.ndarray], label: str, dt_s: float | None = None) -> Record:
    """Check and resample raw signals (project names, project units) into a :class:`Record`."""
    notes: list[str] = []
    t = np.asarray(signals["time_s"], dtype=float)
    if len(t) < 20:
        raise UserError(f"{label}: only {len(t)} samples; a diagnosis needs at least 20")
    if not np.all(np.isfinite(t)):
        i = int(np.argmax(~np.isfinite(t)))
        raise UserError(f"{label}: time is missing (NaN) at row {i + 2}")
    dts = np.diff(t)
    if not np.all(dts > 0):
        i = int(np.argmax(dts <= 0))
        raise UserError(f"{label}: time is not increasing at row {i + 3} (t = {t[i]:g} s then {t[i + 1]:g} s); "
                        f"sort the file or cut out the repeated stretch")
    rest = {k: np.asarray(v, dtype=float) for k, v in signals.items() if k != "time_s"}
    for name in list(rest):
        rest[name] = _fill_gaps(name, rest[name], t, label, notes)
        _check_ranges(name, rest[name], t, label)
    median = float(np.median(dts))
    uniform = float(np.max(np.abs(dts - median))) <= UNIFORM_TOLERANCE * median
    step = dt_s or median
    if not uniform or (dt_s is not None and abs(dt_s - median) > UNIFORM_TOLERANCE * median):
        t_new, rest = _resample(t, rest, step)
        notes.append(f"resampled from {'non-uniform ' if not uniform else ''}sampling "
                     f"(intervals {dts.min():.3g} to {dts.max():.3g} s, median {median:.3g} s) onto a uniform "
                     f"{step:.3g} s grid: outputs interpolated linearly, inputs held")
        t = t_new
    else:
        t = t[0] + median * np.arange(len(t))  # uniform to rounding: one exact step
    inputs = {k: v for k, v in rest.items() if is_input(k)}
    outputs = {k: v for k, v in rest.items() if k in OUTPUTS}
    if not inputs:
        raise UserError(f"{label}: no input signal (valve_command_pct, <feed>_flow_ml_s, "
                        f"level_controller_output_pct)")
    if not outputs:
        raise UserError(f"{label}: no output signal (ph_measured, level_measured_cm)")
    return Record(label, t, inputs, outputs, notes)


def load_record(path: str | Path, cmap: ColumnMap | None = None, dt_s: float | None = None) -> Record:
    """Read one file into a :class:`Record` (see the module docstring for what is read)."""
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    if cmap is not None:
        if path.suffix.lower() != ".csv":
            raise UserError(f"{path}: a column map applies to CSV files")
        signals = read_mapped_csv(path, cmap)
    else:
        signals = read_project_run(path)
    return make_record(signals, path.name, dt_s)
