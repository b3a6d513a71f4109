"""SKAB benchmark: our detector and label-free baselines under the benchmark's protocol.

    .venv/bin/python benchmarks/skab.py ../shared/data/skab --out out/skab

For every file found under DATA_DIR: fit our detector (learned ARX reference +
multichannel wavelet CUSUMs, wavelet_fdi.learned_detector, one configuration for
all files) on its first 400 rows (labels are never an input), run it over the file
in time order, write OUT/predictions/<group>/<n>.csv (``datetime;anomaly;changepoint``,
the test rows; ``;``-separated), then print F1, FAR, MAR and the NAB scores from our
own scorer (phfdi.benchmarks.scoring) next to the published leaderboard, plus the
same scores for trivial label-free baselines: a detector that never alarms, one
that always alarms, a random toggler and Hotelling's T^2, and the labels themselves
played back as a prediction (a perfect outlier detector: the NAB ceiling of a
detector that raises one alarm per episode). With ``--peers``, the change detectors a user
would otherwise pick (wavelet_fdi.peers: CUSUM, FOCuS from changepoint-online, river's
Page-Hinkley and ADWIN) run on the SAME residuals as ours (the learned ARX reference fitted on
the first 400 rows, one peer per channel, alarm = any channel), each threshold calibrated on
the first 400 rows' residuals only (phfdi.benchmarks.skab.peer_detector), one configuration
for all files. Files without labels (anomaly-free.csv)
are predicted and their flagged fraction printed, not scored. Causality is checked:
each file is run again with its test part cut in half and must give the same
predictions on the half it saw. OUT/scores.json holds every number printed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from phfdi.benchmarks import skab
from phfdi.commands.calibrate import add_detector_args, learned_settings_from_args
from phfdi_base.errors import UserError
from wavelet_fdi.peers import PEER_LABELS, PEERS

TOGGLE_PROBABILITIES = (0.02, 0.05, 0.1)


OURS = "ours: learned ARX + wavelet CUSUM"
ORACLE = "labels as prediction (ceiling)"


PEER_NAMES = {f"{PEER_LABELS[p]} on our residuals": p for p in PEERS}


def peers(settings=None) -> dict[str, skab.Detector]:
    """The peer change detectors on the learned reference's residuals (see the module docstring)."""
    return {label: skab.peer_detector(p, settings) for label, p in PEER_NAMES.items()}


def baselines() -> dict[str, skab.Detector]:
    out: dict[str, skab.Detector] = {
        "never alarms": skab.null_detector,
        "always alarms": skab.always_detector,
    }
    for p in TOGGLE_PROBABILITIES:
        out[f"random toggler p={p}"] = skab.random_toggler(p, seed=0)
    out["Hotelling T^2 (99 % of training)"] = skab.hotelling_t2(0.99)
    return out


def table(results: list[skab.BenchmarkResult], leaderboard: bool = True) -> str:
    head = (f"{'algorithm':<36} {'F1':>5} {'FAR %':>7} {'MAR %':>7} {'NAB std':>8} {'NAB lowFP':>9} "
            f"{'NAB lowFN':>9} {'missed':>7} {'FP':>5}")
    lines = [head, "-" * len(head)]
    for r in results:
        s = r.nab.scores
        lines.append(f"{r.name:<36} {r.binary.f1:5.2f} {r.binary.far_pct:7.2f} {r.binary.mar_pct:7.2f} "
                     f"{s['standard']:8.2f} {s['low_fp']:9.2f} {s['low_fn']:9.2f} "
                     f"{r.nab.missed:>3}/{r.nab.windows:<3} {r.nab.false_positives:5d}")
    if leaderboard:
        lines.append("published leaderboard (whole benchmark, 34 files):")
        for name, v in skab.LEADERBOARD.items():
            lines.append(f"  {name:<34} {v[0]:5.2f} {v[1]:7.2f} {v[2]:7.2f} {v[3]:8.2f} {v[4]:9.2f} {v[5]:9.2f}")
    return "\n".join(lines)


