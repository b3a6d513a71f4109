"""Historian exports of one control loop -> :class:`phfdi.run.Run`.

Two formats:

* the tab-separated export of ``../shared/data/plant_loops`` (see its
  PROVENANCE.md): CRLF, a title line ``PROCESSDATA <loop> Data <format>``,
  ``<n> <Ts> <start> <rows>``, tag names (``<tag>.MV``, ``.PV``, ``.SV``,
  ``.MODE``, flags), descriptions, the publisher's solver settings, then rows
  of timestamp, MV (= OP), PV, SV (= SP), MODE and four flags;
* CSV (comma, semicolon or tab) with a header line and a column mapping
  (:class:`ColumnMap`): given on the command line, in a small YAML file, or
  guessed from names (``time_s``/``op_pct``/``pv``/``sp`` as phfdi writes
  them, or tags ending in ``.OP``/``.MV``, ``.PV``, ``.SP``/``.SV``).

Every loop becomes a run with the signals ``time_s`` (from the first sample),
``op_pct`` (controller output, % of span), ``pv`` and ``sp`` (in the units the
historian gives, recorded in ``metadata["units"]``). :func:`check_loop_run`
rejects what cannot be diagnosed with one message naming the problem.
"""

from __future__ import annotations

import csv
import io
import math
import re
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np

from phfdi.run import Run
from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping

#: fewer samples than this cannot hold a training and a validation part
MIN_SAMPLES = 100
#: gaps of up to this many missing samples are filled by linear interpolation
MAX_FILLED_GAP = 3
#: relative spread below which a signal counts as constant
CONSTANT_RTOL = 1e-9

#: process types the identification knows (level loops integrate)
PROCESS_TYPES = ("self_regulating", "integrating")


class LoopDataError(UserError):
    """A loop file that cannot be diagnosed; the message names file and problem."""


@dataclass
class ColumnMap:
    """Which file columns hold time, OP, PV and SP (names as in the header).

    ``time`` None: no time column; ``sample_time_s`` gives the spacing.
    ``sp`` None: no setpoint column (the control error is then PV about its mean).
    """

    op: str
    pv: str
    sp: str | None = None
    time: str | None = None
    sample_time_s: float | None = None
    loop_tag: str | None = None
    time_format: str | None = None

    @classmethod
    def parse(cls, text: str) -> "ColumnMap":
        """From ``op=FIC1.OP,pv=FIC1.PV,sp=FIC1.SP,time=Timestamp`` or a YAML file name."""
        if text.endswith((".yaml", ".yml")):
            return cls.from_yaml(text)
        items: dict[str, str] = {}
        for part in filter(None, (p.strip() for p in text.split(","))):
            key, sep, value = part.partition("=")
            if not sep or not value:
                raise UserError(f"column mapping {part!r}: expected KEY=COLUMN (keys: op, pv, sp, time)")
            items[key.strip()] = value.strip()
        return cls._from_items(items, f"--columns {text!r}")

    @classmethod
    def from_yaml(cls, path: str | Path) -> "ColumnMap":
        path = Path(path)
        data = read_mapping(path, "column mapping file", "a mapping with 'columns' (op, pv, sp, time)")
        items = dict(data.get("columns") or {})
        for key in ("sample_time_s", "loop_tag", "time_format"):
            if key in data:
                items[key] = data[key]
        return cls._from_items(items, str(path))

    @classmethod
    def _from_items(cls, items: dict, where: str) -> "ColumnMap":
        allowed = {"op", "pv", "sp", "time", "sample_time_s", "loop_tag", "time_format"}
        unknown = sorted(set(items) - allowed)
        if unknown:
            raise UserError(f"{where}: unknown key {unknown[0]!r}; allowed: op, pv, sp, time, sample_time_s, "
                            "loop_tag, time_format")
        missing = [k for k in ("op", "pv") if not items.get(k)]
        if missing:
            raise UserError(f"{where}: the mapping needs {' and '.join(missing)} (the columns of OP and PV)")
        st = items.get("sample_time_s")
        return cls(op=str(items["op"]), pv=str(items["pv"]), sp=_opt_str(items.get("sp")),
                   time=_opt_str(items.get("time")), sample_time_s=None if st is None else float(st),
                   loop_tag=_opt_str(items.get("loop_tag")), time_format=_opt_str(items.get("time_format")))


