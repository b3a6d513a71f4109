"""Historian exports of one control loop -> :class:`phfdi.records.Record`, read by :func:`phfdi.records.read_record`
under the historian policy (see docs/records.md).

Two formats:

* the tab-separated export of ``../shared/data/plant_loops`` (see its
  PROVENANCE.md): CRLF, a title line ``PROCESSDATA <loop> Data <format>``,
  ``<n> <Ts> <start> <rows>``, tag names (``<tag>.MV``, ``.PV``, ``.SV``,
  ``.MODE``, flags), descriptions, the publisher's solver settings, then rows
  of timestamp, MV (= OP), PV, SV (= SP), MODE and four flags;
* CSV (comma, semicolon or tab) with a header line and a column mapping
  (the one :class:`phfdi.records.ColumnMap`, from :func:`parse_loop_columns`): given on the command line, in a small YAML file, or
  guessed from names (``time_s``/``op_pct``/``pv``/``sp`` as phfdi writes
  them, or tags ending in ``.OP``/``.MV``, ``.PV``, ``.SP``/``.SV``).

Every loop becomes a run with the signals ``time_s`` (on the median sample
interval), ``op_pct`` (controller output, % of span), ``pv`` and ``sp`` (in the
units the historian gives, recorded in ``metadata["units"]``). Historian
records are taken as they come: repeated stamps are repaired, a MODE column
(the export's ``.MODE`` tag, or ``mode`` in the mapping) keeps only automatic
stretches, a clock reset or jump or a gap of more than ``MAX_FILLED_GAP``
samples ends a stretch; the longest usable stretch is diagnosed
(:func:`read_loop`) or each of them (:func:`read_loop_segments`). Every repair
is a note in ``metadata["notes"]``. :func:`check_loop_run` rejects, with one
message, what cannot be diagnosed (too short, missing values); a constant PV is read, and diagnosed as
frozen by :mod:`.loopcheck`.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np

from phfdi import records
from phfdi.records.record import Record
from phfdi_base.errors import UserError
from phfdi_base.yamlfile import read_mapping

#: fewer samples than this cannot hold a training and a validation part
MIN_SAMPLES = 100
#: gaps of up to this many missing samples are filled by linear interpolation
MAX_FILLED_GAP = 3
#: a text file with more data rows than this is not read whole: :data:`SAMPLED_WINDOWS` windows of
#: :data:`WINDOW_ROWS` rows spread over it are (time and memory bounded; the diagnosis screens at most that
#: many windows of a long record anyway, phfdi.loopdiag.windows)
MAX_READ_ROWS = 200_000
WINDOW_ROWS = 800
SAMPLED_WINDOWS = 64
#: bytes read at a time when counting a long file's lines
CHUNK_BYTES = 1 << 24


class LoopDataError(UserError):
    """A loop file that cannot be diagnosed; the message names file and problem."""


#: the loop mapping's short keys -> the loop run's signals (``--columns op=FIC1.OP,pv=FIC1.PV,...``)
LOOP_KEYS = {"op": "op_pct", "pv": "pv", "sp": "sp", "time": "time_s"}
#: the mapping's other keys, as phfdi.records.ColumnMap takes them
LOOP_OPTIONS = ("mode", "sample_time_s", "loop_tag", "time_format")


def loop_column_map(op: str, pv: str, sp: str | None = None, time: str | None = None, *,
                    mode: str | None = None, sample_time_s: float | None = None, loop_tag: str | None = None,
                    time_format: str | None = None, source: str = "column mapping") -> records.ColumnMap:
    """The one column map (:class:`phfdi.records.ColumnMap`, signals ``op_pct``, ``pv``, ``sp``, ``time_s``) of
    a loop whose OP, PV, SP and time sit in these columns (None or empty: not given).

    ``time`` None: no time column; ``sample_time_s`` gives the spacing. ``sp`` None: no setpoint column (the
    control error is then PV about its mean)."""
    data: dict = {"op_pct": op, "pv": pv}
    data.update({LOOP_KEYS[k]: v for k, v in (("sp", sp), ("time", time)) if v})
    options = {"mode": mode, "sample_time_s": sample_time_s, "loop_tag": loop_tag, "time_format": time_format}
    data.update({k: v for k, v in options.items() if v not in (None, "")})
    return records.ColumnMap.from_mapping(data, source)


def parse_loop_columns(text: str) -> records.ColumnMap:
    """The loop's column map from ``op=FIC1.OP,pv=FIC1.PV,sp=FIC1.SP,time=Timestamp`` or a YAML file name
    (``columns: {op: ..., pv: ...}`` and, beside it, ``sample_time_s``, ``loop_tag``, ``time_format``, ``mode``)."""
    if text.endswith((".yaml", ".yml")):
        path = Path(text)
        data = read_mapping(path, "column mapping file", "a mapping with 'columns' (op, pv, sp, time)")
        items = dict(data.get("columns") or {})
        items.update({k: data[k] for k in LOOP_OPTIONS if k in data})
        return _from_items(items, str(path))
    pairs: dict[str, str] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        key, sep, value = part.partition("=")
        if not sep or not value:
            raise UserError(f"column mapping {part!r}: expected KEY=COLUMN (keys: op, pv, sp, time)")
        pairs[key.strip()] = value.strip()
    return _from_items(pairs, f"--columns {text!r}")


def _from_items(items: dict, where: str) -> records.ColumnMap:
    allowed = {*LOOP_KEYS, *LOOP_OPTIONS}
    unknown = sorted(set(items) - allowed)
    if unknown:
        raise UserError(f"{where}: unknown key {unknown[0]!r}; allowed: op, pv, sp, time, mode, sample_time_s, "
                        "loop_tag, time_format")
    missing = [k for k in ("op", "pv") if not items.get(k)]
    if missing:
        raise UserError(f"{where}: the mapping needs {' and '.join(missing)} (the columns of OP and PV)")
    st = items.get("sample_time_s")
    return loop_column_map(str(items["op"]), str(items["pv"]), _opt_str(items.get("sp")), _opt_str(items.get("time")),
                           sample_time_s=None if st is None else float(st), loop_tag=_opt_str(items.get("loop_tag")),
                           time_format=_opt_str(items.get("time_format")), mode=_opt_str(items.get("mode")))


def _opt_str(v) -> str | None:
    return None if v is None or v == "" else str(v)


_GUESSES = {
    "time": ("time_s", "time", "timestamp", "t", "date", "datetime"),
    "mode": ("mode",),
    "op": ("op_pct", "op", "mv", "co", "output", "controller_output_pct"),
    "pv": ("pv", "process_variable", "measurement"),
    "sp": ("sp", "sv", "setpoint"),
}
_SUFFIXES = {"op": (".op", ".mv", ".out", "_op", "_mv"), "pv": (".pv", "_pv"), "sp": (".sp", ".sv", "_sp", "_sv"),
             "mode": (".mode", "_mode")}


def guess_columns(header: list[str]) -> records.ColumnMap | None:
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
    return loop_column_map(found["op"], found["pv"], found.get("sp"), found.get("time"), loop_tag=tag,
                           mode=found.get("mode"))


# ---- reading -------------------------------------------------------------------------------
def read_loop(path: str | Path, columns: records.ColumnMap | None = None) -> Record:
    """The longest usable stretch of one loop file (plant_loops export or CSV), checked for diagnosis.

    Raises
    ------
    LoopDataError
        A :class:`~phfdi_base.errors.UserError` naming the file and what makes it unusable.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from phfdi.loopdiag import SyntheticLoop, read_loop, simulate_loop
    >>> run = simulate_loop(SyntheticLoop())
    >>> path = Path(tempfile.mkdtemp()) / "FIC101.csv"
    >>> np.savetxt(path, np.column_stack([run.time_s, run["op_pct"], run["pv"]]), delimiter=",",
    ...            header="time,OP,PV", comments="", fmt="%.4f")
    >>> loop = read_loop(path)
    >>> loop.names, loop.metadata["loop_tag"], len(loop)
    (['op_pct', 'pv'], 'FIC101', 750)
    """
    sampled = sampled_table(Path(path))
    runs, why, pieces, cuts = _stretches(Path(path), columns, sampled)
    if not runs:
        raise LoopDataError(why)
    if sampled is not None:
        run = _windows_run(runs, sampled.metadata["sampled"])
        check_loop_run(run)
        return run
    run = max(runs, key=len)
    if pieces > 1:
        a, b = run.metadata["lines"]
        cut = f"; cut where {cuts[0]}" + (f" and {len(cuts) - 1} more" if len(cuts) > 1 else "") if cuts else ""
        run.metadata["notes"].append(f"{pieces} stretches ({len(runs)} of at least {MIN_SAMPLES} samples){cut}; "
                                     f"the longest, lines {a}-{b} ({len(run)} samples), is diagnosed")
    check_loop_run(run)
    return run


def read_loop_segments(path: str | Path, columns: records.ColumnMap | None = None) -> list[Record]:
    """Every usable stretch of one loop file (at least ``MIN_SAMPLES``), not yet checked."""
    runs, why, _, _ = _stretches(Path(path), columns, sampled_table(Path(path)))
    if not runs:
        raise LoopDataError(why)
    return runs


def _stretches(path: Path, columns: records.ColumnMap | None, table=None) -> tuple[list[Record], str, int, list[str]]:
    """Runs of the stretches with at least MIN_SAMPLES samples, why there is none when so, how many
    stretches there are in all and the gaps that cut them (``table``: the rows already read, for a sampled
    long file)."""
    def mapping(header, meta):
        return _mapping(path, columns, header, meta)

    try:
        if table is None:
            rec = records.read_record(path, mapping, policy="historian", min_samples=1)
        else:
            rec = records.record_from_table(path, table, mapping, policy="historian", min_samples=1)
    except records.ReadError as exc:
        raise LoopDataError(str(exc)) from None
    pieces, cuts = [], []
    for seg in rec.segments(automatic_only=True):
        grid = seg.on_grid()
        found, cut = _split_at_gaps(grid)
        pieces += found
        cuts += cut
    runs = [_loop_run(p, rec) for p in pieces if len(p) >= MIN_SAMPLES]
    longest = max((len(p) for p in pieces), default=0)
    why = f"{path}: too short ({longest} samples, need at least {MIN_SAMPLES})"
    if cuts or len(pieces) > 1 or rec.boundaries or rec.automatic is not None and not rec.automatic.all():
        why = (f"{path}: no usable stretch of {MIN_SAMPLES} samples (longest {longest})"
               + (f": {cuts[0]}" if cuts else "; the record breaks at manual mode or time jumps (see notes)"))
    return runs, why, len(pieces), cuts


def _mapping(path: Path, columns: records.ColumnMap | None, header: list[str], meta: dict) -> records.ColumnMap:
    """The given mapping, else one guessed from the header (the export's tags, or conventional names)."""
    cmap = columns or guess_columns([h for h in header if h != "timestamp"] if "declared_rows" in meta else header)
    if cmap is None:
        raise LoopDataError(f"{path}: cannot tell the OP and PV columns from the header "
                            f"({', '.join(header)}); give --columns op=NAME,pv=NAME[,sp=NAME,time=NAME]")
    missing = [s for s in ("op_pct", "pv") if s not in cmap.signals]
    if missing:
        raise LoopDataError(f"{path}: {cmap.source} maps no {' and no '.join(missing)} (the columns of OP and PV)")
    if "declared_rows" in meta:  # the plant_loops export: stamps in the first column, the loop's tag in the title
        data = cmap.to_mapping()
        data.setdefault("time_s", "timestamp")
        data.pop("loop_tag", None)
        if columns is not None and columns.loop_tag:
            data["loop_tag"] = columns.loop_tag
        cmap = records.ColumnMap.from_mapping(data, cmap.source)
    if cmap.time is None and cmap.sample_time_s is None:
        raise LoopDataError(f"{path}: no time column; give time=NAME in the mapping or sample_time_s")
    return cmap


def _split_at_gaps(grid: records.Record) -> tuple[list[records.Record], list[str]]:
    """Pieces without a gap of more than MAX_FILLED_GAP samples in OP or PV, and what cut them."""
    bad = np.isnan(grid.signals["op_pct"]) | np.isnan(grid.signals["pv"])
    d = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    long = (stops - starts) > MAX_FILLED_GAP
    edges = [0, *[x for a, b in zip(starts[long], stops[long]) for x in (a, b)], len(grid)]
    pieces = [grid.subset(slice(a, b)) for a, b in zip(edges[0::2], edges[1::2]) if b > a]
    cuts = [f"OP or PV is missing for {b - a} samples in a row (from t = {grid.time_s[a]:g} s)"
            for a, b in zip(starts[long], stops[long])]
    return pieces, cuts


def _loop_run(piece: records.Record, rec: records.Record) -> Record:
    """A loop run of one stretch: time from the file's first sample, units and notes in the metadata."""
    meta = rec.metadata
    tag = meta.get("loop_tag") or Path(rec.path).stem
    tag = re.sub(r"\s+Data$", "", tag)
    descriptions = meta.get("descriptions") or {}
    run = Record.of({"time_s": piece.time_s.copy(), **{k: v.copy() for k, v in piece.signals.items()}},
              {"loop_tag": tag, "file": rec.path, "sample_time_s": piece.dt_s,
               "units": {"op_pct": "%", "pv": "as exported", "sp": "as exported"},
               "descriptions": {k: descriptions.get(c, c) for k, c in piece.columns.items()},
               "notes": [n.removeprefix(f"{rec.path}: ") for n in piece.note_lines()],
               "lines": [int(piece.lines[piece.lines > 0][0]), int(piece.lines.max())],
               "process_type": process_type_for(tag)})
    return run


# ---- long files ------------------------------------------------------------------------------------
def count_lines(path: Path) -> int:
    """Lines of a file (its newlines, and a last line without one), read in chunks: memory bounded."""
    n, last = 0, b"\n"
    with open(path, "rb") as fh:
        while chunk := fh.read(CHUNK_BYTES):
            n += chunk.count(b"\n")
            last = chunk[-1:]
    return n + (last != b"\n")


def sampled_table(path: Path):
    """The raw table of :data:`SAMPLED_WINDOWS` windows of :data:`WINDOW_ROWS` rows spread evenly over a text
    file with more than :data:`MAX_READ_ROWS` data rows (their line numbers the file's), or None for any other
    file. ``metadata["sampled"]`` says what was read. One pass to count the lines, one to pick the windows'."""
    from phfdi.records.formats import format_of

    try:
        if not path.is_file() or path.stat().st_size < MAX_READ_ROWS * 8:  # no row is shorter than 8 bytes
            return None
        fmt = format_of(path)
        with open(path, "rb") as fh:
            head = fh.read(64)
    except (OSError, UserError):
        return None
    if fmt.name not in ("csv", "text"):
        return None
    header_lines = 5 if head.lstrip(b"\xef\xbb\xbf").startswith(b"PROCESSDATA") else 1
    total = count_lines(path)
    rows = total - header_lines
    if rows <= MAX_READ_ROWS:
        return None
    print(f"loop-diagnose: {path}: {rows} rows, more than {MAX_READ_ROWS}: reading {SAMPLED_WINDOWS} windows of "
          f"{WINDOW_ROWS} rows spread over it", file=sys.stderr, flush=True)  # progress: the reading takes seconds
    starts = np.linspace(header_lines, total - WINDOW_ROWS, SAMPLED_WINDOWS).round().astype(int)
    data, lines = _pick_lines(path, header_lines, starts)
    table = fmt.read(path, data, None)
    table.lines = np.asarray(lines, dtype=np.int64)[np.asarray(table.lines, dtype=np.int64) - 1]
    table.notes = [n for n in table.notes if "the header declares" not in n]
    table.metadata["sampled"] = {"rows": rows, "windows": SAMPLED_WINDOWS, "window_rows": WINDOW_ROWS}
    return table


def _pick_lines(path: Path, header_lines: int, starts: np.ndarray) -> tuple[bytes, list[int]]:
    """The header lines and WINDOW_ROWS lines from each start (0-based line indices), and the file's line number
    (1-based) of every line kept."""
    want = np.zeros(0, dtype=np.int64)
    if len(starts):
        want = np.unique((starts[:, None] + np.arange(WINDOW_ROWS)[None, :]).ravel())
    keep = set(range(header_lines)) | set(want.tolist())
    out, numbers = [], []
    with open(path, "rb") as fh:
        for i, line in enumerate(fh):
            if i in keep:
                out.append(line if line.endswith(b"\n") else line + b"\n")
                numbers.append(i + 1)
    return b"".join(out), numbers


def _windows_run(runs: list[Record], sampled: dict) -> Record:
    """The stretches read from a sampled file as one run, each a window (``metadata["windows"]``: start, stop
    and source lines), with a note saying what was read."""
    runs = sorted(runs, key=lambda r: r.metadata["lines"][0])
    names = [n for n in runs[0].names if all(n in r for r in runs)]
    signals = {n: np.concatenate([r[n] for r in runs]) for n in ["time_s", *names]}
    windows, at = [], 0
    for r in runs:
        windows.append((at, at + len(r), *r.metadata["lines"]))
        at += len(r)
    meta = dict(runs[0].metadata)
    read = sum(len(r) for r in runs)
    meta["notes"] = [f"the file holds {sampled['rows']} rows, more than {MAX_READ_ROWS} (read whole they would take "
                     f"minutes and gigabytes): {sampled['windows']} windows of {sampled['window_rows']} rows spread "
                     f"over it were read ({read} samples in {len(runs)} usable stretches)"]
    # the windows' own reading notes, less the breaks the sampling itself made (time jumps between windows)
    own = {n for r in runs for n in r.metadata.get("notes", [])
           if not any(w in n for w in ("stretches", "time jump", "segment lines"))}
    meta["notes"] += sorted(own)[:10]
    meta["windows"] = windows
    meta["file_rows"] = sampled["rows"]
    meta["lines"] = [windows[0][2], windows[-1][3]]
    return Record.of(signals, meta)


def process_type_for(loop_tag: str) -> str:
    """Level loops (tag with LIC/LC) integrate; every other loop is taken as self-regulating."""
    return "integrating" if re.search(r"(^|[^A-Z])LI?C", loop_tag.upper()) else "self_regulating"


def check_loop_run(run: Record) -> None:
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
            run.metadata.setdefault("notes", []).append(f"filled {int(bad.sum())} missing {name} samples "
                                                         f"(gaps of up to {MAX_FILLED_GAP}) by linear interpolation")
    # a constant PV is no reading error: it is diagnosed (PV frozen under a moving OP, or not a loop at all;
    # phfdi.loopdiag.loopcheck)


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
