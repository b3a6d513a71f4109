"""Text files: detect the encoding (or say which is needed), the delimiter and the decimal mark.

Encodings tried in order: a byte-order mark (UTF-8, UTF-16, UTF-32), UTF-16 without a mark (every
other byte NUL), UTF-8, then latin-1 when the bytes that are not UTF-8 are letters and signs of
latin-1 (0xA0-0xFF), cp1252 when they include its 0x80-0x9F signs (euro, quotes). Anything else
needs ``--encoding``; the error names the line of the first byte that did not decode.
"""

from __future__ import annotations

import codecs
import csv
import io
import re
from dataclasses import dataclass, field

from .errors import ReadError

BOMS = ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"), (codecs.BOM_UTF8, "utf-8-sig"),
        (codecs.BOM_UTF16_LE, "utf-16"), (codecs.BOM_UTF16_BE, "utf-16"))
DELIMITERS = ",;\t"
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d+,\d+\s*$")


@dataclass
class TextTable:
    """A CSV as strings: header, rows (each a list of cells) and the file line of each row (1-based)."""

    header: list[str]
    rows: list[list[str]]
    lines: list[int]
    encoding: str
    delimiter: str
    notes: list[str] = field(default_factory=list)


def decode(data: bytes, path: object, encoding: str | None = None) -> tuple[str, str, list[str]]:
    """Text, the encoding used and notes; :class:`ReadError` when it cannot be told."""
    if encoding:
        return _decode_as(data, path, encoding), encoding, []
    for bom, name in BOMS:
        if data.startswith(bom):
            return _decode_as(data, path, name), name, []
    if _looks_utf16(data):
        name = "utf-16-le" if data[1:2] == b"\0" else "utf-16-be"
        return _decode_as(data, path, name), name, [f"{path}: read as {name} (no byte-order mark)"]
    try:
        return data.decode("utf-8"), "utf-8", []
    except UnicodeDecodeError as exc:
        first_bad = exc.start
    if b"\0" in data:
        raise ReadError(path, "not a text file (NUL bytes); a CSV, Parquet or MCAP file was expected",
                        line=_line_of(data, data.index(b"\0")))
    for name in ("latin-1", "cp1252"):
        text = _plausible(data, name)
        if text is not None:
            return text, name, [f"{path}: not UTF-8 (byte 0x{data[first_bad]:02x} at line "
                                f"{_line_of(data, first_bad)}); read as {name}, give --encoding if that is wrong"]
    raise ReadError(path, f"byte 0x{data[first_bad]:02x} is not UTF-8 and the text is not latin-1 or cp1252; "
                          f"give the file's encoding with --encoding (e.g. --encoding cp1250)",
                    line=_line_of(data, first_bad))


def _decode_as(data: bytes, path: object, name: str) -> str:
    try:
        return data.decode(name)
    except LookupError:
        raise ReadError(path, f"unknown encoding {name!r} (give a Python codec name such as utf-8, latin-1, "
                              f"cp1252, utf-16)") from None
    except UnicodeDecodeError as exc:
        raise ReadError(path, f"not {name} text ({exc.reason} at byte {exc.start}); give the file's encoding "
                              f"with --encoding", line=_line_of(data, exc.start)) from None


def _looks_utf16(data: bytes) -> bool:
    head = data[:4000]
    if len(head) < 4:
        return False
    even, odd = head[0::2], head[1::2]
    return (odd.count(0) > 0.9 * len(odd) and even.count(0) == 0) or \
        (even.count(0) > 0.9 * len(even) and odd.count(0) == 0)


def _plausible(data: bytes, name: str) -> str | None:
    """The text in a single-byte encoding when its non-ASCII characters are printable, else None."""
    try:
        text = data.decode(name)
    except UnicodeDecodeError:
        return None
    odd = [c for c in text if ord(c) > 127]
    if any(not c.isprintable() for c in odd):
        return None
    return text


def _line_of(data: bytes, offset: int) -> int:
    return data.count(b"\n", 0, offset) + 1


#: the longest cell (or header line) read: a wide historian export's header runs past the csv module's default
#: of 128 KiB (thousands of tags); beyond this a file is refused with one line
MAX_CELL_CHARS = 64 << 20
csv.field_size_limit(max(csv.field_size_limit(), MAX_CELL_CHARS))


def sniff_delimiter(text: str) -> str:
    """The delimiter (, ; or tab) that splits the first lines into the same number of columns, most first."""
    lines = [ln for ln in text.splitlines()[:20] if ln.strip()]
    if not lines:
        return ","
    best, best_score = ",", (-1, -1)
    for d in DELIMITERS:
        try:
            counts = [len(next(csv.reader([ln], delimiter=d), [])) for ln in lines]
        except csv.Error:  # not this delimiter's file (parse_csv names the problem if none fits)
            continue
        score = (int(counts[0] > 1 and all(c == counts[0] for c in counts)), counts[0])
        if score > best_score:
            best, best_score = d, score
    return best


def parse_csv(data: bytes, path: object, encoding: str | None = None) -> TextTable:
    """Header and rows of a CSV (blank lines skipped, cells stripped, decimal commas read as points)."""
    text, used, notes = decode(data, path, encoding)
    if not text.strip():
        raise ReadError(path, "empty file", line=1)
    delimiter = sniff_delimiter(text)
    reader = csv.reader(io.StringIO(text, newline=""), delimiter=delimiter)
    header: list[str] | None = None
    rows, lines = [], []
    end = 0  # the last line the reader has consumed
    try:
        for row in reader:
            start, end = end + 1, reader.line_num
            if not any(c.strip() for c in row):
                continue
            if header is None:
                header = [c.strip() for c in row]
                continue
            rows.append([c.strip() for c in row])
            lines.append(start)  # the line the row starts on (a quoted cell may run over several)
    except csv.Error as exc:
        raise ReadError(path, f"not a readable CSV ({exc})", line=reader.line_num) from None
    if header is None:
        raise ReadError(path, "empty file (no header line)", line=1)
    _note_multiline(rows, lines, path, notes)
    if delimiter == ";" and _decimal_comma(rows):
        rows = [[c.replace(",", ".") if _DECIMAL_COMMA.match(c) else c for c in r] for r in rows]
        notes.append(f"{path}: decimal commas read as points (';'-separated file)")
    return TextTable(header, rows, lines, used, delimiter, notes)


def _note_multiline(rows: list[list[str]], lines: list[int], path: object, notes: list[str]) -> None:
    """A quoted cell that runs over line ends (an unclosed quote swallows the lines after it) is said."""
    spread = [(k, sum(c.count("\n") for c in r)) for k, r in enumerate(rows) if any("\n" in c for c in r)]
    if spread:
        k, n = spread[0]
        more = f" ({len(spread)} rows like it)" if len(spread) > 1 else ""
        notes.append(f"{path}: line {lines[k]}: a quoted cell runs over {n + 1} lines (an unclosed quote?): "
                     f"they are read as one row{more}")


def _decimal_comma(rows: list[list[str]]) -> bool:
    sample = [c for r in rows[:50] for c in r if c]
    return bool(sample) and sum(bool(_DECIMAL_COMMA.match(c)) for c in sample) > 0.3 * len(sample)
