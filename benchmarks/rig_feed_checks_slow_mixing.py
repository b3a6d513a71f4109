"""The feed checks' statistic on healthy simulated runs of days whose mixing and probe are slower than the rig's.

Usage: .venv/bin/python benchmarks/rig_feed_checks_slow_mixing.py [--zone-tau-s 25] [--probe-tau-s 6] [--runs 2]
Each operation of the simulator's "unseen" group, ``--runs`` times (seeds from 70000), on its own drawn day with the
mixing zone's and the probe's time constants replaced by the given ones (the rig's fitted: zone 5.4-11.4 s, probe
1-3 s; rigsim.day). Prints the tested windows, the largest statistic with its run, and the windows beyond the level
(wavelet_fdi.feed_checks, 1e-6 per sample): on a healthy run every one of them would be a false fault alarm.
About 20 s.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from phfdi.benchmarks.rig_detection import CHANNELS
from phfdi.rigsim import operation_names, simulate_run
from phfdi.rigsim.day import draw_day
from wavelet_fdi.feed_checks import FeedChecks, level

FIRST_SEED = 70000


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--zone-tau-s", type=float, default=25.0)
    ap.add_argument("--probe-tau-s", type=float, default=6.0)
    ap.add_argument("--runs", type=int, default=2, help="runs of each operation")
    args = ap.parse_args(argv)
    beyond_level = level(1e-6)
    tested, beyond, worst = 0, 0, []
    for i, op in enumerate(operation_names("unseen") * args.runs):
        seed = FIRST_SEED + i
        day = replace(draw_day(seed), zone_tau_s=args.zone_tau_s, probe_tau_s=args.probe_tau_s)
        rec = simulate_run(op, seed, day=day).measured(CHANNELS)
        checks = FeedChecks(-1e9, (-1, 1), gap=1)  # every tested window noted, with its statistic
        checks.scan(rec.time_s, rec.x, first_index=0, from_index=0)
        z = np.array([c.value for c in checks.pending])
        tested += len(z)
        beyond += int((z > beyond_level).sum())
        if len(z):
            worst.append((float(z.max()), op, seed))
    top = max(worst) if worst else (float("nan"), "-", -1)
    print(f"zone {args.zone_tau_s:g} s, probe {args.probe_tau_s:g} s: {tested} windows tested, largest statistic "
          f"{top[0]:.2f} ({top[1]} seed {top[2]}), {beyond} beyond the level {beyond_level:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
