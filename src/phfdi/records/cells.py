"""Cells -> numbers: what is missing and why (empty, NaN, inf, text), and time stamps -> seconds."""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timedelta

import numpy as np

MISSING_WORDS = frozenset({"", "nan", "na", "n/a", "null", "none", "-", "#n/a", "nat"})
#: stamp formats tried after ISO 8601 (the pH rig's export is the second)
STAMP_FORMATS = ("%Y-%m-%d %H:%M:%S", "%m/%d/%Y %I:%M:%S %p", "%d.%m.%Y %H:%M:%S", "%Y/%m/%d %H:%M:%S",
                 "%d/%m/%Y %H:%M:%S")


@dataclass
class Numbers:
    """A column as floats (NaN where missing) and, for each missing cell, why."""

    values: np.ndarray
    empty: np.ndarray  # bool: empty cell or a missing-value word (NA, null, ...)
    nan: np.ndarray  # bool: NaN in the file
    inf: np.ndarray  # bool: +-inf (set to NaN in ``values``)
    text: np.ndarray  # bool: text that is not a number

    @property
    def missing(self) -> np.ndarray:
        return self.empty | self.nan | self.inf | self.text


def to_numbers(cells: list | np.ndarray) -> Numbers:
    """Floats from a column of strings or numbers; inf and unreadable cells become NaN (and are marked)."""
    n = len(cells)
    if isinstance(cells, np.ndarray) and cells.dtype.kind in "fiub":
        x = cells.astype(float)
        nan, inf = np.isnan(x), np.isinf(x)
        x[inf] = math.nan
        zero = np.zeros(n, bool)
        return Numbers(x, zero, nan, inf, zero.copy())
    try:  # every cell a number (the usual case): one C-level pass
        return to_numbers(np.array(cells, dtype=float))
    except (ValueError, TypeError):
        pass
    x = np.empty(n)
    empty, nan, inf, text = (np.zeros(n, bool) for _ in range(4))
    for i, c in enumerate(cells):
        s = str(c).strip()
        try:
            v = float(s)
        except ValueError:
            x[i] = math.nan
            (empty if s.lower() in MISSING_WORDS else text)[i] = True
            continue
        x[i] = v
        if math.isnan(v):
            nan[i] = True
        elif math.isinf(v):
            inf[i], x[i] = True, math.nan
    return Numbers(x, empty, nan, inf, text)


def parse_stamps(cells: list | np.ndarray, fmt: str | None = None) -> tuple[np.ndarray, str | None]:
    """Seconds of each stamp (NaN where unreadable) and the datetime format used (None: plain numbers).

    Plain numbers are taken as seconds as they are; date-time stamps as seconds since the first readable one.
    """
    nums = to_numbers(cells)
    readable = ~nums.missing
    if fmt is None and (readable.sum() >= 0.5 * len(cells) or isinstance(cells, np.ndarray)):
        return nums.values, None
    texts = [str(c).strip() for c in cells]
    used = fmt or _guess_format(texts)
    if used is None:
        return nums.values, None
    out = np.full(len(texts), math.nan)
    t0 = None
    for i, s in enumerate(texts):
        d = _parse(s, used)
        if d is None:
            continue
        t0 = d if t0 is None else t0
        out[i] = (d - t0).total_seconds()
    return out, used


def first_stamp(cells: list | np.ndarray, fmt: str) -> datetime | None:
    """The first readable date-time stamp (what :func:`parse_stamps` counts seconds from): the record's
    wall-clock time at 0 s. Naive; stamps with a UTC offset are converted to UTC as :func:`parse_stamps` does."""
    for c in cells:
        d = _parse(str(c).strip(), fmt)
        if d is not None:
            return d
    return None


def iso_stamp(wall_clock: datetime | None, t_s: float | None) -> str | None:
    """``t_s`` seconds of a record as an ISO 8601 stamp (None when the record has no wall-clock time).

    >>> iso_stamp(datetime(2020, 3, 9, 10, 14, 33), 667.0), iso_stamp(datetime(2020, 3, 9), 0.25)
    ('2020-03-09T10:25:40', '2020-03-09T00:00:00.250')
    """
    if wall_clock is None or t_s is None or not math.isfinite(t_s):
        return None
    when = wall_clock + timedelta(seconds=float(t_s))
    return when.isoformat(timespec="seconds" if when.microsecond == 0 else "milliseconds")


#: the wall-clock time of epoch 0 s, for records whose time column holds epoch stamps
EPOCH = datetime(1970, 1, 1)

#: epoch stamps by magnitude (years 2001 to about 5000): (lowest value, factor to seconds, name)
EPOCH_UNITS = ((1e17, 1e-9, "nanoseconds"), (1e14, 1e-6, "microseconds"), (1e11, 1e-3, "milliseconds"),
               (1e9, 1.0, "seconds"))
#: spreadsheet serial dates (days since 1899-12-30): values of the years 1954 to 2119 stepping below this
SERIAL_DAYS = (20_000.0, 80_000.0, 1e-3)
#: serial day of 1970-01-01: serial days become epoch seconds like the other stamps
SERIAL_UNIX_EPOCH_DAYS = 25_569.0


def numeric_time_unit(t: np.ndarray) -> tuple[float, str | None]:
    """(factor to seconds, what was recognised) of a numeric time column, told by its range and steps: epoch
    seconds, milliseconds, microseconds or nanoseconds, or spreadsheet serial days stepping by under 86 s.
    Plain seconds (a run's own time): (1.0, None).

    >>> numeric_time_unit(np.array([1.7e12, 1.7e12 + 1000.0]))
    (0.001, 'epoch milliseconds')
    >>> numeric_time_unit(np.array([45000.5, 45000.5 + 1 / 86400]))
    (86400.0, 'spreadsheet serial days')
    >>> numeric_time_unit(np.array([0.0, 1.0, 2.0]))
    (1.0, None)
    """
    ok = t[np.isfinite(t)]
    if len(ok) < 2:
        return 1.0, None
    first = float(np.min(ok))
    for low, factor, name in EPOCH_UNITS:
        if first >= low:
            return factor, f"epoch {name}"
    lo, hi, step = SERIAL_DAYS
    steps = np.diff(ok)
    if lo <= first and float(np.max(ok)) <= hi and 0 < float(np.median(steps[steps > 0]) if (steps > 0).any()
                                                                 else 0.0) < step:
        return 86400.0, "spreadsheet serial days"
    return 1.0, None


def _guess_format(texts: list[str]) -> str | None:
    sample = [s for s in texts[:50] if s]
    for fmt in ("iso", *STAMP_FORMATS):
        if sample and sum(_parse(s, fmt) is not None for s in sample) >= 0.8 * len(sample):
            return fmt
    return None


def _parse(text: str, fmt: str) -> datetime | None:
    try:
        d = datetime.fromisoformat(text) if fmt == "iso" else datetime.strptime(text, fmt)
    except (ValueError, OverflowError):
        return None
    return d.replace(tzinfo=None) - (d.utcoffset() or _ZERO) if d.tzinfo else d


_ZERO = datetime(2000, 1, 1) - datetime(2000, 1, 1)
