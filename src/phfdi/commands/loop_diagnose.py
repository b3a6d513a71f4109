"""phfdi loop-diagnose: valve stiction and friends from historian OP, PV and SP."""

from __future__ import annotations

import argparse
import sys

from phfdi.loopdiag.dask_run import CONNECT_TIMEOUT_S

from .common import EPILOG_FORMAT, add_overwrite_arg, print_notes

EXAMPLES = """examples:
  phfdi loop-diagnose ../shared/data/plant_loops/stiction/stic_2111FIC46005_0614_0003.txt
  phfdi loop-diagnose ../shared/data/plant_loops/stiction ../shared/data/plant_loops/no_stiction \\
      --out plant/ --figures plant/figs      # folders: every .txt/.csv/.parquet below them is a loop
  phfdi loop-diagnose historian_export.csv --out plant/           # a wide export: one job per loop tag
  phfdi loop-diagnose /data/unit2 --scheduler tcp://10.0.0.5:8786 --out unit2/
  phfdi loop-diagnose ../shared/data/plant_loops/*/*.txt --json > loops.json
  phfdi loop-diagnose export.csv --columns op=FIC101.OP,pv=FIC101.PV,sp=FIC101.SP,time=Timestamp
  phfdi loop-diagnose export.csv --columns mapping.yaml --process integrating --figure figs/

screen and fits: every loop is screened (structure checks, oscillation, the published indicators, the
dead-band screen, a calibrated p(stiction)); the valve-model fits (Kano S and J, backlash, dead-zone,
saturation, quantisation) run only where the screen flags stiction or undetermined (--fits all: every
loop; --fits none: none, the screen alone). The probability's model, calibration and thresholds were
fitted on simulated loops only. A record longer than 1502 samples is screened in windows of 751 (at
most 64, spread over it); a text file of more than 200 000 rows is read as 64 windows of 800 rows
spread over it (said in a note, with progress on stderr).

inputs: files and folders (every .txt, .csv, .parquet below them). A CSV whose header holds several
loops' tags (<tag>.OP or .MV, .PV, .SP or .SV) is a wide historian export: each loop tag is one job.
Many jobs run on Dask: a local cluster of --workers processes (default 2) or, with --scheduler, a
running one. --out DIR writes loops.parquet and loops.csv (one row per loop: its one verdict -
stiction, no_stiction, undetermined, pv_frozen or not_a_closed_loop - the calibrated p(stiction) with its
strongest evidence, Kano S and J, oscillation, the valve-model fit, notes) and worst_loops.txt.

file formats: the tab-separated historian export of ../shared/data/plant_loops (detected by its
'PROCESSDATA' title line) and CSV with a header line. CSV columns are guessed from names (time_s,
op_pct, pv, sp; or tags ending .OP/.MV, .PV, .SP/.SV) unless --columns maps them; a YAML mapping is

  columns: {time: Timestamp, op: FIC101.OP, pv: FIC101.PV, sp: FIC101.SP, mode: FIC101.MODE}
  loop_tag: FIC101          # optional
  sample_time_s: 10         # when there is no time column

reading: the historian policy of docs/records.md. Repeated stamps are repaired, NaN/text cells are
missing, gaps of up to 3 samples are filled; a MODE column (the export's .MODE tag, or mode= in
--columns) keeps only automatic stretches, and a clock reset, a time jump or a longer gap ends a
stretch. The longest usable stretch (at least 100 samples) is diagnosed, or each of them with
--segments each. Every repair is a note on stderr, in the report and in --json.

exit status: 0 when every file was diagnosed; 1 when some failed (each gets one line on stderr and
a row with its error in --out's table, and the batch goes on); 2 when every file failed or the
arguments are wrong.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("loop-diagnose", help="diagnose valve stiction and friends from historian OP, PV and SP",
                       description="Diagnose control loops from historian records of OP, PV and SP alone: "
                                   "detect an oscillation, identify a linear OP -> PV model, show what it "
                                   "misses, fit valve nonlinearities (stiction with Kano's S and J, backlash, "
                                   "dead-zone, saturation, quantisation) jointly with the linear part, rank them "
                                   "on held-out data and name the cause.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("files", nargs="+", metavar="PATH",
                   help="loop records (plant_loops export or CSV), folders of them, or wide historian exports")
    p.add_argument("--columns", default=None, metavar="MAP",
                   help="CSV column mapping: op=NAME,pv=NAME[,sp=NAME][,time=NAME][,mode=NAME] or a .yaml file")
    p.add_argument("--segments", choices=("longest", "each"), default="longest",
                   help="diagnose the longest usable stretch of each file (default) or each stretch")
    p.add_argument("--process", choices=("auto", "self_regulating", "integrating"), default="auto",
                   help="process type (default auto: level loops, tags with LIC, integrate)")
    p.add_argument("--gain-threshold", type=float, default=None, metavar="PCT",
                   help="held-out NRMSE gain (%%) a valve model needs to be named the cause (default 10)")
    p.add_argument("--causes", default=None, metavar="LIST",
                   help="actuator causes to fit, comma separated (default: all of "
                        "backlash,deadzone,saturation,quantization,stiction)")
    p.add_argument("--no-baselines", action="store_true", help="skip the Horch and He et al. stiction tests")
    p.add_argument("--fits", choices=("flagged", "all", "none"), default="flagged",
                   help="which loops get the valve-model fits (Kano S and J, the other valve models): the ones the "
                        "screen flags, stiction or undetermined (default; the others are screened only), all, or "
                        "none (the screen alone, fastest; its stiction calls are not checked against a fit)")
    p.add_argument("--workers", type=int, default=None, help="Dask worker processes of the local cluster (default: 2)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run on an existing Dask cluster (e.g. tcp://host:8786) instead of a local one; one "
                        f"line and exit status 2 if it does not answer within {CONNECT_TIMEOUT_S:g} s")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="write the plant-wide table (loops.parquet, loops.csv) and worst_loops.txt into DIR")
    p.add_argument("--top", type=int, default=10, metavar="N", help="loops in the ranked summary (default 10)")
    p.add_argument("--figure", "--figures", dest="figure", default=None, metavar="DIR",
                   help="write one PNG per loop into DIR (trends, PV-OP and OP-dPV with the fitted models)")
    add_overwrite_arg(p, folder=True)
    p.add_argument("--json", action="store_true", help="print the reports as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi.loopdiag.diagnose import Settings
    from phfdi.loopdiag.plantwide import diagnose_jobs, expand, format_worst, write_table
    from phfdi.loopdiag.readers import parse_loop_columns
    from phfdi.loopdiag.report import format_report, format_summary, to_json
    from phfdi.loopdiag.vocabulary import ACTUATOR_CAUSES
    from phfdi_base.errors import UserError
    from phfdi_base.outputs import output_folder, write_text

    columns = parse_loop_columns(args.columns) if args.columns else None
    settings = Settings(baselines=not args.no_baselines,
                        process_type=None if args.process == "auto" else args.process, fits=args.fits)
    if args.gain_threshold is not None:
        if not args.gain_threshold >= 0:
            raise UserError(f"--gain-threshold must be a percentage >= 0, got {args.gain_threshold}")
        settings.gain_threshold_percent = args.gain_threshold
    if args.causes:
        causes = tuple(c.strip() for c in args.causes.split(",") if c.strip())
        unknown = [c for c in causes if c not in ACTUATOR_CAUSES]
        if unknown or not causes:
            raise UserError(f"--causes: unknown cause {unknown[0] if unknown else '(none)'!r}; "
                            f"known: {', '.join(ACTUATOR_CAUSES)}")
        settings.causes = causes
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    if args.top < 1:
        raise UserError(f"--top must be at least 1, got {args.top}")
    if args.scheduler is not None:  # a malformed address: one line before any file is read
        from phfdi.loopdiag.dask_run import check_scheduler_address

        check_scheduler_address(args.scheduler)
    for folder in (args.out, args.figure):  # before the work, not after it; an earlier run's: only --overwrite
        if folder:
            output_folder(folder, args.overwrite)
    jobs = expand(args.files, columns)
    reports = diagnose_jobs(jobs, settings, args.figure, args.scheduler, args.workers, _progress(len(jobs)),
                            each_segment=args.segments == "each")
    for r in reports:
        if "error" in r:
            print(f"phfdi loop-diagnose: {r['error']}", file=sys.stderr)
        else:
            print_notes("loop-diagnose", [f"{r['file']}: {n}" for n in r.get("reading_notes", [])])
    ok = any("error" not in r for r in reports)
    if args.out:
        pq_path, csv_path = write_table(reports, args.out)
        worst = format_worst(reports, args.top) if ok else "no loop could be diagnosed"
        write_text(pq_path.parent / "worst_loops.txt", worst + "\n", overwrite=True)
        print(f"phfdi loop-diagnose: {len(reports)} loop records -> {pq_path}, {csv_path}", file=sys.stderr)
    if args.json:
        print(to_json(reports))
    elif args.out and len(reports) > 1:
        print(worst)
    else:
        good = [r for r in reports if "error" not in r]
        for r in good:
            print(format_report(r))
            print()
        if len(reports) > 1:
            print(format_summary(reports))
            print()
            print(format_worst(reports, args.top))
    if not ok:
        return 2
    return 1 if any("error" in r for r in reports) else 0  # some failed: each is a row with its reason, said


def _progress(total: int):
    """``loop-diagnose: k/n loops`` on stderr for batches (every 5 % and at the end)."""
    if total < 2:
        return None
    step = max(1, total // 20)
    shown = [0]  # the last 5 % mark printed: loops arrive in chunks, so done need not hit a mark

    def show(done: int, n: int) -> None:
        if done == n or done // step > shown[0]:
            shown[0] = done // step
            print(f"loop-diagnose: {done}/{n} loops", file=sys.stderr, flush=True)

    return show
