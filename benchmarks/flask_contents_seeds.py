"""The flask's-contents hidden-effect test over many seeds: how often is the cause named, how close are pKa and amount?

Replays the procedure of ``tests/diagnosis/test_hidden_structure.py::test_flask_contents_are_named_with_their_pka_and_amount``
(and, with ``--control``, of its control) for consecutive seeds: the record is simulated with the effect hidden, only
its CSV (time, both pump flows, pH) reaches `phfdi diagnose`, and the answer is compared with the truth here.

    .venv/bin/python benchmarks/flask_contents_seeds.py --seeds 200 240
    .venv/bin/python benchmarks/flask_contents_seeds.py --seeds 300 320 --control
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "diagnosis"))

import test_hidden_structure as case  # noqa: E402  (the test's own case generator)

from phfdi.cli import main as phfdi  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs=2, default=(200, 240), metavar=("FIRST", "STOP"))
    ap.add_argument("--control", action="store_true", help="no effect hidden (the control: `none` expected)")
    args = ap.parse_args(argv)
    passed = 0
    for seed in range(*args.seeds):
        rng = np.random.default_rng(seed)
        tmp = Path(tempfile.mkdtemp())
        edit: dict = {}
        path, _, pka, tol = case.make_case(rng, "none" if args.control else "flask_contents", tmp / "data", edit,
                                           balanced=True)
        out = io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
            phfdi(["diagnose", "--data", str(path), "--model", "rig_flask", "--set", case.NOMINAL[0], "--initial",
                   "fit", "--candidates", *case.CONTENTS, "--no-pairs", "--out", str(tmp / "report"), "--json",
                   "--quiet"])
        rep = json.loads(out.getvalue())
        if args.control:
            ok = rep["verdict"] == "none"
            print(f"{seed}: {rep['verdict']} {rep['cause']}", flush=True)
        else:
            conc = [v for k, v in rep["parameters"].items() if k.startswith("conc_mol_l[")]
            truth = edit["contents"][0]
            fitted = rep["parameters"].get("pka", float("nan"))
            ok = (rep["cause"] == "flask_contents" and rep.get("fixed", {}).get("species") == "weak_acid"
                  and (rep["verdict"] == "explained" or rep["validation_rmse_over_noise"] < 5.0)
                  and abs(fitted - pka) <= tol and len(conc) == 1 and abs(conc[0] - truth) <= 0.1 * truth)
            print(f"{seed}: {rep['verdict']} {rep['cause']} {rep.get('fixed')}; pKa {fitted:.3f} (true {pka:.3f}), "
                  f"amount {conc[0] * 1e3 if conc else float('nan'):.4f} mM (true {truth * 1e3:.4f}); held-out "
                  f"{rep.get('validation_rmse_over_noise', float('nan')):.2f} x the floor, nominal "
                  f"{rep['nominal']['combined_rmse_over_noise']:.1f} x{'' if ok else '  FAIL'}", flush=True)
        passed += ok
    print(f"{passed} / {args.seeds[1] - args.seeds[0]} pass the test's rule")
    return 0


if __name__ == "__main__":
    sys.exit(main())
