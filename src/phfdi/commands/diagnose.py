"""phfdi diagnose: what the model gets wrong on measured data, the cause, the extended model and its gain."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from phfdi_base.errors import UserError

from .common import EPILOG_FORMAT, add_overwrite_arg, column_map_from_args, plant_runs_on, print_notes

EXAMPLES = """examples:
  # a run of the project (CSV, Parquet or .mcap bag) against the paper model, segments held out
  phfdi diagnose --data runs/plant.csv --model paper --out out/diag
  # any CSV with a column map; fit on two files, validate on a third; JSON on stdout
  phfdi diagnose --fit a.csv b.csv --validate c.csv --map my_columns.yaml --model my_loop.yaml --json
  phfdi diagnose --data log.csv --column time_s=t --column valve_command_pct=OP --column ph_measured=PV
  # the teaching-lab rig: estimate the nominal model from the titrations, then diagnose the other runs
  phfdi diagnose --model rig_flask --map ph_rig --initial fit --fit titration1.csv titration2.csv \\
      --calibrate plant.feeds.acid.recipe.H2SO4 plant.feeds.base.recipe.NaOH plant.tank.volume_ml
  phfdi diagnose --model out/diagnose/calibrated_model.yaml --map ph_rig --initial fit \\
      --fit add_base.csv add_acid.csv --validate control.csv
  # structure search (mixing zone, tanks in series, feed dead times, pump curves and lags, carbonate, CO2 from
  # the air, the flask's own starting contents, probe dynamics and calibration
  # added one at a time while the held-out gain is significant); reagent strengths and probe offsets per day
  # (the date in the file name); a day absent from the fit gets those from the first 20 % of its record
  phfdi diagnose --model rig_flask --map ph_rig --initial fit --structure --group '^([0-9.]{10})' \\
      --adapt 0.2 --fit 2025.02.24-*.csv 2025.03.03-*.csv --validate 2025.04.07-*.csv

column map (YAML; signal: column, or signal: {column: NAME, unit: UNIT}):
  time_s: {column: "ElapsedTime (s)", unit: s}        # s, ms, min, h
  base_flow_ml_s: {column: "Base Flow, mL/s", unit: mL/s}   # mL/s, mL/min, L/min, L/h, m3/h
  valve_command_pct: OP                                # %, fraction
  level_controller_output_pct: LIC_OP
  ph_measured: pH                                      # pH
  level_measured_cm: {column: level, unit: mm}         # cm, mm, m
Named maps shipped with phfdi: ph_rig (../shared/data/ph_rig). Files are read under the reading
policy of docs/records.md (any delimiter, encoding detected or --encoding, repeated stamps repaired,
NaN/inf/text cells missing; short gaps of up to 5 samples filled); every repair is printed as a note
and listed in the report. A measured output with no value at all is an error.

