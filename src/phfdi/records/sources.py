"""File formats -> a raw :class:`Table` of columns (cells as found), with the source line of each row.

CSV/TSV text (any delimiter, see :mod:`.text`), the plant_loops historian export (``PROCESSDATA``
title line), Parquet (pyarrow) and MCAP bags of the node graph (:func:`phfdi.bagread.load_bag`).
Damaged files give a :class:`ReadError`, never the parser's own exception.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.signals import unit_of

from .errors import ReadError, regular_file
from .formats import Format, Table, format_of, register_format
from .text import TextTable, decode, parse_csv

PARQUET_MAGIC = b"PAR1"
MCAP_MAGIC = b"\x89MCAP"


def read_table(path: Path, encoding: str | None = None) -> Table:
    """The raw table of any registered format (:mod:`.formats`): by extension and then by its first bytes."""
    if path.is_dir():
        fmt = format_of(path)
        if fmt.folder_marker and (path / fmt.folder_marker).exists():
            return fmt.read(path, None, encoding)
        raise ReadError(path, "a folder, not a record file (CSV, Parquet or MCAP)")
    regular_file(path)  # a FIFO, a device or a link loop: one line, never a hang
    try:
        head = refuse_nul_filled(path)  # before the file is read whole: a sparse 2 GB file cost 15 GB
        fmt = format_of(path, head)
        data = None if fmt.name == "bag" else path.read_bytes()  # a bag is read from its file, by its index
    except OSError as exc:
        raise ReadError(path, f"cannot read the file ({exc.strerror})") from None
    return fmt.read(path, data, encoding)


#: the NUL sample taken before a file is read: blocks of this many bytes, this many of them spread over the file
NUL_BLOCK_BYTES = 4096
NUL_SAMPLES = 32


def refuse_nul_filled(path: Path) -> bytes:
    """The file's first bytes; a :class:`ReadError` when its start, or most of it, is NUL bytes.

    NUL is valid UTF-8 and a CSV line may be any length, so a sparse file (``truncate -s 2G``) or a zero-filled
    preallocation was decoded whole and cost several times its size in memory before the csv module refused it.
    A record is never mostly NUL: text has none (UTF-16 has one every other byte, never a whole block), and an
    MCAP or Parquet file (told by its first bytes, and not checked) has headers and lengths in every few hundred
    bytes. So: the first block all NUL, or more than half of :data:`NUL_SAMPLES` blocks spread over the file all
    NUL, is refused after reading at most NUL_SAMPLES x NUL_BLOCK_BYTES bytes. A short NUL tail (a logger that
    died mid-write) is left to the reader, which marks that line and says so.
    """
    with open(path, "rb") as fh:
        head = fh.read(NUL_BLOCK_BYTES)
        if head.startswith((PARQUET_MAGIC, MCAP_MAGIC)):
            return head
        size = os.fstat(fh.fileno()).st_size
        what = f"a sparse or zero-filled file ({_size_text(size)}), not a record (CSV, Parquet or MCAP)"
        if head and head.count(0) == len(head):
            raise ReadError(path, f"its first {len(head)} bytes are all NUL: {what}")
        last = max(size - NUL_BLOCK_BYTES, 0)
        offsets = sorted({last * k // (NUL_SAMPLES - 1) for k in range(NUL_SAMPLES)})
        empty = 0
        for offset in offsets:
            fh.seek(offset)
            block = fh.read(NUL_BLOCK_BYTES)
            empty += bool(block) and block.count(0) == len(block)
        if empty > len(offsets) // 2:
            raise ReadError(path, f"{empty} of {len(offsets)} blocks sampled across it are all NUL bytes: {what}")
    return head


def _size_text(size: int) -> str:
    """'2.0 GiB', '512 kiB', '900 bytes'."""
    for unit, shift in (("GiB", 30), ("MiB", 20), ("kiB", 10)):
        if size >= 1 << shift:
            return f"{size / (1 << shift):.1f} {unit}"
    return f"{size} bytes"


# ---- text ---------------------------------------------------------------------------------
def read_text(path: Path, data: bytes | None, encoding: str | None = None) -> Table:
    """A CSV (or the plant_loops export, detected by its title line)."""
    data = path.read_bytes() if data is None else data
    if not data.strip():
        raise ReadError(path, "empty file", line=1)
    head = data[:16].lstrip(b"\xef\xbb\xbf")
    if head.startswith(b"PROCESSDATA"):
        return read_processdata(path, data, encoding)
    table = parse_csv(data, path, encoding)
    return _text_columns(path, table, table.header)


def _text_columns(path: Path, table: TextTable, header: list[str], metadata: dict | None = None) -> Table:
    columns: dict[str, list | np.ndarray] = {}
    notes = list(table.notes)
    for i, name in enumerate(header):
        if not name:
            continue  # trailing empty columns (",,,," at the end of every line)
        if name in columns:
            notes.append(f"{path}: line 1: column {name!r} appears twice; the first is read")
            continue
        columns[name] = [r[i] if i < len(r) else "" for r in table.rows]
    if not columns:
        raise ReadError(path, "the header names no column", line=1)
    if not table.rows:
        raise ReadError(path, "no data rows after the header", line=2)
    meta = {"encoding": table.encoding, "delimiter": table.delimiter, **(metadata or {})}
    return Table(str(path), columns, np.asarray(table.lines, dtype=np.int64), "line", meta, {}, notes)


def read_processdata(path: Path, data: bytes, encoding: str | None = None) -> Table:
    """The refinery historian export of ../shared/data/plant_loops (see its PROVENANCE.md)."""
    text, used, notes = decode(data, path, encoding)
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    if len(lines) < 6:
        raise ReadError(path, "export ends before its data: expected 5 header lines, then rows", line=len(lines))
    title, head, tags, descs = (ln.split("\t") for ln in lines[:4])
    try:
        sample_time_s, declared = float(head[1]), int(head[3])
    except (IndexError, ValueError):
        raise ReadError(path, f"expected '<n> <Ts> <start> <rows>', got {lines[1][:60]!r}", line=2) from None
    if tags[0].strip() != "tagname":
        raise ReadError(path, f"expected tag names after 'tagname', got {lines[2][:60]!r}", line=3)
    header = ["timestamp", *(t.strip() for t in tags[1:])]
    rows, numbers = [], []
    for k, ln in enumerate(lines[5:], start=6):
        if ln.strip():
            rows.append([c.strip() for c in ln.split("\t")])
            numbers.append(k)
    meta = {"loop_tag": title[1].strip().removesuffix(" Data").strip() if len(title) > 1 else path.stem,
            "sample_time_s": sample_time_s, "declared_rows": declared,
            "descriptions": {t: descs[i].strip() for i, t in enumerate(header) if 0 < i < len(descs)}}
    if len(rows) != declared:
        notes.append(f"{path}: line 2: the header declares {declared} rows, the file has {len(rows)}")
    table = TextTable(header, rows, numbers, used, "\t", notes)
    return _text_columns(path, table, header, meta)


# ---- Parquet ------------------------------------------------------------------------------
def read_parquet(path: Path, data: bytes | None = None, encoding: str | None = None) -> Table:
    """Columns of a Parquet file; numbers as float arrays, time stamps as seconds, the rest as text."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(pa.BufferReader(data) if data is not None else path)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several types for damaged files
        raise ReadError(path, f"not a readable Parquet file ({type(exc).__name__}: {_short(exc)})") from None
    columns, units = {}, {}
    for fld in table.schema:
        columns[fld.name] = _arrow_column(table.column(fld.name), fld.type)
        meta = fld.metadata or {}
        if b"unit" in meta:
            units[fld.name] = meta[b"unit"].decode("utf-8", "replace")
    if not columns:
        raise ReadError(path, "the Parquet file has no column")
    try:
        metadata = json.loads((table.schema.metadata or {}).get(b"phfdi_run", b"{}"))
    except ValueError:
        metadata = {}
    n = table.num_rows
    if n == 0:
        raise ReadError(path, "no rows", where="row")
    return Table(str(path), columns, np.arange(1, n + 1), "row",
                 metadata if isinstance(metadata, dict) else {}, units)


