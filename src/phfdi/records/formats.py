"""The registry of record file formats: name, file suffixes, first bytes -> the reader that turns a file into a
:class:`Table`. Every reader of files consults it: :func:`phfdi.records.read_record`
(and so :func:`phfdi.records.read_run`, :func:`phfdi.bagio.load_run`, every command), the loop diagnosis's
folder scan (:mod:`phfdi.loopdiag.plantwide`). A new format is one :func:`register_format` call; the built-in
ones are registered at the end of :mod:`phfdi.records.sources`.

Examples
--------
>>> from phfdi.records.formats import format_of, run_suffixes
>>> format_of("day.mcap").name, format_of("loop.pq").name, format_of("export.txt").name
('bag', 'parquet', 'text')
>>> run_suffixes()
('.mcap', '.parquet', '.pq', '.csv')
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from phfdi_base.errors import UserError

__all__ = ["Format", "FORMATS", "Table", "WRITE_SUFFIXES", "format_of", "historian_suffixes", "register_format",
           "run_suffixes", "unregister_format", "writable_format"]


@dataclass
class Table:
    """Columns of one file: strings (text files) or arrays (Parquet, bags), one entry per row."""

    path: str
    columns: dict[str, list | np.ndarray]
    lines: np.ndarray  # source line (text) or row/sample number (1-based) of each row
    where: str  # "line", "row" or "sample": what ``lines`` counts
    metadata: dict = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.lines)


@dataclass(frozen=True)
class Format:
    """One file format.

    ``read(path, data, encoding)``: the file's :class:`Table` (``data`` is the file's
    bytes, None for a folder). A file is of the first registered format whose ``suffixes`` hold its suffix or
    whose ``magic`` its first bytes start with; a folder of the first whose ``folder_marker`` file it holds;
    anything else is read as text. ``run``: a run is read from it (:func:`phfdi.records.read_run`);
    ``historian``: the loop diagnosis takes it from a folder (plant historian exports), listed in this order
    (1 first; 0: not taken).
    """

    name: str
    suffixes: tuple[str, ...]
    read: Callable[[Path, bytes | None, str | None], Table]
    magic: bytes | None = None
    folder_marker: str | None = None
    run: bool = True
    historian: int = 0


#: name -> format, in registration (matching) order
FORMATS: dict[str, Format] = {}
#: the format of files no registered format claims (CSV and other text)
FALLBACK = "csv"


def register_format(fmt: Format) -> Format:
    """Add a format (a new name goes last in the matching order; a known name is replaced in place)."""
    FORMATS[fmt.name] = fmt
    return fmt


def unregister_format(name: str) -> None:
    FORMATS.pop(name, None)


def format_of(path: str | Path, data: bytes | None = None) -> Format:
    """The format of a file (by its suffix or, with ``data``, its first bytes) or of a folder (its marker file)."""
    path = Path(path)
    if path.is_dir():
        found = next((f for f in FORMATS.values() if f.folder_marker and (path / f.folder_marker).exists()), None)
        if found is not None:
            return found
    suffix = path.suffix.lower()
    for fmt in FORMATS.values():
        if suffix in fmt.suffixes or (data is not None and fmt.magic is not None and data.startswith(fmt.magic)):
            return fmt
    return FORMATS[FALLBACK]


def is_format(path: str | Path, name: str) -> bool:
    """True when ``path`` (by suffix, or as a folder by marker) is of the format ``name``."""
    fmt = format_of(path)
    return fmt.name == name and (Path(path).suffix.lower() in fmt.suffixes or Path(path).is_dir())


#: the formats a run is written to, by :meth:`phfdi.records.Record.save` (the readers are the registry's)
WRITE_SUFFIXES = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet"}


def writable_format(path: str | Path) -> str:
    """The format :meth:`~phfdi.records.Record.save` writes ``path`` in ("csv" or "parquet"); a one-line
    UserError for others."""
    fmt = WRITE_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise UserError(f"cannot write a run to {path}: use a .csv or .parquet file name")
    return fmt


def run_suffixes() -> tuple[str, ...]:
    """Suffixes of the formats a run is read from."""
    return tuple(s for f in FORMATS.values() if f.run for s in f.suffixes)


def historian_suffixes() -> tuple[str, ...]:
    """Suffixes the loop diagnosis takes from a folder, in its listing order.

    >>> historian_suffixes()
    ('.txt', '.csv', '.parquet', '.pq')
    """
    formats = sorted((f for f in FORMATS.values() if f.historian), key=lambda f: f.historian)
    return tuple(s for f in formats for s in f.suffixes)


def firsts(suffixes: tuple[str, ...]) -> list[str]:
    """One of ``suffixes`` per format (the first), in their order."""
    out: list[str] = []
    for s in suffixes:
        fmt = next(f for f in FORMATS.values() if s in f.suffixes)
        if not any(o in fmt.suffixes for o in out):
            out.append(s)
    return out


def expected(suffixes: tuple[str, ...]) -> str:
    """'.a, .b or .c' (one suffix per format: the first)."""
    names = firsts(suffixes)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"
