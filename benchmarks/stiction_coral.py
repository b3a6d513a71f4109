"""Aligning a plant's features to the simulator's (CORAL), measured on a simulated plant. Not shipped.

    .venv/bin/python benchmarks/stiction_coral.py                # 1000 loops a generator (about 2 min)

Issue 35 allows unlabelled real records for domain adaptation, as Deep CORAL does (Sun & Saenko 2016). For the
verdict's linear model, CORAL (Sun, Feng & Saenko 2016) is a map of the target's screen features onto the first two
moments of the simulated data set's features (benchmarks/results/stiction_dataset.json: its training and
calibration loops): x' = mu_s + (x - mu_t) C_t^(-1/2) C_s^(1/2) (in those loops' standardised units, each
covariance with eps on its diagonal), or, in the diagonal form, each feature's mean and
standard deviation alone. The model, its calibration and cut stay as shipped.

Measured where the truth is known: the "plant" is the simulator's own loops with the controller scanning ten
times per record sample (``SyntheticLoop.scan_s``, the shift measured by benchmarks/stiction_domain_shift.py),
half of them sticky (development seeds no training set, test or earlier draw uses). One half gives unlabelled
pools of 59 loops (as many as the refinery records), 100 pools drawn at random, and the whole half as one pool;
the other half is scored with the shipped model's screen calls (p at or above the cut; no valve-model fit):
recall, false calls, hard negatives called and the undetermined share, without and with the map, and the rank
AUC of p (sticky against the other loops): whether the map separates better, or only moves the loops' p. No
refinery record is read. Prints figures, no pass/fail; changes nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.linalg import sqrtm
from stiction_information_bound import HARD, draw, rank_auc

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
#: development seeds: neither training (35001, 35002), the fresh tests (1013, 2026-2032), the bounds nor the
#: earlier development draws (35101-35112, 4242-4254) use them
SEEDS = {"domain": 35113, "training": 4255}
SCANS = 10
POOL = 59
POOLS = 100
#: (label, diagonal form, eps)
MAPS = (("per feature (mean, std)", True, 0.1), ("CORAL, eps 0.1", False, 0.1), ("CORAL, eps 1", False, 1.0))


def coral_map(source: np.ndarray, pool: np.ndarray, diagonal: bool, eps: float):
    """The map of target features onto the source's first two moments (module docstring)."""
    mu, sd = source.mean(0), source.std(0)
    sd = np.where(sd > 1e-12, sd, 1.0)
    zs, zt = (source - mu) / sd, (pool - mu) / sd
    shift = zt.mean(0)
    if diagonal:
        a = np.diag(zs.std(0) / np.sqrt(zt.var(0) + eps))
    else:
        eye = np.eye(zs.shape[1])
        a = np.real(np.linalg.inv(sqrtm(np.cov(zt, rowvar=False) + eps * eye)) @ sqrtm(np.cov(zs, rowvar=False) + eps * eye))
    return lambda x: ((x - mu) / sd - shift) @ a * sd + mu


def loop_row(loop) -> list[float]:
    """Sticky, hard negative, then the screen's features with SCANS controller scans per record sample."""
    from phfdi.loopdiag.dataset import screen_row
    from phfdi.loopdiag.synthetic import simulate_loop

    run = simulate_loop(replace(loop.spec, scan_s=loop.spec.dt_s / SCANS))
    run.metadata["process_type"] = loop.process_type
    return [float(loop.stiction), float(loop.loop_class in HARD)] + screen_row(run, loop.process_type)["features"]


def rates(model, x: np.ndarray, sticky: np.ndarray, hard: np.ndarray) -> np.ndarray:
    """Recall, false calls, hard negatives called, undetermined share of the screen's calls, rank AUC of p."""
    p = model.calibrated(x)
    low, cut = model.cuts()
    called = p >= cut
    return np.array([called[sticky].mean(), called[~sticky].mean(), called[~sticky & hard].mean(),
                     ((p >= low) & ~called).mean(), rank_auc(p, sticky)])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--loops", type=int, default=1000, help="simulated loops per generator, half sticky (default 1000)")
    args = ap.parse_args(argv)
    if args.loops < 4 * POOL:
        ap.error(f"--loops {args.loops}: at least {4 * POOL}, so that half of them holds a pool of {POOL} with both "
                 "classes")
    if not DATASET.is_file():
        print(f"stiction_coral: {DATASET} not found; run benchmarks/stiction_dataset.py first", file=sys.stderr)
        return 2
    from phfdi.loopdiag.classifier import load_model
    from phfdi.loopdiag.dask_run import dask_client, map_ordered

    model = load_model()
    source = np.array([r["features"] for r in json.loads(DATASET.read_text())["rows"] if not r.get("error")])
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    print(f"shipped model's screen calls (p >= {model.cuts()[1]:.3f}) on loops with {SCANS} scans a sample; "
          f"pools of {POOL} unlabelled loops ({POOLS} of them: mean and 5-95 %), or the whole half")
    print("| generator | map | pool | recall | false calls | hard negatives called | undetermined | rank AUC of p |")
    print("|---|---|---|---|---|---|---|---|")
    with dask_client(None, None) as client:
        for generator, seed in SEEDS.items():
            loops = [loop for loop, _ in draw(generator, args.loops, seed)]
            a = np.array(map_ordered(client, loop_row, loops, lambda d, n, g=generator: print(
                f"{g}: {d}/{n} loops ({time.perf_counter() - t0:.0f} s)", file=sys.stderr) if d % 200 == 0 or d == n
                else None, chunk=4))
            sticky, hard, x = a[:, 0] > 0.5, a[:, 1] > 0.5, a[:, 2:]
            order = rng.permutation(len(a))
            pools, test = order[:len(a) // 2], order[len(a) // 2:]
            r = rates(model, x[test], sticky[test], hard[test])
            print(f"| {generator} (seed {seed}) | none | - | {r[0]:.3f} | {r[1]:.1%} | {r[2]:.1%} | {r[3]:.1%} | "
                  f"{r[4]:.3f} |")
            for label, diagonal, eps in MAPS:
                whole = coral_map(source, x[pools], diagonal, eps)
                r = rates(model, whole(x[test]), sticky[test], hard[test])
                print(f"| | {label} | whole half | {r[0]:.3f} | {r[1]:.1%} | {r[2]:.1%} | {r[3]:.1%} | {r[4]:.3f} |")
                rs = np.array([rates(model, coral_map(source, x[rng.choice(pools, POOL, replace=False)], diagonal,
                                                      eps)(x[test]), sticky[test], hard[test]) for _ in range(POOLS)])
                lo, hi = np.quantile(rs, [0.05, 0.95], axis=0)
                m = rs.mean(0)
                print(f"| | {label} | {POOL} loops | {m[0]:.3f} ({lo[0]:.3f}-{hi[0]:.3f}) | {m[1]:.1%} ({lo[1]:.1%}-"
                      f"{hi[1]:.1%}) | {m[2]:.1%} ({lo[2]:.1%}-{hi[2]:.1%}) | {m[3]:.1%} | {m[4]:.3f} ({lo[4]:.3f}-"
                      f"{hi[4]:.3f}) |")
    print(f"\n{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
