"""Train the stiction classifier and measure it: nested leave-one-loop-out on the refinery records.

    .venv/bin/python benchmarks/stiction_dataset.py            # features of every record (minutes, Dask)
    .venv/bin/python benchmarks/train_stiction_classifier.py   # seconds: evaluation, weights, model JSON
    .venv/bin/python benchmarks/train_stiction_classifier.py --no-write   # evaluate only
    .venv/bin/python benchmarks/train_stiction_classifier.py --no-nested  # ship the model without scoring the real records

Prints

* the leave-one-loop-out table on the 59 labelled records (positive class: stiction): the
  classifier under *nested* leave-one-loop-out (for each of the 17 loops, every choice - L2
  strength, weight of the synthetic loops, decision threshold - is made inside the other 16 loops
  and the synthetic loops, then the model trained on them predicts the held-out loop's files), with
  the shipped criterion (inner leave-one-loop-out averaged with a 5-fold cross-validation of the
  synthetic loops) and with the real records alone; Horch (1999) and He et al. (2007) at their
  published thresholds, and the previous diagnosis of this project (a valve model beating the
  linear one by 10 % on held-out data);
* the shipped model's weights (trained on all records and the synthetic training loops), and
  writes it to src/phfdi/loopdiag/models/stiction_classifier.json;
* the one-verdict answer of the same nested procedure: calibrated p(stiction) with an undetermined
  band chosen in the inner folds only; precision and recall of the confident "stiction" calls, the
  share of no-stiction records called "stiction", the share left undetermined, the calibration
  (Brier score, reliability by tenths); and the structure checks on the real records (frozen PV, not
  a closed loop: each record as it is, with PV held constant, and OP beside another loop's PV);
* the check on fresh synthetic loops (another seed, never trained on): accuracy, precision, recall
  and false alarms per disturbance condition.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from phfdi.loopdiag.classifier import (
    CRITERIA,
    MAX_FALSE_STICTION,
    MAX_UNDETERMINED,
    TARGET_PRECISION,
    Data,
    call_rates,
    nested_lolo,
    nested_lolo_calls,
    train,
)
from phfdi.loopdiag.evaluate import frozen_copies, repeated_records, structure_checks, unrelated_pairs
from phfdi.loopdiag.features import FEATURE_SIGNS, FEATURES
from phfdi.loopdiag.readers import read_loop

ROOT = Path(__file__).resolve().parents[1]
DATASET = ROOT / "benchmarks" / "results" / "stiction_dataset.json"
MODEL = ROOT / "src" / "phfdi" / "loopdiag" / "models" / "stiction_classifier.json"
DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data")) / "plant_loops"


def real_runs(real: list[dict]) -> dict:
    """{name: (OP, PV, SP or None)} of the real records as read; {} without the data."""
    if not all((DATA / r["name"]).is_file() for r in real):
        print(f"(no records under {DATA}: the tables of distinct records and of the structure checks are skipped)")
        return {}
    runs = {r["name"]: read_loop(str(DATA / r["name"])) for r in real}
    return {k: (v["op_pct"], v["pv"], v["sp"] if "sp" in v else None) for k, v in runs.items()}


def repeats(runs: dict) -> dict[str, tuple[str, float]]:
    """Real records that repeat another's samples (phfdi.loopdiag.evaluate.repeated_records)."""
    return repeated_records({k: (op, pv) for k, (op, pv, _) in runs.items()}) if runs else {}


