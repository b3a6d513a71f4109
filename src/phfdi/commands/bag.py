"""phfdi bag: inspect and recover MCAP bags of the node graph."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .common import EPILOG_FORMAT, add_overwrite_arg

EXAMPLES = """examples:
  phfdi bag info bags/run.mcap                 # topics, types, counts, simulated time range
  phfdi bag info bags/run.mcap --json
  phfdi bag recover bags/killed.mcap bags/fixed.mcap   # everything up to the last complete chunk
  phfdi bag to-run bags/run.mcap runs/run.csv  # the run's signals (CSV or Parquet)
  phfdi bag from-csv rig.csv bags/rig.mcap --exclude anomaly,changepoint   # a measured record as a bag
  phfdi replay --live bags/rig.mcap --reference ref.json                   # ... played into the detector node

from-csv reads the record like phfdi replay (--map/--column/--encoding, the
reading policy of docs/records.md, a note per repair) and writes one
phfdi_interfaces/MeasuredSample per row on /measured/sample (every column but
time and --exclude), stamped with the row's own time to the ns (a record whose
time is below 0 or beyond 9e9 s: from its first row).
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bag", help="inspect, recover or convert an MCAP bag of the graph",
                       description="Inspect (info), recover (a bag whose recorder was killed) or convert "
                                   "(to-run: the run's signals with units) an MCAP bag of the node graph.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    bag_sub = p.add_subparsers(dest="bag_command", metavar="ACTION", required=True)
    info = bag_sub.add_parser("info", help="topics, types, message counts and time range",
                              epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    info.add_argument("file", help="bag (.mcap)")
    info.add_argument("--json", action="store_true", help="print as JSON")
    info.set_defaults(func=run_info)
    rec = bag_sub.add_parser("recover", help="copy everything up to the last complete chunk into a new bag",
                             epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    rec.add_argument("input", help="truncated bag (.mcap)")
    rec.add_argument("output", help="new bag to write (.mcap)")
    add_overwrite_arg(rec)
    rec.set_defaults(func=run_recover)
    conv = bag_sub.add_parser("to-run", help="write the run's signals (names with units) as CSV or Parquet",
                              epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    conv.add_argument("input", help="bag (.mcap)")
    conv.add_argument("output", help="run file to write (.csv or .parquet)")
    add_overwrite_arg(conv)
    conv.set_defaults(func=run_to_run)
    fc = bag_sub.add_parser("from-csv", help="write a measured record (CSV, Parquet) as a bag of "
                                             "/measured/sample messages",
                            description="Write a measured record as an MCAP bag (ros2 profile, schemas embedded): "
                                        "one phfdi_interfaces/MeasuredSample per row on /measured/sample, which "
                                        "phfdi replay --live BAG --reference REF plays into the detector node.",
                            epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    fc.add_argument("input", help="measured record (.csv or .parquet)")
    fc.add_argument("output", help="bag to write (.mcap)")
    add_overwrite_arg(fc)
    fc.add_argument("--exclude", default="", metavar="COLS", help="columns that are not channels (e.g. labels)")
    from .common import add_record_args

    add_record_args(fc, units=True)
    fc.set_defaults(func=run_from_csv)


def run_info(args: argparse.Namespace) -> int:
    from phfdi.bagio import bag_info, format_info

    info = bag_info(args.file)
    print(json.dumps(info, indent=2) if args.json else format_info(info))
    return 0


def run_recover(args: argparse.Namespace) -> int:
    from phfdi.bagio import recover

    r = recover(args.input, args.output, overwrite=args.overwrite)
    where = "the input was complete" if r["complete_input"] else f"the input stops at {r['stopped_at']}"
    last = f", last at {r['last_s']:.3f} s" if r["last_s"] is not None else ""
    print(f"recovered {r['messages']} messages{last} into {r['path']} ({where})")
    return 0


def run_to_run(args: argparse.Namespace) -> int:
    from phfdi.records import read_run
    from phfdi.records.formats import is_format, writable_format
    from phfdi_base.errors import UserError
    from phfdi_base.outputs import refuse_existing

    from .common import print_notes

    writable_format(args.output)  # refused before the bag is read
    refuse_existing(args.output, args.overwrite)
    if not is_format(args.input, "bag"):
        raise UserError(f"{args.input}: to-run converts a bag: give an .mcap file")
    run = read_run(args.input)
    print_notes("bag", run.metadata["notes"])
    path = run.save(args.output, overwrite=args.overwrite)
    print(f"wrote {len(run)} samples of {len(run.names) + 1} signals to {path}")  # time_s counted, a column
    return 0


def run_from_csv(args: argparse.Namespace) -> int:
    from phfdi.bagio import write_measured
    from phfdi.bagread import line_runs
    from phfdi.learned import read_measured
    from phfdi_base.errors import UserError
    from phfdi_base.outputs import refuse_existing, staged

    from .common import column_map_from_args, print_notes

    if not args.output.endswith(".mcap"):
        raise UserError(f"{args.output}: the bag must be an .mcap file")
    refuse_existing(args.output, args.overwrite)  # before the record is read
    rec = read_measured(args.input, column_map_from_args(args),
                        exclude=[c.strip() for c in args.exclude.split(",") if c.strip()], encoding=args.encoding)
    print_notes("bag from-csv", rec.notes)
    with staged(args.output, args.overwrite) as tmp:
        # the source's positions and wall clock go along, so a live replay of the bag names the record's own
        # lines and stamps, as the offline replay of the record does
        where = {"source_where": rec.where, "source_lines": line_runs(rec.lines),
                 "wall_clock": rec.wall_clock.isoformat() if rec.wall_clock else None}
        write_measured(rec.time_s, rec.x, list(rec.channels), tmp, source=str(args.input), metadata=where,
                       file_name=Path(args.output).name)  # the rosbag2 metadata names the final file
    path = args.output
    print(f"wrote {len(rec.x)} rows x {len(rec.channels)} channels ({', '.join(rec.channels)}) to {path} "
          f"on /measured/sample")
    return 0
