"""Seed files for the fuzz tests: real measured records (../shared/data, cut short), a short run of the project
written as CSV, Parquet and MCAP, and the shipped files (scenarios and column maps in YAML, the physics reference in JSON)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from tests.conftest import ROOT, SHARED_DATA

#: a short paper loop (the fuzz runs and what the commands simulate beside them)
SHORT = ["duration_s=150", "setpoints.ph.changes=[{at_s: 50, value: 8.0}]"]
#: data rows kept of each real file (enough for every command's minimum, small enough to be quick)
ROWS = 160


def _head(src: Path, dst: Path, lines: int) -> Path:
    with open(src, "rb") as fh:
        dst.write_bytes(b"".join(fh.readline() for _ in range(lines)))
    return dst


@pytest.fixture(scope="session")
def seeds(tmp_path_factory) -> dict[str, Path]:
    """name -> seed file; the real records only when ../shared/data is there."""
    from phfdi.bagio import write_run
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    out = tmp_path_factory.mktemp("seeds")
    run = simulate(load_scenario("paper", fault="healthy", overrides=SHORT))
    files = {"run.csv": run.to_csv(out / "run.csv"), "run.parquet": run.to_parquet(out / "run.parquet"),
             "run.mcap": write_run(run, out / "run.mcap")}
    for name, src in (("scenario.yaml", ROOT / "src/phfdi/scenarios/paper.yaml"),
                      ("map.yaml", ROOT / "src/phfdi/diagnosis/maps/ph_rig.yaml"),
                      ("reference.json", ROOT / "src/wavelet_fdi/calibrations/paper_physics.json")):
        files[name] = Path(shutil.copy(src, out / name))
    (out / "loopmap.yaml").write_text("columns: {time: timestamp, op: X.MV, pv: X.PV, sp: X.SV}\nloop_tag: X\n")
    files["loopmap.yaml"] = out / "loopmap.yaml"
    if SHARED_DATA.is_dir():
        real = {"ph_rig.csv": next(iter(sorted((SHARED_DATA / "ph_rig").glob("*.csv")))),
                "skab.csv": SHARED_DATA / "skab" / "valve1" / "0.csv",
                "loop.txt": next(iter(sorted((SHARED_DATA / "plant_loops" / "stiction").glob("*.txt"))))}
        for name, src in real.items():
            if src.is_file():
                files[name] = _head(src, out / name, ROWS + 5)
    return files
