"""phfdi paper-runs: the healthy loop and each fault preset, as in the paper's Section 5."""

from __future__ import annotations

import argparse
import json

from .common import EPILOG_FORMAT, Progress, add_overwrite_arg

EXAMPLES = """examples:
  phfdi paper-runs --out out/paper
  phfdi paper-runs --out out/paper --onset 7000     # faults strike at 7000 s (the paper's Section 7)

Writes DIR/<run>.csv and DIR/<run>.png per run, DIR/overview.png (Figure 27, one panel per run),
DIR/overview_map.png (Figure 28 as a map:
pH minus setpoint, one row per run) and DIR/summary.json.
"""

PAPER_FAULTS = ["healthy", "backlash", "friction", "deadzone", "saturation", "stiction", "probe_delay"]


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("paper-runs", help="healthy and faulty runs of the paper's loop, with figures",
                       description="Simulate the paper scenario healthy and with each fault preset (backlash, "
                                   "friction, dead-zone, saturation, stiction, probe delay), write each run, one "
                                   "figure per run (like the paper's Figures 19 to 26) and the overview "
                                   "(Figures 27 and 28). Faults act from t = 0 as in the paper's Section 5 "
                                   "unless --onset is given.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite_arg(p, folder=True)
    p.add_argument("--scenario", default="paper", help="scenario preset or .yaml (default: paper)")
    p.add_argument("--onset", type=float, default=0.0, metavar="S", help="fault onset (s), default 0")
    p.add_argument("--json", action="store_true", help="print the summaries as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi.figures import plot_overview, plot_overview_map, plot_run
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario
    from phfdi.summary import format_summary, summarize
    from phfdi_base.outputs import output_folder, write_text

    out = output_folder(args.out, args.overwrite)
    runs, labels, summaries = [], [], {}
    progress = Progress("paper-runs", enabled=True)
    for i, fault in enumerate(PAPER_FAULTS):
        spec = load_scenario(args.scenario, fault=fault, onset_s=None if fault == "healthy" else args.onset)
        result = simulate(spec)
        result.to_csv(out / f"{fault}.csv")
        plot_run(result, out / f"{fault}.png")
        runs.append(result)
        labels.append(fault)
        summaries[fault] = summarize(result)
        progress((i + 1) / len(PAPER_FAULTS))
    plot_overview(runs, labels, out / "overview.png")
    plot_overview_map(runs, labels, out / "overview_map.png")
    write_text(out / "summary.json", json.dumps(summaries, indent=2), overwrite=True)
    if args.json:
        print(json.dumps(summaries, indent=2))
    else:
        for fault in PAPER_FAULTS:
            print(format_summary(summaries[fault]))
        print(f"wrote {len(PAPER_FAULTS)} runs, figures and summary.json to {out}/")
    return 0
