"""phfdi inject: a probe or pump fault hidden in a measured record, with its truth beside it for scoring."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG_FORMAT

EXAMPLES = """examples:
  # a +0.3 pH probe bias from 60 s of record time (the file's ElapsedTime) on
  phfdi inject ../shared/data/ph_rig/2025.02.24-add_acid_pH7-3.csv --fault probe_bias --onset 60 --size 0.3 \\
      --out add_acid_bias.csv
  # the base pump delivers 20 % less than recorded from 500 s on; the truth printed as JSON
  phfdi inject control.csv --fault pump_low --pump base --onset 500 --size 0.2 --out faulty_low.csv --json
  # the base pump delivers nothing while the record says 2 mL/s wherever the data's base pump was off
  phfdi inject control.csv --fault pump_stuck --pump base --onset 500 --size 2 --out faulty_stuck.csv
  phfdi inject add_base.csv --fault probe_noise --size 0.05 --seed 7 --onset 30 --out faulty_noise.csv

faults (--size in the unit and range given):
{kinds}
Sensor faults change the pH column only, rounded to the meter's 0.01 pH and clipped to 0..14. Pump faults
are model free: the measured pH is what the pumps really delivered, so the fault is written into the
RECORDED command (%) and flow (mL/s) columns of --pump (both, kept proportional, at the file's decimals).
A fault that would change no cell (e.g. pump_low on a pump that is off after the onset, pump_stuck on a
pump that runs) is refused. probe_lag is discretised exactly (zero-order hold) at the mean sample interval
after the onset (scipy.signal.lfilter), started at the onset's value.

The output keeps every other cell, the header, the row order and the line endings byte for byte, so it
reads with the same --map as the input. The truth goes to OUT.fault.json (kind, family, channels changed,
onset in record time and as a sample index, size and unit, seed, source file and its sha256, a description);
a detector never needs it. Both files are written atomically; an existing file is replaced only with
--overwrite. Bad input exits with status 2 and one line naming the problem. See docs/injection.md.
"""


def _examples() -> str:
    from phfdi.inject_kinds import KINDS

    return EXAMPLES.replace("{kinds}", "\n".join(f"  {k.name:13s} [{k.inject.size_text()}] {k.inject.what}"
                                                for k in KINDS.values()))


def register(sub: argparse._SubParsersAction) -> None:
    from phfdi.inject_kinds import KINDS, PUMPS

    p = sub.add_parser("inject", help="hide a probe or pump fault in a measured record (with its truth for scoring)",
                       description="Write a copy of a measured CSV with a sensor (pH probe) or actuator (pump) fault "
                                   "from an onset in the record's own time, changing only the cells the fault "
                                   "changes, and its truth in a sidecar OUT.fault.json for scoring detectors.",
                       epilog=_examples(), formatter_class=EPILOG_FORMAT)
    p.add_argument("run", metavar="RUN", help="the measured record (CSV)")
    p.add_argument("--fault", required=True, choices=list(KINDS), metavar="KIND",
                   help=f"the fault: {', '.join(KINDS)}")
    p.add_argument("--onset", required=True, type=float, metavar="S",
                   help="onset in the record's time (s; the map's time_s column, ElapsedTime for ph_rig)")
    p.add_argument("--size", type=float, default=None, metavar="X",
                   help="fault size in the fault's unit (see below; not needed for probe_frozen)")
    p.add_argument("--pump", choices=PUMPS, default=None, help="the pump of a pump fault")
    p.add_argument("--seed", type=int, default=0, help="seed of probe_noise's draw (default 0)")
    p.add_argument("--map", default="ph_rig", metavar="MAP",
                   help="column map: a YAML file or a shipped name (default ph_rig)")
    p.add_argument("--out", required=True, metavar="FILE", help="the faulty CSV to write (truth: FILE.fault.json)")
    p.add_argument("--overwrite", action="store_true", help="replace FILE and its .fault.json if they exist")
    p.add_argument("--json", action="store_true", help="print the truth as JSON on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi.inject import inject_fault, write_injected
    from phfdi_base.errors import UserError

    if args.pump and not args.fault.startswith("pump_"):
        raise UserError(f"--pump goes with a pump fault, not {args.fault}")
    data, truth = inject_fault(args.run, args.fault, args.onset, args.size, pump=args.pump, seed=args.seed,
                               column_map=args.map)
    out, side = write_injected(args.out, data, truth, overwrite=args.overwrite)
    if args.json:
        print(json.dumps(truth, indent=2))
    else:
        print(f"{truth['description']}; {truth['rows_changed']} rows changed")
        print(f"wrote {out} and {side}")
    return 0
