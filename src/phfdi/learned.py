"""Measured records through the learned detector: read, learn, replay (application floor).

The record is read by :func:`phfdi.records.read_record` (any CSV, Parquet or MCAP bag, a column
map, the project's reading policy with a note for every repair). One row is one sample: the
learned detector assumes a roughly uniform sampling (the reader notes gaps and uneven stamps);
times in alarms are the record's seconds from its first row.
"""

from __future__ import annotations

import math
from dataclasses import replace
from datetime import datetime, timedelta
from pathlib import Path
from typing import Sequence

import numpy as np

from phfdi.records import Record, read_record
from phfdi.records.cells import iso_stamp
from phfdi_base.errors import UserError
from phfdi_base.stamps import record_stamps_ns, stamps_seconds
from wavelet_fdi.learned_detector import LearnedEvent, LearnedModel, LearnedSettings, learn, run_record

#: a channel may miss at most this fraction of the healthy rows the reference learns from
MAX_MISSING_HEALTHY = 0.2


def read_measured(path: str | Path, column_map=None, channels: Sequence[str] | None = None,
                  exclude: Sequence[str] = (), encoding: str | None = None) -> Record:
    """The record's channels as a matrix: ``channels`` (each must exist) or every column but ``exclude``."""

    rec = read_record(path, column_map, channels=list(channels) if channels else None, encoding=encoding)
    if len(rec) == 0:
        raise UserError(f"{path}: no data rows")
    names = list(channels) if channels else [n for n in rec.names if n not in set(exclude)]
    unknown = [e for e in exclude if e not in rec.names]
    if unknown:
        raise UserError(f"{path}: --exclude {unknown[0]!r}: no such channel; it has {', '.join(rec.names)}")
    if not names:
        raise UserError(f"{path}: no channel left to monitor")
    return replace(rec.select(names), path=str(path), time_s=np.asarray(rec.time_s, dtype=float),
                   lines=np.asarray(rec.lines))


def _check_healthy(rec: Record, part: slice) -> None:
    rows = part.stop - part.start
    for c, name in enumerate(rec.channels):
        miss = ~np.isfinite(rec.x[part, c])
        if miss.mean() > MAX_MISSING_HEALTHY:
            first = part.start + int(np.argmax(miss))
            raise UserError(f"{rec.path}: column {name!r} is missing in {int(miss.sum())} of the {rows} healthy rows "
                            f"(first at {rec.where} {rec.lines[first]}); the reference needs it in at least "
                            f"{100 * (1 - MAX_MISSING_HEALTHY):.0f} % of them")


def time_bound(text: str, rec: Record, flag: str) -> float:
    """A --from/--to bound in the record's seconds: a number is the record's own time (what alarms print), an
    ISO 8601 stamp is taken on the record's wall clock (only when its time column holds one)."""
    try:
        t = float(text)
    except ValueError:
        t = math.nan
    else:
        if math.isfinite(t):
            return t
    try:
        when = datetime.fromisoformat(text.strip())
    except ValueError:
        raise UserError(f"{flag} {text!r}: give seconds of the record's time or an ISO 8601 stamp "
                        f"(e.g. 2020-03-09T11:20:00)") from None
    if rec.wall_clock is None:
        raise UserError(f"{flag} {text}: {rec.path} has no wall-clock time column; give seconds of its own time "
                        f"({rec.time_s[0]:g} to {rec.time_s[-1]:g} s)")
    if when.tzinfo is not None:  # the reader keeps stamps with an offset in UTC: compare in UTC
        when = when.replace(tzinfo=None) - (when.utcoffset() or timedelta(0))
    return (when - rec.wall_clock).total_seconds()


def training_rows(rec: Record, rows: int | None = None, start: str | None = None,
                  end: str | None = None) -> slice:
    """The healthy rows: the first ``rows`` (None: all), or those from ``start`` to ``end`` (both included;
    seconds or ISO 8601 stamps, see :func:`time_bound`). A window without a row is one line."""
    if start is None and end is None:
        n = len(rec.x) if rows is None else int(rows)
        if n < 2 or n > len(rec.x):
            raise UserError(f"{rec.path}: --rows {rows}: the record has {len(rec.x)} rows")
        return slice(0, n)
    if rows is not None:
        raise UserError("give --rows or --from/--to, not both")
    lo = -math.inf if start is None else time_bound(start, rec, "--from")
    hi = math.inf if end is None else time_bound(end, rec, "--to")
    inside = np.flatnonzero((rec.time_s >= lo) & (rec.time_s <= hi))
    window = " ".join(f"{flag} {v}" for flag, v in (("--from", start), ("--to", end)) if v is not None)
    if len(inside) < 2:
        raise UserError(f"{rec.path}: {window}: {'no row' if len(inside) == 0 else 'only one row'} in that window; "
                        f"the record runs from {rec.when(rec.time_s[0])} to {rec.when(rec.time_s[-1])}")
    return slice(int(inside[0]), int(inside[-1]) + 1)  # time increases (the run policy): one stretch


