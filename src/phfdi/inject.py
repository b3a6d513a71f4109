"""Faults hidden in measured records: a probe or pump fault written into a CSV's own columns, with its truth.

:func:`inject_fault` reads a measured CSV (checked by :func:`phfdi.records.read_record` under a column map),
changes only the cells the fault changes from its onset on (the rest of the file, header, other columns, row
order, line endings and number formats, stays byte for byte) and returns the new file's bytes and the fault's
truth (a dict for scoring; a detector never needs it). :func:`write_injected` writes both atomically.

Sensor faults change the pH column (rounded to :data:`PH_RESOLUTION`, clipped to 0..14). Pump faults are
model free: the measured pH is what the pumps really delivered, so a pump fault is written into the
*recorded* command and flow columns of that pump (kept proportional). See docs/injection.md.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.faults import Fault
from phfdi_base.outputs import write_together

from .inject_kinds import KINDS, PH_CAL_POINT, PH_MAX, PH_MIN, PH_RESOLUTION, PUMPS, TRUTH_FORMAT

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


# ---- the CSV as text ------------------------------------------------------------------------
@dataclass
class CsvText:
    """A CSV kept as its lines (with their endings) plus the parsed cells of its data rows.

    ``line_of[k]`` is the index in ``lines`` of data row ``k``; ``cells[column][k]`` its cell as the reader
    parses it. Only :meth:`to_bytes` with changes alters anything, and only inside the changed cells.
    """

    path: str
    lines: list[str]
    header: list[str]
    cells: dict[str, list[str]]
    line_of: list[int]
    delimiter: str
    encoding: str
    sha256: str
    notes: list[str] = field(default_factory=list)

    def numbers(self, column: str) -> np.ndarray:
        from phfdi.records.cells import to_numbers

        return to_numbers(self.cells[column]).values

    def to_bytes(self, changes: dict[tuple[int, str], str]) -> bytes:
        """The file with cell (row, column) -> new number text; all else as it was."""
        lines = list(self.lines)
        by_row: dict[int, dict[int, str]] = {}
        for (k, column), text in changes.items():
            by_row.setdefault(k, {})[self.header.index(column)] = text
        for k, cols in by_row.items():
            lines[self.line_of[k]] = _put_cells(lines[self.line_of[k]], self.delimiter, cols)
        return "".join(lines).encode(self.encoding)


def read_csv_text(path: str | Path, encoding: str | None = None) -> CsvText:
    """A CSV as :class:`CsvText`, parsed by the records reader's own text layer (encoding, delimiter)."""
    from phfdi.records.errors import ReadError
    from phfdi.records.text import decode, parse_csv

    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ReadError(path, f"cannot read the file ({exc.strerror})") from None
    text, used, _ = decode(data, path, encoding)
    table = parse_csv(data, path, encoding)
    if any("decimal commas" in n or "runs over" in n for n in table.notes):
        raise UserError(f"{path}: inject writes plain CSV rows only (no decimal commas, no cell over several lines)")
    lines = io.StringIO(text, newline="").readlines()
    cells = {name: [r[i] if i < len(r) else "" for r in table.rows] for i, name in enumerate(table.header) if name}
    return CsvText(str(path), lines, table.header, cells, [n - 1 for n in table.lines], table.delimiter,
                   used, hashlib.sha256(data).hexdigest())


def _field_spans(body: str, delimiter: str) -> list[tuple[int, int]]:
    spans, start, quoted = [], 0, False
    for i, ch in enumerate(body):
        if ch == '"':
            quoted = not quoted
        elif ch == delimiter and not quoted:
            spans.append((start, i))
            start = i + 1
    spans.append((start, len(body)))
    return spans


def _put_cells(line: str, delimiter: str, new: dict[int, str]) -> str:
    """The line with the number inside each given field replaced (spaces, quotes and line ending kept)."""
    body = line.rstrip("\r\n")
    ending = line[len(body):]
    spans = _field_spans(body, delimiter)
    for i in sorted(new, reverse=True):
        start, end = spans[i]
        raw = body[start:end]
        m = _NUMBER.search(raw)
        assert m is not None, f"no number in cell {raw!r}"  # only cells holding numbers are changed
        body = body[:start] + raw[:m.start()] + new[i] + raw[m.end():] + body[end:]
    return body + ending


