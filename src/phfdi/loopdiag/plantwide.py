"""Plant-wide loop diagnosis: many loops on Dask, one table, the worst loops first.

Inputs are files, folders (every historian export below them: ``.txt``, ``.csv``, ``.parquet``; the formats
registered in :mod:`phfdi.records.formats`) and wide historian
exports: a CSV whose header holds the tags of several loops (``<tag>.OP``/``.MV``, ``.PV``,
``.SP``/``.SV``, optionally ``.MODE``) becomes one job per loop tag. Each job is read and diagnosed
on a Dask worker (:mod:`.dask_run`: a LocalCluster by default, ``--scheduler`` for a running one).

The table has one row per loop record: the stiction classifier's verdict and probability, Kano's S
and J from the Hammerstein fit, the oscillation, the Hammerstein cause, the three strongest pieces
of evidence and the reading notes. :func:`worst_loops` ranks by the stiction probability (ties: the
more regular oscillation first).
"""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from phfdi import records
from phfdi.records.formats import firsts, historian_suffixes, is_format
from phfdi.records.sources import refuse_nul_filled
from phfdi_base.errors import UserError
from phfdi_base.outputs import staged, write_text

from .diagnose import Settings
from .readers import loop_column_map, read_loop

_ROLE = {"OP": "op", "MV": "op", "OUT": "op", "PV": "pv", "SP": "sp", "SV": "sp", "MODE": "mode"}
_TIME = ("time_s", "timestamp", "time", "datetime", "date", "tagname")


@dataclass(frozen=True)
class Job:
    """One loop to diagnose: a file, and for a wide export the columns of one loop."""

    path: str
    columns: records.ColumnMap | None = None
    loop_tag: str | None = None

    @property
    def label(self) -> str:
        return f"{self.path}[{self.loop_tag}]" if self.loop_tag else self.path


def wide_loops(header: list[str]) -> dict[str, dict[str, str]]:
    """Loop tag -> {op, pv[, sp][, mode]} column names, from ``<tag>.<ROLE>`` headers; only tags with OP and PV."""
    loops: dict[str, dict[str, str]] = {}
    for name in header:
        m = re.match(r"^(.+)[._]([A-Za-z]+)$", name.strip())
        if not m:
            continue
        role = _ROLE.get(m.group(2).upper())
        if role:
            loops.setdefault(m.group(1), {}).setdefault(role, name)
    return {tag: cols for tag, cols in loops.items() if "op" in cols and "pv" in cols}


def _csv_header(path: Path) -> list[str]:
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        first = fh.readline()
    delim = max((",", ";", "\t"), key=first.count)
    return next(csv.reader(io.StringIO(first), delimiter=delim), [])  # an empty file: no header, one plain job


def expand(inputs: list[str], columns: records.ColumnMap | None = None) -> list[Job]:
    """Jobs for files, folders and wide exports (a column map applies to every plain file)."""
    jobs: list[Job] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            suffixes = historian_suffixes()  # the formats registered as historian exports (phfdi.records.formats)
            files = sorted(f for f in p.rglob("*") if f.is_file() and f.suffix.lower() in suffixes)
            if not files:
                raise UserError(f"{item}: no {', '.join(firsts(suffixes))} files in this folder")
        else:
            files = [p]
        for f in files:
            jobs.extend(_jobs_of_file(f, columns))
    return jobs


def _jobs_of_file(f: Path, columns: records.ColumnMap | None) -> list[Job]:
    if columns is not None or not is_format(f, "csv") or not f.is_file():
        return [Job(str(f), columns)]
    try:
        refuse_nul_filled(f)  # a sparse file is one endless line: its job's reader refuses it in one line
        header = _csv_header(f)
    except (OSError, UserError):
        return [Job(str(f))]
    loops = wide_loops(header)
    if len(loops) < 2:
        return [Job(str(f))]
    time_col = next((h for h in header if h.strip().lower() in _TIME), None)
    return [Job(str(f), loop_column_map(c["op"], c["pv"], c.get("sp"), time_col, loop_tag=tag, mode=c.get("mode")),
                tag)
            for tag, c in sorted(loops.items())]


