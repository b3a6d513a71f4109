"""read_record: any supported file -> :class:`Record` under the reading policy (see :mod:`.policy`)."""

from __future__ import annotations

import difflib
from dataclasses import replace
from datetime import datetime
from pathlib import Path
from typing import Callable

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.signals import unit_of

from . import policy as P
from .cells import EPOCH, SERIAL_UNIX_EPOCH_DAYS, first_stamp, numeric_time_unit, parse_stamps, to_numbers
from .columns import PROJECT_UNIT, ColumnMap, ColumnSpec, kind_of, normal_cell
from .errors import ReadError
from .formats import expected, format_of, run_suffixes
from .notes import counted, places
from .record import Record
from .sources import Table, read_table

#: what names a column map: the map, its dict form, a YAML file, or None (every column under its own name)
MapLike = ColumnMap | dict | str | Path | None

#: column names taken as time when no column map says which (case-insensitive)
TIME_NAMES = ("time_s", "timestamp", "time", "datetime", "date")
DEFAULT_SOURCE = "the file's header"


def read_record(path: str | Path, column_map: ColumnMap | dict | str | Path | Callable | None = None, *,
                policy: str = "run", channels: list[str] | tuple[str, ...] | None = None,
                encoding: str | None = None, min_samples: int = 2, required: tuple[str, ...] = ()) -> Record:
    """Read a record (CSV, Parquet or an MCAP bag), repair what the policy repairs, refuse the rest.

    ``column_map``: a :class:`ColumnMap`, its dict form, a YAML file, or a function (header, file metadata)
    -> ColumnMap; None reads every column under its own name (time from ``time_s``, ``timestamp`` or ``time``).
    ``channels``: only these signals (each must exist); ``required``: signals that must exist and hold values
    even when ``channels`` is None. ``policy``: "run" (a clock reset is refused) or "historian" (it starts a
    new segment). ``min_samples``: fewer usable samples are refused.
    Raises :class:`ReadError` (one line naming file, line and column) for what cannot be used.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.records import read_record
    >>> path = Path(tempfile.mkdtemp()) / "loop.csv"
    >>> _ = path.write_text("Time (s),PV,OP\\n0,7.0,0.50\\n1,7.1,0.51\\n2,,0.52\\n3,7.3,0.53\\n")
    >>> record = read_record(path, {"time_s": "Time (s)", "ph_measured": "PV",
    ...                             "valve_command_pct": {"column": "OP", "unit": "fraction"}})
    >>> record.signals["ph_measured"], record.signals["valve_command_pct"]
    (array([7. , 7.1, nan, 7.3]), array([50., 51., 52., 53.]))
    >>> print(record.notes[0].split(": ", 1)[1])
    column 'PV': 1 cell not a number (empty 1), first at line 4: marked missing
    """
    if policy not in P.POLICIES:
        raise ValueError(f"policy must be one of {P.POLICIES}, got {policy!r}")
    path = Path(path)
    table = read_table(path, encoding)
    return record_from_table(path, table, column_map, policy=policy, channels=channels, min_samples=min_samples,
                             required=required)


def record_from_table(path: str | Path, table: Table, column_map: ColumnMap | dict | str | Path | Callable | None = None,
                      *, policy: str = "run", channels: list[str] | tuple[str, ...] | None = None,
                      min_samples: int = 2, required: tuple[str, ...] = ()) -> Record:
    """:func:`read_record` on a raw table already read (e.g. the rows of a long file a caller chose to read,
    with ``table.lines`` their line numbers in the file): the same columns, policy and refusals.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.records import record_from_table
    >>> from phfdi.records.sources import read_table
    >>> path = Path(tempfile.mkdtemp()) / "loop.csv"
    >>> _ = path.write_text("time_s,PV,OP\\n0,7.0,50\\n1,7.1,51\\n2,7.2,52\\n")
    >>> table = read_table(path, None)
    >>> record = record_from_table(path, table, {"time_s": "time_s", "pv": "PV", "op_pct": "OP"})
    >>> record.signals["pv"], record.lines  # the lines are the file's
    (array([7. , 7.1, 7.2]), array([2, 3, 4]))
    """
    if policy not in P.POLICIES:
        raise ValueError(f"policy must be one of {P.POLICIES}, got {policy!r}")
    path = Path(path)
    cmap = _resolve_map(column_map, table, channels, required)
    rows = _rows(table, cmap)
    columns = {name: spec.column for name, spec in cmap.signals.items() if name != "time_s"}
    units = {name: _unit(name, spec, table) for name, spec in cmap.signals.items() if name != "time_s"}
    _apply_policy(rows, policy)
    asked = set(required) | (set(columns) if channels is not None or cmap.source != DEFAULT_SOURCE else set())
    _refuse_unusable(rows, columns, min_samples, table.where, asked)
    P.note_holds_and_steps(rows, units, columns)
    meta = dict(table.metadata)
    if cmap.loop_tag:
        meta["loop_tag"] = cmap.loop_tag
    return Record(str(path), rows.time_s, rows.values, units, columns, rows.lines, table.where, policy,
                  [*table.notes, *rows.notes], rows.automatic, rows.boundaries, meta, rows.wall_clock)



