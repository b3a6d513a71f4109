"""A simulated teaching-lab pH rig for operations the five recorded runs never showed (docs/simulation.md,
"A simulated rig for unseen operations").

An operation of the catalogue (``operations.yaml``: the recorded runs replayed, open-loop additions and ramps,
on/off and PI control) runs on a randomised "day" of the rig (reagent strengths, flask, carbonate, a weak
buffer, a mixing zone at the probe, probe lag, calibration, noise and the pumps' stroke ripple, each within a
range taken from the recorded runs) with a seed, and gives a record in the rig's own CSV format together with
the truth behind it (the flask's pH, the pH at the probe). A probe fault can act on the reading the controller
sees, which no fault written into a recorded file afterwards can do.

    run = simulate_run("on_off_base", seed=3)                 # day 3, its own draws of the operation
    write_run(run, "out/on_off_base_3.csv")                   # + .rigsim.json (+ .fault.json)
    run = simulate_run("pi_base", seed=4, day=0, probe_fault=ProbeFault("probe_bias", 300.0, 0.5))

Command line: ``phfdi rig-sim``.

Examples
--------
>>> from phfdi.rigsim import DAY_RANGES, FLOW_PER_PCT, HEADER, PROBE_FAULTS
>>> DAY_RANGES["zone_tau_s"].low, DAY_RANGES["zone_tau_s"].high, DAY_RANGES["zone_tau_s"].unit
(3.0, 12.0, 's')
>>> f"{60 * FLOW_PER_PCT['acid']:.2f} {100 * FLOW_PER_PCT['base']:.2f}"  # mL/s at 60 % acid, 100 % base
'4.31 6.45'
>>> HEADER.split(",")[:2], sorted(PROBE_FAULTS)[:2]
(['Time', ' ElapsedTime (s)'], ['probe_bias', 'probe_drift'])
"""

from .day import DAY_RANGES, FLOW_PER_PCT, RigDay, draw_day
from .operations import Operation, OperationSpec, draw_operation, load_catalogue, operation_names
from .record import HEADER, command_profile, csv_text, write_run
from .simulate import PROBE_FAULTS, ProbeFault, RigRun, draw_runs, simulate_run
from .stats import RunStatistics, run_statistics

__all__ = ["DAY_RANGES", "FLOW_PER_PCT", "HEADER", "PROBE_FAULTS", "Operation", "OperationSpec", "ProbeFault",
           "RigDay", "RigRun", "RunStatistics", "command_profile", "csv_text", "draw_day", "draw_runs", "draw_operation",
           "load_catalogue", "operation_names", "run_statistics", "simulate_run", "write_run"]
