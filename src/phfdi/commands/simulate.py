"""phfdi simulate: run a scenario's closed loop in this process."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG_FORMAT, Progress, add_overwrite_arg, add_scenario_args, scenario_from_args

EXAMPLES = """examples:
  phfdi simulate --scenario paper --fault backlash --out runs/backlash.csv
  phfdi simulate --fault stiction --out runs/stiction.parquet --figure runs/stiction.png
  phfdi simulate --fault stiction --set duration_s=2000 --set 'setpoints.ph.changes=[]' --onset 1000 \\
      --out runs/short.csv   # 2000 s at pH 12 (no setpoint change), stiction from 1000 s
  phfdi simulate --scenario my_loop.yaml --json
  phfdi simulate --fault friction --inputs recorded.csv --out replayed.csv   # open loop from recorded inputs
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("simulate", help="simulate a scenario's closed loop and write the run",
                       description="Simulate a scenario (plant, valve with its faults, sensors, PI controllers) "
                                   "in one process and write every signal with units to CSV or Parquet.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    add_scenario_args(p)
    p.add_argument("--out", default=None, help="run file to write (.csv or .parquet)")
    p.add_argument("--figure", default=None, help="PNG figure of the run (pH, controller effort, level)")
    add_overwrite_arg(p)
    p.add_argument("--json", action="store_true", help="print the run summary as JSON")
    p.add_argument("--inputs", default=None, metavar="RUN",
                   help="open loop: drive plant, valve and sensors from this run file's time_s and "
                        "valve_command_pct (or <feed>_flow_ml_s), instead of the controllers")
    p.set_defaults(func=run)


def read_inputs(path: str):
    """Recorded open-loop inputs (phfdi.records, run policy): the commands and flows the plant is driven with
    must have every sample; the reader's notes go to stderr."""
    import numpy as np

    from phfdi.records import ReadError, read_record

    from .common import print_notes

    rec = read_record(path, policy="run")
    print_notes("simulate", rec.note_lines())
    for name in rec.names:
        if name in ("valve_command_pct", "level_controller_output_pct") or \
                (name.endswith("_flow_ml_s") and name != "outlet_flow_ml_s"):
            rec.refuse_missing(name, "open-loop inputs need every sample of the commands and feed flows")
            negative = np.flatnonzero(rec.signals[name] < 0)
            if name.endswith("_flow_ml_s") and len(negative):
                i = int(negative[0])
                raise ReadError(path, f"a flow cannot be negative ({rec.signals[name][i]:g})",
                                line=int(rec.lines[i]), column=rec.columns.get(name, name), where=rec.where)
    return rec.to_run()


def run(args: argparse.Namespace) -> int:
    from phfdi.loop import simulate, simulate_open_loop
    from phfdi.summary import format_summary, summarize
    from phfdi_base.errors import UserError
    from phfdi_base.outputs import refuse_existing

    for path in (args.out, args.figure):  # an existing output is kept unless --overwrite, said before any work
        if path:
            refuse_existing(path, args.overwrite)
    spec = scenario_from_args(args)
    if args.inputs:
        inputs = read_inputs(args.inputs)
        try:
            result = simulate_open_loop(spec, inputs)
        except ValueError as exc:  # the plant core's own check of physical inputs (no steady state, ...)
            raise UserError(f"{args.inputs}: the plant cannot run on these inputs ({exc})") from None
    else:
        result = simulate(spec, progress=Progress(f"simulate {spec.name}"))
    summary = summarize(result)
    if args.out:
        summary["run_file"] = str(result.save(args.out, overwrite=args.overwrite))
    if args.figure:
        from phfdi.figures import plot_run

        summary["figure"] = str(plot_run(result, args.figure))
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
        for key in ("run_file", "figure"):
            if key in summary:
                print(f"  wrote {summary[key]}")
    return 0
