"""Leave-one-run-out on the real pH rig: can a model fitted on the other runs predict the held-out run?

For each run of ../shared/data/ph_rig (PROVENANCE.md) in turn: fit on the other runs, predict the held-out run
from its measured pump flows, score the held-out NRMSE (RMSE over the run's own standard deviation, after the
samples that set its start). Four models, all fitted on the same data, every choice made without the held-out run:

* nominal: the calibrated ``rig_flask`` preset, only each run's starting pH fitted;
* best single cause: the catalogue candidate (or structural one) of lowest *inner* held-out error (below);
* structure search: the forward selection of `phfdi diagnose --structure` (mixing zone, feed dead times, reagent
  strengths, carbonate in the caustic, the flask's starting contents, probe lag and calibration), run on the inner
  held-out errors, then the chosen set refitted on the four training runs;
* black box: a Wiener model (linear dynamics on the acid/base imbalance, fitted titration curve;
  phfdi.diagnosis.blackbox), which has no choice to make.

Nested selection (phfdi.diagnosis.nested): which single cause is "best", which effects the search adds and when it
stops are decided by an inner leave-one-run-out over the four training runs (each inner fold fits on three and
validates on the fourth under the same start/adapt rules; the inner held-out errors are pooled). Only then are
the chosen models fitted on the four training runs and the held-out run scored. Inner leave-one-run-out rather
than interleaved blocks within the training runs: the blocks would test prediction within a run (a per-run
parameter seen on both sides), not across runs, which is what the held-out run is asked. Before 2026-11-26 this
benchmark picked the best single cause by its error on the held-out run and let `diagnose` run the search with the
held-out run as its validation set: those numbers were selected on the run they scored, not predictions. The
table still shows, for comparison and labelled so, the single cause of lowest error on the held-out run.

The nominal model each fold starts from (``--nominal``, default ``calibrated``): the ``rig_flask`` preset's
physical parameters (H2SO4 and NaOH strengths, flask volume) calibrated on the fold's four training runs by
``phfdi.diagnosis.calibrate`` (the code of ``phfdi diagnose --calibrate``), with the keys, bounds and first guesses
the preset was calibrated with (docs/diagnosis.md, "Real measured data", step 1; the training runs at their own
sampling, interleaved blocks, one value per key for all of them: calibration has no groups). On the two titrations
that procedure gives the preset's values exactly (1.697 mM, 20.0 mM, 4.11 L). ``--nominal preset`` starts every
fold from the shipped preset instead, which was calibrated on the March and April titrations: the folds that
hold out a titration then start from a model fitted on it (the behaviour before 2026-11-27). Search bounds
(``--bounds``, default ``training``): the candidates' ranges (pKa from the pH quantiles, the longest delay from
the durations, the largest feed flows) and the noise unit from the training runs only (``Options.setup_from_fit``);
``--bounds all`` from every record, the held-out one included (before 2026-11-27). ``--nominal preset --bounds
all`` reproduces the earlier numbers; ``--compare OLD.json`` prints a run's table beside an earlier one.

Groups are the days in the file names (2025.02.24, 2025.03.03, 2025.04.07): reagent strengths (and the other
declared per-group parameters) are fitted per day. A held-out run of a day that is in the fit set uses that day's
values and only its start is set from its first 20 samples; a run of a day absent from the fit set (the March and
April titrations, one run each) gets its start and its day's declared parameters from its first ``--adapt``
fraction (0.2), which is then not scored. Nothing is tuned to any run: the same command for every fold.

    .venv/bin/python benchmarks/rig_holdout.py                 # all five folds, table on stdout
    .venv/bin/python benchmarks/rig_holdout.py --runs 2025.02.24-005 --dt 1 --json out/rig_holdout.json
    .venv/bin/python benchmarks/rig_holdout.py --nominal preset --bounds all --json out/old.json   # as before
    .venv/bin/python benchmarks/rig_holdout.py --compare out/old.json --json out/new.json         # side by side

Also printed, per run: its in-sample NRMSE under the chosen structure when it was in the fit set (median over the
folds that fitted it) beside its held-out NRMSE: a run fitted well but predicted badly is one whose parameters are
not shared with the other runs.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

from phfdi.diagnosis.blackbox import fit_wiener
from phfdi.diagnosis.data import diagnosis_map, load_record
from phfdi.diagnosis.evidence import BANDS, evidence
from phfdi.diagnosis.evidence import figure as evidence_figure
from phfdi.diagnosis.evidence import table as evidence_table
from phfdi.diagnosis.model import Evaluator, nominal_raw
from phfdi.diagnosis.nested import Fold, outer_fold
from phfdi.diagnosis.pipeline import Options
from phfdi.records import ColumnMap

ROOT = Path(__file__).resolve().parents[1]
MAP = ROOT / "src" / "phfdi" / "diagnosis" / "maps" / "ph_rig.yaml"
GROUP = r"^([0-9]{4}\.[0-9]{2}\.[0-9]{2})"
#: The rig's pumps run at one or two speeds (0/60/100 % in February, 20->50 % and 50 % in the titrations): a pump
#: curve's threshold is not identifiable there and its gain is the reagent strength (left out); probe: one lag and
#: the two-point calibration; the process: flask volume, reagent strengths, carbonate, mixing zone, feed dead time,
#: and what the flask holds at the start (a weak acid of its own water, its amount per run).
DEFAULT_CANDIDATES = ["reagent_concentration", "holdup", "carbonate", "mixing_zone", "feed_delay", "sensor_lag",
                      "two_point_calibration", "flask_contents"]


#: how the rig_flask preset was calibrated (docs/diagnosis.md, "Real measured data", step 1): these keys and bounds,
#: from these first guesses; each fold repeats it on its training runs (--nominal calibrated)
CALIBRATE_KEYS = ["plant.feeds.acid.recipe.H2SO4=0.0002:0.05", "plant.feeds.base.recipe.NaOH=0.0005:0.1",
                  "plant.tank.volume_ml=50:20000"]
FIRST_GUESSES = ["plant.feeds.acid.recipe.H2SO4=0.005", "plant.feeds.base.recipe.NaOH=0.01",
                 "plant.tank.volume_ml=500"]
SHORT = {"plant.feeds.acid.recipe.H2SO4": ("H2SO4", 1e3, "mM"), "plant.feeds.base.recipe.NaOH": ("NaOH", 1e3, "mM"),
         "plant.tank.volume_ml": ("flask", 1e-3, "L")}


def shared_data() -> Path:
    env = os.environ.get("PHFDI_SHARED_DATA")
    return Path(env) if env else ROOT.parent / "shared" / "data"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=None, help="the ph_rig folder (default ../shared/data/ph_rig)")
    ap.add_argument("--runs", nargs="*", default=None, help="hold out only runs whose name starts with these")
    ap.add_argument("--dt", type=float, default=1.0, help="resample onto this sample time (s; default 1)")
    ap.add_argument("--adapt", type=float, default=0.2)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--search-width", type=int, default=4)
    ap.add_argument("--search-steps", type=int, default=4)
    ap.add_argument("--candidates", nargs="*", default=DEFAULT_CANDIDATES,
                    help="causes tried (default: those a rig with on/off pumps can tell apart, see below)")
    ap.add_argument("--nominal", choices=["calibrated", "preset"], default="calibrated",
                    help="the nominal model of each fold: the preset's acid and base strengths and flask volume "
                         "calibrated on the fold's training runs (default), or the shipped rig_flask preset "
                         "(calibrated on the two titrations: not a prediction of those)")
    ap.add_argument("--bounds", choices=["training", "all"], default="training",
                    help="the candidates' search bounds and noise unit from the training runs only (default), or "
                         "from every record, the held-out one included (before 2026-11-27)")
    ap.add_argument("--compare", type=Path, default=None, metavar="OLD.json",
                    help="also print this table beside the one in OLD.json (an earlier --json)")
    ap.add_argument("--json", type=Path, default=None, help="write the table and the fitted models here")
    ap.add_argument("--predictions", type=Path, default=None,
                    help="write each fold's predictions of its held-out run (every model) to DIR/<run>.json, "
                         "for --evidence")
    ap.add_argument("--evidence", type=Path, nargs="+", default=None, metavar="DIR",
                    help="no fitting: read the folds saved in DIR by --predictions and print, per held-out run, what "
                         "no fitted model reproduces (pH bands, timing, titration-curve shape, span, offset); with "
                         "several DIRs (runs with other --candidates), a run's models are pooled, its table row and "
                         "structure from the first DIR")
    ap.add_argument("--figure", type=Path, default=None, help="with --evidence: write the figure here (PNG)")
    args = ap.parse_args(argv)
    if args.evidence:
        return show_evidence(args.evidence, args.figure)
    folder = args.data or shared_data() / "ph_rig"
    files = sorted(folder.glob("*.csv"))
    if not files:
        print(f"rig_holdout: no runs in {folder}", file=sys.stderr)
        return 2
    cmap = diagnosis_map(ColumnMap.load(MAP))
    groups = [re.match(GROUP, f.name).group(1) for f in files]
    nominal = nominal_raw("rig_flask", FIRST_GUESSES if args.nominal == "calibrated" else [])
    rows, fitted_in_sample = [], {f.name: [] for f in files}
    t_all = time.perf_counter()
    for h, held in enumerate(files):
        if args.runs and not any(held.name.startswith(r) for r in args.runs):
            continue
        row, pred, wf = run_fold(files, groups, h, cmap, nominal, args, fitted_in_sample)
        rows.append(row)
        if args.predictions:
            save_fold(args.predictions, pred, wf, row, args.adapt, row["group_in_fit"])
        print(f"{row['run']}: the fold's nominal model: {describe_nominal(row['nominal_model'])}", file=sys.stderr)
        print(f"{row['run']}: nominal {row['nominal']:.3f}, best single, nested ({row['best_single_cause']}) "
              f"{row['best_single']:.3f}, structure, nested ({' -> '.join(row['structure_path'])}) "
              f"{row['structure']:.3f}, black box {row['black_box']:.3f}; selected on the held-out run (not a "
              f"prediction): best single ({row['best_single_on_test_cause']}) {row['best_single_on_test']:.3f}  "
              f"[{row['seconds']:.0f} s, selection {row['selection']['seconds']:.0f} s]", file=sys.stderr, flush=True)
        if args.json:  # after every fold: a long run keeps what it measured
            write_json(args.json, rows, fitted_in_sample)
    print(table(rows, fitted_in_sample))
    print(f"\ntotal {time.perf_counter() - t_all:.0f} s (dt {args.dt} s, {args.workers} workers, nominal "
          f"{args.nominal}, bounds from {args.bounds})")
    if args.json:
        write_json(args.json, rows, fitted_in_sample)
    if args.compare:
        print()
        print(comparison(rows, json.loads(args.compare.read_text())["rows"], str(args.compare)))
    return 0


def write_json(path: Path, rows: list[dict], in_sample: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"rows": rows, "in_sample": in_sample}, indent=2, default=float))


def run_fold(files: list[Path], groups: list[str], h: int, cmap, nominal: dict, args, fitted_in_sample: dict):
    """One outer fold (phfdi.diagnosis.nested.outer_fold): calibrate the nominal model on the four training runs
    (``--nominal calibrated``), select on them (inner leave-one-run-out), then fit the chosen models on them and
    score the held-out run."""
    held = files[h]
    fit_recs = [load_record(f, cmap, args.dt) for i, f in enumerate(files) if i != h]
    held_rec = load_record(held, cmap, args.dt)
    fold_groups = [g for i, g in enumerate(groups) if i != h] + [groups[h]]
    t0 = time.perf_counter()
    say = lambda text: print(f"  [{held.name[:22]}] {text}", file=sys.stderr, flush=True)  # noqa: E731
    opts = Options(initial="fit", structure=True, adapt=args.adapt, candidates=args.candidates or None, pairs=False,
                   workers=args.workers, search_width=args.search_width, search_steps=args.search_steps,
                   progress=say, setup_from_fit=args.bounds == "training")
    start = f"calibrated on the {len(fit_recs)} training runs" if args.nominal == "calibrated" else "the preset"
    bounds = "the training runs" if args.bounds == "training" else "every run, the held-out one included"
    say(f"nominal: {start}; bounds from {bounds}; "
        f"selecting on the {len(fit_recs)} training runs only (inner leave-one-run-out)")
    calibrated = args.nominal == "calibrated"  # at the data's own sampling, as the preset was calibrated
    cal_recs = [load_record(f, cmap, None) for i, f in enumerate(files) if i != h] if calibrated else None
    fold = outer_fold(fit_recs, held_rec, fold_groups, nominal, "rig_flask", opts,
                      CALIBRATE_KEYS if calibrated else None, cal_recs)
    sel, pred = fold.selection, fold.prediction
    if fold.calibration is not None:
        say(f"calibrated on the training runs: {describe_nominal(nominal_entry(fold, nominal))}")
    say(f"chosen without the held-out run: best single {sel.best_single}; structure "
        f"{' + '.join(sel.chosen) or 'nothing added'} ({sel.stopped}) [{sel.seconds:.0f} s]")
    d = pred.diagnosis
    wf = fit_wiener(d.records, d.train, d.val, ["acid", "base"], "base", fold_groups, args.adapt)
    row = fold_row(fold, held.name, groups[h], groups[h] in fold_groups[:-1], wf)
    row.update(seconds=time.perf_counter() - t0, nominal_model=nominal_entry(fold, nominal),
               setup={"nominal": args.nominal, "bounds": args.bounds, "context": context_entry(d.context)})
    final = pred.structure
    if final is not None:  # in-sample NRMSE of the fitted runs under the chosen structure
        for i, rec in enumerate(d.records[:-1]):
            raw = final.record_raws[i] if final.record_raws else final.raw
            p = Evaluator(rec, raw, "fit").predict(raw, final.starts[i]).outputs["ph_measured"]
            y = rec.outputs["ph_measured"]
            fitted_in_sample[rec.name].append(float(np.sqrt(np.mean((p - y) ** 2)) / np.std(y)))
    return row, pred, wf


def fold_row(fold: Fold, name: str, group: str, seen: bool, wf) -> dict:
    """The fold's table row: held-out NRMSE of every model, what was chosen and fitted, the old rule's pick."""
    sel, pred = fold.selection, fold.prediction
    d = pred.diagnosis
    on_test = min(d.singles, key=lambda r: r.val_by_record.get(name, np.inf))  # the old rule: NOT a prediction
    final = pred.structure
    nom_nrmse = d.report["structure_search"]["nrmse_by_record_nominal"].get(name)
    return {"run": name, "group": group, "group_in_fit": seen, "nominal": nom_nrmse,
            "best_single": pred.best_single.val_by_record.get(name) if pred.best_single else nom_nrmse,
            "best_single_cause": sel.best_single or "none",
            "structure": final.val_by_record.get(name) if final is not None else nom_nrmse,
            "structure_path": ["nominal"] + list(sel.chosen),
            "structure_chain": {f.label: f.val_by_record.get(name) for f in pred.chain},
            "structure_parameters": final.params if final is not None else {},
            "structure_intervals": final.intervals if final is not None else {},
            "adapted": (final.fitted_where.get("adapted", {}) if final is not None else {}),
            "black_box": wf.nrmse_by_record.get(name),
            "best_single_on_test": on_test.val_by_record.get(name), "best_single_on_test_cause": on_test.label,
            "selection": {"protocol": "inner leave-one-run-out over the training runs, pooled inner held-out error",
                          "inner_held_out": sel.inner_records, "singles_pooled_cost": sel.singles,
                          "nominal_pooled_cost": sel.nominal, "path": sel.path, "stopped": sel.stopped,
                          "seconds": sel.seconds, "joint_fits": sel.fits},
            "singles": {r.label: r.val_by_record.get(name) for r in d.singles},
            "singles_parameters": {r.label: r.params for r in d.singles},
            "singles_adapted": {r.label: (r.fitted_where.get("adapted") or {}).get(name) for r in d.singles}}


def nominal_entry(fold: Fold, start: dict) -> dict:
    """The fold's nominal model: the calibrated keys with their intervals, or the preset's values."""
    keys = [k.partition("=")[0] for k in CALIBRATE_KEYS]

    def value(raw: dict, key: str) -> float:
        node = raw
        for part in key.split("."):
            node = node[part]
        return float(node)

    if fold.calibration is None:
        return {"source": "preset rig_flask (calibrated on the March and April titrations)",
                "params": {k: value(fold.nominal, k) for k in keys}, "intervals": {}}
    cal = fold.calibration
    return {"source": "calibrated on the fold's training runs (interleaved blocks)",
            "params": {k: float(cal.params[k]) for k in keys},
            "intervals": {k: [float(x) for x in cal.intervals.get(k, [np.nan, np.nan])] for k in keys},
            "first_guesses": {k: value(start, k) for k in keys},
            "calibration_nrmse_first_guesses": cal.nominal.get("ph_measured"),
            "calibration_nrmse": cal.calibrated.get("ph_measured"),
            "records": [r.name for r in cal.records]}


def describe_nominal(entry: dict) -> str:
    """'H2SO4 1.70 mM [1.66, 1.73], NaOH ...' from a nominal_entry."""
    out = []
    for k, v in entry["params"].items():
        name, f, unit = SHORT.get(k, (k, 1.0, ""))
        iv = entry["intervals"].get(k)
        out.append(f"{name} {f * v:.3g} {unit}" + (f" [{f * iv[0]:.3g}, {f * iv[1]:.3g}]" if iv else ""))
    return ", ".join(out)


def context_entry(ctx) -> dict:
    """What of the fits' search context depends on the data (for the record)."""
    if ctx is None:
        return {}
    return {"ph_range": list(ctx.ph_range), "duration_s": ctx.duration_s, "feed_max_flow_ml_s": ctx.feed_max_flow_ml_s,
            "vessel_volume_ml": ctx.vessel_volume_ml, "feed_strength_mol_l": ctx.feed_strength_mol_l}


