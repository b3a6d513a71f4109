"""One way to write a file: staged beside the target, flushed and synced, renamed over it.

Every command writes its outputs through here, so that a full disk, a read-only folder or a crash mid-write
never leaves a half-written file and never destroys an earlier good one:

* the data go to a temporary file in the target's own folder (``.NAME.XXXX.partial.SUFFIX``: the suffix is
  kept, so writers that choose a format by it, such as matplotlib's ``savefig``, still do);
* it is flushed and fsync'ed, then put in place: without ``overwrite`` (the commands' default) by a hard link,
  which fails if the target exists, so of two commands writing the same new file at once one gets it and the
  other is refused (an "exists?" check before a rename let both through, the second replacing the first); with
  ``overwrite`` (``--overwrite``) renamed over the target (atomic on POSIX: a reader sees the old file or the new
  one, never a mix);
* any failure removes the temporary file and becomes one :class:`UserError` naming the path and the reason
  (the command line prints it as one line, exit status 2);
* files that belong together (a faulty record and its truth) are written by :func:`write_together`: staged,
  then placed while holding their folder's lock, so two writers never interleave their files.

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
import errno
import os
import tempfile
from pathlib import Path
from typing import Iterator

from .errors import UserError

__all__ = ["OutputError", "check_writable_folder", "folder_lock", "output_folder", "refuse_existing", "save_figure",
           "staged", "write_bytes", "write_text", "write_together"]


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
    """A temporary path beside ``path`` for a writer to fill; on a clean exit it is synced and put in place
    (:func:`place`), on any error removed (an OSError becomes one :class:`OutputError`).

    >>> import tempfile
    >>> from pathlib import Path
    >>> target = Path(tempfile.mkdtemp()) / "run.csv"
    >>> with staged(target) as tmp:
    ...     _ = tmp.write_text("time_s\\n0\\n")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('time_s\\n0\\n', ['run.csv'])
    """
    target = Path(path)
    refuse_existing(target, overwrite)  # at once, before the work: the placing refuses again, race free
    tmp = _temporary(target)
    try:
        yield tmp
        _sync(tmp)
        place(tmp, target, overwrite)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _temporary(target: Path) -> Path:
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:  # a file where a folder of the path should be
        blocker = next((p for p in reversed(target.parents) if p.exists() and not p.is_dir()), target.parent)
        raise OutputError(f"cannot write {target}: {blocker} is a file, not a folder") from None
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=f".partial{target.suffix}",
                                    dir=target.parent)
        os.close(fd)
    except OSError as exc:
        raise OutputError(f"cannot write {target}: {_reason(exc)}") from None
    return Path(name)


def _sync(tmp: Path) -> None:
    with open(tmp, "rb+") as handle:  # what the writer wrote reaches the disk before it is placed
        os.fsync(handle.fileno())
    os.chmod(tmp, 0o666 & ~_umask())  # mkstemp's 0600 would make outputs private


#: errors of a hard link on a file system that has none (FAT, some network and FUSE file systems)
_NO_LINKS = {errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EMLINK, errno.EXDEV, errno.ENOSYS}


def place(tmp: Path, target: Path, overwrite: bool) -> None:
    """Put the finished ``tmp`` at ``target``: renamed over it with ``overwrite``; else created only if no file
    is there (a hard link: "exists?" and "create" in one step), :class:`OutputError` if one is (``tmp`` is then
    left for the caller to remove). Where the file system has no hard links, the name is reserved by an
    exclusive create (O_EXCL) and the file renamed onto it."""
    if overwrite:
        os.replace(tmp, target)
        return
    try:
        os.link(tmp, target)
    except FileExistsError:
        raise OutputError(f"{target} exists; give --overwrite to replace it") from None
    except OSError as exc:
        if exc.errno not in _NO_LINKS:
            raise
        try:
            os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600))
        except FileExistsError:
            raise OutputError(f"{target} exists; give --overwrite to replace it") from None
        try:
            os.replace(tmp, target)
        except OSError:
            target.unlink(missing_ok=True)  # the empty file that reserved the name: ours
            raise
        return
    with contextlib.suppress(OSError):
        tmp.unlink()


@contextlib.contextmanager
def folder_lock(folder: str | Path) -> Iterator[None]:
    """Hold an exclusive lock (flock) on ``folder`` while placing files that belong together, so that two
    writers of the same files place theirs one after the other. Advisory: only writers that take it wait; where
    a file system has no locks it is a no-op (the files' own atomic placing still holds)."""
    import fcntl

    try:
        fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError:
        yield
        return
    try:
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


def write_together(files: list[tuple[str | Path, bytes]], overwrite: bool = False) -> list[Path]:
    """Write files that belong together (a faulty record and its truth) as one unit, in the given order.

    All are staged and synced first; then, holding their folder's lock (:func:`folder_lock`), each is placed
    (:func:`place`). Without ``overwrite`` a file that exists refuses the whole unit: the files this call had
    already placed are removed again, so the earlier ones never stand without the later. With ``overwrite``, two
    writers of the same unit at once place theirs one after the other: the files never come from two runs (a
    reader that takes no lock can still find the first file renamed and the second not yet: put a hash of one in
    the other to tell, as :func:`phfdi.inject.write_injected` does).
    """
    targets = [Path(p) for p, _ in files]
    for target in targets:
        refuse_existing(target, overwrite)
    temps: list[Path] = []
    placed: list[Path] = []
    current = targets[0]
    try:
        for target, (_, data) in zip(targets, files):
            current = target
            temps.append(_temporary(target))
            temps[-1].write_bytes(data)
            _sync(temps[-1])
        with folder_lock(targets[0].parent):
            for tmp, target in zip(temps, targets):
                current = target
                place(tmp, target, overwrite)
                placed.append(target)
    except BaseException as exc:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
        if not overwrite:
            for target in placed:  # ours: created by this call, which no other writer can have replaced
                target.unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OutputError(f"cannot write {current}: {_reason(exc)}") from None
        raise
    return targets


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


def output_folder(folder: str | Path, overwrite: bool) -> Path:
    """The output folder of a command that writes several files (``--out DIR``), made and proven writable before
    the work (:func:`check_writable_folder`). The same rule as for a file: a folder that already holds files is
    written into only with ``overwrite`` (``--overwrite``: the files the command writes are replaced, each
    atomically; others are left as they are); without it, one :class:`OutputError` before any work.

    >>> import tempfile
    >>> from pathlib import Path
    >>> folder = output_folder(Path(tempfile.mkdtemp()) / "report", overwrite=False)  # new: made
    >>> _ = (folder / "REPORT.md").write_text("# a report")
    >>> try:
    ...     output_folder(folder, overwrite=False)
    ... except OutputError as exc:
    ...     print(str(exc).replace(str(folder), "DIR"))
    DIR holds files of an earlier run; give --overwrite to replace them (or another folder)
    >>> output_folder(folder, overwrite=True) == folder
    True
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise OutputError(f"{folder} is a file; give a folder")
    if not overwrite and folder.is_dir() and any(folder.iterdir()):
        raise OutputError(f"{folder} holds files of an earlier run; give --overwrite to replace them (or another "
                          f"folder)")
    return check_writable_folder(folder)


def save_figure(fig, path: str | Path, dpi: float, overwrite: bool = True) -> Path:
    """``fig.savefig`` through :func:`staged` (the format from ``path``'s suffix, as matplotlib does)."""
    with staged(path, overwrite) as tmp:
        fig.savefig(tmp, dpi=dpi)
    return Path(path)