def causality_check(detector: skab.Detector, files: list[skab.SkabFile]) -> int:
    """Each file with its test part cut in half must give the same predictions on the kept half."""
    for f in files:
        train, test = f.split()
        half = len(test) // 2
        full = detector(train, test, f.time_s[skab.TRAIN_ROWS:])
        cut = detector(train, test[:half], f.time_s[skab.TRAIN_ROWS:skab.TRAIN_ROWS + half])
        if not np.array_equal(full[:half], cut):
            raise SystemExit(f"skab: causality violated on {f.key}: predictions depend on later rows")
    return len(files)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="example: benchmarks/skab.py ../shared/data/skab --out out/skab")
    ap.add_argument("data_dir", help="SKAB data directory (its groups as subdirectories of .csv files)")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--by-group", action="store_true", help="also score each group (subdirectory) alone")
    ap.add_argument("--peers", action="store_true",
                    help="also run the peer change detectors (CUSUM, FOCuS, Page-Hinkley, ADWIN) on our residuals")
    ap.add_argument("--toggler-seeds", type=int, default=0, metavar="N",
                    help="also print the random togglers' NAB over N seeds (mean, min, max)")
    add_detector_args(ap.add_argument_group("learned detector settings for ours and the peers (phfdi calibrate's "
                                           "options; e.g. --form oe --correction-samples 100 for the output-error "
                                           "reference)"))
    ap.add_argument("--learned", action="append", default=[], metavar="KEY=VALUE",
                    help="the old form of those options (--learned form=oe is --form oe)")
    args = ap.parse_args(argv)
    try:
        settings = learned_settings_from_args(args)
        paths = skab.find_files(args.data_dir)
        files = [skab.read_skab_csv(p) for p in paths]
    except UserError as exc:
        print(f"skab: error: {exc}", file=sys.stderr)
        return 2
    labelled = [f for f in files if f.labelled]
    print(f"{len(files)} files under {args.data_dir}, {len(labelled)} labelled (scored): "
          f"{sum(len(f.values) - skab.TRAIN_ROWS for f in labelled)} test rows", flush=True)
    out = Path(args.out)
    results, report = [], {}
    detectors = {OURS: skab.learned_detector(settings), **(peers(settings) if args.peers else {}), **baselines()}
    per_detector = {}
    for i, (name, det) in enumerate(detectors.items()):
        t0 = time.perf_counter()
        per_file = skab.run_detector(det, files)
        per_detector[name] = per_file
        res = skab.score(name, per_file)
        results.append(res)
        report[name] = {"all": res.row(), "seconds": time.perf_counter() - t0}
        print(f"[{i + 1}/{len(detectors)}] {name}: {time.perf_counter() - t0:.2f} s", file=sys.stderr, flush=True)
    oracle = [skab.FileResult(f, f.anomaly[skab.TRAIN_ROWS:].astype(np.int8)) for f in labelled]
    results.append(skab.score(ORACLE, oracle))
    report[ORACLE] = {"all": results[-1].row()}
    if args.by_group:
        for name, per_file in per_detector.items():
            for g in sorted({f.group for f in labelled}):
                report[name][g] = skab.score(name, [r for r in per_file if r.file.group == g]).row()
    written = skab.write_predictions(per_detector[OURS], out)
    causal = causality_check(skab.learned_detector(settings), files)
    if args.peers:
        for name, det in peers().items():
            causality_check(det, files)
            report[name]["causal_files"] = len(files)
        print(f"causality: the peers too, on {len(files)} files", file=sys.stderr)
    unlabelled = [r for name in per_detector if name == OURS or name in PEER_NAMES
                  for r in per_detector[name] if not r.file.labelled]
    print(table(results))
    if args.by_group:
        for g in sorted({f.group for f in labelled}):
            print(f"\ngroup {g}:")
            print(table([skab.score(r.name, [x for x in r.files if x.file.group == g]) for r in results], False))
    if unlabelled:
        print()
    for r in unlabelled:
        frac = float(np.mean(r.prediction)) if len(r.prediction) else 0.0
        who = next(n for n in per_detector if any(x is r for x in per_detector[n]))
        print(f"{r.file.key} (no labels): {who} flags {100 * frac:.2f} % of its {len(r.prediction)} rows after "
              f"the first {skab.TRAIN_ROWS}")
        report[who][f"flagged_pct_{r.file.key}"] = 100 * frac
    for p in TOGGLE_PROBABILITIES if args.toggler_seeds > 0 else ():
        runs = [skab.score("t", skab.run_detector(skab.random_toggler(p, seed), labelled))
                for seed in range(args.toggler_seeds)]
        nab = np.array([r.nab.scores["standard"] for r in runs])
        f1 = np.array([r.binary.f1 for r in runs])
        print(f"random toggler p={p} over {len(runs)} seeds: NAB standard mean {nab.mean():.1f} "
              f"(min {nab.min():.1f}, max {nab.max():.1f}), F1 mean {f1.mean():.2f}")
        report[f"random toggler p={p}"]["seeds"] = {"nab_standard": nab.tolist(), "f1": f1.tolist()}
    print(f"causality: {causal} files run again with half their test rows give the same predictions on that half")
    print(f"predictions: {len(written)} files under {out / 'predictions'}")
    report[OURS]["causal_files"] = causal
    out.mkdir(parents=True, exist_ok=True)
    (out / "scores.json").write_text(json.dumps(report, indent=2), encoding="utf-8")
    print(f"\nscores: {out / 'scores.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