def show_evidence(folders: list[Path], figure_path: Path | None) -> int:
    """Per held-out run, what the best of all fitted models still misses (phfdi.diagnosis.evidence)."""
    by_run: dict[str, dict] = {}
    for folder in folders:
        paths = sorted(folder.glob("*.json")) if folder.is_dir() else []
        for p in paths:
            fold = json.loads(p.read_text())
            if "predictions" not in fold:
                continue
            if fold["run"] not in by_run:
                by_run[fold["run"]] = fold
                continue
            pooled = by_run[fold["run"]]["predictions"]
            for k, v in fold["predictions"].items():
                if k not in pooled and k not in ("structure", "best_single"):
                    pooled[k] = v
    folds = [by_run[r] for r in sorted(by_run)]
    if not folds:
        print(f"rig_holdout: no folds in {' '.join(map(str, folders))} (write them with --predictions DIR)",
              file=sys.stderr)
        return 2
    evs = [evidence(f) for f in folds]
    in_sample: dict[str, list[float]] = {}
    for f in folds:  # the final structure's in-sample NRMSE of each run it was fitted on
        for r in f["fitted_in_sample"]:
            y, p = np.asarray(r["measured"]), np.asarray(r["structure"])
            in_sample.setdefault(r["run"], []).append(float(np.sqrt(np.mean((p - y) ** 2)) / np.std(y)))
    print(table([f["row"] for f in folds], in_sample))
    print()
    print(evidence_table(evs))
    for f, ev in zip(folds, evs):
        ins = [rmse_in_bands(r) for r in f["fitted_in_sample"]]
        print(f"{ev.run}: pH-7 crossing errors (s) per model: "
              + "; ".join(f"{k}: {', '.join('-' if e is None else f'{e:+.0f}' for e in v)}"
                          for k, v in ev.crossing_error_s.items() if k in ("nominal", "structure", "black_box",
                                                                             ev.best_model)))
        print("  fitted in this fold (in-sample RMSE per band acidic/transition/basic, pH): "
              + "; ".join(f"{r['run'][:22]} {' / '.join(_f(x) for x in b)}" for r, b in zip(f["fitted_in_sample"], ins)))
    if figure_path:
        figure_path.parent.mkdir(parents=True, exist_ok=True)
        evidence_figure(folds, evs, figure_path)
        print(f"figure: {figure_path}")
    return 0