catalogue: stiction backlash deadzone saturation coulomb_viscous_friction leakage valve_gain (actuator),
  sensor_delay sensor_lag sensor_bias sensor_drift sensor_gain (sensor),
  buffer reagent_concentration holdup disturbance_flow (process); verdicts: explained, not_explained,
  none, not_identifiable. Structural candidates (--structure, or by name with --candidates): mixing_zone
  tanks_in_series feed_delay carbonate co2_absorption flask_contents (process), pump_curve pump_lag
  (actuator), probe_asymmetric_lag sensor_second_order two_point_calibration (sensor). flask_contents: a
  weak acid the vessel holds at the start (carbonate, or one of fitted pKa), its amount fitted per record.
{own_candidates}
  Bad input exits with status 2 and one line naming the problem.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("diagnose", help="diagnose a model against measured data: misfit, cause, extended model, gain",
                       description="Simulate the nominal model open loop on measured inputs, show where and how it "
                                   "misses the measured outputs, fit a catalogue of model extensions (actuator, "
                                   "sensor, process), name the cause that explains the held-out data, write the "
                                   "extended model as a scenario file and measure its gain on held-out data.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    src = p.add_argument_group("data")
    src.add_argument("--data", nargs="+", metavar="FILE", help="records to diagnose: interleaved blocks of each are "
                                                              "fitted and held out")
    src.add_argument("--fit", nargs="+", metavar="FILE", help="records to fit on")
    src.add_argument("--validate", nargs="+", metavar="FILE", help="records held out for validation (with --fit)")
    src.add_argument("--map", default=None, help="column map: a YAML file or a shipped name (ph_rig)")
    src.add_argument("--column", action="append", default=[], metavar="SIGNAL=COLUMN",
                     help="map one column (instead of --map)")
    src.add_argument("--unit", action="append", default=[], metavar="SIGNAL=UNIT", help="unit of a --column")
    src.add_argument("--encoding", default=None,
                     help="text encoding of the CSV files when it cannot be detected (e.g. cp1250)")
    src.add_argument("--dt", type=float, default=None, metavar="S", help="resample onto this sample time (s)")
    mod = p.add_argument_group("model")
    mod.add_argument("--model", default="paper", help="nominal model: scenario preset or .yaml (default: paper)")
    mod.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                     help="override a model key, e.g. --set plant.tank.volume_ml=900 --set sensors.ph.lag_s=5")
    mod.add_argument("--initial", choices=["steady", "fit"], default="steady",
                     help="plant state at each record's start: steady state of its first inputs (default), or "
                          "fitted (records that start mid-transient, e.g. titrations)")
    how = p.add_argument_group("diagnosis")
    how.add_argument("--candidates", nargs="+", default=None, metavar="CAUSE", help="restrict the catalogue")
    how.add_argument("--no-pairs", action="store_true", help="do not fit pairs of candidates")
    how.add_argument("--calibrate", nargs="+", default=None, metavar="KEY[=LOW:HIGH]",
                     help="instead of diagnosing: estimate these model keys from the data and write the calibrated "
                          "model (calibrated_model.yaml)")
    how.add_argument("--workers", type=int, default=None, help="worker processes (default: every core)")
    how.add_argument("--out", default="out/diagnose", help="report folder (default: out/diagnose)")
    add_overwrite_arg(how, folder=True)
    how.add_argument("--structure", action="store_true",
                     help="forward structure search: add the effect with the largest held-out gain, refit all "
                          "jointly, stop when the next addition is not significant; writes structure_model.yaml")
    how.add_argument("--search-width", type=int, default=6, metavar="N",
                     help="candidates tried at each step of the structure search (default 6)")
    how.add_argument("--search-steps", type=int, default=5, metavar="N", help="at most N effects (default 5)")
    how.add_argument("--group", default=None, metavar="REGEX",
                     help="group records by a pattern of their file name (its first parenthesised group, else the "
                          "match): declared parameters (reagent strengths, probe offset) are fitted per group")
    how.add_argument("--adapt", type=float, default=0.0, metavar="FRACTION",
                     help="with --group: a validation record of a group absent from the fit gets its start and its "
                          "group's declared parameters from this first fraction of it (not scored); e.g. 0.2")
    how.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    how.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def _map(args):
    """The diagnosis column map of --map or --column (checked: time, an input, an output), or None."""
    from phfdi.diagnosis.data import diagnosis_map

    cmap = column_map_from_args(args)
    if cmap is None:
        return None
    return diagnosis_map(cmap)


def _groups(pattern: str, files: list[str]) -> list[str]:
    """Group of each file: the first parenthesised group of ``pattern`` in its name, else the whole match."""
    import re

    try:
        rx = re.compile(pattern)
    except re.error as exc:
        raise UserError(f"--group {pattern!r}: not a regular expression ({exc})") from None
    out = []
    for f in files:
        m = rx.search(Path(f).name)
        if m is None:
            raise UserError(f"--group {pattern!r}: no match in the file name {Path(f).name!r}")
        out.append(m.group(1) if rx.groups else m.group(0))
    return out


def _records(files, cmap, dt, encoding=None):
    from phfdi.diagnosis.data import load_record

    return [load_record(f, cmap, dt, encoding) for f in files]