def diagnose_job(job: Job, settings: Settings | None = None, figure_dir: str | None = None,
                 each_segment: bool = False) -> list[dict]:
    """Reports of one job: its longest usable stretch, or with ``each_segment`` every stretch
    (``error`` set when it cannot be read or diagnosed); runs on a worker."""
    from .single import diagnose_file_segments, diagnose_run

    try:
        if each_segment:
            reps = diagnose_file_segments(job.path, job.columns, settings, figure_dir)
        else:
            run = read_loop(job.path, job.columns)
            if job.loop_tag:
                run.metadata["loop_tag"] = job.loop_tag
            reps = [diagnose_run(run, settings, figure_dir)]
    except UserError as exc:
        return [{"file": job.path, "loop_tag": job.loop_tag, "error": str(exc)}]
    except Exception as exc:  # noqa: BLE001 - one loop's failure is its row, never the plant-wide run's end
        return [{"file": job.path, "loop_tag": job.loop_tag,
                 "error": f"{job.path}: cannot be diagnosed ({type(exc).__name__}: {exc})"}]
    for r in reps:
        if job.loop_tag:
            r["loop_tag"] = job.loop_tag
    return reps


def _job_args(args: tuple) -> list[dict]:
    return diagnose_job(*args)


def diagnose_jobs(jobs: list[Job], settings: Settings | None = None, figure_dir: str | None = None,
                  scheduler: str | None = None, workers: int | None = None,
                  progress: Callable[[int, int], None] | None = None, processes: bool = True,
                  each_segment: bool = False, chunk: int | None = None) -> list[dict]:
    """Every job on Dask (one job in this process: no cluster for a single loop); reports in job order.
    ``chunk`` jobs per Dask task (None: :func:`.dask_run.chunk_size`, up to 16 for thousands of loops)."""
    from .dask_run import chunk_size, dask_client, map_ordered

    args = [(j, settings, figure_dir, each_segment) for j in jobs]
    if len(jobs) == 1 and not scheduler:
        nested = [_job_args(args[0])]
        if progress:
            progress(1, 1)
    else:
        with dask_client(scheduler, workers, processes) as client:
            size = chunk_size(len(args), client) if chunk is None else chunk
            nested = map_ordered(client, _job_args, args, progress, chunk=size)
    return [r for reps in nested for r in reps]


# ---- the table ---------------------------------------------------------------------------------
COLUMNS = ("file", "loop_tag", "lines", "samples", "sample_time_s", "process_type", "verdict", "verdict_summary",
           "stiction", "stiction_probability",
           "kano_s_pct", "kano_j_pct", "oscillating", "period_s", "regularity", "hammerstein_cause",
           "hammerstein_verdict", "gain_percent", "top_evidence", "notes", "error")


def table_row(rep: dict) -> dict:
    """One flat row of the plant-wide table."""
    row: dict[str, Any] = {c: None for c in COLUMNS}
    row["file"] = rep.get("file")
    row["loop_tag"] = rep.get("loop_tag")
    if rep.get("lines"):
        row["lines"] = f"{rep['lines'][0]}-{rep['lines'][1]}"
    if "error" in rep:
        row["error"] = rep["error"]
        return row
    osc = rep.get("oscillation") or {}
    st = rep.get("stiction") or {}
    lv = rep.get("loop_verdict") or {}
    top = [e for e in st.get("evidence", []) if e.get("measured")][:3]
    row.update({
        "samples": rep.get("samples"), "sample_time_s": rep.get("sample_time_s"),
        "process_type": rep.get("process_type"),
        "verdict": lv.get("verdict"), "verdict_summary": lv.get("summary"),
        "stiction": lv.get("verdict") == "stiction" if lv else None,
        "stiction_probability": st.get("probability"),
        "kano_s_pct": st.get("kano_s_pct"), "kano_j_pct": st.get("kano_j_pct"),
        "oscillating": osc.get("oscillating"), "period_s": osc.get("period_s"), "regularity": osc.get("regularity"),
        "hammerstein_cause": rep.get("cause"), "hammerstein_verdict": rep.get("verdict"),
        "gain_percent": rep.get("gain_percent"),
        "top_evidence": "; ".join(f"{e['feature']} {e['value']:.3g} ({e['contribution']:+.2f})" for e in top),
        "notes": " | ".join(dict.fromkeys([*(rep.get("reading_notes") or []), *(rep.get("notes") or [])])),
    })
    return row


