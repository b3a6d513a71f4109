"""Many loop files at once (on Dask, :mod:`.plantwide`); a bad file is one message, never the end of the batch."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Iterable

from phfdi import records

from .diagnose import Settings
from .single import diagnose_file, diagnose_file_segments, diagnose_run  # noqa: F401 - the batch's public API


def diagnose_files(paths: Iterable[str], columns: records.ColumnMap | None = None, settings: Settings | None = None,
                   workers: int | None = None, progress: Callable[[int, int, str], None] | None = None,
                   figure_dir: str | None = None, each_segment: bool = False,
                   scheduler: str | None = None) -> list[dict]:
    """Reports in the order of ``paths`` (with ``each_segment``, one per usable stretch), on Dask
    (:mod:`.plantwide`; a single file runs in this process).

    A file that cannot be diagnosed gives ``{"file": ..., "error": message}`` in its place; the batch goes on.

    Examples
    --------
    >>> from phfdi.loopdiag import diagnose_files
    >>> reports = diagnose_files(["no_such_file.csv"])
    >>> [r["error"] for r in reports]
    ['no_such_file.csv: no such file']
    """
    from .plantwide import Job, diagnose_jobs

    paths = [str(p) for p in paths]
    show = (lambda done, total: progress(done, total, "")) if progress else None
    return diagnose_jobs([Job(p, columns) for p in paths], settings, figure_dir, scheduler, workers, show,
                         each_segment=each_segment)


def stderr_progress(enabled: bool | None = None) -> Callable[[int, int, str], None]:
    """``[k/n] file`` lines on stderr (only on a terminal unless forced)."""
    on = sys.stderr.isatty() if enabled is None else enabled

    def show(done: int, total: int, path: str) -> None:
        if on:
            print(f"\rloop-diagnose: {done}/{total} {Path(path).name[:60]:60s}", end="\n" if done == total else "",
                  file=sys.stderr, flush=True)

    return show
