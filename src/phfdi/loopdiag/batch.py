"""Many loop files at once, on all cores; a bad file is one message, never the end of the batch."""

from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Callable, Iterable

from phfdi_base.errors import UserError

from .diagnose import Settings, gather_evidence, report
from .readers import ColumnMap, check_loop_run, read_loop, read_loop_segments


def diagnose_file(path: str, columns: ColumnMap | None = None, settings: Settings | None = None,
                  figure_dir: str | None = None) -> dict:
    """The report of one file (its longest usable stretch), or ``{"file": ..., "error": message}``."""
    try:
        run = read_loop(path, columns)
    except UserError as exc:
        return {"file": str(path), "error": str(exc)}
    return diagnose_run(run, settings, figure_dir)


def diagnose_run(run, settings: Settings | None = None, figure_dir: str | None = None) -> dict:
    """The report of one loop run, or ``{"file": ..., "error": message}`` when it cannot be diagnosed."""
    try:
        settings = settings or Settings()
        ev = gather_evidence(run, settings)
        rep = report(run, ev, settings)
    except UserError as exc:
        return {"file": run.metadata.get("file"), "error": str(exc)}
    if figure_dir:
        from .figures import plot_loop

        rep["figure"] = str(plot_loop(run, ev, rep, figure_dir))
    return rep


def diagnose_file_segments(path: str, columns: ColumnMap | None = None, settings: Settings | None = None,
                           figure_dir: str | None = None) -> list[dict]:
    """One report per usable stretch of the file (each with its source lines), or one error."""
    try:
        runs = read_loop_segments(path, columns)
    except UserError as exc:
        return [{"file": str(path), "error": str(exc)}]
    out = []
    for run in runs:
        a, b = run.metadata["lines"]
        try:
            check_loop_run(run)
        except UserError as exc:
            out.append({"file": str(path), "lines": [a, b], "error": str(exc)})
            continue
        rep = diagnose_run(run, settings, figure_dir)
        rep["lines"] = [a, b]
        out.append(rep)
    return out


def _worker(args: tuple) -> list[dict]:
    *job, each = args
    return diagnose_file_segments(*job) if each else [diagnose_file(*job)]


def default_workers() -> int:
    return max(1, min(2, os.cpu_count() or 1))


def diagnose_files(paths: Iterable[str], columns: ColumnMap | None = None, settings: Settings | None = None,
                   workers: int | None = None, progress: Callable[[int, int, str], None] | None = None,
                   figure_dir: str | None = None, each_segment: bool = False) -> list[dict]:
    """Reports in the order of ``paths`` (with ``each_segment``, one per usable stretch); ``workers`` processes
    (default: both cores)."""
    paths = [str(p) for p in paths]
    workers = default_workers() if workers is None else max(1, workers)
    jobs = [(p, columns, settings, figure_dir, each_segment) for p in paths]
    results: list[list[dict] | None] = [None] * len(paths)
    if workers == 1 or len(paths) == 1:
        for i, job in enumerate(jobs):
            results[i] = _worker(job)
            if progress:
                progress(i + 1, len(paths), paths[i])
        return [r for rs in results for r in rs]  # type: ignore[union-attr]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_worker, job): i for i, job in enumerate(jobs)}
        done = 0
        for fut in as_completed(futures):
            i = futures[fut]
            results[i] = fut.result()
            done += 1
            if progress:
                progress(done, len(paths), paths[i])
    return [r for rs in results for r in rs]  # type: ignore[union-attr]


def stderr_progress(enabled: bool | None = None) -> Callable[[int, int, str], None]:
    """``[k/n] file`` lines on stderr (only on a terminal unless forced)."""
    on = sys.stderr.isatty() if enabled is None else enabled

    def show(done: int, total: int, path: str) -> None:
        if on:
            print(f"\rloop-diagnose: {done}/{total} {Path(path).name[:60]:60s}", end="\n" if done == total else "",
                  file=sys.stderr, flush=True)

    return show