def read_run(path: str | Path, column_map: MapLike | Callable = None, *, encoding: str | None = None,
             required: tuple[str, ...] = ()) -> Record:
    """A run from a run file or a bag of the graph (any format of :mod:`.formats` a run is read from: .mcap,
    .parquet, .csv), read by :func:`read_record` under the run policy: the one way every command and
    :func:`phfdi.bagio.load_run` read a run.

    Repairs (duplicate rows, repeated stamps, cells that are not numbers: NaN) are listed in
    ``metadata["notes"]``; what cannot be repaired is a one-line :class:`~phfdi_base.errors.UserError`.
    ``column_map``, ``encoding``, ``required``: as :func:`read_record`.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.records import read_run
    >>> path = Path(tempfile.mkdtemp()) / "run.csv"
    >>> _ = path.write_text("time_s,ph_measured\\n0,7.0\\n1,7.1\\n1,7.1\\n2,7.2\\n")
    >>> run = read_run(path)
    >>> run["ph_measured"], len(run.metadata["notes"])
    (array([7. , 7.1, 7.2]), 1)
    """
    path = Path(path)
    if not format_of(path).run:
        raise UserError(f"cannot read a run from {path}: expected {expected(run_suffixes())}")
    return read_record(path, column_map, policy="run", encoding=encoding, required=required).to_run()


def _apply_policy(rows: P.Rows, policy: str) -> None:
    P.drop_exact_duplicates(rows)
    P.split_backwards(rows, policy)
    P.respace_repeats(rows)
    P.average_repeats(rows)
    P.split_jumps(rows, policy)


# ---- which columns -----------------------------------------------------------------------
def _resolve_map(given: MapLike | Callable[[list[str], dict], MapLike], table: Table, channels,
                 required=()) -> ColumnMap:
    if callable(given):  # a resolver that chooses the columns from the header and the file's metadata
        given = given(list(table.columns), dict(table.metadata))
    if isinstance(given, (str, Path)):
        cmap = ColumnMap.load(given)
    elif isinstance(given, dict):
        cmap = ColumnMap.from_mapping(given)
    else:
        cmap = _default_map(table) if given is None else given
    wanted = [*(channels or ()), *(c for c in required if c not in (channels or ()))]
    if wanted:
        absent = [c for c in wanted if c not in cmap.signals]
        if absent:
            if cmap.source == DEFAULT_SOURCE:
                _no_column(table, absent[0], absent[0])
            raise ReadError(cmap.source, f"no column mapped for {absent[0]!r}")
    if channels is not None:
        keep = {"time_s", *channels, *required}
        cmap = ColumnMap({k: v for k, v in cmap.signals.items() if k in keep}, cmap.sample_time_s,
                         cmap.time_format, cmap.loop_tag, cmap.mode, cmap.quality, cmap.source)
    for name, spec in cmap.signals.items():
        if spec.column not in table.columns:
            _no_column(table, spec.column, name)
    cmap = _with_time_detected(cmap, table)
    for column in ([cmap.mode.column] if cmap.mode else []) + [q.column for q in cmap.quality]:
        if column not in table.columns:
            _no_column(table, column, "mode/quality")
    if cmap.time is None and not (cmap.sample_time_s or table.metadata.get("sample_time_s")):
        raise ReadError(table.path, f"no time column ({', '.join(TIME_NAMES[:3])}); give a column map with "
                                    f"time_s or sample_time_s", line=1 if table.where == "line" else None)
    if not cmap.channels():
        raise ReadError(table.path, "no signal column besides time", line=1 if table.where == "line" else None)
    return cmap


