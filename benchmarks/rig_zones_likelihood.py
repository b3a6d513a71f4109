"""What the estimator's pH zones gain on the real rig: held-out innovations' log-likelihood per sample.

Leave-one-run-out over the five shared rig runs: the estimator (wavelet_fdi.reference_estimator) is fitted on four
runs with one strength factor per pump for every pH (``adapt_zones_ph=()``) and with the default zones (pH 5 and
9), and the fifth run goes through a fresh filter of each. Printed per held-out run: the mean log-likelihood per
sample of its innovations (higher is better) and the fitted rate uncertainty and walk.

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rig_zones_likelihood.py   (about 2 minutes)
"""

from __future__ import annotations

import argparse
import glob
import os
from dataclasses import replace
from pathlib import Path

from phfdi.benchmarks.rig_detection import CHANNELS
from phfdi.commands.common import shipped_map
from phfdi.estimator import start_from_model
from phfdi.learned import read_measured
from wavelet_fdi.estimator_fit import fit_reference
from wavelet_fdi.reference_estimator import ADAPT_ZONES_PH


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    args = ap.parse_args()
    cmap = shipped_map("ph_rig")
    paths = sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
    recs = {p: read_measured(p, cmap, channels=list(CHANNELS)) for p in paths}

    def run(p: str):
        r = recs[p]
        return r.time_s - r.time_s[0], r.x

    print("held-out run | one factor: log-likelihood/sample (rate_rel_std, walk) | zones " + str(list(ADAPT_ZONES_PH)))
    for held in paths:
        line = Path(held).name
        for zones in ((), ADAPT_ZONES_PH):
            start = replace(start_from_model("rig_flask"), adapt_zones_ph=zones)
            ref = fit_reference([run(q) for q in paths if q != held], start)
            stream = ref.new_state()
            t, x = run(held)
            stream.residuals(t, x)
            line += (f" | {-stream.nll / len(t):+.3f} ({ref.noise.rate_rel_std:.2f}, "  # type: ignore[attr-defined]
                     f"{ref.noise.walk_ph_per_sqrt_s:.4f})")
        print(line, flush=True)


if __name__ == "__main__":
    main()
