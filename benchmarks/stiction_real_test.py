"""The one verdict on the 59 labelled refinery loop records, as a pure test: nothing is fitted on them.

    .venv/bin/python benchmarks/stiction_real_test.py                 # diagnoses the 59 records (Dask, minutes)
    .venv/bin/python benchmarks/stiction_real_test.py --from-rows benchmarks/results/stiction_real_test.json

The shipped classifier was trained, calibrated and given its operating point on simulated loops only
(benchmarks/train_stiction_classifier.py); the valve-model reconciliation's rules were fixed without these
records. Each record of ../shared/data/plant_loops (PROVENANCE.md there) goes through ``phfdi loop-diagnose``'s
whole path (reader, structure checks, screen, valve-model fits where flagged, the one verdict) with the
default settings, and the labels of labels.csv are used only here, to count:

* precision of the "stiction" calls, recall (sticky records called "stiction"), false calls (records without
  stiction called "stiction"), and the share left undetermined (or not scored: PV frozen, not a closed loop);
* the same for each stretch of data once (files that repeat another's samples left out);
* per loop tag, the calls.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

from phfdi.loopdiag.batch import diagnose_files
from phfdi.loopdiag.evaluate import read_labels, repeated_records
from phfdi.loopdiag.readers import read_loop

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("PHFDI_SHARED_DATA", ROOT.parent / "shared" / "data")) / "plant_loops"
OUT = ROOT / "benchmarks" / "results" / "stiction_real_test.json"
CALLS = ("stiction", "undetermined", "no_stiction")


def row_of(rep: dict, label: bool, loop_tag: str, name: str) -> dict:
    lv = rep.get("loop_verdict") or {}
    st = rep.get("stiction") or {}
    return {"file": name, "loop_tag": loop_tag, "stiction": label, "verdict": lv.get("verdict", "error"),
            "summary": lv.get("summary"), "probability": lv.get("probability"), "screen_call": st.get("verdict"),
            "contradiction": lv.get("contradiction"), "valve_model_cause": rep.get("cause"),
            "gain_percent": rep.get("gain_percent"), "kano_s_pct": st.get("kano_s_pct"),
            "op_noise": st.get("op_noise"), "error": rep.get("error")}


def rates(rows: list[dict]) -> dict:
    pos = [r for r in rows if r["stiction"]]
    neg = [r for r in rows if not r["stiction"]]
    tp = sum(r["verdict"] == "stiction" for r in pos)
    fp = sum(r["verdict"] == "stiction" for r in neg)
    und = sum(r["verdict"] not in ("stiction", "no_stiction") for r in rows)
    return {"records": len(rows), "stiction_records": len(pos), "tp": tp, "fp": fp,
            "precision": tp / (tp + fp) if tp + fp else math.nan, "recall": tp / len(pos) if pos else math.nan,
            "false_call_rate": fp / len(neg) if neg else math.nan, "undetermined": und,
            "undetermined_share": und / len(rows) if rows else math.nan,
            "no_stiction_calls_right": sum(r["verdict"] == "no_stiction" for r in neg),
            "no_stiction_calls": sum(r["verdict"] == "no_stiction" for r in rows)}


def table(results: dict[str, dict]) -> str:
    out = ["| records | precision of \"stiction\" | recall | records without stiction called stiction | "
           "undetermined or not scored | \"no stiction\" calls right |", "|---|---|---|---|---|---|"]
    for name, m in results.items():
        prec = "n/a" if math.isnan(m["precision"]) else f"{m['precision']:.2f}"
        out.append(f"| {name} | **{prec}** ({m['tp']}/{m['tp'] + m['fp']}) | **{m['recall']:.2f}** "
                   f"({m['tp']}/{m['stiction_records']}) | **{m['false_call_rate']:.1%}** "
                   f"({m['fp']}/{m['records'] - m['stiction_records']}) | **{m['undetermined_share']:.1%}** "
                   f"({m['undetermined']}/{m['records']}) | {m['no_stiction_calls_right']}/{m['no_stiction_calls']} |")
    return "\n".join(out)


def per_loop(rows: list[dict]) -> list[str]:
    lines = ["per loop (stiction / undetermined / no stiction calls):"]
    tags = sorted({(r["loop_tag"], r["stiction"]) for r in rows}, key=lambda t: (not t[1], t[0]))
    for tag, lab in tags:
        rs = [r for r in rows if r["loop_tag"] == tag]
        k = [sum(r["verdict"] == c for r in rs) for c in CALLS]
        other = len(rs) - sum(k)
        lines.append(f"  {'stiction   ' if lab else 'no stiction'} {tag:28s} {k[0]:2d} / {k[1]:2d} / {k[2]:2d}"
                     + (f"  ({other} not scored)" if other else ""))
    return lines


def collect(labels: Path, workers: int | None) -> list[dict]:
    items = read_labels(labels)
    t0 = time.perf_counter()

    def show(done, total, _path):
        if done % 10 == 0 or done == total:
            print(f"{done}/{total} records, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

    reports = diagnose_files([it.file for it in items], workers=workers, progress=show)
    return [row_of(rep, it.stiction, it.loop_tag, str(Path(it.file).relative_to(labels.parent)))
            for rep, it in zip(reports, items)]


def repeats(rows: list[dict]) -> dict:
    """Records that repeat another's samples (evaluate.repeated_records), from the files."""
    runs = {}
    for r in rows:
        try:
            run = read_loop(str(DATA / r["file"]))
        except Exception:  # noqa: BLE001 - a record that cannot be read cannot repeat another
            continue
        runs[r["file"]] = (run["op_pct"], run["pv"])
    return repeated_records(runs)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--labels", type=Path, default=DATA / "labels.csv")
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--out", type=Path, default=OUT, help="where the per-record verdicts are written")
    p.add_argument("--from-rows", type=Path, default=None, help="count verdicts written earlier")
    args = p.parse_args(argv)
    if args.from_rows:
        rows = json.loads(args.from_rows.read_text())["rows"]
    else:
        if not args.labels.is_file():
            print(f"no labels at {args.labels} (set PHFDI_SHARED_DATA)", file=sys.stderr)
            return 2
        t0 = time.perf_counter()
        rows = collect(args.labels, args.workers)
        print(f"diagnosis wall time: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"rows": rows}, indent=1))
    results = {"all 59": rates(rows)}
    rep = repeats(rows) if DATA.is_dir() else {}
    if rep:
        results[f"{len(rows) - len(rep)} distinct"] = rates([r for r in rows if r["file"] not in rep])
    print(f"{len(rows)} refinery records, {sum(r['stiction'] for r in rows)} labelled stiction, "
          f"{len({r['loop_tag'] for r in rows})} loops; the model fitted on simulated loops only\n")
    print(table(results))
    print()
    print("\n".join(per_loop(rows)))
    demoted = [r for r in rows if r["contradiction"]]
    print(f"\nstiction calls made undetermined by the valve-model fit: {len(demoted)}")
    for r in demoted:
        print(f"  {r['file']} ({'stiction' if r['stiction'] else 'no stiction'}): {r['contradiction']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