def _arrow_column(col, typ) -> list | np.ndarray:
    import pyarrow as pa
    import pyarrow.compute as pc

    if pa.types.is_integer(typ) or pa.types.is_floating(typ) or pa.types.is_boolean(typ) \
            or pa.types.is_decimal(typ):
        return np.asarray(pc.cast(col, pa.float64()).to_numpy(zero_copy_only=False), dtype=float)
    if pa.types.is_timestamp(typ):
        ns = pc.cast(pc.cast(col, pa.timestamp("ns")), pa.int64()).to_numpy(zero_copy_only=False)
        return np.asarray(ns, dtype=float) * 1e-9
    return ["" if v is None else str(v) for v in col.to_pylist()]


def _short(exc: BaseException, limit: int = 160) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


# ---- bags ---------------------------------------------------------------------------------
def read_bag(path: Path, data: bytes | None = None, encoding: str | None = None) -> Table:
    """The run signals of a bag of the node graph (time from /plant/measurement's stamps), or a measured record's
    channels from a bag of ``phfdi bag from-csv`` (/measured/sample, time from its stamps)."""
    from phfdi.bagread import has_topic, load_bag, load_measured_bag
    from phfdi_base.topics import MEASURED_SAMPLE

    try:
        run = load_bag(path)
    except ReadError:
        raise
    except UserError as exc:
        if not has_topic(path, MEASURED_SAMPLE.name):  # not a measured record's bag either: the graph's reason
            raise ReadError(path, str(exc).removeprefix(f"{path}: ")) from None
        try:
            measured = load_measured_bag(path)
        except UserError as inner:
            raise ReadError(path, str(inner).removeprefix(f"{path}: ")) from None
        columns, lines, where, metadata = measured
        return Table(str(path), dict(columns), lines, where, metadata, {})
    except Exception as exc:  # noqa: BLE001 - rosbags/mcap raise many types on damaged bags
        raise ReadError(path, f"not a readable MCAP bag ({type(exc).__name__}: {_short(exc)}); if its "
                              f"recorder was killed, run: phfdi bag recover {path} FIXED.mcap") from None
    if len(run) == 0:
        raise ReadError(path, "the bag holds no sample of /plant/measurement")
    units = {"time_s": unit_of("time_s"), **run.units}
    metadata = dict(run.metadata)
    notes = metadata.pop("notes", [])
    return Table(str(path), {"time_s": run.time_s, **run.signals}, np.arange(1, len(run) + 1), "sample", metadata, units, notes)


# ---- the built-in formats (matching order: a bag, Parquet, then text; see :mod:`.formats`) ------------------
register_format(Format("bag", (".mcap",), read_bag, magic=MCAP_MAGIC, folder_marker="metadata.yaml"))
register_format(Format("parquet", (".parquet", ".pq"), read_parquet, magic=PARQUET_MAGIC, historian=3))
register_format(Format("csv", (".csv",), read_text, historian=2))
register_format(Format("text", (".txt",), read_text, run=False, historian=1))  # plant_loops exports
