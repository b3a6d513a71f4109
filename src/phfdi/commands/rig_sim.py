"""phfdi rig-sim: a simulated run of the teaching-lab pH rig in the rig's own CSV format (phfdi.rigsim)."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG_FORMAT, add_overwrite_arg

EXAMPLES = """examples:
  phfdi rig-sim --list                                        # the operations, shared and unseen
  # an on/off base pump about drawn setpoints, run seed 3 (on day 3), 10 minutes
  phfdi rig-sim --operation on_off_base --seed 3 --duration-s 600 --out on_off_base_3.csv
  # the same run with a +0.5 pH probe bias from 300 s that the controller acts on (truth: .fault.json)
  phfdi rig-sim --operation on_off_base --seed 3 --duration-s 600 --probe-fault probe_bias --size 0.5 \\
      --onset 300 --out on_off_base_3_bias.csv
  # a PI controller on the base pump on day 0 (the day's rig), run seed 7
  phfdi rig-sim --operation pi_base --seed 7 --day 0 --out pi_base_7.csv
  # a recorded run's own commands replayed on simulated day 2
  phfdi rig-sim --replay ../shared/data/ph_rig/2025.03.03-001_acid_to_base_titration.csv --seed 2 --out march_2.csv

The output reads like a recorded rig file: `phfdi calibrate --estimator RUN ... --map ph_rig`, `phfdi replay
RUN --map ph_rig` and `phfdi inject RUN ...` take it unchanged. Beside it, OUT.rigsim.json says what made it
(the operation's drawn parameters, the day's rig, the seed) and, with --probe-fault, OUT.fault.json holds the
fault's truth in `phfdi inject`'s format (kind, size, unit, onset in record time and as a row index). A probe
fault acts on the reading the controller sees: in closed loop the controller reacts and the flask's true pH
moves (a probe bias b moves it by about -b while the reading returns to the setpoint), which a fault written
into a recorded file afterwards cannot show.

A run is fixed by (operation, --seed, --day, --duration-s, the fault): the same numbers on any machine. The
day (default: the seed) draws the rig: reagent strengths, flask, carbonate, buffer, mixing zone, probe lag and
calibration, noise and pump stroke ripple (ranges and their sources: docs/simulation.md, "A simulated rig for
unseen operations"). Files are written atomically; an existing file is replaced only with --overwrite. Bad
input exits with status 2 and one line naming the problem.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("rig-sim", help="simulate a run of the teaching-lab pH rig (its CSV format, with the truth)",
                       description="Simulate one run of the teaching-lab pH rig (../shared/data/ph_rig): an operation "
                                   "of the catalogue (recorded runs replayed, open-loop additions and ramps, on/off "
                                   "and PI control) on a randomised day of the rig, written in the rig's own CSV "
                                   "format, optionally with a probe fault the controller sees.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--operation", metavar="NAME", help="an operation of the catalogue (see --list)")
    what.add_argument("--replay", metavar="CSV", help="replay a recorded rig run's pump commands (its first pH, "
                                                      "duration and command changes)")
    what.add_argument("--list", action="store_true", help="list the catalogue's operations and exit")
    p.add_argument("--seed", type=int, default=0, help="run seed: the operation's drawn parameters, sampling, noise "
                                                       "(default 0)")
    p.add_argument("--day", type=int, default=None, help="the rig's day (default: the seed)")
    p.add_argument("--duration-s", type=float, default=None, metavar="S",
                   help="run length (s; default: the operation's, drawn)")
    p.add_argument("--probe-fault", default=None, metavar="KIND",
                   help="a probe fault on the reading the controller sees: probe_bias (pH), probe_drift (pH/min), "
                        "probe_frozen, probe_noise (pH std), probe_lag (s), probe_gain (fraction)")
    p.add_argument("--size", type=float, default=None, metavar="X", help="the probe fault's size in its unit")
    p.add_argument("--onset", type=float, default=None, metavar="S",
                   help="the probe fault's onset in the record's time (s, its ElapsedTime)")
    p.add_argument("--fault-seed", type=int, default=0, help="seed of a probe_noise fault's draw (default 0)")
    p.add_argument("--catalogue", default=None, metavar="YAML", help="an operations catalogue of your own "
                                                                     "(default: the shipped one)")
    p.add_argument("--out", default=None, metavar="FILE", help="the CSV to write (sidecars FILE.rigsim.json, "
                                                               "FILE.fault.json)")
    add_overwrite_arg(p)
    p.add_argument("--json", action="store_true", help="print what made the run (OUT.rigsim.json) on stdout")
    p.set_defaults(func=run)


def _list(catalogue) -> int:
    from phfdi.rigsim import load_catalogue

    ops = load_catalogue(catalogue)
    width = max(len(n) for n in ops)
    for group in ("shared", "unseen"):
        print(f"{group}:")
        for name, op in ops.items():
            if op.group == group:
                print(f"  {name:{width}s}  {op.kind:9s}  {op.description}")
    return 0


def _replay_spec(path: str):
    from phfdi.rigsim import OperationSpec, command_profile

    p = command_profile(path)
    return OperationSpec(name="replay", group="shared", kind="profile", description=f"{path} replayed",
                         duration_s=p["duration_s"], start_ph=p["start_ph"], start_elapsed_s=p["start_elapsed_s"],
                         profile=[tuple(row) for row in p["profile"]])


def run(args: argparse.Namespace) -> int:
    from phfdi.rigsim import ProbeFault, simulate_run, write_run
    from phfdi.rigsim.record import sidecars
    from phfdi_base.errors import UserError
    from phfdi_base.outputs import refuse_existing

    if args.list:
        return _list(args.catalogue)
    if args.out is None:
        raise UserError("give --out FILE (the CSV to write)")
    fault_given = [flag for flag, v in (("--size", args.size), ("--onset", args.onset)) if v is not None]
    if args.probe_fault is None and fault_given:
        raise UserError(f"{fault_given[0]} goes with --probe-fault")
    if args.probe_fault is not None and args.onset is None:
        raise UserError("--probe-fault needs --onset S (record time)")
    if args.seed < 0 or (args.day is not None and args.day < 0):
        raise UserError("--seed and --day must be non-negative integers")
    meta_path, fault_path = sidecars(args.out)
    for target in (args.out, meta_path, *([fault_path] if args.probe_fault else [])):
        refuse_existing(target, args.overwrite)  # before any work
    fault = ProbeFault(args.probe_fault, args.onset, args.size, args.fault_seed) if args.probe_fault else None
    operation = _replay_spec(args.replay) if args.replay else args.operation
    result = simulate_run(operation, args.seed, args.day, duration_s=args.duration_s, probe_fault=fault,
                          catalogue=args.catalogue)
    written = write_run(result, args.out, overwrite=args.overwrite)
    if args.json:
        print(json.dumps(result.meta(), indent=2))
    else:
        span = float(result.time_s[-1] - result.time_s[0])
        print(f"{result.operation.name}, seed {result.seed}, day {result.day.number}: {len(result)} samples over "
              f"{span:.0f} s, pH {result.ph.min():.2f} to {result.ph.max():.2f}"
              + (f"; {result.fault['description']}" if result.fault else ""))
        print("wrote " + " and ".join(str(p) for p in written))
    return 0
