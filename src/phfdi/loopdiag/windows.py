"""Long records: screened in windows of the training loops' length, bounded in time and memory.

The classifier learned from records of :data:`WINDOW` samples (the refinery exports' length), and every step of
the diagnosis costs at least its record's length (the valve-model fits more), so a record of a million samples is
not diagnosed whole. A record longer than :data:`WHOLE_MAX` samples is cut into windows of :data:`WINDOW`
samples; at most :data:`MAX_WINDOWS` of them, spread evenly over the record, are screened (the structure checks,
the indicators, the calibrated p and its call), and the record's verdict is read from the windows' calls:

* **stiction** when at least ``k`` windows call stiction, ``k`` the smallest count that windows of a loop without
  stiction would reach with probability at most :data:`WINDOW_ALPHA`, each window taken as an independent test
  with the false-call rate of the classifier's operating point on the simulated calibration loops (windows of one
  loop are not independent: the count is a guide, stated with the answer);
* **undetermined** when fewer do but stiction and undetermined windows together are at least half;
* **no stiction** otherwise; and when no window is a closed loop to score, the structure verdict most windows
  had (PV frozen, not a closed loop).

The valve-model fit then runs on one window (the stiction window with the highest p, or the window with the
median p), and the report is that window's, with the record's length, the windows' counts and a note saying
what was screened. A file too long to read whole arrives already as windows (:func:`.readers.read_loop`), which
are screened the same way.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import binom

from phfdi.records.record import Record

from .classifier import NO_STICTION, SIM_FALSE_CALL, STICTION, UNDETERMINED
from .diagnose import Settings
from .features import screen_evidence, stiction_verdict
from .loopcheck import check_loop

#: the length of a window (samples), the training loops'
WINDOW = 751
#: records up to this many samples are diagnosed whole
WHOLE_MAX = 2 * WINDOW
#: at most this many windows are screened per record
MAX_WINDOWS = 64
#: the level of the count rule (module docstring)
WINDOW_ALPHA = 0.01
#: windows screened before a progress line is printed (long records only)
PROGRESS_EVERY = 16


def window_bounds(run: Record) -> list[tuple[int, int]]:
    """(start, stop) sample indices of the windows to screen: the stretches a sampled file was read as
    (``metadata["windows"]``), else windows of :data:`WINDOW` samples; at most :data:`MAX_WINDOWS`, evenly
    spread."""
    given = run.metadata.get("windows")
    if given:
        bounds = [(int(a), int(b)) for a, b, *_ in given]
    else:
        n = len(run)
        count = max(1, n // WINDOW)
        starts = np.linspace(0, n - WINDOW, count).round().astype(int) if count > 1 else np.array([0])
        bounds = [(int(a), int(min(a + WINDOW, n))) for a in starts]
    if len(bounds) > MAX_WINDOWS:
        pick = np.linspace(0, len(bounds) - 1, MAX_WINDOWS).round().astype(int)
        bounds = [bounds[i] for i in pick]
    return bounds


def window_run(run: Record, a: int, b: int) -> Record:
    """Samples a..b-1 of a run, with its metadata (a copy)."""
    meta = dict(run.metadata)
    meta.pop("windows", None)
    meta["notes"] = []
    return Record.of({"time_s": run.time_s[a:b].copy(), **{k: v[a:b].copy() for k, v in run.signals.items()}}, meta)


def critical_count(m: int, false_rate: float = SIM_FALSE_CALL, alpha: float = WINDOW_ALPHA) -> int:
    """The least number of stiction windows among ``m`` that loops without stiction reach with probability at
    most ``alpha`` (binomial, windows independent): binom.sf(k - 1, m, false_rate) <= alpha."""
    for k in range(1, m + 1):
        if binom.sf(k - 1, m, false_rate) <= alpha:
            return k
    return m + 1


def screen_windows(run: Record, settings: Settings, progress=None) -> list[dict]:
    """Per window: its bounds, the structure check and, for a closed loop, the screen's p and call."""
    process_type = settings.process_type or run.metadata.get("process_type", "self_regulating")
    out = []
    bounds = window_bounds(run)
    for k, (a, b) in enumerate(bounds):
        w = window_run(run, a, b)
        sp = w["sp"] if "sp" in w else None
        check = check_loop(w["op_pct"], w["pv"], sp)
        item = {"start": a, "stop": b, "structure": check.verdict, "call": None, "probability": None}
        if check.verdict is None:
            st = stiction_verdict(screen_evidence(w["op_pct"], w["pv"], sp, w.dt_s, process_type))
            item.update(call=st["verdict"], probability=st["probability"])
        out.append(item)
        if progress and ((k + 1) % PROGRESS_EVERY == 0 or k + 1 == len(bounds)):
            progress(k + 1, len(bounds))
    return out


def record_call(windows: list[dict]) -> dict:
    """The record's call from its windows' (module docstring), with the counts behind it."""
    scored = [w for w in windows if w["call"] is not None]
    counts = {c: sum(w["call"] == c for w in scored) for c in (STICTION, UNDETERMINED, NO_STICTION)}
    m = len(scored)
    out = {"windows": len(windows), "scored": m, **counts, "critical": critical_count(m) if m else None,
           "false_rate_assumed": SIM_FALSE_CALL, "alpha": WINDOW_ALPHA}
    if not m:
        kinds = [w["structure"] for w in windows]
        out["call"] = max(set(kinds), key=kinds.count)
    elif counts[STICTION] >= out["critical"]:
        out["call"] = STICTION
    elif counts[STICTION] + counts[UNDETERMINED] >= 0.5 * m:
        out["call"] = UNDETERMINED
    else:
        out["call"] = NO_STICTION
    return out


def representative(windows: list[dict], call: str) -> dict:
    """The window the valve models are fitted on and the report is read from: the stiction window with the
    highest p when the record's call is stiction, else the scored window with the median p (the first when none
    is scored)."""
    scored = [w for w in windows if w["call"] is not None]
    if not scored:
        return windows[0]
    if call == STICTION:
        return max((w for w in scored if w["call"] == STICTION), key=lambda w: w["probability"])
    ordered = sorted(scored, key=lambda w: w["probability"])
    return ordered[len(ordered) // 2]
