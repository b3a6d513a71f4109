"""One loop file or run: read, diagnose, report (what a batch job runs on a worker)."""

from __future__ import annotations

import sys
from dataclasses import replace

from phfdi import records
from phfdi.records.record import Record
from phfdi_base.errors import UserError

from .classifier import NO_STICTION, STICTION, UNDETERMINED
from .diagnose import Evidence, Settings, gather_evidence, report
from .features import ScreenEvidence, _r4, baselines_of, kano_fit, screen_evidence, stiction_verdict
from .indicators import ramp_noise_level
from .loopcheck import PV_FROZEN, LoopCheck, check_loop
from .oscillation import detect_oscillation
from .readers import check_loop_run, read_loop, read_loop_segments
from .verdict import loop_verdict
from .vocabulary import FRICTION_CAUSES
from .windows import (
    PROGRESS_EVERY,
    WHOLE_MAX,
    WINDOW,
    WINDOW_ALPHA,
    record_call,
    representative,
    screen_windows,
    window_bounds,
    window_run,
)

#: the screen's calls that get the valve-model fits
FLAGGED = (STICTION, UNDETERMINED)


def diagnose_file(path: str, columns: records.ColumnMap | None = None, settings: Settings | None = None,
                  figure_dir: str | None = None) -> dict:
    """The report of one file (its longest usable stretch), or ``{"file": ..., "error": message}``.

    Parameters
    ----------
    path : str
        A plant_loops export or a CSV with time, OP, PV (and SP) columns.
    columns : phfdi.records.ColumnMap, optional
        Which column is which (default: guessed from the header).
    settings : Settings, optional
    figure_dir : str, optional
        Also draw the loop's figure there.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> import numpy as np
    >>> from phfdi.loopdiag import Settings, SyntheticLoop, diagnose_file, simulate_loop
    >>> run = simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), ti_s=30,
    ...                                   setpoint_steps=[(100, 52), (1500, 49)]))
    >>> path = Path(tempfile.mkdtemp()) / "FIC101.csv"
    >>> np.savetxt(path, np.column_stack([run.time_s, run["op_pct"], run["pv"], run["sp"]]), delimiter=",",
    ...            header="time,OP,PV,SP", comments="", fmt="%.4f")
    >>> report = diagnose_file(str(path), settings=Settings(baselines=False))
    >>> report["loop_tag"], report["cause"]
    ('FIC101', 'stiction')
    >>> diagnose_file("no_such_file.csv")["error"]
    'no_such_file.csv: no such file'
    """
    try:
        run = read_loop(path, columns)
    except UserError as exc:
        return {"file": str(path), "error": str(exc)}
    return diagnose_run(run, settings, figure_dir)


def diagnose_run(run, settings: Settings | None = None, figure_dir: str | None = None) -> dict:
    """The report of one loop run: its one verdict (``report["loop_verdict"]``: stiction, no_stiction,
    undetermined, pv_frozen or not_a_closed_loop, with its evidence), the stiction classifier's answer
    (``report["stiction"]``) and, for the loops the screen flags, the valve-model (Hammerstein) fit (cause, S and
    J) it lists as evidence; or ``{"file": ..., "error": message}`` when it cannot be diagnosed. A record that is
    not a closed loop (or whose PV is frozen) is said to be one and not scored. A record longer than
    :data:`.windows.WHOLE_MAX` samples is screened in windows (:mod:`.windows`).

    Parameters
    ----------
    run : Record
        ``time_s``, ``op_pct``, ``pv`` and optionally ``sp`` (e.g. from :func:`read_loop`).
    settings : Settings, optional
    figure_dir : str, optional
        Also draw the loop's figure there (``report["figure"]``).

    Examples
    --------
    >>> from phfdi.loopdiag import Settings, SyntheticLoop, diagnose_run, simulate_loop
    >>> run = simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), ti_s=30,
    ...                                   setpoint_steps=[(100, 52), (1500, 49)]))
    >>> report = diagnose_run(run, Settings(baselines=False))
    >>> report["loop_verdict"]["verdict"], report["cause"]
    ('stiction', 'stiction')
    >>> {name: round(value) for name, value in report["parameters"].items()}  # simulated: S 3 %, J 1 %
    {'s_pct': 3, 'j_pct': 1}
    """
    settings = settings or Settings()
    if len(run) > WHOLE_MAX:
        return diagnose_long(run, settings, figure_dir)
    check = check_loop(run["op_pct"], run["pv"], run["sp"] if "sp" in run else None)
    if check.verdict is not None:
        return structure_report(run, check, settings, figure_dir)
    try:
        rep, scr, ev = screened_report(run, settings)
    except UserError as exc:
        return {"file": run.metadata.get("file"), "error": str(exc)}
    rep["loop_verdict"] = loop_verdict(check, rep)
    if figure_dir:
        from .figures import plot_loop, plot_record

        rep["figure"] = str(plot_loop(run, ev, rep, figure_dir) if ev is not None else plot_record(run, rep, figure_dir))
    return rep