def _decimals(cell: str) -> int:
    m = _NUMBER.search(cell)
    text = m.group(0) if m else ""
    return len(text.split(".")[1].split("e")[0].split("E")[0]) if "." in text else 0


def _changed_cells(csv: CsvText, column: str, rows: np.ndarray, values: np.ndarray,
                   decimals: int | None = None) -> dict[tuple[int, str], str]:
    """Cell texts for ``values`` at ``rows`` (formatted with the cell's own decimals), those that differ."""
    out = {}
    for k, v in zip(rows.tolist(), values.tolist()):
        old = csv.cells[column][k]
        if not math.isfinite(v) or not _NUMBER.search(old):
            continue  # a missing cell stays missing
        text = f"{v + 0.0:.{_decimals(old) if decimals is None else decimals}f}"
        if float(text) != float(_NUMBER.search(old).group(0)):  # type: ignore[union-attr]
            out[(k, column)] = text
    return out


# ---- sensor faults --------------------------------------------------------------------------
def _filled(x: np.ndarray) -> np.ndarray:
    """Missing values replaced by the last one before (the first valid one at the start)."""
    ok = np.isfinite(x)
    if not ok.any():
        return x
    idx = np.where(ok, np.arange(len(x)), 0)
    np.maximum.accumulate(idx, out=idx)
    out = x[idx]
    out[: int(np.argmax(ok))] = x[int(np.argmax(ok))]
    return out


def _lag(ph: np.ndarray, t_s: np.ndarray, tau_s: float, seed: int) -> np.ndarray:  # noqa: ARG001
    """First-order lag started at the onset's value; exact (zero-order hold) at the mean interval, lfilter."""
    from scipy.signal import lfilter

    x = _filled(ph)
    dt_s = float(np.nanmean(np.diff(t_s))) if len(t_s) > 1 else 0.0
    a = math.exp(-dt_s / tau_s)
    y, _ = lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    return np.asarray(y)


SENSOR: dict[str, Callable[[np.ndarray, np.ndarray, float, int], np.ndarray]] = {
    "probe_bias": lambda ph, t, size, seed: ph + size,
    "probe_drift": lambda ph, t, size, seed: ph + size * t / 60.0,
    "probe_frozen": lambda ph, t, size, seed: np.full_like(ph, _filled(ph)[0]),
    "probe_noise": lambda ph, t, size, seed: ph + np.random.default_rng(seed).normal(0.0, size, len(ph)),
    "probe_lag": _lag,
    "probe_gain": lambda ph, t, size, seed: PH_CAL_POINT + (1.0 + size) * (ph - PH_CAL_POINT),
}


def _sensor_changes(csv: CsvText, cmap, kind: str, k0: int, time_s: np.ndarray, onset_s: float, size: float,
                    seed: int) -> tuple[dict, list[str]]:
    column = _mapped(cmap, "ph_measured")
    ph = csv.numbers(column)[k0:]
    faulty = SENSOR[kind](ph, time_s[k0:] - onset_s, size, seed)  # time since the onset (s)
    faulty = np.clip(np.round(faulty / PH_RESOLUTION) * PH_RESOLUTION, PH_MIN, PH_MAX)
    return _changed_cells(csv, column, np.arange(k0, len(time_s)), faulty, decimals=2), [column]


# ---- pump faults ----------------------------------------------------------------------------
def command_column(header: list[str], pump: str) -> str | None:
    """The pump's command column (%): a header naming '%' and the pump (e.g. "%, Acid"), or None."""
    found = [c for c in header if "%" in c and pump.lower() in c.lower()]
    return found[0] if found else None


def _flow_per_pct(flow: np.ndarray, cmd: np.ndarray, pump: str, path: str) -> float:
    runs = (cmd > 0) & (flow > 0)
    if not runs.any():
        raise UserError(f"pump_stuck on the {pump} pump: {path} never runs that pump, so its flow per % (to "
                        f"write the command) is unknown")
    return float(np.median(flow[runs] / cmd[runs]))


