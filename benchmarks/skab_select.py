"""How much of our SKAB score is selection: hyper-parameters chosen on one group, scored on the other.

    .venv/bin/python benchmarks/skab_select.py ../shared/data/skab      # a few minutes

Runs a grid of the learned detector's design settings (wavelet level, mean CUSUM k and h,
observer time constant, block length, clear fraction) over every labelled SKAB file, then

* chooses the setting with the best F1 on valve1 and scores it on `other` (held out),
* chooses the setting with the best F1 on `other` and scores it on valve1 (held out),
* pools the two held-out halves: every file predicted by a setting chosen without it
  (the cross-fitted score, the number to quote as held out),

and prints where the shipped defaults (wavelet_fdi.learned_detector.LearnedSettings) rank.
Labels are used only to score, never by the detector.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import asdict, replace

from phfdi.benchmarks import skab
from phfdi_base.errors import UserError
from wavelet_fdi.learned_detector import LearnedSettings

GRID = {
    "level": (1, 2, 3),
    "mean_k": (3.0, 4.0, 5.0, 6.0),
    "mean_h": (5.0, 10.0),
    "observer_time_constant_s": (100.0, 300.0),
    "block_samples": (16, 32),
    "clear_fraction": (0.0, 0.2),
}


def line(name: str, r: skab.BenchmarkResult) -> str:
    return (f"{name:<44} F1 {r.binary.f1:.3f}  FAR {r.binary.far_pct:5.1f} %  MAR {r.binary.mar_pct:5.1f} %  "
            f"NAB std {r.nab.scores['standard']:5.1f}  lowFP {r.nab.scores['low_fp']:5.1f}  "
            f"lowFN {r.nab.scores['low_fn']:5.1f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="example: benchmarks/skab_select.py ../shared/data/skab")
    ap.add_argument("data_dir")
    args = ap.parse_args(argv)
    try:
        files = [f for f in (skab.read_skab_csv(p) for p in skab.find_files(args.data_dir)) if f.labelled]
    except UserError as exc:
        print(f"skab_select: error: {exc}", file=sys.stderr)
        return 2
    groups = sorted({f.group for f in files})
    if len(groups) != 2:
        print(f"skab_select: error: needs exactly two groups of labelled files, found {groups}", file=sys.stderr)
        return 2
    base = LearnedSettings()
    combos = [dict(zip(GRID, v)) for v in itertools.product(*GRID.values())]
    results = []
    for i, kw in enumerate(combos):
        per_file = skab.run_detector(skab.learned_detector(replace(base, **kw)), files)
        results.append((kw, per_file))
        if (i + 1) % 12 == 0 or i + 1 == len(combos):
            print(f"[{i + 1}/{len(combos)}] settings run", file=sys.stderr, flush=True)

    def score(per_file, group=None):
        return skab.score("x", [r for r in per_file if group is None or r.file.group == group])

    held_out = []
    for choose, test in (groups, groups[::-1]):
        kw, per_file = max(results, key=lambda kr: score(kr[1], choose).binary.f1)
        print(f"\nchosen on {choose}: {kw}")
        print(line(f"  on {choose} (selection, in-sample)", score(per_file, choose)))
        print(line(f"  on {test} (held out)", score(per_file, test)))
        print(line("  on all files", score(per_file)))
        held_out += [r for r in per_file if r.file.group == test]
    print()
    print(line("cross-fitted (each group held out)", skab.score("x", held_out)))
    defaults = {k: getattr(base, k) for k in GRID}
    ranked = sorted(results, key=lambda kr: -score(kr[1]).binary.f1)
    rank = next((i + 1 for i, (kw, _) in enumerate(ranked) if kw == defaults), None)
    print(f"shipped defaults {defaults}: rank {rank} of {len(results)} by F1 on all files"
          if rank else f"shipped defaults {defaults} are not on the grid")
    print(f"other settings fixed at: { {k: v for k, v in asdict(base).items() if k not in GRID} }")
    return 0


if __name__ == "__main__":
    sys.exit(main())
