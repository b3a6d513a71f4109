"""Rig records: a simulated run written in the rig's own CSV format, and a recorded run's command profile.

The format is the recorded files' (``../shared/data/ph_rig``), byte for byte in its layout: the same header,
``Time`` as the logging PC's wall clock (``2/24/2025 12:56:28 PM `` with its trailing space),
``ElapsedTime (s)`` with spaces around it and 15 significant digits (the recorded values are differences of
the logger's uptime clock, whose rounding shows in the last digits: the simulation's are made the same way),
commands and flows with 2 decimals, pH and T_Room with 2, four empty trailing columns, ``\\n`` line ends. So
``phfdi.learned.read_measured(path, shipped_map("ph_rig"))`` and every command with ``--map ph_rig`` read it
unchanged.
"""

from __future__ import annotations

import json
import math
from datetime import timedelta
from pathlib import Path

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.outputs import refuse_existing, staged

from .simulate import RigRun

HEADER = 'Time, ElapsedTime (s),"%, Acid","%, Base","Acid Flow, mL/s","Base Flow, mL/s","pH","T_Room",,,,'


def _clock(when) -> str:
    hour = when.hour % 12 or 12
    return f"{when.month}/{when.day}/{when.year} {hour}:{when.minute:02d}:{when.second:02d} " \
           f"{'AM' if when.hour < 12 else 'PM'} "


def _elapsed_texts(run: RigRun) -> list[str]:
    """ElapsedTime as the logger writes it: (uptime + t) - uptime, 15 significant digits."""
    up = run.uptime_s
    return [f" {((up + t) - up):.15g} " for t in run.time_s.tolist()]


def csv_text(run: RigRun) -> str:
    """The run as the rig's CSV (see the module docstring).

    Examples
    --------
    >>> from phfdi.rigsim import HEADER, csv_text, simulate_run
    >>> lines = csv_text(simulate_run("shared_add_base", seed=1, duration_s=20.0)).splitlines()
    >>> lines[0] == HEADER, lines[1].count(","), lines[1].endswith(",,,,")
    (True, 11, True)
    """
    elapsed = _elapsed_texts(run)
    rows = [HEADER]
    whole_s = run.clock_start.replace(microsecond=0)
    frac = run.clock_start.microsecond / 1e6
    last_second, stamp = None, ""
    for k in range(len(run)):
        second = int(math.floor(frac + float(run.time_s[k])))
        if second != last_second:
            stamp, last_second = _clock(whole_s + timedelta(seconds=second)), second
        rows.append(f"{stamp},{elapsed[k]},{run.acid_pct[k]:.2f},{run.base_pct[k]:.2f},"
                    f"{run.acid_flow_ml_s[k]:.2f},{run.base_flow_ml_s[k]:.2f},{run.ph[k]:.2f},"
                    f"{run.room_temp_c[k]:.2f},,,,")
    return "\n".join(rows) + "\n"


def sidecars(out: str | Path) -> tuple[Path, Path]:
    """Beside ``out``: ``OUT.rigsim.json`` (what made the run) and ``OUT.fault.json`` (a probe fault's truth,
    in ``phfdi inject``'s format)."""
    out = Path(out)
    return out.with_name(out.name + ".rigsim.json"), out.with_name(out.name + ".fault.json")


def write_run(run: RigRun, out: str | Path, overwrite: bool = False) -> list[Path]:
    """Write the run's CSV and its sidecars atomically (:mod:`phfdi_base.outputs`); returns the paths written.

    Nothing is replaced without ``overwrite`` (checked for every file before any is written); the sidecars
    are placed first, then the CSV, so a CSV never stands without its truth; a failure removes what this call
    placed. A fault-free run removes a stale ``OUT.fault.json`` only with ``overwrite``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.rigsim import simulate_run, write_run
    >>> out = Path(tempfile.mkdtemp()) / "run.csv"
    >>> [p.name for p in write_run(simulate_run("slow_rise", seed=1, duration_s=60.0), out)]
    ['run.csv', 'run.csv.rigsim.json']
    >>> try:
    ...     write_run(simulate_run("slow_rise", seed=2, duration_s=60.0), out)
    ... except Exception as exc:
    ...     print(str(exc).endswith("exists; give --overwrite to replace it"))
    True
    """
    out = Path(out)
    meta_path, fault_path = sidecars(out)
    targets = [out, meta_path] + ([fault_path] if run.fault is not None else [])
    for target in targets:
        refuse_existing(target, overwrite)
    if run.fault is None and fault_path.exists() and not overwrite:
        raise UserError(f"{fault_path} exists (a probe fault's truth for an earlier {out.name}); give --overwrite "
                        f"to replace the run and remove it")
    placed: list[Path] = []
    try:
        with staged(out, overwrite) as tmp:
            tmp.write_text(csv_text(run), encoding="utf-8", newline="")
            for path, data in ((meta_path, run.meta()), (fault_path, run.fault)):
                if data is None:
                    continue
                with staged(path, overwrite) as side:
                    side.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
                placed.append(path)
    except BaseException:
        for path in placed:  # no truth without its run
            path.unlink(missing_ok=True)
        raise
    if run.fault is None:
        fault_path.unlink(missing_ok=True)  # a stale truth must not describe the new run
    return [out, *placed]


def command_profile(path: str | Path) -> dict:
    """A recorded rig run's operation: its first reading, duration, first ElapsedTime and the change points
    of its pump commands (s from its start, acid %, base %), for replaying it in the simulation.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.rigsim.record import HEADER, command_profile
    >>> path = Path(tempfile.mkdtemp()) / "run.csv"
    >>> rows = [f"1/1/2025 1:00:0{k} PM , {1 + 0.35 * k} ,0.00,{20 if k < 3 else 50:.2f},0.00,0,{3 + k / 10:.2f},"
    ...         f"22.00,,,," for k in range(6)]
    >>> _ = path.write_text(HEADER + "\\n" + "\\n".join(rows) + "\\n")
    >>> p = command_profile(path)
    >>> p["start_ph"], p["profile"]
    (3.0, [[0.0, 0.0, 20.0], [1.05, 0.0, 50.0]])
    """
    from phfdi.records import ColumnMap, read_record

    cmap = ColumnMap.from_mapping({"time_s": "ElapsedTime (s)", "acid_command_pct": "%, Acid",
                                   "base_command_pct": "%, Base", "ph_measured": "pH"})
    rec = read_record(path, cmap)
    t = np.asarray(rec.time_s, dtype=float)
    acid, base = rec.signals["acid_command_pct"], rec.signals["base_command_pct"]
    if len(t) < 2 or not np.all(np.isfinite(acid)) or not np.all(np.isfinite(base)):
        raise UserError(f"{path}: a replay needs at least two rows and every pump command")
    change = np.flatnonzero((np.diff(acid) != 0) | (np.diff(base) != 0)) + 1
    rows = np.r_[0, change]
    profile = [[round(float(t[k] - t[0]), 3), float(acid[k]), float(base[k])] for k in rows]
    ph = np.asarray(rec.signals["ph_measured"], dtype=float)
    return {"start_ph": float(ph[np.isfinite(ph)][0]), "duration_s": round(float(t[-1] - t[0]), 3),
            "start_elapsed_s": round(float(t[0]), 3), "profile": profile}
