"""Benchmark: the full Section 6 analysis of the 35 x 1440 multisignal (target: under 2 s).

Simulations are not timed: the 35 runs are simulated first (or read with --runs DIR of .parquet files
written by `phfdi analyze --save-runs`, e.g. out/analysis/runs/section6). Prints the time of each step and of
the whole analysis (phfdi.study.analysis.analyze_multisignal: decomposition, approximations, denoising with
every rule at levels 5 and 7, compression, clustering with both methods and silhouette-chosen k, severity),
first call (imports and caches cold) and best of --repeat warm calls. Figures and Section 7 are not included.

    .venv/bin/python benchmarks/analysis.py --jobs 2
    .venv/bin/python benchmarks/analysis.py --runs out/analysis/runs/section6
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", default=None, help="folder of Section 6 .parquet runs (default: simulate them)")
    ap.add_argument("--jobs", type=int, default=2, help="simulation processes")
    ap.add_argument("--repeat", type=int, default=5, help="warm repetitions")
    args = ap.parse_args()

    from phfdi.records import read_run
    from phfdi.study.multisignal import from_runs
    from phfdi.study.paperset import PAPER_GROUPING, section6_variants, simulate_variants

    t0 = time.perf_counter()
    if args.runs:
        files = sorted(Path(args.runs).glob("*.parquet"))
        runs = [read_run(f) for f in files]
        labels = [r.metadata["label"] for r in runs]
        names = [f.stem for f in files]
    else:
        variants = section6_variants()
        runs = simulate_variants(variants, jobs=args.jobs)
        labels, names = [v.label for v in variants], [v.name for v in variants]
    info = [{"seed": r.metadata.get("seed"), "severity_factor": r.metadata.get("severity_factor")} for r in runs]
    print(f"data: {len(runs)} runs in {time.perf_counter() - t0:.1f} s (not part of the benchmark)")

    t = time.perf_counter()
    ms = from_runs(runs, labels, "ph_measured", 1440, names, info=info)
    print(f"resampling {len(runs)} runs to {ms.shape[0]} x {ms.shape[1]}: {1000 * (time.perf_counter() - t):.1f} ms")

    from phfdi.study import cluster, compress, denoise
    from phfdi.study.analysis import Options, analyze_multisignal
    from phfdi.study.multisignal import decompose

    t = time.perf_counter()
    analyze_multisignal(ms, Options(), PAPER_GROUPING)
    cold = time.perf_counter() - t

    def best(fn, n=args.repeat):
        times = []
        for _ in range(n):
            t = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t)
        return min(times)

    dec = decompose(ms.data)
    steps = {
        "decompose (sym4, level 7)": lambda: decompose(ms.data),
        "approximation at level 7": lambda: dec.approximation(7),
        "denoise (universal, soft, level noise)": lambda: denoise.denoise(dec),
        "denoise (SURE)": lambda: denoise.denoise(dec, "sure"),
        "compress to 99 % energy": lambda: compress.compress_energy(dec),
        "Ward clustering, k = 3": lambda: cluster.hierarchical(dec.ca, 3),
        "k-means, k = 3, 10 restarts": lambda: cluster.kmeans(dec.ca, 3),
    }
    for name, fn in steps.items():
        print(f"  {name:42s} {1000 * best(fn):8.2f} ms")
    warm = best(lambda: analyze_multisignal(ms, Options(), PAPER_GROUPING))
    print(f"full analysis of {ms.shape[0]} x {ms.shape[1]}: first call {cold:.2f} s, warm best of {args.repeat} "
          f"{warm:.2f} s (target < 2 s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
