"""What a path is, when it is not a file to read (no project imports): one description for every reader.

>>> import tempfile
>>> not_a_file(tempfile.mkdtemp()), not_a_file("/no/such/path")
('a folder, not a file', 'no such file')
"""

from __future__ import annotations

import stat
from pathlib import Path

__all__ = ["not_a_file"]


def not_a_file(path: str | Path) -> str | None:
    """None when ``path`` is a regular file (or a link to one); else what it is, in words: no such file, a
    folder, a FIFO or a device (a read would block or never end), or why it cannot be opened (a link loop,
    no permission)."""
    try:
        mode = Path(path).stat().st_mode
    except FileNotFoundError:
        return "no such file"
    except OSError as exc:  # ELOOP (a link loop), EACCES, ...
        return f"cannot open it ({exc.strerror or exc})"
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder, not a file"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), not a file: reading it would wait for a writer"
    return "a device or socket, not a file"