def screened_report(run, settings: Settings) -> tuple[dict, ScreenEvidence, Evidence | None]:
    """The screen of one closed loop (indicators, dead-band screen, calibrated p and its call) and, when the
    screen flags it (or ``settings.fits`` is "all"), the valve-model fit; the report, the screen and the fit
    (None when not run)."""
    process_type = settings.process_type or run.metadata.get("process_type", "self_regulating")
    sp = run["sp"] if "sp" in run else None
    scr = screen_evidence(run["op_pct"], run["pv"], sp, run.dt_s, process_type)
    st = stiction_verdict(scr)
    ev = None
    if settings.fits == "all" or (settings.fits == "flagged" and st["verdict"] in FLAGGED):
        causes = tuple(settings.causes) + tuple(c for c in FRICTION_CAUSES if c not in settings.causes)
        ev = gather_evidence(run, replace(settings, causes=causes, baselines=False))
        ev.baselines = baselines_of(scr.indicators)
        rep = report(run, ev, settings)
        rep["valve_models"] = "fitted"
        st.update(kano_fit(ev) or {})
    else:
        rep = unfitted_report(run, scr, settings, st)
    if not settings.baselines:
        rep["baselines"] = {}
    st["op_noise"] = _r4(ramp_noise_level(run["op_pct"]))
    rep["stiction"] = st
    rep["indicators"] = {k: v.to_dict() for k, v in scr.indicators.items()}
    return rep, scr, ev


def unfitted_report(run, scr: ScreenEvidence, settings: Settings, st: dict) -> dict:
    """The report of a loop the screen did not flag: its oscillation and indicators, no valve-model fit (the
    catalogue's keys present and empty; ``valve_models`` says why)."""
    notes = list(run.metadata.get("notes") or [])
    low = st["band"][0]
    why = (f"valve models not fitted: the screen found no stiction (p = {st['probability']:.2f} below "
           f"{low:.2f}); --fits all fits them for every loop")
    if settings.fits == "none":
        why = "valve models not fitted (--fits none: the screen alone; a stiction call is not checked against them)"
    return {"file": run.metadata.get("file"), "loop_tag": run.metadata.get("loop_tag"),
            "process_type": settings.process_type or run.metadata.get("process_type"), "samples": len(run),
            "sample_time_s": run.dt_s, "oscillation": scr.oscillation.to_dict(), "cause": "none", "family": "none",
            "parameters": {}, "confidence": None, "verdict": "none", "reason": why, "nrmse_nominal": None,
            "nrmse_extended": None, "gain_percent": None, "extended_cause": None, "ranking": [],
            "baselines": baselines_of(scr.indicators), "notes": notes, "reading_notes": notes,
            "valve_models": "not fitted"}


