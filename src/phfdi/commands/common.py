"""Arguments and output helpers shared by subcommands."""

from __future__ import annotations

import argparse
import sys
import time

EPILOG_FORMAT = argparse.RawDescriptionHelpFormatter


def add_scenario_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default="paper", help="scenario preset name or a .yaml file (default: paper)")
    p.add_argument("--fault", default=None,
                   help="fault from the library replacing the scenario's faults (healthy, backlash, friction, "
                        "deadzone, saturation, stiction, probe_delay, leakage, blocking)")
    p.add_argument("--onset", type=float, default=None, metavar="S", help="fault onset time (s)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key, e.g. --set duration_s=2000 --set sensors.ph.noise_std=0.02")


def scenario_from_args(args: argparse.Namespace):
    from phfdi.scenario import load_scenario

    return load_scenario(args.scenario, fault=args.fault, overrides=args.overrides, onset_s=args.onset)


class Progress:
    """One line of progress on stderr for long work (silent when not a terminal unless forced)."""

    def __init__(self, label: str, enabled: bool | None = None) -> None:
        self.label = label
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self.t0 = time.perf_counter()

    def __call__(self, fraction: float) -> None:
        if self.enabled:
            end = "\n" if fraction >= 1.0 else ""
            print(f"\r{self.label}: {100 * fraction:5.1f} %  ({time.perf_counter() - self.t0:5.1f} s)",
                  end=end, file=sys.stderr, flush=True)
