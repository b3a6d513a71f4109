"""One way to write a file: staged beside the target, flushed and synced, renamed over it.

Every command writes its outputs through here, so that a full disk, a read-only folder or a crash mid-write
never leaves a half-written file and never destroys an earlier good one:

* the data go to a temporary file in the target's own folder (``.NAME.XXXX.partial.SUFFIX``: the suffix is
  kept, so writers that choose a format by it, such as matplotlib's ``savefig``, still do);
* it is flushed and fsync'ed, then renamed over the target (atomic on POSIX: a reader sees the old file or
  the new one, never a mix);
* any failure removes the temporary file and becomes one :class:`UserError` naming the path and the reason
  (the command line prints it as one line, exit status 2);
* an existing target is replaced only when ``overwrite`` is true (the commands' ``--overwrite``).

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from phfdi_base.outputs import write_text
>>> path = write_text(Path(tempfile.mkdtemp()) / "alarms.json", "[]\\n")
>>> path.read_text()
'[]\\n'
>>> try:
...     write_text(path, "[1]\\n")
... except Exception as exc:
...     print(str(exc).replace(str(path), "PATH"))
PATH exists; give --overwrite to replace it
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import UserError

__all__ = ["OutputError", "check_writable_folder", "refuse_existing", "save_figure", "staged", "write_bytes",
           "write_text"]


class OutputError(UserError):
    """An output could not be written (the message names the path and the reason)."""


def _reason(exc: OSError) -> str:
    return exc.strerror or str(exc)


def refuse_existing(path: str | Path, overwrite: bool) -> None:
    """One line if ``path`` exists and may not be replaced."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path} is a folder; give a file name")
    if path.exists() and not overwrite:
        raise OutputError(f"{path} exists; give --overwrite to replace it")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def staged(path: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """A temporary path beside ``path`` for a writer to fill; on a clean exit it is synced and renamed over
    ``path``, on any error removed (an OSError becomes one :class:`OutputError`).

    >>> import tempfile
    >>> from pathlib import Path
    >>> target = Path(tempfile.mkdtemp()) / "run.csv"
    >>> with staged(target) as tmp:
    ...     _ = tmp.write_text("time_s\\n0\\n")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('time_s\\n0\\n', ['run.csv'])
    """
    target = Path(path)
    refuse_existing(target, overwrite)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".partial{target.suffix}",
                                    dir=target.parent)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as handle:  # what the writer wrote reaches the disk before the rename
            os.fsync(handle.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would make outputs private
        os.replace(tmp, target)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes(path: str | Path, data: bytes, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (see the module docstring); returns the path."""
    with staged(path, overwrite) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | Path, text: str, overwrite: bool = False, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see the module docstring); returns the path."""
    return write_bytes(path, text.encode(encoding), overwrite)


def check_writable_folder(folder: str | Path) -> Path:
    """Make ``folder`` (with its parents) and prove a file can be created in it, before long work: one
    :class:`OutputError` otherwise, so that hours of computation are not lost at the end."""
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".phfdi-write-check.", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise OutputError(f"cannot write to {folder}: {_reason(exc)}") from None
    return folder


def save_figure(fig, path: str | Path, dpi: float, overwrite: bool = True) -> Path:
    """``fig.savefig`` through :func:`staged` (the format from ``path``'s suffix, as matplotlib does)."""
    with staged(path, overwrite) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return Path(path)