def run(args: argparse.Namespace) -> int:
    from phfdi.diagnosis.model import nominal_raw
    from phfdi.diagnosis.pipeline import Options

    if args.data and (args.fit or args.validate):
        raise UserError("give --data, or --fit (and --validate), not both")
    if not args.data and not args.fit:
        raise UserError("no data: give --data FILE ... or --fit FILE ... [--validate FILE ...]")
    if args.validate and not args.fit:
        raise UserError("--validate needs --fit")
    from phfdi_base.outputs import output_folder

    cmap = _map(args)
    fit_records = _records(args.data or args.fit, cmap, args.dt, args.encoding)
    val_records = _records(args.validate or [], cmap, args.dt, args.encoding)
    output_folder(args.out, args.overwrite)  # after the records are read, before minutes of fitting
    print_notes("diagnose", [f"{r.name}: {n}" for r in fit_records + val_records for n in r.notes])
    nominal = nominal_raw(args.model, args.overrides)
    progress = None if args.quiet else (lambda text: print(f"diagnose: {text}", file=sys.stderr, flush=True))
    if not 0.0 <= args.adapt < 1.0:
        raise UserError(f"--adapt {args.adapt}: a fraction in [0, 1)")
    if args.adapt and not args.group:
        raise UserError("--adapt needs --group (it adapts the parameters of a group the fit has not seen)")
    if args.search_width < 1 or args.search_steps < 1:
        raise UserError("--search-width and --search-steps must be at least 1")
    groups = _groups(args.group, (args.data or args.fit) + (args.validate or [])) if args.group else None
    opts = Options(initial=args.initial, candidates=args.candidates, pairs=not args.no_pairs,
                   workers=args.workers, progress=progress, structure=args.structure,
                   search_width=args.search_width, search_steps=args.search_steps, groups=groups, adapt=args.adapt)
    command = "phfdi " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv and "phfdi" in sys.argv[0] \
        else ""
    if args.calibrate:
        return _calibrate(args, fit_records, val_records, nominal, opts)
    from phfdi.diagnosis.output import terminal_summary, write_all
    from phfdi.diagnosis.pipeline import diagnose
    from phfdi.diagnosis.report import to_json

    with plant_runs_on(", ".join(r.name for r in fit_records + val_records)):
        d = diagnose(fit_records, val_records, nominal, args.model, opts)
    rep = write_all(d, args.out, args.model, command)
    if args.json:
        print(to_json(rep))
    else:
        print(terminal_summary(rep))
    if rep["verdict"] == "not_identifiable":
        print(f"phfdi diagnose: error: nothing identifiable: {rep['reason']}", file=sys.stderr)
        return 2
    return 0


def _calibrate(args, fit_records, val_records, nominal, opts) -> int:
    from phfdi.diagnosis.calibrate import calibrate
    from phfdi.diagnosis.extend import write_model
    from phfdi.diagnosis.report import clean, fmt_num, fmt_params

    if all(r.constant_inputs() for r in fit_records + val_records) and args.initial == "steady":
        raise UserError("nothing identifiable: every input is constant and the model starts at rest "
                        "(use --initial fit for records that start mid-transient)")
    with plant_runs_on(", ".join(r.name for r in fit_records + val_records)):
        cal = calibrate(fit_records, val_records, nominal, args.calibrate, opts)
    out = Path(args.out)
    header = (f"written by phfdi diagnose --calibrate: {args.model!r} with "
              f"{fmt_params(cal.params, cal.intervals)}\n"
              f"held-out NRMSE: " + ", ".join(f"{o} {fmt_num(cal.nominal[o], '.4f')} -> {fmt_num(cal.calibrated[o], '.4f')}"
                                              for o in cal.nominal))
    path = write_model(out / "calibrated_model.yaml", args.model, cal.raw, header,
                       f"{Path(args.model).stem}-calibrated")
    rep = clean({"model": args.model, "calibrated_model": str(path), "parameters": cal.params,
                 "confidence_intervals": cal.intervals, "nrmse_nominal": cal.nominal,
                 "nrmse_calibrated": cal.calibrated,
                 "initial_ph": [s.ph for s in cal.starts] if args.initial == "fit" else None,
                 "data": [r.name for r in cal.records], "notes": [n for r in cal.records for n in r.notes]})
    from phfdi_base.outputs import write_text

    write_text(out / "calibration.json", json.dumps(rep, indent=2), overwrite=True)
    if args.json:
        print(json.dumps(rep, indent=2))
    else:
        print(f"calibrated {args.model} on {', '.join(rep['data'])}")
        print(f"  {fmt_params(cal.params, cal.intervals)}")
        for o in cal.nominal:
            print(f"  held-out NRMSE {o}: {fmt_num(cal.nominal[o], '.4f')} -> {fmt_num(cal.calibrated[o], '.4f')}")
        print(f"  wrote {path}")
    return 0