def _with_time_detected(cmap: ColumnMap, table: Table) -> ColumnMap:
    """A map that names neither a time column nor a sample time (``--column ph_measured=pH`` alone) gets the
    file's time column the way a file read without a map does (``time_s``, ``timestamp``, ...), noted: naming
    the signals should not lose the time."""
    if cmap.time is not None or cmap.sample_time_s is not None:
        return cmap
    used = set(cmap.columns_used())
    low = {c.lower(): c for c in table.columns if c not in used}
    found = next((low[n] for n in TIME_NAMES if n in low), None)
    if found is None:
        return cmap
    table.notes.append(f"{table.path}: time from column {found!r} (the column map names none)")
    return replace(cmap, signals={"time_s": ColumnSpec(found), **cmap.signals})  # unit told by its range


def _default_map(table: Table) -> ColumnMap:
    low = {c.lower(): c for c in table.columns}
    time = next((low[n] for n in TIME_NAMES if n in low), None)
    signals = {"time_s": ColumnSpec(time)} if time else {}
    signals.update({c: ColumnSpec(c) for c in table.columns if c != time})
    return ColumnMap(signals, source=DEFAULT_SOURCE)


def _short(name: str, limit: int = 60) -> str:
    """A column name fit for a one-line message (a wide export's header cell can run to kilobytes)."""
    return name if len(name) <= limit else f"{name[:limit - 15]}...({len(name)} chars)"


def _no_column(table: Table, column: str, signal: str) -> None:
    close = [c for c in table.columns if c.lower().replace(" ", "") == column.lower().replace(" ", "")] \
        or difflib.get_close_matches(column, list(table.columns), n=1)
    hint = f" (did you mean {_short(close[0])!r}?)" if close else ""
    cols = list(table.columns)
    names = ", ".join(repr(_short(c)) for c in cols[:12]) + (f" and {len(cols) - 12} more" if len(cols) > 12 else "")
    raise ReadError(table.path, f"no such column (for {signal}){hint}; the file has: {names}",
                    line=1 if table.where == "line" else None, column=column)


def _unit(name: str, spec: ColumnSpec, table: Table) -> str:
    """The project's unit for signals of a known kind, else the map's unit, the file's, or the name's."""
    kind = kind_of(name)
    if spec.unit is not None:
        return PROJECT_UNIT[kind] if kind is not None else spec.unit
    return table.units.get(spec.column) or unit_of(name)


# ---- cells -> rows -------------------------------------------------------------------------
def _rows(table: Table, cmap: ColumnMap) -> P.Rows:
    time_s, stamps, wall_clock = _time(table, cmap)
    values, numbers = {}, {}
    for name, spec in cmap.signals.items():
        if name == "time_s":
            continue
        numbers[spec.column] = nums = to_numbers(table.columns[spec.column])
        values[name] = nums.values * spec.factor
    _note_missing_cells(table, numbers)
    rows = P.Rows(table.path, table.where, time_s, values, table.lines.copy(), stamps, wall_clock=wall_clock)
    _apply_quality(rows, table, cmap)
    _apply_mode(rows, table, cmap)
    readable = ~np.isnan(rows.time_s)
    if not readable.all():
        bad = np.flatnonzero(~readable)
        assert cmap.time is not None  # without a time column every stamp is made from sample_time_s
        rows.note(f"{places(table.where, spans_of(table, bad))}, column {cmap.time.column!r}: {len(bad)} "
                  f"{'row' if len(bad) == 1 else 'rows'} without a readable time stamp, dropped")
        rows.keep(readable)
    return rows


def spans_of(table: Table, index: np.ndarray) -> list[tuple[int, int]]:
    return P.spans(table.lines, index)


