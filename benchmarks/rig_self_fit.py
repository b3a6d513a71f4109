"""Can a candidate reproduce a rig run's shape at all? Each candidate fitted on ALL samples of one run (in-sample).

`phfdi diagnose --data RUN` fits on interleaved blocks and scores the others; a feature that lies in one held-out
block (the April titration's passage pH 9 -> 5 lies in block 6 of 8) is then never fitted, and a candidate that
could reproduce it is not seen to. This script asks the capacity question instead: every named candidate (and the
nominal model) fitted by the diagnosis's own fitter (start grid, least squares, the record's start pH as a
nuisance) on every sample of the run, and then, on those same samples, the RMSE overall and per measured-pH band
(acidic < 5, transition 5..9, basic > 9) and each passage through pH 5..9 (``phfdi.diagnosis.evidence``).

These are in-sample numbers: they say what a model class CAN do on this run, not what it predicts on another
(``benchmarks/rig_holdout.py`` measures that).

    .venv/bin/python benchmarks/rig_self_fit.py --run 2025.04.07 --candidates flask_contents buffer carbonate
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

from phfdi.diagnosis.data import diagnosis_map, load_record
from phfdi.diagnosis.evidence import BANDS, passages
from phfdi.diagnosis.fit import Fitter, Problem, one_blas_thread
from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.pipeline import context_for
from phfdi.diagnosis.residual import noise_floor
from phfdi.records import ColumnMap

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "src" / "phfdi" / "diagnosis" / "maps" / "ph_rig.yaml"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=None, help="the ph_rig folder (default $PHFDI_SHARED_DATA/ph_rig)")
    ap.add_argument("--run", required=True, help="the run: a file name prefix, e.g. 2025.04.07")
    ap.add_argument("--candidates", nargs="+", required=True)
    ap.add_argument("--dt", type=float, default=1.0)
    args = ap.parse_args(argv)
    folder = args.data or Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data")) / "ph_rig"
    files = [f for f in sorted(folder.glob("*.csv")) if f.name.startswith(args.run)]
    if len(files) != 1:
        print(f"rig_self_fit: {len(files)} runs in {folder} start with {args.run!r}", file=sys.stderr)
        return 2
    rec = load_record(files[0], diagnosis_map(ColumnMap.load(MAP)), args.dt)
    nominal = nominal_raw("rig_flask")
    y, t = rec.outputs["ph_measured"], rec.time_s - rec.time_s[0]
    every = np.ones(len(rec), bool)
    noise = {"ph_measured": noise_floor(y)}
    problem = Problem([rec], nominal, "fit", [every], [every], noise, {"ph_measured": float(np.std(y))},
                      ["ph_measured"], context_for(nominal, [rec], ["ph_measured"]), args.candidates)
    with one_blas_thread():
        fitter = Fitter(problem)
        fits = [fitter.nominal()] + [fitter.fit([c]) for c in fitter.candidates.values()]
    print(f"{rec.name}: every sample fitted and scored (in-sample), {len(rec)} samples at {rec.dt_s:g} s; "
          f"measured passages pH 5-9: {_passages(t, y)}\n")
    print("| model | fitted parameters | in-sample RMSE (pH) | acidic / transition / basic (pH) | passages pH 5-9 (s) |")
    print("| --- | --- | ---: | --- | --- |")
    for r in sorted(fits, key=lambda r: r.val_cost):
        p = fitter.predict(0, r.record_raws[0] if r.record_raws else r.raw, r.starts[0]).outputs["ph_measured"]
        bands = " / ".join(_band_rmse(y, p, lo, hi) for _, lo, hi in BANDS)
        params = ", ".join(f"{k.split('[')[0]} {v:.4g}" for k, v in r.params.items()) or "-"
        print(f"| {r.label if r.label != 'none' else 'nominal'} | {params} | {np.sqrt(np.mean((p - y) ** 2)):.3f} | "
              f"{bands} | {_passages(t, p)} |")
    return 0


def _band_rmse(y: np.ndarray, p: np.ndarray, lo: float, hi: float) -> str:
    m = (y >= lo) & (y < hi)
    return f"{np.sqrt(np.mean((p[m] - y[m]) ** 2)):.2f}" if m.sum() >= 10 else "-"


def _passages(t: np.ndarray, y: np.ndarray) -> str:
    return ", ".join(f"{d:.0f} ({'down' if s < 0 else 'up'})" for d, s in passages(t, y)) or "none"


if __name__ == "__main__":
    sys.exit(main())