def structure_report(run, check: LoopCheck, settings: Settings, figure_dir: str | None = None) -> dict:
    """The report of a record that is no closed loop to score (PV frozen, or not a loop): its verdict and
    reasons, the oscillation test of PV (not for a frozen one), no valve model and no stiction score."""
    sp = run["sp"] if "sp" in run else None
    osc = None if check.verdict == PV_FROZEN else detect_oscillation(run["pv"], sp, run.dt_s).to_dict()
    verdict = loop_verdict(check, {})
    notes = list(run.metadata.get("notes") or [])
    rep = {"file": run.metadata.get("file"), "loop_tag": run.metadata.get("loop_tag"),
           "process_type": settings.process_type or run.metadata.get("process_type"), "samples": len(run),
           "sample_time_s": run.dt_s, "oscillation": osc, "cause": "none", "family": "none", "parameters": {},
           "confidence": None, "verdict": "not_identifiable", "reason": verdict["summary"],
           "nrmse_nominal": None, "nrmse_extended": None, "gain_percent": None, "extended_cause": None,
           "ranking": [], "baselines": {}, "stiction": None, "loop_verdict": verdict, "notes": notes,
           "reading_notes": notes}
    if figure_dir:
        from .figures import plot_record

        rep["figure"] = str(plot_record(run, rep, figure_dir))
    return rep


def diagnose_file_segments(path: str, columns: records.ColumnMap | None = None, settings: Settings | None = None,
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


# ---- long records (phfdi.loopdiag.windows) ---------------------------------------------------------
def diagnose_long(run: Record, settings: Settings, figure_dir: str | None = None) -> dict:
    """The report of a record longer than :data:`.windows.WHOLE_MAX` samples (:mod:`.windows`)."""
    where = run.metadata.get("file") or run.metadata.get("loop_tag") or "record"
    progress = _stderr_progress(where) if len(window_bounds(run)) > PROGRESS_EVERY else None
    windows = screen_windows(run, settings, progress)
    rc = record_call(windows)
    rep_w = representative(windows, rc["call"])
    sub = window_run(run, rep_w["start"], rep_w["stop"])
    rep = diagnose_run(sub, settings)
    if "error" in rep:
        return rep
    samples = sum(w["stop"] - w["start"] for w in windows)
    total = int(run.metadata.get("file_rows") or len(run))
    note = (f"record of {total} samples: {len(windows)} windows of up to {WINDOW} samples screened "
            f"({samples} samples, {100.0 * samples / total:.1f} %), evenly spread; stiction in {rc[STICTION]}, "
            f"undetermined in {rc[UNDETERMINED]}, no stiction in {rc[NO_STICTION]} of {rc['scored']} scored windows; "
            f"valve models and this report: samples {rep_w['start']}-{rep_w['stop'] - 1}")
    rep["samples"] = total
    rep["windows"] = {**rc, "report_window": [rep_w["start"], rep_w["stop"]], "samples_screened": samples}
    rep["notes"] = list(run.metadata.get("notes") or []) + [note] + list(rep.get("notes") or [])
    rep["reading_notes"] = list(run.metadata.get("notes") or [])
    _apply_record_call(rep, rc)
    if figure_dir:  # the report window's trends under the record's verdict
        from .figures import plot_record

        rep["figure"] = str(plot_record(sub, rep, figure_dir))
    return rep


def _apply_record_call(rep: dict, rc: dict) -> None:
    """The record's call in the report's one verdict (the representative window's evidence stays)."""
    lv = rep.get("loop_verdict") or {}
    if rc["scored"] == 0 or rep.get("stiction") is None:
        return
    rep["stiction"]["verdict"] = rc["call"]
    structure = lv.get("structure") or {}
    check = LoopCheck(None, list(structure.get("reasons") or []))
    rep["loop_verdict"] = loop_verdict(check, rep)
    head = (f"{rc[STICTION]} of {rc['scored']} windows call stiction (stiction from {rc['critical']}, the count "
            f"{WINDOW_ALPHA:.0%} of healthy loops would reach at a {rc['false_rate_assumed']:.0%} false-call rate "
            "per window)")
    rep["loop_verdict"]["evidence"].insert(0, head)


def _stderr_progress(where: str):
    def show(done: int, total: int) -> None:
        print(f"loop-diagnose: {where}: screened {done}/{total} windows", file=sys.stderr, flush=True)
    return show