def banded_table(rows: dict[str, dict]) -> str:
    out = ["| records | confident stiction: precision | recall | no stiction called stiction | undetermined | "
           "TP | FP | no-stiction calls right / all | stiction missed (called no stiction) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for name, m in rows.items():
        prec = "n/a" if math.isnan(m["precision"]) else f"{m['precision']:.2f}"
        out.append(f"| {name} | **{prec}** ({m['tp']}/{m['tp'] + m['fp']}) | {m['recall']:.2f} | "
                   f"**{100 * m['false_stiction_rate']:.1f} %** ({m['fp']}/{m['no_stiction_records']}) | "
                   f"**{100 * m['undetermined_share']:.1f} %** ({m['undetermined']}/{m['files']}) | {m['tp']} | {m['fp']} | "
                   f"{m['tn']}/{m['tn'] + m['fn']} | {m['fn']} |")
    return "\n".join(out)


def calibration_lines(p_cal: np.ndarray, p_raw: np.ndarray, y: np.ndarray) -> list[str]:
    """Brier scores and a reliability table (tenths of the calibrated probability)."""
    y = np.asarray(y, float)
    lines = [f"Brier score: calibrated {np.mean((p_cal - y) ** 2):.3f}, the model's own probability "
             f"{np.mean((p_raw - y) ** 2):.3f} (always 0.5: 0.250)",
             "| calibrated p | records | mean p | share sticky |", "|---|---|---|---|"]
    edges = np.linspace(0.0, 1.0, 6)
    for lo, hi in zip(edges[:-1], edges[1:]):
        k = (p_cal >= lo) & ((p_cal < hi) if hi < 1 else (p_cal <= hi))
        if k.any():
            lines.append(f"| {lo:.1f}-{hi:.1f} | {int(k.sum())} | {np.mean(p_cal[k]):.2f} | {np.mean(y[k]):.2f} |")
    return lines


def verdict_tables(d: Data, real: list[dict], runs: dict, rep: dict, criterion: str) -> dict[str, dict]:
    """One verdict per record under nested leave-one-loop-out (band chosen in the inner folds), printed;
    the structure checks' verdicts take precedence (a record that is not a loop gets no stiction call)."""
    t0 = time.perf_counter()
    nested = nested_lolo_calls(d, criterion=criterion)
    t_nested = time.perf_counter() - t0
    ri = np.flatnonzero(d.real)
    y, groups = d.y[ri], [d.groups[i] for i in ri]
    calls = nested.calls[ri].copy()
    structure = structure_checks(runs) if runs else {}
    for k, r in enumerate(real):
        if structure.get(r["name"]):
            calls[k] = structure[r["name"]]
    print(f"\none verdict per record (nested leave-one-loop-out, {t_nested:.1f} s; calibration and undetermined band "
          f"chosen in the inner folds for precision >= {TARGET_PRECISION}, no-stiction called stiction <= "
          f"{100 * MAX_FALSE_STICTION:.0f} %, undetermined <= {100 * MAX_UNDETERMINED:.0f} %):\n")
    results = {"all records": call_rates(calls, y)}
    if rep:
        keep = [k for k, r in enumerate(real) if r["name"] not in rep]
        results["distinct records"] = call_rates(calls[keep], y[keep])
    print(banded_table(results))
    if runs:
        n_struct = sum(1 for r in real if structure.get(r["name"]))
        print(f"\nstructure checks on the {len(runs)} real records: {n_struct} not scored (frozen PV or not a closed loop)")
        fr = frozen_copies(runs)
        print(f"the same records with PV held constant: {fr['pv_frozen']}/{fr['records']} called pv_frozen")
        un = unrelated_pairs(runs, {r["name"]: r["group"] for r in real})
        print(f"OP of one record beside the PV of another loop's record, no setpoint: {un['pairs'] - un['coupled']}/"
              f"{un['pairs']} called not_a_closed_loop ({100 * un['coupled'] / un['pairs']:.1f} % taken for a loop; "
              f"test level 1 %)")
        results["structure"] = {"not_scored": n_struct, **{f"frozen_{k}": v for k, v in fr.items()},
                                **{f"unrelated_{k}": v for k, v in un.items()}}
    print()
    print("\n".join(calibration_lines(nested.calibrated[ri], nested.prob[ri], y)))
    print("\nper loop (stiction / undetermined / no stiction calls), fold's band on the calibrated p:")
    for g in sorted(set(groups), key=lambda g: (not y[groups.index(g)], g)):
        idx = [k for k, gg in enumerate(groups) if gg == g]
        lab = "stiction   " if y[idx[0]] else "no stiction"
        c = [int(np.sum(calls[idx] == v)) for v in ("stiction", "undetermined", "no_stiction")]
        ch = nested.choices[g]
        band = "-" if ch["band"] is None else f"{ch['band'][0]:.2f}-{ch['band'][1]:.2f}"
        print(f"  {lab} {g:28s} {c[0]:2d} / {c[1]:2d} / {c[2]:2d}   band {band}"
              + ("" if ch["band_met_inner"] else " (inner targets not met)"))
    return {f"one verdict, {k}": v for k, v in results.items()}


def metrics(y: np.ndarray, pred: np.ndarray, groups: list[str]) -> dict:
    y, pred = np.asarray(y, bool), np.asarray(pred, bool)
    tp, fp = int(np.sum(pred & y)), int(np.sum(pred & ~y))
    fn, tn = int(np.sum(~pred & y)), int(np.sum(~pred & ~y))
    loops: dict[str, list] = {}
    for g, yi, pi in zip(groups, y, pred):
        loops.setdefault(g, []).append((yi, pi))
    right = sum(1 for v in loops.values() if (sum(p for _, p in v) * 2 > len(v)) == v[0][0])
    return {"files": len(y), "tp": tp, "fp": fp, "fn": fn, "tn": tn,
            "accuracy": (tp + tn) / len(y) if len(y) else math.nan,
            "precision": tp / (tp + fp) if tp + fp else math.nan,
            "recall": tp / (tp + fn) if tp + fn else math.nan,
            "loops": len(loops), "loops_right": right}


def table(rows: dict[str, dict]) -> str:
    out = ["| method | accuracy | precision | recall | TP | FP | FN | TN | loops right (majority of files) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for name, m in rows.items():
        prec = "n/a" if math.isnan(m["precision"]) else f"{m['precision']:.2f}"
        out.append(f"| {name} | {m['accuracy']:.2f} | {prec} | {m['recall']:.2f} | {m['tp']} | {m['fp']} | "
                   f"{m['fn']} | {m['tn']} | {m['loops_right']}/{m['loops']} |")
    return "\n".join(out)


def data_from(rows: list[dict], names: list[str]) -> Data:
    return Data(np.array([r["features"] for r in rows], float), np.array([r["stiction"] for r in rows], bool),
                [r["group"] for r in rows], np.array([r["source"] == "real" for r in rows], bool), names,
                list(FEATURE_SIGNS))


def nested_tables(d: Data, real: list[dict], rows: list[dict], fresh: list[dict], failed: list[dict],
                  criterion: str) -> dict[str, dict]:
    """The nested leave-one-loop-out of the classifier on the real records beside the baselines,
    printed; the metrics by method."""
    t0 = time.perf_counter()
    prob, pred, choices = nested_lolo(d, criterion=criterion)
    other = [c for c in CRITERIA if c != criterion][0]
    _, pred_other, _ = nested_lolo(d, criterion=other)
    t_nested = time.perf_counter() - t0
    ri = np.flatnonzero(d.real)
    y_real, g_real = d.y[ri], [d.groups[i] for i in ri]
    results = {f"classifier (nested LOLO, chosen on {criterion})": metrics(y_real, pred[ri], g_real),
               f"classifier (nested LOLO, chosen on {other})": metrics(y_real, pred_other[ri], g_real)}
    results["Horch 1999 (CCF, psi > 0.5)"] = metrics(y_real, [r["horch_decision"] == "stiction" for r in real], g_real)
    results["He et al. 2007 (SI >= 0.6)"] = metrics(y_real, [r["he_decision"] == "stiction" for r in real], g_real)
    results["previous: Hammerstein valve model, gain >= 10 %"] = metrics(
        y_real, [(r["hammerstein_gain_percent"] or 0.0) >= 10.0 for r in real], g_real)
    runs = real_runs(real)
    rep = repeats(runs)
    if rep:
        keep = [k for k, r in enumerate(real) if r["name"] not in rep]
        yk, gk = y_real[keep], [g_real[k] for k in keep]
        distinct = {f"classifier (nested LOLO, chosen on {criterion})": metrics(yk, pred[ri][keep], gk),
                    "Horch 1999 (CCF, psi > 0.5)": metrics(yk, [real[k]["horch_decision"] == "stiction" for k in keep], gk),
                    "He et al. 2007 (SI >= 0.6)": metrics(yk, [real[k]["he_decision"] == "stiction" for k in keep], gk)}
        results.update({f"{k} [distinct records]": v for k, v in distinct.items()})
    n_loops = len(set(g_real))
    print(f"{len(real)} real records ({int(y_real.sum())} stiction) from {n_loops} loops; "
          f"{sum(r['source'] == 'synthetic' for r in rows)} synthetic training loops; {len(fresh)} fresh loops; "
          f"{len(failed)} records unreadable")
    for r in failed:
        print(f"  {r['name']}: {r['error']}")
    print(f"\nleave-one-loop-out on the real records (nested for the classifier, {t_nested:.1f} s):\n")
    print(table({k: v for k, v in results.items() if not k.endswith("[distinct records]")}))
    if rep:
        shares = [100 * v[1] for v in rep.values()]
        print(f"\nthe same, each stretch of data once: {len(rep)} files repeat {min(shares):.0f}-{max(shares):.0f} % "
              f"of another file's samples under other time stamps, left out:")
        for n, (orig, share) in sorted(rep.items()):
            print(f"  {Path(n).name} repeats {Path(orig).name} ({100 * share:.0f} %)")
        print()
        print(table({k.removesuffix(" [distinct records]"): v for k, v in results.items()
                     if k.endswith("[distinct records]")}))
    print("\nper loop (files called stiction / files): classifier | Horch | He | previous; fold's choices")
    for g in sorted(set(g_real), key=lambda g: (not y_real[g_real.index(g)], g)):
        idx = [k for k, gg in enumerate(g_real) if gg == g]
        lab = "stiction   " if y_real[idx[0]] else "no stiction"
        cells = [f"{int(sum(pred[ri][k] for k in idx))}/{len(idx)}",
                 f"{sum(real[k]['horch_decision'] == 'stiction' for k in idx)}/{len(idx)}",
                 f"{sum(real[k]['he_decision'] == 'stiction' for k in idx)}/{len(idx)}",
                 f"{sum((real[k]['hammerstein_gain_percent'] or 0) >= 10 for k in idx)}/{len(idx)}"]
        c = choices[g]
        print(f"  {lab} {g:28s} " + " | ".join(cells)
              + f"   (l2 {c['l2']:g}, synthetic x{c['synthetic_ratio']:g}, threshold {c['threshold']:.2f})")
    results.update(verdict_tables(d, real, runs, rep, criterion))
    return results


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--dataset", type=Path, default=DATASET)
    p.add_argument("--model", type=Path, default=MODEL)
    p.add_argument("--no-write", action="store_true", help="do not write the model JSON")
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    p.add_argument("--no-nested", action="store_true",
                   help="train and write the model and check the fresh loops, without the nested leave-one-loop-out "
                        "on the real records (score them once, when the change is final)")
    p.add_argument("--criterion", choices=CRITERIA, default="real+synthetic",
                   help="what hyper-parameters and threshold are chosen for (default real+synthetic)")
    args = p.parse_args(argv)
    if not args.dataset.is_file():
        print(f"no data set at {args.dataset}: run benchmarks/stiction_dataset.py first", file=sys.stderr)
        return 2
    doc = json.loads(args.dataset.read_text())
    names = doc["features"]
    if names != [f.name for f in FEATURES]:
        print("the data set's features are not the classifier's: re-run benchmarks/stiction_dataset.py",
              file=sys.stderr)
        return 2
    rows = [r for r in doc["rows"] if not r.get("error")]
    failed = [r for r in doc["rows"] if r.get("error")]
    real = [r for r in rows if r["source"] == "real"]
    train_rows = [r for r in rows if r["source"] in ("real", "synthetic")]
    fresh = [r for r in rows if r["source"] == "fresh"]
    d = data_from(train_rows, names)
    n_loops = len({r["group"] for r in real})
    results: dict[str, dict] = {}
    if not args.no_nested:
        results = nested_tables(d, real, rows, fresh, failed, args.criterion)
    model = train(d, args.criterion)
    model.info.update({"trained_on": {"real_records": len(real), "real_loops": n_loops,
                                      "synthetic_loops": int(np.sum(~d.real)),
                                      "synthetic_seed": doc.get("train_seed")},
                       "nested_lolo": {k: {kk: (None if isinstance(vv, float) and math.isnan(vv) else vv)
                                           for kk, vv in v.items()} for k, v in results.items()},
                       "script": "benchmarks/train_stiction_classifier.py"})
    print(f"\nshipped model (criterion {args.criterion}): l2 {model.l2:g}, synthetic x{model.synthetic_ratio:g}, "
          f"threshold {model.threshold:.3f}, intercept {model.bias:+.3f}")
    print("| feature | mean | scale | weight (log-odds per standard deviation) |\n|---|---|---|---|")
    for f, mu, sc, w in sorted(zip(model.features, model.mean, model.scale, model.weights), key=lambda t: -abs(t[3])):
        print(f"| {f} | {mu:.3g} | {sc:.3g} | {w:+.3f} |")
    if not args.no_write:
        model.save(args.model)
        print(f"model written to {args.model.relative_to(ROOT) if args.model.is_relative_to(ROOT) else args.model}")

    if fresh:
        fd = data_from(fresh, names)
        fp = model.probability(fd.x) >= model.threshold
        fm = metrics(fd.y, fp, fd.groups)
        print(f"\nfresh synthetic loops (seed {doc.get('fresh_seed')}, never trained on): accuracy {fm['accuracy']:.2f}, "
              f"precision {fm['precision']:.2f}, recall {fm['recall']:.2f} (TP {fm['tp']}, FP {fm['fp']}, "
              f"FN {fm['fn']}, TN {fm['tn']})")
        print("| condition | loops | stiction found | false alarms on healthy loops |\n|---|---|---|---|")
        conds = sorted({c for r in fresh for c in r.get("conditions", [])})
        for c in conds:
            idx = [k for k, r in enumerate(fresh) if c in r.get("conditions", [])]
            pos = [k for k in idx if fd.y[k]]
            neg = [k for k in idx if not fd.y[k]]
            print(f"| {c} | {len(idx)} | {sum(fp[k] for k in pos)}/{len(pos)} | {sum(fp[k] for k in neg)}/{len(neg)} |")
        for pt in ("self_regulating", "integrating"):
            idx = [k for k, r in enumerate(fresh) if r.get("process_type") == pt]
            pos = [k for k in idx if fd.y[k]]
            neg = [k for k in idx if not fd.y[k]]
            print(f"| process {pt} | {len(idx)} | {sum(fp[k] for k in pos)}/{len(pos)} | "
                  f"{sum(fp[k] for k in neg)}/{len(neg)} |")
        results["fresh synthetic (shipped model)"] = fm
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
