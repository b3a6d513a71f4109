"""phfdi demo: the main job on the built-in default scenario."""

from __future__ import annotations

import argparse
from pathlib import Path

from .common import EPILOG_FORMAT

EXAMPLES = """examples:
  phfdi demo                 # paper scenario with a backlash fault at 7000 s, figures in out/demo
  phfdi demo --out /tmp/demo --fault stiction
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job on the default scenario (summary and figures)",
                       description="Simulate the paper scenario healthy and with a valve fault at 7000 s, print "
                                   "a short summary of both and write the runs and figures.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--out", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--fault", default="backlash", help="fault preset (default: backlash)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi.figures import plot_overview, plot_run
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario
    from phfdi.summary import format_summary, summarize

    out = Path(args.out)
    healthy = simulate(load_scenario("paper", fault="healthy"))
    faulty = simulate(load_scenario("paper", fault=args.fault))
    for name, r in (("healthy", healthy), (args.fault, faulty)):
        r.to_csv(out / f"{name}.csv")
        plot_run(r, out / f"{name}.png")
        print(format_summary(summarize(r)))
    plot_overview([healthy, faulty], ["healthy", args.fault], out / "overview.png")
    print(f"wrote runs (CSV) and figures (PNG) to {out}/")
    return 0