def _opt_str(v) -> str | None:
    return None if v is None or v == "" else str(v)


@dataclass
class LoopRecord:
    """What a reader found besides the samples (goes into ``Run.metadata``)."""

    loop_tag: str
    file: str
    sample_time_s: float
    start: str | None = None
    units: dict = field(default_factory=dict)
    descriptions: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)


# ---- format detection ----------------------------------------------------------------
def read_loop(path: str | Path, columns: ColumnMap | None = None) -> Run:
    """Read one loop file (plant_loops TSV or CSV) and check it can be diagnosed."""
    path = Path(path)
    if not path.is_file():
        raise LoopDataError(f"{path}: no such file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise LoopDataError(f"{path}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if text.startswith("PROCESSDATA"):
        run = read_plant_export(path, text)
    else:
        run = read_csv(path, columns, text)
    check_loop_run(run)
    return run


# ---- plant_loops tab-separated export -------------------------------------------------
_TAG_ROLES = {"MV": "op_pct", "OP": "op_pct", "PV": "pv", "SV": "sp", "SP": "sp", "MODE": "mode"}


def read_plant_export(path: Path, text: str | None = None) -> Run:
    """The refinery historian export of ../shared/data/plant_loops (see module docstring)."""
    text = path.read_text(encoding="utf-8-sig") if text is None else text
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if len(lines) < 6:
        raise LoopDataError(f"{path}: export has {len(lines)} lines, expected 5 header lines and rows")
    title = lines[0].split("\t")
    loop_tag = title[1].strip() if len(title) > 1 else path.stem
    loop_tag = re.sub(r"\s+Data$", "", loop_tag)
    head = lines[1].split("\t")
    try:
        sample_time_s = float(head[1])
        declared_rows = int(head[3])
    except (IndexError, ValueError):
        raise LoopDataError(f"{path}: line 2 should be '<n> <Ts> <start> <rows>', got {lines[1]!r}") from None
    tags = lines[2].split("\t")
    descs = lines[3].split("\t")
    if not tags or tags[0] != "tagname":
        raise LoopDataError(f"{path}: line 3 should list tag names after 'tagname', got {lines[2][:60]!r}")
    roles: dict[str, int] = {}
    descriptions: dict[str, str] = {}
    for i, tag in enumerate(tags[1:], start=1):
        suffix = tag.rsplit(".", 1)[-1].upper() if "." in tag else ""
        role = _TAG_ROLES.get(suffix)
        if role and role not in roles:
            roles[role] = i
            descriptions[role] = descs[i] if i < len(descs) else ""
    missing = [name for name, role in (("MV (OP)", "op_pct"), ("PV", "pv")) if role not in roles]
    if missing:
        raise LoopDataError(f"{path}: no {' or '.join(missing)} column among the tags "
                            f"{', '.join(tags[1:])}")
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    if not rows:
        raise LoopDataError(f"{path}: no data rows after the 5 header lines")
    stamps = [r[0] for r in rows]
    signals: dict[str, np.ndarray] = {}
    for role, col in roles.items():
        signals[role] = np.array([_number(r, col) for r in rows], dtype=float)
    t = _times_from_stamps(stamps, "%Y-%m-%d %H:%M:%S", path)
    notes = []
    if len(rows) != declared_rows:
        notes.append(f"header declares {declared_rows} rows, file has {len(rows)}")
    if t is None:
        t = np.arange(len(rows)) * sample_time_s
    record = LoopRecord(loop_tag=loop_tag, file=str(path), sample_time_s=sample_time_s, start=stamps[0],
                        units={"op_pct": "%", "pv": "as exported", "sp": "as exported"},
                        descriptions=descriptions, notes=notes)
    return _make_run(t, signals, record, path)


def _number(row: list[str], col: int) -> float:
    try:
        return float(row[col])
    except (IndexError, ValueError):
        return math.nan


# ---- CSV --------------------------------------------------------------------------------
_GUESSES = {
    "time": ("time_s", "time", "timestamp", "t", "date", "datetime"),
    "op": ("op_pct", "op", "mv", "co", "output", "controller_output_pct"),
    "pv": ("pv", "process_variable", "measurement"),
    "sp": ("sp", "sv", "setpoint"),
}
_SUFFIXES = {"op": (".op", ".mv", ".out", "_op", "_mv"), "pv": (".pv", "_pv"), "sp": (".sp", ".sv", "_sp", "_sv")}


def guess_columns(header: list[str]) -> ColumnMap | None:
    """A mapping from conventional names, or None when OP or PV cannot be told."""
    low = {h.strip().lower(): h for h in header}
    found: dict[str, str] = {}
    for key, names in _GUESSES.items():
        for n in names:
            if n in low:
                found[key] = low[n]
                break
    for key, suffixes in _SUFFIXES.items():
        if key not in found:
            hits = [h for h in header if h.strip().lower().endswith(suffixes)]
            if len(hits) == 1:
                found[key] = hits[0]
    if "op" not in found or "pv" not in found:
        return None
    tag = None
    if "." in found["pv"]:
        tag = found["pv"].rsplit(".", 1)[0]
    return ColumnMap(op=found["op"], pv=found["pv"], sp=found.get("sp"), time=found.get("time"), loop_tag=tag)


def read_csv(path: Path, columns: ColumnMap | None = None, text: str | None = None) -> Run:
    """A CSV export with a header line; columns from ``columns`` or guessed from names."""
    text = path.read_text(encoding="utf-8-sig") if text is None else text
    sample = text[:4096]
    try:
        dialect = csv.Sniffer().sniff(sample, delimiters=",;\t")
    except csv.Error:
        dialect = csv.excel
    reader = csv.reader(io.StringIO(text), dialect)
    try:
        header = [h.strip() for h in next(reader)]
    except StopIteration:
        raise LoopDataError(f"{path}: empty file") from None
    rows = [r for r in reader if any(c.strip() for c in r)]
    cmap = columns or guess_columns(header)
    if cmap is None:
        raise LoopDataError(f"{path}: cannot tell the OP and PV columns from the header "
                            f"({', '.join(header)}); give --columns op=NAME,pv=NAME[,sp=NAME,time=NAME]")
    index = {h: i for i, h in enumerate(header)}
    wanted = {"op_pct": cmap.op, "pv": cmap.pv}
    if cmap.sp:
        wanted["sp"] = cmap.sp
    absent = [name for name in [*wanted.values(), *([cmap.time] if cmap.time else [])] if name not in index]
    if absent:
        raise LoopDataError(f"{path}: no column {absent[0]!r} in the header ({', '.join(header)})")
    signals = {role: np.array([_number(r, index[name]) for r in rows], dtype=float)
               for role, name in wanted.items()}
    if not rows:
        raise LoopDataError(f"{path}: no data rows after the header")
    notes: list[str] = []
    if cmap.time:
        raw = [r[index[cmap.time]] if index[cmap.time] < len(r) else "" for r in rows]
        t = _times_from_column(raw, cmap.time_format, path)
        dt = float(np.median(np.diff(t))) if len(t) > 1 else float(cmap.sample_time_s or 1.0)
    else:
        if cmap.sample_time_s is None:
            raise LoopDataError(f"{path}: no time column; give time=NAME in the mapping or sample_time_s")
        dt = float(cmap.sample_time_s)
        t = np.arange(len(rows)) * dt
    tag = cmap.loop_tag or path.stem
    record = LoopRecord(loop_tag=tag, file=str(path), sample_time_s=dt,
                        units={"op_pct": "%", "pv": "as exported", "sp": "as exported"},
                        descriptions={"op_pct": cmap.op, "pv": cmap.pv, "sp": cmap.sp or ""}, notes=notes)
    return _make_run(t, signals, record, path)


def _times_from_column(raw: list[str], fmt: str | None, path: Path) -> np.ndarray:
    try:
        return np.array([float(v) for v in raw]) - float(raw[0])
    except ValueError:
        pass
    t = _times_from_stamps(raw, fmt, path)
    if t is None:
        raise LoopDataError(f"{path}: cannot read the time column (first value {raw[0]!r}); give time_format")
    return t


def _times_from_stamps(stamps: list[str], fmt: str | None, path: Path) -> np.ndarray | None:
    """Seconds since the first stamp, or None when the stamps do not parse."""
    out = np.empty(len(stamps))
    t0 = None
    for i, s in enumerate(stamps):
        s = s.strip()
        try:
            d = datetime.strptime(s, fmt) if fmt else datetime.fromisoformat(s)
        except ValueError:
            return None
        t0 = d if t0 is None else t0
        out[i] = (d - t0).total_seconds()
    return out


# ---- common ------------------------------------------------------------------------------
def _make_run(t: np.ndarray, signals: dict[str, np.ndarray], record: LoopRecord, path: Path) -> Run:
    if len(t) > 1:
        dt = np.diff(t)
        if np.any(dt <= 0):
            k = int(np.argmax(dt <= 0))
            raise LoopDataError(f"{path}: time does not increase at row {k + 2} of the data")
        step = float(np.median(dt))
        if np.any(np.abs(dt - step) > 0.01 * step):
            k = int(np.argmax(np.abs(dt - step) > 0.01 * step))
            raise LoopDataError(f"{path}: samples are not evenly spaced (step {dt[k]:g} s after row {k + 1}, "
                                f"usual {step:g} s); resample the export to a fixed interval")
        record.sample_time_s = step
    signals = {"time_s": np.asarray(t, dtype=float), **signals}
    meta = {"loop_tag": record.loop_tag, "file": record.file, "sample_time_s": record.sample_time_s,
            "start": record.start, "units": record.units, "descriptions": record.descriptions,
            "notes": record.notes, "process_type": process_type_for(record.loop_tag)}
    return Run(signals, meta)


def process_type_for(loop_tag: str) -> str:
    """Level loops (tag with LIC/LC) integrate; every other loop is taken as self-regulating."""
    return "integrating" if re.search(r"(^|[^A-Z])LI?C", loop_tag.upper()) else "self_regulating"


def check_loop_run(run: Run) -> None:
    """Reject, with one message, a loop that cannot be diagnosed; fill short gaps in place."""
    where = run.metadata.get("file", "loop")
    n = len(run)
    if n < MIN_SAMPLES:
        raise LoopDataError(f"{where}: too short ({n} samples, need at least {MIN_SAMPLES})")
    for name in ("op_pct", "pv", "sp"):
        if name not in run:
            continue
        x = run.signals[name]
        bad = ~np.isfinite(x)
        if bad.all():
            raise LoopDataError(f"{where}: {_label(name)} has no numeric values")
        longest, start = _longest_run(bad)
        if longest > MAX_FILLED_GAP:
            t = run.time_s
            raise LoopDataError(f"{where}: {_label(name)} is missing for {longest} samples in a row "
                                f"(from t = {t[start]:g} s); cut the file around the gap")
        if bad.any():
            good = np.flatnonzero(~bad)
            x[bad] = np.interp(np.flatnonzero(bad), good, x[good])
            run.metadata.setdefault("notes", []).append(f"filled {int(bad.sum())} missing {name} samples")
    pv = run.signals["pv"]
    if np.ptp(pv) <= CONSTANT_RTOL * max(1.0, float(np.max(np.abs(pv)))):
        raise LoopDataError(f"{where}: PV is constant ({pv[0]:g}); a frozen or disconnected transmitter "
                            "cannot be diagnosed")


def _label(name: str) -> str:
    return {"op_pct": "OP", "pv": "PV", "sp": "SP"}.get(name, name)


def _longest_run(mask: np.ndarray) -> tuple[int, int]:
    """Length and start index of the longest stretch of True."""
    if not mask.any():
        return 0, 0
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(padded)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    k = int(np.argmax(ends - starts))
    return int(ends[k] - starts[k]), int(starts[k])
