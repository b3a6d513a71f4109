"""Measured records for diagnosis: read, map columns, check, resample.

A record is what the diagnosis may see of a plant: a uniform time base,
the *inputs* it was driven with and the *outputs* it measured, in the
project's signal names (:mod:`phfdi_base.signals`):

* inputs: ``valve_command_pct`` (the pH controller's output), ``<feed>_flow_ml_s``
  (measured feed flows), ``level_controller_output_pct`` (outlet valve command);
* outputs: ``ph_measured``, ``level_measured_cm``.

Nothing else is read from a project run (``ph_true``, valve position, fault
severity and the run's metadata would tell the answer), so a diagnosis sees
the same as it would on a plant historian.

Sources: a run of the project (.csv, .parquet, or a .mcap bag), or any
record with a column map (:class:`phfdi.records.ColumnMap`: a small YAML file
or ``--column SIGNAL=COLUMN``; units converted to the project's). Files are
read by :func:`phfdi.records.read_record` under the run policy: its repairs
become the record's notes, and a measured output with no value at all is an
error, never silently left out.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from phfdi import records
from phfdi.records import Record  # the one measured record: the diagnosis reads it on a uniform grid
from phfdi.records.columns import OUTPUTS, is_input
from phfdi_base.errors import UserError
from phfdi_base.signals import unit_of

UNITS = records.columns.UNITS

#: longest stretch of missing samples filled by interpolation (samples)
MAX_GAP_SAMPLES = 5
#: relative spread of sampling intervals still taken as uniform
UNIFORM_TOLERANCE = 0.01


def kind_of(signal: str) -> str:
    """Kind of a mapped signal (records.columns.kind_of); a name that says nothing is a user error here."""
    kind = records.columns.kind_of(signal)
    if kind is not None:
        return kind
    raise UserError(f"column map: cannot map onto {signal!r}: use time_s, valve_command_pct, "
                    f"level_controller_output_pct, <feed>_flow_ml_s, ph_measured or level_measured_cm")


def diagnosis_map(cmap: records.ColumnMap) -> records.ColumnMap:
    """``cmap`` (the one column map of :mod:`phfdi.records`) checked for diagnosis: signals of known kinds, time,
    an input and an output; raises a UserError naming what is missing."""
    for signal in cmap.signals:
        kind_of(signal)
    if "time_s" not in cmap.signals:
        raise UserError(f"{cmap.source}: the map needs time_s (the column holding time)")
    if not any(s in OUTPUTS for s in cmap.signals):
        raise UserError(f"{cmap.source}: the map needs an output: ph_measured or level_measured_cm")
    if not any(is_input(s) for s in cmap.signals):
        raise UserError(f"{cmap.source}: the map needs an input: valve_command_pct, <feed>_flow_ml_s "
                        f"or level_controller_output_pct")
    return cmap


def read_project_run(path: Path, encoding: str | None = None) -> tuple[dict[str, np.ndarray], list[str]]:
    """The signals of a project run (CSV, Parquet or bag) that a plant would have measured, and the notes."""
    rec = records.read_record(path, policy="run", encoding=encoding)
    sig, notes = rec.signals, rec.note_lines()
    out = {"time_s": rec.time_s}
    if "valve_command_pct" in sig:
        out["valve_command_pct"] = sig["valve_command_pct"]
    elif "ph_controller_output_pct" in sig:
        out["valve_command_pct"] = sig["ph_controller_output_pct"]
    for name, values in sig.items():
        if name.endswith("_flow_ml_s") and name != "outlet_flow_ml_s":
            out[name] = values
    if "level_controller_output_pct" in sig:
        if np.isnan(sig["level_controller_output_pct"]).all():
            notes.append(f"{path}: level_controller_output_pct has no value: not used as an input")
        else:
            out["level_controller_output_pct"] = sig["level_controller_output_pct"]
    for name in OUTPUTS:
        if name in sig:
            rec.refuse_empty(name)
            out[name] = sig[name]
    if not any(n in out for n in OUTPUTS):
        raise UserError(f"{path}: no measured output (ph_measured or level_measured_cm) - for a file that is "
                        f"not a phfdi run, give a column map (--map or --column)")
    return {k: np.asarray(v, dtype=float) for k, v in out.items()}, notes


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


def _check_time_gaps(t: np.ndarray, dts: np.ndarray, median_s: float, dt_s: float | None, label: str) -> None:
    """A jump in time longer than the gaps that are filled, or a --dt that would blow the grid up: refused."""
    i = int(np.argmax(dts))
    if dts[i] > (MAX_GAP_SAMPLES + 1) * median_s:
        raise UserError(f"{label}: time jumps from t = {t[i]:g} s to {t[i + 1]:g} s, a gap of about "
                        f"{dts[i] / median_s - 1:.0f} samples; gaps of up to {MAX_GAP_SAMPLES} samples are filled, "
                        f"longer ones must be cut out")
    if dt_s is not None and (t[-1] - t[0]) / dt_s > 20 * len(t):
        raise UserError(f"--dt {dt_s:g} s would make {(t[-1] - t[0]) / dt_s:.3g} samples of {len(t)}: use a sample "
                        f"time near the data's ({median_s:.3g} s)")


def make_record(signals: dict[str, np.ndarray], label: str, dt_s: float | None = None,
                notes: list[str] | None = None) -> Record:
    """Check and resample raw signals (project names, project units) into a :class:`Record`.

    Raises
    ------
    UserError
        Fewer than 20 samples, missing or decreasing time (naming the row), and the like.

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.diagnosis import make_record
    >>> record = make_record({"time_s": np.arange(100.0), "acid_flow_ml_s": np.full(100, 9.8),
    ...                       "ph_measured": np.full(100, 12.0)}, "at_rest")
    >>> list(record.inputs), list(record.outputs)
    (['acid_flow_ml_s'], ['ph_measured'])
    """
    notes = list(notes or [])
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
    _check_time_gaps(t, dts, median, dt_s, label)
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
    signals = {**inputs, **outputs}
    return Record(label, t, signals, units={k: unit_of(k) for k in signals}, columns={k: k for k in signals},
                  lines=np.arange(len(t)), where="sample", notes=notes, grid_s=float(step))


def load_record(path: str | Path, cmap: records.ColumnMap | None = None, dt_s: float | None = None,
                encoding: str | None = None) -> Record:
    """Read one file into a :class:`Record` (see the module docstring for what is read).

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.diagnosis import load_record
    >>> path = Path(tempfile.mkdtemp()) / "run.csv"
    >>> rows = "".join(f"{t},9.8,12.0\\n" for t in range(30))
    >>> _ = path.write_text("time_s,acid_flow_ml_s,ph_measured\\n" + rows)
    >>> record = load_record(path)
    >>> record.name, list(record.outputs)
    ('run.csv', ['ph_measured'])
    """
    path = Path(path)
    if cmap is not None:
        rec = records.read_record(path, cmap, policy="run", channels=cmap.channels(), encoding=encoding)
        signals, notes = {"time_s": rec.time_s, **rec.signals}, rec.note_lines()
    else:
        signals, notes = read_project_run(path, encoding)
    prefix = f"{path}: "
    return make_record(signals, path.name, dt_s, [n.removeprefix(prefix) for n in notes])