def _f(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{x:.2f}"


def rmse_in_bands(r: dict) -> list[float]:
    """RMSE (pH) of a fitted run's in-sample structure prediction per measured pH band."""
    y, p = np.asarray(r["measured"]), np.asarray(r["structure"])
    out = []
    for _, lo, hi in BANDS:
        m = (y >= lo) & (y < hi)
        out.append(float(np.sqrt(np.mean((p[m] - y[m]) ** 2))) if m.sum() >= 10 else float("nan"))
    return out


def scored_mask(n: int, adapt: float, seen: bool, init_window: int = 20) -> np.ndarray:
    """The held-out run's scored samples: all but those that set its start (and, for an unseen day, its
    declared per-day parameters), as in ``Fitter.validate``."""
    mask = np.ones(n, bool)
    mask[: init_window if seen or adapt <= 0 else max(init_window, int(round(adapt * n)))] = False
    return mask


def save_fold(folder: Path, pred, wf, row: dict, adapt: float, seen: bool) -> Path:
    """Every model's prediction of the held-out run (the last record) and the chosen structure's in-sample
    predictions of the fitted runs: what ``--evidence`` analyses. ``pred``: phfdi.diagnosis.nested.Prediction."""
    d = pred.diagnosis
    h = len(d.records) - 1
    rec = d.records[h]

    def pred_of(fit, i: int = h):
        raw = fit.record_raws[i] if fit.record_raws else fit.raw
        return Evaluator(d.records[i], raw, "fit").predict(raw, fit.starts[i])

    preds = {"nominal": d.nominal[h].outputs["ph_measured"].tolist()}
    for fit in d.singles:
        preds[fit.label] = pred_of(fit).outputs["ph_measured"].tolist()
    for fit in pred.chain[1:]:
        preds[f"structure: {fit.label}"] = pred_of(fit).outputs["ph_measured"].tolist()
    final = pred.structure
    preds["structure"] = pred_of(final).outputs["ph_measured"].tolist() if final is not None else preds["nominal"]
    preds["black_box"] = wf.predictions[rec.name].tolist()
    preds["best_single"] = preds[pred.best_single.label] if pred.best_single is not None else preds["nominal"]
    fitted = []
    for i, r in enumerate(d.records[:h]):
        p = pred_of(final, i) if final is not None else d.nominal[i]
        fitted.append({"run": r.name, "time_s": (r.time_s - r.time_s[0]).tolist(),
                       "measured": r.outputs["ph_measured"].tolist(), "structure": p.outputs["ph_measured"].tolist()})
    out = {"run": rec.name, "group_in_fit": seen, "dt_s": rec.dt_s, "time_s": (rec.time_s - rec.time_s[0]).tolist(),
           "measured": rec.outputs["ph_measured"].tolist(),
           "flows_ml_s": {k: v.tolist() for k, v in rec.inputs.items() if k.endswith("_flow_ml_s")},
           "scored": scored_mask(len(rec), adapt, seen).tolist(), "noise_floor_ph": d.noise.get("ph_measured"),
           "predictions": preds, "row": row, "fitted_in_sample": fitted}
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{Path(rec.name).stem}.json"
    path.write_text(json.dumps(out, default=float))
    return path


def table(rows: list[dict], in_sample: dict) -> str:
    """Held-out NRMSE per run: the genuine predictions (every choice made on the training runs), then the single
    cause picked by its error on the held-out run itself (the old rule: not a prediction, for comparison)."""
    out = ["| held-out run | its day in the fit? | nominal | best single cause (nested) | structure search (nested) "
           "| black box (Wiener) | best single selected on the held-out run (not a prediction) "
           "| structure, in-sample when fitted (median) | the fold's nominal model |",
           "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | --- |"]
    for r in rows:
        ins = in_sample.get(r["run"]) or []
        path = [s for s in r.get("structure_path", []) if s != "nominal"]
        on_test = (f"{r['best_single_on_test']:.3f} ({r['best_single_on_test_cause']})"
                   if r.get("best_single_on_test") is not None else "-")
        out.append(f"| {r['run']} | {'yes' if r['group_in_fit'] else 'no (--adapt)'} | {r['nominal']:.3f} | "
                   f"{r['best_single']:.3f} ({r['best_single_cause']}) | {r['structure']:.3f} "
                   f"({' + '.join(path) or 'nothing added'}) | {r['black_box']:.3f} | {on_test} | "
                   f"{f'{np.median(ins):.3f}' if ins else '-'} | "
                   f"{describe_nominal(r['nominal_model']) if r.get('nominal_model') else 'preset rig_flask'} |")
    return "\n".join(out)


def comparison(rows: list[dict], old_rows: list[dict], old_name: str) -> str:
    """Held-out NRMSE of this run beside an earlier one's (``--compare``), per held-out run and model."""
    old = {r["run"]: r for r in old_rows}

    def setup(r: dict | None) -> str:
        s = (r or {}).get("setup") or {"nominal": "preset", "bounds": "all"}
        return f"nominal {s['nominal']}, bounds {s['bounds']}"

    out = [f"this run ({setup(rows[0] if rows else None)}) / {old_name} "
           f"({setup(old_rows[0] if old_rows else None)}): held-out NRMSE",
           "| held-out run | nominal | best single (nested) | structure (nested) | black box (Wiener) |",
           "| --- | ---: | ---: | ---: | ---: |"]
    for r in rows:
        o = old.get(r["run"], {})
        cells = []
        for k, cause in (("nominal", None), ("best_single", "best_single_cause"), ("structure", "structure_path"),
                         ("black_box", None)):
            was = f"{o[k]:.3f}" if o.get(k) is not None else "-"
            why = ""
            if cause == "best_single_cause":
                why = f" ({r[cause]} / {o.get(cause, '-')})"
            elif cause == "structure_path":
                why = (f" ({' + '.join(r[cause][1:]) or 'nothing'} / "
                       f"{' + '.join(o.get(cause, ['nominal'])[1:]) or 'nothing'})")
            cells.append(f"{r[k]:.3f} / {was}{why}")
        out.append(f"| {r['run']} | " + " | ".join(cells) + " |")
    return "\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
