"""Plant-wide loop-diagnose: folders and wide exports on a local Dask cluster, one table, the worst loops."""

from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from phfdi.cli import main
from phfdi.loopdiag.plantwide import Job, diagnose_jobs, expand, wide_loops
from phfdi.loopdiag.synthetic import SyntheticLoop, simulate_loop

FAST = ["--causes", "backlash", "--no-baselines"]


def _loop(tag: str, stiction: bool, seed: int):
    return simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}) if stiction else None,
                                       ti_s=30, dt_s=4.0, duration_s=1600, setpoint_steps=[(100, 51)],
                                       load_ar_std=0.5 if not stiction else 0.0, seed=seed, loop_tag=tag))


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("plant")
    for k, st in enumerate((True, False, True, False)):
        _loop(f"FIC{k}", st, k).to_csv(d / f"FIC{k}.csv")
    return d


def test_four_loops_through_a_local_dask_cluster(folder, tmp_path, capsys):
    t0 = time.perf_counter()
    status = main(["loop-diagnose", str(folder), "--out", str(tmp_path / "out"), "--workers", "1", *FAST])
    elapsed = time.perf_counter() - t0
    out, err = capsys.readouterr()
    assert status == 0, err
    table = pq.read_table(tmp_path / "out" / "loops.parquet").to_pylist()
    assert sorted(r["loop_tag"] for r in table) == ["FIC0", "FIC1", "FIC2", "FIC3"]
    assert all(r["error"] is None and 0.0 <= r["stiction_probability"] <= 1.0 for r in table)
    with open(tmp_path / "out" / "loops.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 4
    worst = (tmp_path / "out" / "worst_loops.txt").read_text()
    ranked = [ln.split()[1] for ln in worst.splitlines()[2:]]
    assert len(ranked) == 4
    probs = {r["loop_tag"]: r["stiction_probability"] for r in table}
    assert [probs[t] for t in ranked] == sorted(probs.values(), reverse=True)
    # the limit cycles of the sticky valves rank above the healthy loops under a load
    assert set(ranked[:2]) == {"FIC0", "FIC2"}
    assert "4/4 loops" in err
    print(f"4 loops through Dask in {elapsed:.1f} s")


def test_wide_export_is_one_job_per_loop(tmp_path):
    runs = {tag: _loop(tag, tag == "FIC2", i) for i, tag in enumerate(("FIC1", "FIC2"))}
    path = tmp_path / "export.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["Timestamp"] + [f"{t}.{r}" for t in runs for r in ("OP", "PV", "SP")])
        n = len(runs["FIC1"])
        for k in range(n):
            w.writerow([runs["FIC1"].time_s[k]] + [f"{runs[t][s][k]:.6g}" for t in runs for s in ("op_pct", "pv", "sp")])
    assert set(wide_loops(["Timestamp", "A.OP", "A.PV", "B.MV", "B.PV", "B.SV", "C.PV"])) == {"A", "B"}
    jobs = expand([str(path)])
    assert [j.loop_tag for j in jobs] == ["FIC1", "FIC2"]
    reports = diagnose_jobs(jobs, workers=1, processes=False)
    assert [r["loop_tag"] for r in reports] == ["FIC1", "FIC2"]
    for tag, rep in zip(("FIC1", "FIC2"), reports):
        assert "error" not in rep
        assert rep["samples"] == len(runs[tag])
        assert np.isclose(rep["sample_time_s"], 4.0)


def test_unreadable_job_is_a_row_with_its_error(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    rep = diagnose_jobs([Job(str(bad))], workers=1, processes=False)[0]
    assert "error" in rep and str(bad) in rep["error"]


def test_empty_folder_is_one_line(tmp_path, capsys):
    assert main(["loop-diagnose", str(tmp_path)]) == 2
    assert "no .txt, .csv, .parquet files" in capsys.readouterr().err


def test_each_stretch_is_a_row_with_its_lines(folder, tmp_path):
    """A gap in PV cuts a record in two (the historian reader); with --segments each both stretches
    are rows of the table, each with its source lines, next to the other files' loops."""
    run = _loop("FIC9", True, 9)
    run.signals["pv"][150:170] = float("nan")
    gap = run.to_csv(tmp_path / "FIC9.csv")
    other = folder / "FIC1.csv"
    status = main(["loop-diagnose", str(gap), str(other), "--segments", "each", "--out", str(tmp_path / "out"),
                   "--workers", "1", *FAST])
    assert status == 0
    rows = pq.read_table(tmp_path / "out" / "loops.parquet").to_pylist()
    fic9 = [r for r in rows if r["loop_tag"] == "FIC9"]
    assert len(fic9) == 2 and all(r["error"] is None for r in fic9)
    assert [r["samples"] for r in fic9] == [150, len(run) - 170]
    assert all(r["lines"] for r in fic9) and fic9[0]["lines"] != fic9[1]["lines"]
    assert [r["loop_tag"] for r in rows].count("FIC1") == 1


def test_loops_in_chunks_per_task_keep_their_order_and_progress(folder, tmp_path):
    """Several loops per Dask task (what thousands of loops use): the same reports in job order as
    one loop per task, and progress counted in loops."""
    bad = tmp_path / "bad.csv"
    bad.write_text("a,b\n1,2\n")
    jobs = expand([str(folder)]) + [Job(str(bad))]
    seen = []
    one = diagnose_jobs(jobs, workers=1, processes=False, chunk=1)
    chunked = diagnose_jobs(jobs, workers=1, processes=False, chunk=2, progress=lambda d, t: seen.append((d, t)))
    assert [r["file"] for r in chunked] == [j.path for j in jobs]
    assert [r.get("stiction", {}).get("probability") for r in chunked] == \
        [r.get("stiction", {}).get("probability") for r in one]
    assert "error" in chunked[-1]
    assert sorted(seen) == [(2, 5), (4, 5), (5, 5)]


def test_progress_every_5_percent_when_loops_arrive_in_chunks(capsys):
    from phfdi.commands.loop_diagnose import _progress

    show = _progress(1000)
    for done in [*range(16, 1000, 16), 1000]:  # 16 loops per task, the last task shorter
        show(done, 1000)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 20 and lines[0] == "loop-diagnose: 64/1000 loops" and lines[-1].endswith("1000/1000 loops")


def test_an_empty_or_broken_file_in_a_folder_is_a_row_not_the_end(folder, tmp_path, capsys):
    """One empty CSV (and one that is not a loop) among good loops: each failure is a row with its reason, the
    others are diagnosed, the exit status is 1 (some failed), no traceback."""
    import shutil

    mixed = tmp_path / "mixed"
    shutil.copytree(folder, mixed)
    (mixed / "empty.csv").write_bytes(b"")
    (mixed / "notes.csv").write_text("remark\nvalve serviced\n")
    status = main(["loop-diagnose", str(mixed), "--out", str(tmp_path / "out"), "--workers", "1", *FAST])
    out, err = capsys.readouterr()
    assert status == 1, err
    assert "Traceback" not in err
    rows = {Path(r["file"]).name: r for r in pq.read_table(tmp_path / "out" / "loops.parquet").to_pylist()}
    assert sorted(rows) == ["FIC0.csv", "FIC1.csv", "FIC2.csv", "FIC3.csv", "empty.csv", "notes.csv"]
    assert "empty file" in rows["empty.csv"]["error"] and rows["notes.csv"]["error"]
    assert all(rows[f"FIC{k}.csv"]["error"] is None for k in range(4))