def learn_from(rec: Record, rows: int | slice | None = None, settings: LearnedSettings | None = None
               ) -> LearnedModel:
    """Fit the learned reference on healthy rows of a record: the first ``rows`` (None: all of it) or a slice
    (:func:`training_rows`)."""
    part = rows if isinstance(rows, slice) else training_rows(rec, rows)
    _check_healthy(rec, part)
    dt = float(np.median(np.diff(rec.time_s[part])))
    if not dt > 0:
        raise UserError(f"{rec.path}: the healthy rows' time stamps do not increase")
    s = settings or LearnedSettings()
    s = LearnedSettings(**{**s.__dict__, "sample_time_s": dt})
    a, b = part.start, part.stop - 1
    source = {"file": rec.path, "rows": b - a + 1, "first_row": row_number(rec, a), "last_row": row_number(rec, b),
              "from_s": float(rec.time_s[a]), "to_s": float(rec.time_s[b]),
              "units": {c: rec.units.get(c, "") for c in rec.channels}}
    if rec.wall_clock is not None:
        source.update(from_stamp=rec.stamp(rec.time_s[a]), to_stamp=rec.stamp(rec.time_s[b]))
    return learn(rec.x[part], rec.channels, s, source=source)


def row_number(rec: Record, index: int) -> int:
    """The number a person finds sample ``index`` by in the file: its line (text), row (Parquet) or sample (bag)."""
    return int(rec.lines[min(max(index, 0), len(rec.lines) - 1)])


def event_dict(e: LearnedEvent, rec: Record) -> dict:
    out = {"kind": e.kind, "time": e.time_s, "stamp": rec.stamp(e.time_s),
           "line": int(rec.lines[e.index]) if 0 <= e.index < len(rec.lines) else None, "message": e.message}
    if e.alarm:
        out["alarm"] = e.alarm
    return out


def alarm_summaries(events: list[LearnedEvent], rec: Record) -> list[dict]:
    """One dict per alarm (its last state: cleared or not), with the record's time and line of each step."""
    alarms: dict[int, dict] = {}
    for e in events:
        if e.alarm is None:
            continue
        a = dict(e.alarm)
        # an event carries the alarm as it was then: a 'cleared' event made in the same chunk as, but before, the
        # naming lacks the name the 'named' event carries, whichever of the two comes last in sample order
        earlier = alarms.get(a["alarm_id"], {})
        if a.get("isolation") is None and earlier.get("isolation") is not None:
            a["isolation"] = earlier["isolation"]
        alarms[a["alarm_id"]] = a
    return [located(alarms[k], rec.lines, rec.where, rec.wall_clock) for k in sorted(alarms)]


def located(alarm: dict, lines: np.ndarray, where: str, wall_clock: datetime | None) -> dict:
    """An alarm with the file positions of its detection and clearing (``detection_line``, ``cleared_line``,
    ``where``: line, row or sample as the reader counts them) and its steps' wall-clock stamps (None without a
    date-time or epoch time column). One numbering for offline and live replay: the source file's own."""
    a = dict(alarm)
    a["where"] = where
    a["detection_line"] = int(lines[min(a["detection_index"], len(lines) - 1)])
    if a.get("cleared_index") is not None:
        a["cleared_line"] = int(lines[min(a["cleared_index"], len(lines) - 1)])
    for step in ("onset", "detection", "cleared"):  # the historian's own time beside the seconds
        a[f"{step}_stamp"] = iso_stamp(wall_clock, a.get(f"{step}_time"))
    return a


def outside_healthy_range(model: LearnedModel, rec: Record) -> list[dict]:
    """Where the record leaves the healthy range of the reference's calibration runs
    (:func:`wavelet_fdi.healthy_range.outside_ranges`; none for a reference file from before the ranges were
    kept): there the reference extrapolates."""
    from wavelet_fdi.healthy_range import outside_ranges

    return outside_ranges(model.source.get("healthy_ranges") or {}, rec.x, rec.channels)


def replay_measured(rec: Record, model: LearnedModel, refit_rows: int | None = None, name_faults: bool = True
                    ) -> tuple[list[LearnedEvent], np.ndarray, LearnedModel]:
    """Run the learned detector over a record (optionally re-fitting the reference on its first rows;
    ``name_faults`` False: detection only)."""
    missing = [c for c in model.channels if c not in rec.channels]
    if missing:
        raise UserError(f"{rec.path}: no column {missing[0]!r} (the reference was learned on "
                        f"{', '.join(model.channels)})")
    rec = rec.select(model.channels)
    if refit_rows is not None:
        if getattr(model.reference, "kind", "arx") != "arx":
            raise UserError(f"--refit-rows re-fits a learned (arx) reference; this one is {model.reference.kind!r} "
                            f"(phfdi calibrate --estimator fits it on healthy runs)")
        model = learn_from(rec, refit_rows, model.settings)
    # alarms in the record's own time, to the ns as a bag's stamps carry it: the learned node gets the same floats
    events, states, _ = run_record(model, stamps_seconds(record_stamps_ns(rec.time_s)), rec.x,
                                   name_faults=name_faults)
    return events, states, model


