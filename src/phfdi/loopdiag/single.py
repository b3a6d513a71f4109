"""One loop file or run: read, diagnose, report (what a batch job runs on a worker)."""

from __future__ import annotations

from phfdi_base.errors import UserError

from .diagnose import Settings, report
from .features import loop_evidence, stiction_verdict
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
    """The report of one loop run: the Hammerstein diagnosis (cause, S and J) and the stiction
    classifier's verdict with its evidence (``report["stiction"]``), or ``{"file": ..., "error": message}``
    when it cannot be diagnosed."""
    try:
        settings = settings or Settings()
        le = loop_evidence(run, settings)
        rep = report(run, le.evidence, settings)
    except UserError as exc:
        return {"file": run.metadata.get("file"), "error": str(exc)}
    if not settings.baselines:
        rep["baselines"] = {}
    rep["stiction"] = stiction_verdict(le)
    rep["indicators"] = {k: v.to_dict() for k, v in le.indicators.items()}
    if figure_dir:
        from .figures import plot_loop

        rep["figure"] = str(plot_loop(run, le.evidence, rep, figure_dir))
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