def _pump_changes(csv: CsvText, cmap, kind: str, pump: str | None, k0: int, onset_s: float,
                  size: float) -> tuple[dict, list[str]]:
    if pump not in PUMPS:
        raise UserError(f"{kind} needs --pump acid or --pump base")
    flow_col = _mapped(cmap, f"{pump}_flow_ml_s")
    unit = cmap.signals[f"{pump}_flow_ml_s"].factor  # file unit -> mL/s
    cmd_col = command_column(csv.header, pump)
    flow = csv.numbers(flow_col) * unit
    rows = np.arange(len(flow)) >= k0
    if kind == "pump_stuck":
        rows &= flow == 0
        if not rows.any():
            raise UserError(f"pump_stuck would change nothing: the {pump} pump runs in every row from the onset at "
                            f"{onset_s:g} s (a stuck pump is injected only where the record's pump is off)")
        new_flow = np.full(len(flow), size)
        per_pct = _flow_per_pct(flow, csv.numbers(cmd_col) * 1.0, pump, csv.path) if cmd_col else 1.0
        new_cmd = new_flow / per_pct
    else:
        rows &= flow > 0
        if not rows.any():
            raise UserError(f"{kind} would change nothing: the {pump} pump is off in every row from the onset at "
                            f"{onset_s:g} s (a model-free pump fault changes only a running pump's record)")
        factor = 1.0 / (1.0 - size) if kind == "pump_low" else 1.0 / (1.0 + size)
        new_flow = flow * factor
        new_cmd = csv.numbers(cmd_col) * factor if cmd_col else new_flow
    at = np.flatnonzero(rows)
    changes = _changed_cells(csv, flow_col, at, new_flow[at] / unit)
    if cmd_col:
        changes.update(_changed_cells(csv, cmd_col, at, new_cmd[at]))
        if (new_cmd[at] > 100.0).any():
            csv.notes.append(f"the recorded {cmd_col!r} exceeds 100 % in {int((new_cmd[at] > 100.0).sum())} rows "
                             f"(a real record could not show that)")
    return changes, [cmd_col, flow_col] if cmd_col else [flow_col]


# ---- the fault ------------------------------------------------------------------------------
def _mapped(cmap, signal: str) -> str:
    if signal not in cmap.signals:
        why = "the onset is in the record's time" if signal == "time_s" else "needed by this fault"
        raise UserError(f"the column map names no column for {signal!r} ({why})")
    return cmap.signals[signal].column


def _check_size(spec: Fault, size: float | None) -> float:
    """The size, if it is in the kind's range (its catalogue entry's injection form); one line naming the range."""
    form = spec.inject
    if form.sizes is None:
        return 0.0
    if size is None or not math.isfinite(size):
        raise UserError(f"{spec.name} needs a finite --size, {form.sizes.says(form.unit)}")
    if size not in form.sizes:
        raise UserError(f"--size {size:g}: {spec.name} takes a size {form.sizes.says(form.unit)}")
    return float(size)


#: how far an onset may lie outside the record's first or last stamp and still be taken as that stamp, relative to
#: the larger stamp (and never less than this many seconds): float noise, as the rig's 1.25200000000041 s shown 1.252
ONSET_TOLERANCE = 1e-9


def _onset_row(time_s: np.ndarray, onset_s: float, column: str) -> int:
    """The first row at or after the onset; an onset outside the record is refused naming its exact range."""
    lo, hi = float(np.nanmin(time_s)), float(np.nanmax(time_s))
    slack = ONSET_TOLERANCE * max(1.0, abs(lo), abs(hi))
    if not (math.isfinite(onset_s) and lo - slack <= onset_s <= hi + slack):
        raise UserError(f"--onset {onset_s!r} s is outside the record: its time ({column!r}) runs from {lo!r} to "
                        f"{hi!r} s")
    return int(np.flatnonzero(time_s >= min(onset_s, hi))[0])


