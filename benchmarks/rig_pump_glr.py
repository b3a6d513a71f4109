"""Can a likelihood-ratio test on the pumps tell a pump delivering other than recorded from a healthy rig run?

A measurement, not a detector: issue 21's one unmet point is the pumps (about a quarter of the injected pump
faults found at the larger size, leave-one-run-out). The estimator's adaptation absorbs a strength error at its
120 s pace and the detector watches the innovations; the test that fits the fault's own signature is the
generalised likelihood ratio (Willsky & Jones 1976; Basseville & Nikiforov 1993, ch. 7): at every evaluation time,
for every window ending there (``--windows`` samples) and every pump that ran in it, refit "the pump delivers c
times what is recorded since the window's start" (c in 0..3) with the model-trusting filter the fault naming uses
(wavelet_fdi.estimator_isolation: adaptation off, the rate and walk uncertainty cut tenfold, from the filter's
state at the window's start) and take the gain in log-likelihood over c = 1. The statistic is the largest gain.

Leave-one-run-out over the five shared runs (the fold's estimator fitted on the other four, as
benchmarks/rig_detection.py): the statistic's largest value on each held-out healthy run (what a threshold with no
false alarm must exceed), and on each run with a pump fault injected at the larger size (50 % less or more, stuck
at 3 mL/s; phfdi inject, the same onsets) its largest value before the onset and after it. Separable if the
faulty runs' values after their onsets exceed every healthy run's maximum and their own values before the onset.

    PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_pump_glr.py [--json out/rig_pump_glr.json]
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from phfdi.benchmarks.rig_detection import CHANNELS, injected_cases
from phfdi.commands.common import shipped_map
from phfdi.estimator import fit_estimator, start_from_model
from phfdi.learned import read_measured
from wavelet_fdi.estimator_isolation import PUMP_RANGE, STIFFNESS

EVERY_SAMPLES = 32  # evaluation times: every block


def pump_glr(ref, t: np.ndarray, rows: np.ndarray, windows: tuple[int, ...]) -> np.ndarray:
    """The largest pump log-likelihood gain of every window ending at each evaluation time (NaN before the first
    full window): (n_times,) at samples EVERY_SAMPLES, 2 EVERY_SAMPLES, ..."""
    # the fault naming's window filter (wavelet_fdi.estimator_isolation): adaptation off, model trusted
    quiet = replace(ref, adapt_time_constant_s=0.0,
                    noise=replace(ref.noise, rate_rel_std=ref.noise.rate_rel_std * STIFFNESS,
                                  walk_ph_per_sqrt_s=ref.noise.walk_ph_per_sqrt_s * STIFFNESS))

    def scaled(i: int, c: float):  # the hypothesis "pump i delivers c times what is recorded"
        return replace(quiet, feeds=tuple(replace(g, strength_mM=g.strength_mM * c) if j == i else g
                                          for j, g in enumerate(quiet.feeds)))

    # the adapted filter as it runs (the estimator's own state), forked at every evaluation time
    states = {}
    stream = ref.new_state()
    n = len(t)
    for k in range(0, n, EVERY_SAMPLES):
        states[k] = stream.fork()
        stream.residuals(t[k:k + EVERY_SAMPLES], rows[k:k + EVERY_SAMPLES])
    m = len(ref.feeds)
    out = np.full(n // EVERY_SAMPLES, np.nan)
    for e in range(len(out)):
        end = (e + 1) * EVERY_SAMPLES
        best = -np.inf
        for w in windows:
            a = end - w
            if a < EVERY_SAMPLES:
                continue
            tw, xw = t[a:end], rows[a:end]

            def nll(r):
                s = states[a].fork(r)
                s.residuals(tw, xw)
                return s.nll

            healthy = nll(quiet)
            for i in range(m):
                if not np.nanmax(np.abs(xw[:, i])) > 0:
                    continue
                res = minimize_scalar(lambda c: nll(scaled(i, c)), bounds=PUMP_RANGE, method="bounded",
                                      options={"xatol": 1e-2})
                best = max(best, healthy - float(res.fun))
        out[e] = best if np.isfinite(best) else np.nan
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--windows", type=int, nargs="+", default=[64, 128, 256])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    cmap = shipped_map("ph_rig")
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    recs = {p: read_measured(p, cmap, channels=list(CHANNELS)) for p in paths}
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for held in paths:
            model = fit_estimator([recs[q] for q in paths if q != held], start_from_model("rig_flask"))
            rec = recs[held]
            th = rec.time_s - rec.time_s[0]
            g = pump_glr(model.reference, th, rec.x, tuple(args.windows))
            at = float(th[(int(np.nanargmax(g)) + 1) * EVERY_SAMPLES - 1])
            ph_at = float(rec.x[(int(np.nanargmax(g)) + 1) * EVERY_SAMPLES - 1, -1])
            rows.append({"run": Path(held).name, "case": "healthy", "max": float(np.nanmax(g)), "at_s": at,
                         "ph_at": ph_at})
            print(f"{Path(held).name}: healthy, largest pump gain {np.nanmax(g):.1f} at {at:.0f} s (pH {ph_at:.2f}) "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)
            for truth, frec in injected_cases(held, rec, Path(tmp), cmap):
                if not truth["kind"].startswith("pump") or truth["size_rank"] != "larger":
                    continue
                tf = frec.time_s - frec.time_s[0]
                gf = pump_glr(model.reference, tf, frec.x, tuple(args.windows))
                times = tf[np.arange(1, len(gf) + 1) * EVERY_SAMPLES - 1]
                onset = truth["onset_s"] - float(frec.time_s[0])
                before = gf[times < onset]
                after = gf[times >= onset]
                rows.append({"run": Path(held).name, "case": truth["kind"], "pump": truth.get("pump"),
                             "onset_s": truth["onset_s"],
                             "max_before": float(np.nanmax(before)) if np.isfinite(before).any() else None,
                             "max_after": float(np.nanmax(after)) if np.isfinite(after).any() else None})
                print(f"  {truth['kind']} {truth.get('pump')} at {truth['onset_s']:.0f} s: before "
                      f"{rows[-1]['max_before']}, after {rows[-1]['max_after']}", flush=True)
    healthy_max = max(r["max"] for r in rows if r["case"] == "healthy")
    faulty = [r for r in rows if r["case"] != "healthy"]
    above = [r for r in faulty if r["max_after"] is not None and r["max_after"] > healthy_max
             and (r["max_before"] is None or r["max_before"] <= healthy_max)]
    print(f"largest healthy value {healthy_max:.1f}; pump cases above it after the onset and not before: "
          f"{len(above)} of {len(faulty)}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"windows": args.windows, "rows": rows, "healthy_max": healthy_max}, indent=1))


if __name__ == "__main__":
    main()