def write_table(reports: list[dict], out_dir: str | Path) -> tuple[Path, Path]:
    """``loops.parquet`` and ``loops.csv`` in out_dir (one row per loop record)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = [table_row(r) for r in reports]
    cols = {c: [r[c] for r in rows] for c in COLUMNS}
    types = {"samples": pa.int64(), "sample_time_s": pa.float64(), "stiction": pa.bool_(),
             "stiction_probability": pa.float64(), "kano_s_pct": pa.float64(), "kano_j_pct": pa.float64(),
             "oscillating": pa.bool_(), "period_s": pa.float64(), "regularity": pa.float64(),
             "gain_percent": pa.float64()}
    table = pa.table({c: pa.array(v, type=types.get(c, pa.string())) for c, v in cols.items()})
    with staged(out / "loops.parquet", overwrite=True) as tmp:
        pq.write_table(table, tmp)
    text = io.StringIO(newline="")
    w = csv.DictWriter(text, fieldnames=COLUMNS)
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    write_text(out / "loops.csv", text.getvalue(), overwrite=True)
    return out / "loops.parquet", out / "loops.csv"


def worst_loops(reports: list[dict], n: int = 10) -> list[dict]:
    """Rows of the n scored loop records most likely to have a sticky valve (ties: more regular oscillation);
    records with no stiction score (PV frozen, not a closed loop) are not ranked."""
    rows = [table_row(r) for r in reports if "error" not in r and r.get("stiction")]
    rows.sort(key=lambda r: (-(r["stiction_probability"] or 0.0), -(r["regularity"] or 0.0)))
    return rows[:n]


def format_worst(reports: list[dict], n: int = 10) -> str:
    rows = worst_loops(reports, n)
    failed = sum("error" in r for r in reports)
    unscored = [r for r in reports if "error" not in r and not r.get("stiction")]
    lines = [f"worst loops ({len(rows)} of {len(reports) - failed} diagnosed"
             + (f", {failed} failed" if failed else "")
             + (f", {len(unscored)} not scored: PV frozen or not a closed loop" if unscored else "")
             + "), most likely stiction first:",
             f"{'rank':>4s}  {'loop':24s} {'file':34s} {'verdict':13s} {'p(stiction)':>11s} {'S %':>6s} {'J %':>6s} "
             f"{'period s':>8s}  evidence"]
    for k, r in enumerate(rows, 1):
        s = "-" if r["kano_s_pct"] is None else f"{r['kano_s_pct']:.2g}"
        j = "-" if r["kano_j_pct"] is None else f"{r['kano_j_pct']:.2g}"
        per = f"{r['period_s']:.0f}" if r["oscillating"] and r["period_s"] else "-"
        lines.append(f"{k:4d}  {str(r['loop_tag'])[:24]:24s} {Path(str(r['file'])).name[:34]:34s} "
                     f"{r['verdict']:13s} {r['stiction_probability']:11.2f} {s:>6s} {j:>6s} {per:>8s}  {r['top_evidence']}")
    if unscored:
        lines += ["not scored:", format_unscored(reports)]
    return "\n".join(lines)


def format_unscored(reports: list[dict]) -> str:
    """One line per record with no stiction score: its verdict and why."""
    return "\n".join(f"  {str(r.get('loop_tag'))[:24]:24s} {Path(str(r['file'])).name[:34]:34s} "
                     f"{r['loop_verdict']['summary']}"
                     for r in reports if "error" not in r and not r.get("stiction") and r.get("loop_verdict"))