def inject_fault(path: str | Path, kind: str, onset_s: float, size: float | None = None, *,
                 pump: str | None = None, seed: int = 0, column_map="ph_rig") -> tuple[bytes, dict]:
    """The CSV at ``path`` with a fault from ``onset_s`` (record time, s) on, and the fault's truth.

    ``kind``: one of :data:`KINDS` (``size`` in its unit; ``pump`` for the pump faults); ``column_map``: a
    :class:`~phfdi.records.ColumnMap`, a YAML file or a shipped map name. Raises
    :class:`~phfdi_base.errors.UserError` for a fault that would change nothing or an onset outside the record.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.inject import inject_fault
    >>> path = Path(tempfile.mkdtemp()) / "rig.csv"
    >>> _ = path.write_text("t,pH,Acid Flow\\n0,7.00,1.00\\n1,7.10,1.00\\n2,7.20,1.00\\n")
    >>> cmap = {"time_s": "t", "ph_measured": "pH", "acid_flow_ml_s": "Acid Flow"}
    >>> data, truth = inject_fault(path, "probe_bias", 1.0, 0.5, column_map=cmap)
    >>> print(data.decode(), end="")
    t,pH,Acid Flow
    0,7.00,1.00
    1,7.60,1.00
    2,7.70,1.00
    >>> truth["onset_index"], truth["size"], truth["unit"], truth["channels"]
    (1, 0.5, 'pH', ['pH'])
    """
    from phfdi.records import read_record

    if kind not in KINDS:
        raise UserError(f"unknown fault {kind!r}; one of {', '.join(KINDS)}")
    spec = KINDS[kind]
    cmap = _column_map(column_map)
    record = read_record(path, cmap)
    csv = read_csv_text(path)
    time_col = _mapped(cmap, "time_s")
    time_s = _times(csv, cmap)
    k0 = _onset_row(time_s, onset_s, time_col)
    size = _check_size(spec, size)
    if spec.family == "sensor":
        changes, channels = _sensor_changes(csv, cmap, kind, k0, time_s, onset_s, size, seed)
    else:
        changes, channels = _pump_changes(csv, cmap, kind, pump, k0, onset_s, size)
    if not changes:
        raise UserError(f"{kind} of size {size:g} {spec.inject.unit} from {onset_s:g} s would change no cell of {path} "
                        f"(at the file's resolution); nothing written")
    truth = _truth(csv, spec, channels, onset_s, k0, size, pump, seed, changes)
    last_s = float(record.time_s[-1])  # an onset a rounding past the last stamp is that stamp (_onset_row)
    truth["onset_index"] = int(np.searchsorted(record.time_s, min(onset_s, last_s), side="left"))
    data = csv.to_bytes(changes)
    truth["output_sha256"] = hashlib.sha256(data).hexdigest()  # the file this truth belongs to (read_truth)
    return data, truth


def _times(csv: CsvText, cmap) -> np.ndarray:
    """Each row's record time (s), read as the records reader reads it (seconds, or date-times from the first)."""
    from phfdi.records.cells import parse_stamps

    time_s, fmt = parse_stamps(csv.cells[cmap.signals["time_s"].column], cmap.time_format)
    return time_s * cmap.signals["time_s"].factor if fmt is None else time_s


def _column_map(given):
    from phfdi.records import ColumnMap

    if isinstance(given, ColumnMap):
        return given
    if isinstance(given, dict):
        return ColumnMap.from_mapping(given)
    if isinstance(given, str) and not given.endswith((".yaml", ".yml")):
        from importlib import resources

        shipped = Path(str(resources.files("phfdi.diagnosis"))) / "maps" / f"{given}.yaml"
        if not shipped.exists():
            raise UserError(f"--map {given!r}: not a .yaml file nor a shipped map (ph_rig)")
        given = shipped
    return ColumnMap.load(given)


