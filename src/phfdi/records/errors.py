"""The one error a record reader raises: a :class:`~phfdi_base.errors.UserError` that names file, line and column."""

from __future__ import annotations

from pathlib import Path

from phfdi_base.errors import UserError


class ReadError(UserError):
    """A record that cannot be read or used; the message is one line ``FILE: line N, column 'X': problem``.

    A :class:`~phfdi_base.errors.UserError`: the command line prints it and exits 2.

    Examples
    --------
    >>> from phfdi.records import ReadError
    >>> error = ReadError("loop.csv", "not a number", line=3, column="PV")
    >>> print(error)
    loop.csv: line 3, column 'PV': not a number
    >>> error.line, error.column
    (3, 'PV')
    """

    def __init__(self, path: object, problem: str, line: int | None = None, column: str | None = None,
                 where: str = "line") -> None:
        super().__init__(f"{place(path, line, column, where)}: {problem}")
        self.path = str(path)
        self.line = line
        self.column = column


def place(path: object, line: int | None = None, column: str | None = None, where: str = "line") -> str:
    """``FILE``, ``FILE: line N``, ``FILE: column 'X'`` or ``FILE: line N, column 'X'`` (``where``: line/row/sample)."""
    parts = []
    if line is not None:
        parts.append(f"{where} {line}")
    if column is not None:
        parts.append(f"column {column!r}")
    return f"{path}: {', '.join(parts)}" if parts else str(path)


def regular_file(path: str | Path) -> Path:
    """``path`` if it is a regular file (or a link to one); else one :class:`ReadError` saying what it is: no
    such file, a folder, a FIFO or a device (which would block or never end a read), a link loop.

    >>> import tempfile
    >>> try:
    ...     regular_file(tempfile.mkdtemp())
    ... except ReadError as exc:
    ...     print(str(exc).split(": ", 1)[1])
    a folder, not a file
    """
    from phfdi_base.files import not_a_file

    why = not_a_file(path)
    if why is not None:
        raise ReadError(path, why)
    return Path(path)
