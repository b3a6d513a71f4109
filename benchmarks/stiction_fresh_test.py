"""The one verdict on fresh simulated loops from another generator and seed than training (never trained on).

    .venv/bin/python benchmarks/stiction_fresh_test.py                      # 40 loops per class, seed 1013 (Dask)
    .venv/bin/python benchmarks/stiction_fresh_test.py --from-rows benchmarks/results/stiction_fresh_test.json
    .venv/bin/python benchmarks/stiction_fresh_test.py --classes healthy_load_steps,stiction --per-class 1000 \
        --seed 2028 --out OUT.json          # a larger draw of two classes

The classifier is trained and calibrated on phfdi.loopdiag.domain's loops (seeds 35001, 35002). This test draws
from a different randomisation, phfdi.loopdiag.training's per-class generator (its own process, tuning,
disturbance and noise ranges and classes), with a seed no training set uses (1013): healthy valves answering load
steps and ramps, healthy loops tuned to oscillate, healthy loops under other disturbances, sticky valves (Kano
and He models), other valve nonlinearities (dead-zone, quantisation, saturation) and backlash. Every loop goes
through the whole path of ``phfdi loop-diagnose`` (structure checks, screen, the valve-model fits where the
screen flags, the one verdict with its reconciliation) on Dask, and the verdicts are counted:

* precision of the "stiction" calls, recall, false calls on the loops without stiction, the undetermined share;
* accuracy two ways: undetermined counted as not calling stiction, and over the confident calls only;
* the calls per class. Backlash (a dead-band is Kano's model with J = 0: neither label is right) is reported
  apart and not scored;
* the sticky loops' calls by the valve's size (Kano's S or He's fs, % of travel), by how often the simulated
  stem broke away (:func:`phfdi.loopdiag.domain.slips`) and by how far the valve moves PV, in noise levels, against
  the same loop with a linear valve (:func:`phfdi.loopdiag.domain.valve_effect_on_pv`): which sticky valves the
  verdict finds, not only how many.

``--classes`` draws a subset of the classes (a larger draw of the ones whose rate is in question); the metrics
over a subset are those of that subset's mix, not of the test's.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from phfdi.loopdiag.dask_run import dask_client, map_ordered
from phfdi.loopdiag.domain import slips, valve_effect_on_pv
from phfdi.loopdiag.training import LOOP_CLASSES, class_round_robin, draw_class_loops
from phfdi_base.errors import UserError
from phfdi_base.outputs import check_writable_folder, write_text

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "stiction_fresh_test.json"
#: never used by a training set (benchmarks/stiction_dataset.py uses 35001 and 35002)
TEST_SEED = 1013
UNSCORED = ("backlash",)
CALLS = ("stiction", "undetermined", "no_stiction")


def verdict_row(loop) -> dict:
    """The one verdict of one simulated loop through the whole diagnosis."""
    from phfdi.loopdiag.diagnose import Settings
    from phfdi.loopdiag.single import diagnose_run
    from phfdi.loopdiag.synthetic import simulate_loop
    from phfdi.loopdiag.verdict import contradiction, friction_decides

    run = simulate_loop(loop.spec)
    run.metadata["process_type"] = loop.process_type
    rep = diagnose_run(run, Settings(baselines=False))
    lv = rep.get("loop_verdict") or {}
    fitted = rep.get("valve_models") == "fitted" and bool(rep.get("stiction"))
    return {"name": loop.group, "loop_class": loop.loop_class, "stiction": bool(loop.stiction),
            "conditions": list(loop.conditions), "valve": loop.spec.valve,
            "slips": slips(run["stem_pct"], run["op_pct"]), "verdict": lv.get("verdict", "error"),
            # how far a sticky valve moves PV, in noise levels (against the same loop with a linear valve)
            "valve_effect_noise_levels": valve_effect_on_pv(loop.spec, run) if loop.stiction else None,
            "probability": lv.get("probability"), "contradiction": lv.get("contradiction"),
            "screen_call": (rep.get("stiction") or {}).get("verdict"), "error": rep.get("error"),
            # what the valve-model fit says where it ran, whatever the screen's call: the verdict's rules
            # (phfdi.loopdiag.verdict) applied under another operating point can be counted from these
            "fit_decides": fitted and friction_decides(rep) is not None,
            "fit_takes_back": fitted and contradiction(rep) is not None}


def metrics(rows: list[dict]) -> dict:
    scored = [r for r in rows if r["loop_class"] not in UNSCORED]
    pos = [r for r in scored if r["stiction"]]
    neg = [r for r in scored if not r["stiction"]]
    tp = sum(r["verdict"] == "stiction" for r in pos)
    fp = sum(r["verdict"] == "stiction" for r in neg)
    und = sum(r["verdict"] not in ("stiction", "no_stiction") for r in scored)
    confident = [r for r in scored if r["verdict"] in ("stiction", "no_stiction")]
    right = sum((r["verdict"] == "stiction") == r["stiction"] for r in confident)
    return {"loops": len(scored), "stiction_loops": len(pos), "tp": tp, "fp": fp,
            "precision": tp / (tp + fp) if tp + fp else float("nan"), "recall": tp / len(pos) if pos else float("nan"),
            "false_call_rate": fp / len(neg) if neg else float("nan"),
            "undetermined_share": und / len(scored) if scored else float("nan"),
            "accuracy_undetermined_as_no": (tp + len(neg) - fp) / len(scored) if scored else float("nan"),
            "accuracy_confident": right / len(confident) if confident else float("nan"),
            "demoted_by_valve_model": sum(bool(r["contradiction"]) for r in scored)}


def class_table(rows: list[dict]) -> str:
    out = ["| class | label | loops | stiction | undetermined | no stiction |", "|---|---|---|---|---|---|"]
    for c in LOOP_CLASSES:
        idx = [r for r in rows if r["loop_class"] == c]
        if not idx:
            continue
        lab = "stiction" if c == "stiction" else ("not scored" if c in UNSCORED else "no stiction")
        k = [sum(r["verdict"] == v for r in idx) for v in CALLS]
        out.append(f"| {c} | {lab} | {len(idx)} | " + " | ".join(f"{v} ({v / len(idx):.0%})" for v in k) + " |")
    return "\n".join(out)


#: bands of a sticky valve's size, S (Kano) or fs (He), % of travel
SIZE_BANDS_PCT = (0.0, 0.6, 1.2, 2.5, 5.0, float("inf"))
#: bands of the simulated stem's break-aways in the record
SLIP_BANDS = (0, 3, 10, 30, float("inf"))
#: bands of how far a sticky valve moves PV (:func:`phfdi.loopdiag.domain.valve_effect_on_pv`), noise levels
EFFECT_BANDS = (0.0, 1.0, 2.0, 4.0, 8.0, float("inf"))


def _band_rows(rows: list[dict], values: list[float], edges: tuple, unit: str) -> list[str]:
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        # the last band is open above: it takes inf (a noiseless loop's valve effect) too
        idx = [r for r, v in zip(rows, values) if lo <= v and (v < hi or hi == float("inf"))]
        if not idx:
            continue
        k = [sum(r["verdict"] == v for r in idx) for v in CALLS]
        name = f">= {lo:g}{unit}" if hi == float("inf") else f"{lo:g}-{hi:g}{unit}"
        out.append(f"| {name} | {len(idx)} | " + " | ".join(f"{v} ({v / len(idx):.0%})" for v in k) + " |")
    return out


def valve_size_pct(valve) -> float:
    """A sticky valve's S (Kano's model) or fs (He's), % of travel."""
    params = valve[1]
    return float(params.get("s_pct", params.get("fs_pct", float("nan"))))


def size_tables(rows: list[dict]) -> str:
    """The sticky loops' calls by the valve's size, by the stem's break-aways and (rows that carry it) by how far
    the valve moves PV."""
    sticky = [r for r in rows if r["stiction"] and r["loop_class"] not in UNSCORED]
    if not sticky:
        return ""
    head = ["| {} | sticky loops | stiction | undetermined | no stiction |", "|---|---|---|---|---|"]
    out = [head[0].format("S or fs, % of travel"), head[1]]
    out += _band_rows(sticky, [valve_size_pct(r["valve"]) for r in sticky], SIZE_BANDS_PCT, " %")
    out += ["", head[0].format("break-aways of the simulated stem"), head[1]]
    out += _band_rows(sticky, [float(r["slips"]) for r in sticky], SLIP_BANDS, "")
    if all(r.get("valve_effect_noise_levels") is not None for r in sticky):  # rows written before 2026-12-08 do not
        out += ["", head[0].format("how far the valve moves PV: std of PV less the same loop's with a linear valve, "
                                   "noise levels"), head[1]]
        out += _band_rows(sticky, [float(r["valve_effect_noise_levels"]) for r in sticky], EFFECT_BANDS, "")
    return "\n".join(out)


def print_report(rows: list[dict], label: str) -> dict:
    m = metrics(rows)
    print(f"{label}: {m['loops']} scored loops ({m['stiction_loops']} sticky)")
    print(f"  precision {m['precision']:.3f} ({m['tp']}/{m['tp'] + m['fp']}), recall {m['recall']:.3f}, false calls on "
          f"loops without stiction {m['false_call_rate']:.1%} ({m['fp']}/{m['loops'] - m['stiction_loops']}), "
          f"undetermined {m['undetermined_share']:.1%}")
    print(f"  accuracy {m['accuracy_undetermined_as_no']:.3f} (undetermined counted as not calling stiction), "
          f"{m['accuracy_confident']:.3f} over the confident calls; {m['demoted_by_valve_model']} stiction calls "
          "made undetermined by the valve-model fit")
    print(class_table(rows))
    sizes = size_tables(rows)
    if sizes:
        print("\nsticky loops by the valve's size, by the stem's break-aways and by how far the valve moves PV:")
        print(sizes)
    return m


def main(argv: list[str] | None = None) -> int:
    try:
        return run(argv)
    except UserError as exc:  # an output that cannot be written: one line, the earlier file left as it was
        print(f"stiction_fresh_test: {exc}", file=sys.stderr)
        return 2


def run(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--per-class", type=int, default=40)
    p.add_argument("--seed", type=int, default=TEST_SEED)
    p.add_argument("--out", type=Path, default=OUT, help="where the verdicts are written")
    p.add_argument("--from-rows", type=Path, default=None, help="count verdicts written earlier")
    p.add_argument("--scheduler", default=None)
    p.add_argument("--workers", type=int, default=None)
    p.add_argument("--json", type=Path, default=None, help="also write the metrics here")
    p.add_argument("--classes", default=",".join(LOOP_CLASSES),
                   help=f"comma-separated classes to draw (default all: {','.join(LOOP_CLASSES)})")
    args = p.parse_args(argv)
    classes = [c.strip() for c in args.classes.split(",") if c.strip()]
    unknown = [c for c in classes if c not in LOOP_CLASSES]
    if unknown or not classes:
        p.error(f"--classes: unknown class {', '.join(unknown) or '(none given)'}; one of {', '.join(LOOP_CLASSES)}")
    for target in ([] if args.from_rows else [args.out]) + ([args.json] if args.json else []):
        check_writable_folder(target.parent)  # before minutes of simulation, not after
    if args.from_rows:
        rows = json.loads(args.from_rows.read_text())["rows"]
    else:
        t0 = time.perf_counter()
        sequence = [c for c in class_round_robin(args.per_class) if c in classes]
        loops = [d for d, _ in draw_class_loops(sequence, args.seed, "TEST")]

        def show(done, total):
            if done % 24 == 0 or done == total:
                print(f"{done}/{total} loops, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)

        with dask_client(args.scheduler, args.workers) as client:
            rows = map_ordered(client, verdict_row, loops, show, chunk=4)
        write_text(args.out, json.dumps({"seed": args.seed, "generator": "phfdi.loopdiag.training.draw_class_loops",
                                         "classes": classes, "rows": rows}, indent=0), overwrite=True)
        print(f"{len(rows)} loops in {time.perf_counter() - t0:.0f} s -> {args.out}", file=sys.stderr)
    m = print_report(rows, f"fresh simulated loops (seed {args.seed}, the per-class generator)")
    if args.json:
        write_text(args.json, json.dumps(m, indent=1), overwrite=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
