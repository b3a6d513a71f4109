"""Many loop files at once (on Dask, :mod:`.plantwide`); a bad file is one message, never the end of the batch."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, Iterable

from phfdi.errors import UserError

from .diagnose import Settings, report
from .features import loop_evidence, stiction_verdict
from .readers import ColumnMap, read_loop


def diagnose_file(path: str, columns: ColumnMap | None = None, settings: Settings | None = None,
                  figure_dir: str | None = None) -> dict:
    """The report of one file, or ``{"file": ..., "error": message}`` for a file that cannot be diagnosed."""
    try:
        run = read_loop(path, columns)
    except UserError as exc:
        return {"file": str(path), "error": str(exc)}
    return diagnose_loop_run(run, settings, figure_dir)


def diagnose_loop_run(run, settings: Settings | None = None, figure_dir: str | None = None) -> dict:
    """The report of one loop: the Hammerstein diagnosis (cause, S and J) and the stiction
    classifier's verdict with its evidence (``report["stiction"]``)."""
    settings = settings or Settings()
    le = loop_evidence(run, settings)
    rep = report(run, le.evidence, settings)
    if not settings.baselines:
        rep["baselines"] = {}
    rep["stiction"] = stiction_verdict(le)
    rep["indicators"] = {k: v.to_dict() for k, v in le.indicators.items()}
    if figure_dir:
        from .figures import plot_loop

        rep["figure"] = str(plot_loop(run, le.evidence, rep, figure_dir))
    return rep


def diagnose_files(paths: Iterable[str], columns: ColumnMap | None = None, settings: Settings | None = None,
                   workers: int | None = None, progress: Callable[[int, int, str], None] | None = None,
                   figure_dir: str | None = None, scheduler: str | None = None) -> list[dict]:
    """Reports in the order of ``paths``, on Dask (:mod:`.plantwide`; one file runs in this process)."""
    from .plantwide import Job, diagnose_jobs

    paths = [str(p) for p in paths]
    show = (lambda done, total: progress(done, total, "")) if progress else None
    return diagnose_jobs([Job(p, columns) for p in paths], settings, figure_dir, scheduler, workers, show)


def stderr_progress(enabled: bool | None = None) -> Callable[[int, int, str], None]:
    """``[k/n] file`` lines on stderr (only on a terminal unless forced)."""
    on = sys.stderr.isatty() if enabled is None else enabled

    def show(done: int, total: int, path: str) -> None:
        if on:
            print(f"\rloop-diagnose: {done}/{total} {Path(path).name[:60]:60s}", end="\n" if done == total else "",
                  file=sys.stderr, flush=True)

    return show