def _time(table: Table, cmap: ColumnMap) -> tuple[np.ndarray, list[str] | None, datetime | None]:
    """Seconds of each row, the stamps as written (date-time stamps) and the wall-clock time at 0 s (None when
    the record's time is not a clock: plain seconds, or samples counted from sample_time_s)."""
    spec = cmap.time
    if spec is None:
        dt = float(cmap.sample_time_s or table.metadata["sample_time_s"])
        return dt * np.arange(len(table)), None, None
    cells = table.columns[spec.column]
    t, fmt = parse_stamps(cells, cmap.time_format)
    bad = np.isnan(t) | np.isinf(t)
    if bad.sum() > 0.5 * len(t):
        i = int(np.argmax(bad))
        raise ReadError(table.path, f"{str(cells[i])[:40]!r} is not a time (seconds, or a date-time: give "
                                    f"time_format in the column map)", line=int(table.lines[i]),
                        column=spec.column, where=table.where)
    t = np.where(bad, np.nan, t)
    if fmt is None:
        what = None
        if spec.unit is None:  # no unit stated in the map: tell epoch stamps and serial days by their range
            factor, what = numeric_time_unit(t)
            if factor != 1.0:  # (epoch seconds are seconds already: read as they are, as before)
                table.notes.append(f"{table.path}: column {spec.column!r}: read as {what}, converted to (epoch) seconds "
                                   f"(told by its range; give the column's unit in a column map if that is wrong)")
                t = (t - SERIAL_UNIX_EPOCH_DAYS) * factor if what and what.startswith("spreadsheet") else t * factor
        if what is None and table.metadata.get("mode") == "measured" and table.metadata.get("wall_clock"):
            # a measured record's bag keeps its source's wall clock at 0 s (phfdi bag from-csv)
            try:
                return t * spec.factor, None, datetime.fromisoformat(str(table.metadata["wall_clock"]))
            except ValueError:
                table.notes.append(f"{table.path}: the bag's wall clock {table.metadata['wall_clock']!r} is not a "
                                   f"date-time: times in seconds only")
        return t * spec.factor, None, EPOCH if what else None  # epoch stamps are a wall clock too
    return t, [str(c).strip() for c in cells], first_stamp(cells, fmt)


def _note_missing_cells(table: Table, numbers: dict) -> None:
    """One note per set of columns missing in the same rows for the same reasons (a row cut short: one note)."""
    groups: dict[tuple, list[str]] = {}
    for column, nums in numbers.items():
        if nums.missing.any():
            key = (nums.missing.tobytes(), nums.empty.tobytes(), nums.nan.tobytes(), nums.inf.tobytes())
            groups.setdefault(key, []).append(column)
    for columns in groups.values():
        nums = numbers[columns[0]]
        total = int(nums.missing.sum())
        first = int(np.argmax(nums.missing))
        kinds = {"empty": nums.empty, "NaN": nums.nan, "inf": nums.inf, "text": nums.text}
        counts = counted({k: int(v.sum()) for k, v in kinds.items()})
        example = ""
        if nums.text.any():
            example = f" (e.g. {str(table.columns[columns[0]][int(np.argmax(nums.text))])[:20]!r})"
        amount = f"all {total}" if total == len(nums.values) > 1 else f"{total}"
        names = (f"column {columns[0]!r}" if len(columns) == 1 else
                 f"columns {', '.join(repr(c) for c in columns)}")
        each = " each" if len(columns) > 1 else ""
        table.notes.append(f"{table.path}: {names}: {amount} {'cell' if total == 1 else 'cells'}{each} not a "
                           f"number ({counts}){example}, first at {table.where} {table.lines[first]}: marked missing")


def _apply_quality(rows: P.Rows, table: Table, cmap: ColumnMap) -> None:
    for q in cmap.quality:
        good = np.array([normal_cell(c) in q.good for c in table.columns[q.column]])
        if good.all():
            continue
        targets = [s for s in (q.signals or rows.values) if s in rows.values]
        for s in targets:
            rows.values[s] = np.where(good, rows.values[s], np.nan)
        bad = np.flatnonzero(~good)
        rows.note(f"{places(table.where, P.spans(table.lines, bad))}, column {q.column!r}: {len(bad)} samples "
                  f"flagged bad: {', '.join(targets)} marked missing")


def _apply_mode(rows: P.Rows, table: Table, cmap: ColumnMap) -> None:
    if cmap.mode is None:
        return
    auto = np.array([cmap.mode.is_automatic(c) for c in table.columns[cmap.mode.column]])
    rows.automatic = auto
    if not auto.all():
        manual = np.flatnonzero(~auto)
        rows.note(f"{places(table.where, P.spans(table.lines, manual))}, column {cmap.mode.column!r}: "
                  f"{len(manual)} samples not in automatic (mode {str(table.columns[cmap.mode.column][manual[0]])!r}"
                  f"{' ...' if len(manual) > 1 else ''}): not judged where only automatic stretches are used")


def _refuse_unusable(rows: P.Rows, columns: dict[str, str], min_samples: int, where: str, asked: set[str]) -> None:
    """Too few samples, or a channel the caller asked for without a single value: refused."""
    if len(rows) < min_samples:
        raise ReadError(rows.path, f"only {len(rows)} usable {'sample' if len(rows) == 1 else 'samples'} "
                                   f"after reading; at least {min_samples} are needed")
    for name, v in rows.values.items():
        if name in asked and np.isnan(v).all():
            raise ReadError(rows.path, f"no usable value in any of the {len(v)} rows (all missing)",
                            line=int(rows.lines[0]), column=columns[name], where=where)