def _truth(csv: CsvText, spec: Fault, channels: list[str], onset_s: float, k0: int, size: float,
           pump: str | None, seed: int, changes: dict) -> dict:
    rows = sorted({k for k, _ in changes})
    where = f"the {pump} pump's recorded {' and '.join(repr(c) for c in channels)}" if pump and \
        spec.family == "actuator" else " and ".join(repr(c) for c in channels)
    amount = "" if spec.name == "probe_frozen" else f" of {size:g} {spec.inject.unit}"
    truth = {
        "format": TRUTH_FORMAT, "kind": spec.name, "family": spec.family, "channels": channels,
        "pump": pump if spec.family == "actuator" else None,
        "onset_s": float(onset_s), "onset_index": None, "onset_line": csv.line_of[k0] + 1,
        "size": size, "unit": spec.inject.unit, "seed": seed,
        "rows_changed": len(rows), "first_changed_line": csv.line_of[rows[0]] + 1,
        "source": csv.path, "source_sha256": csv.sha256,
        "description": f"{spec.name}{amount} in {where} from {onset_s:g} s (record time): "
                       f"{spec.inject.what.replace('SIZE', f'{size:g}')}",
        "notes": list(csv.notes),
    }
    if spec.name == "probe_lag":
        truth["discretisation"] = "exact (zero-order hold) at the mean sample interval after the onset, lfilter"
    if spec.family == "sensor":
        truth["resolution"] = {"value": PH_RESOLUTION, "unit": "pH", "clipped_to": [PH_MIN, PH_MAX]}
    return truth


# ---- writing --------------------------------------------------------------------------------
def sidecar_path(out: str | Path) -> Path:
    """Where the truth of ``out`` is written: ``OUT.fault.json`` beside it."""
    out = Path(out)
    return out.with_name(out.name + ".fault.json")


def write_injected(out: str | Path, data: bytes, truth: dict, overwrite: bool = False) -> tuple[Path, Path]:
    """Write the faulty CSV and its truth (``OUT.fault.json``) as one unit (:func:`phfdi_base.outputs.write_together`,
    the one way every command writes); an OSError becomes one UserError naming the file.

    The truth carries ``output_sha256``, the hash of the CSV it belongs to (:func:`read_truth` checks it). Without
    ``overwrite`` an existing file refuses both, and two commands writing the same new pair at once cannot both
    succeed (each file is created exclusively; the truth goes first, and is removed again if its CSV cannot
    follow, so a faulty file never stands without its truth). With ``overwrite`` the pair is placed under its
    folder's lock, so two such commands at once leave one run's pair, never a CSV of one with the truth of the
    other. The folder is made; a failure leaves no staged file.
    """
    out = Path(out)
    side = sidecar_path(out)
    if str(out.resolve()) == str(Path(truth["source"]).resolve()):
        raise UserError(f"--out {out} is the input file; write the faulty copy elsewhere")
    truth = {**truth, "output_sha256": hashlib.sha256(data).hexdigest()}
    write_together([(side, (json.dumps(truth, indent=2) + "\n").encode("utf-8")), (out, data)], overwrite)
    return out, side


def read_truth(out: str | Path) -> dict:
    """The truth of the faulty file ``out`` (its ``OUT.fault.json``), checked against the file: a
    :class:`~phfdi_base.errors.UserError` if the truth is missing or belongs to another version of the file.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "rig.csv").write_text("t,pH\\n0,7.00\\n1,7.10\\n2,7.20\\n")
    >>> cmap = {"time_s": "t", "ph_measured": "pH"}
    >>> data, truth = inject_fault(folder / "rig.csv", "probe_bias", 1.0, 0.5, column_map=cmap)
    >>> out, _ = write_injected(folder / "faulty.csv", data, truth)
    >>> read_truth(out)["kind"]
    'probe_bias'
    >>> _ = out.write_text("t,pH\\n0,7.00\\n1,7.10\\n2,7.20\\n")
    >>> try:
    ...     read_truth(out)
    ... except UserError as exc:
    ...     print(str(exc).split(": ", 1)[1])
    its truth faulty.csv.fault.json belongs to another version of the file (sha256 differs): inject it again
    """
    out = Path(out)
    side = sidecar_path(out)
    try:
        truth = json.loads(side.read_text(encoding="utf-8"))
        data = out.read_bytes()
    except FileNotFoundError as exc:
        raise UserError(f"{out}: no {Path(exc.filename).name}; write both with phfdi inject") from None
    except (OSError, ValueError) as exc:
        raise UserError(f"{side}: not a readable truth ({exc})") from None
    want = truth.get("output_sha256") if isinstance(truth, dict) else None
    if want is not None and want != hashlib.sha256(data).hexdigest():
        raise UserError(f"{out}: its truth {side.name} belongs to another version of the file (sha256 differs): "
                        f"inject it again")
    return truth
