"""The simulated rig against the five recorded runs: the same operations (replayed from the recorded command
columns) on several simulated days, their pH side by side, and the reading's statistics on both.

Writes docs/figures/rigsim_real_vs_sim.png (one panel per recorded run: the measured pH in black, the simulated
counterparts on DAYS days in colour, each day's flask pH dashed; beside it the noise and ripple: each run's
flattest 30 s minus its local trend; the closed loop twice, its commands replayed and its controller simulated)
and prints, per run, the statistics of :func:`phfdi.rigsim.run_statistics` for the recorded run and their range
over the simulated days (noise after the detrend, autocorrelation 1 and 2 samples apart, ripple period,
repeats, time of the passage between pH 9 and 5).

Nothing here is fitted to a recorded run: the days are the seeds 0..DAYS-1 of the day ranges
(phfdi.rigsim.DAY_RANGES), whose sources are stated there.

Usage: PHFDI_SHARED_DATA=../shared/data .venv/bin/python benchmarks/rigsim_real_vs_sim.py [--days 6]   (~15 s)
"""

from __future__ import annotations

import argparse
import glob
import os
from pathlib import Path

import numpy as np

from phfdi.commands.common import shipped_map
from phfdi.learned import read_measured
from phfdi.rigsim import run_statistics, simulate_run
from phfdi.rigsim.stats import detrended
from phfdi_base.outputs import save_figure

#: recorded file (its name's start) -> the catalogue's replay of it
RUNS = [
    ("2025.02.24-001", "shared_add_base", "base addition 60 %, 24 Feb"),
    ("2025.02.24-add", "shared_add_acid", "acid addition 60 %, 24 Feb"),
    ("2025.02.24-005", "shared_control_ph7", "closed loop, base on/off, 24 Feb: its recorded commands replayed"),
    ("2025.02.24-005", "shared_control_ph7_loop", "the same closed loop simulated as its on/off controller "
                                                  "(base on below pH 3.24, off above 10.9)"),
    ("2025.03.03", "shared_acid_to_base", "titration acid to base, 3 Mar"),
    ("2025.04.07", "shared_base_to_acid", "titration base to acid, 7 Apr"),
]


def passage_s(t: np.ndarray, ph: np.ndarray) -> float:
    """Seconds the first passage between pH 9 and 5 (either way) takes on the smoothed reading: from the last
    sample beyond one end to the first beyond the other (NaN without one): the knee's sharpness."""
    from scipy.signal import savgol_filter

    y = savgol_filter(ph, 9, 2) if len(ph) > 9 else ph
    side = np.where(y >= 9.0, 1, np.where(y <= 5.0, -1, 0))
    last, k_last = 0, -1
    for k, s in enumerate(side.tolist()):
        if s == 0:
            continue
        if last and s != last:
            return float(t[k] - t[k_last])
        last, k_last = s, k
    return float("nan")


def quiet_window(t: np.ndarray, ph: np.ndarray, width_s: float = 30.0) -> float:
    """Start (s) of the recorded run's flattest stretch of ``width_s`` (smallest range of its smoothed pH, on a
    10 s grid): where the zoom shows noise and ripple rather than the process."""
    from scipy.signal import savgol_filter

    smooth = savgol_filter(ph, 17, 2)
    starts = np.arange(float(t[0]), float(t[-1]) - width_s, 10.0)
    spans = [np.ptp(smooth[(t >= a) & (t <= a + width_s)]) for a in starts]
    return float(starts[int(np.argmin(spans))]) if len(starts) else float(t[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("PHFDI_SHARED_DATA", "../shared/data"))
    ap.add_argument("--days", type=int, default=6, help="simulated days per run (seeds 0..DAYS-1)")
    ap.add_argument("--figure", default="docs/figures/rigsim_real_vs_sim.png")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cmap = shipped_map("ph_rig")
    fig, axes = plt.subplots(len(RUNS), 2, figsize=(13, 3.0 * len(RUNS)), gridspec_kw={"width_ratios": [3, 1]})
    colours = plt.get_cmap("tab10")
    print("run | statistic | recorded | simulated days (min..max)")
    for row, (prefix, operation, title) in enumerate(RUNS):
        path = next(p for p in sorted(glob.glob(str(Path(args.data) / "ph_rig" / "*.csv")))
                    if Path(p).name.startswith(prefix))
        rec = read_measured(path, cmap, channels=["ph_measured"])
        t_real, ph_real = rec.time_s - rec.time_s[0], rec.x[:, 0]
        sims = [simulate_run(operation, seed=day) for day in range(args.days)]
        ax, zoom = axes[row]
        ax.plot(t_real, ph_real, color="black", lw=1.2, label="recorded", zorder=5)
        a = quiet_window(t_real, ph_real)
        window = (t_real >= a) & (t_real <= a + 30.0)
        zoom.plot(t_real[window] - a, detrended(t_real, ph_real)[0][window], color="black", lw=1.2, marker=".",
                  ms=3, label="recorded")
        for i, run in enumerate(sims):
            t = run.time_s - run.time_s[0]
            ax.plot(t, run.ph, color=colours(i), lw=0.7, alpha=0.8, label=f"simulated day {i}")
            ax.plot(t, run.ph_true, color=colours(i), lw=0.7, ls="--", alpha=0.6)
            if i < 2:
                a = quiet_window(t, run.ph)
                w = (t >= a) & (t <= a + 30.0)
                zoom.plot(t[w] - a, detrended(t, run.ph)[0][w], color=colours(i), lw=0.8, marker=".", ms=2,
                          label=f"simulated day {i}")
        ax.set_title(f"{title} (dashed: the flask's pH, simulated)", fontsize=9)
        ax.set_ylabel("pH (pH)")
        ax.set_ylim(1.5, 13.0)
        zoom.set_title("each run's flattest 30 s, detrended", fontsize=9)
        zoom.set_ylabel("pH minus local trend (pH)")
        if row == len(RUNS) - 1:
            ax.set_xlabel("time from the run's start (s)")
            zoom.set_xlabel("time from the stretch's start (s)")
        if row == 0:
            ax.legend(fontsize=7, ncol=3, loc="lower right")
        stats_real = run_statistics(rec.time_s, ph_real)
        stats_sim = [run_statistics(r.time_s, r.ph) for r in sims]
        for name in ("noise_ph", "lag1_autocorrelation", "lag2_autocorrelation", "ripple_period_s", "repeat_share",
                     "longest_repeat"):
            values = [getattr(s, name) for s in stats_sim]
            print(f"{operation} | {name} | {getattr(stats_real, name):.3f} | {min(values):.3f}..{max(values):.3f}")
        p_sim = [passage_s(r.time_s, r.ph) for r in sims]
        print(f"{operation} | passage pH 5..9 (s) | {passage_s(rec.time_s, ph_real):.1f} | "
              f"{np.nanmin(p_sim) if np.isfinite(p_sim).any() else float('nan'):.1f}.."
              f"{np.nanmax(p_sim) if np.isfinite(p_sim).any() else float('nan'):.1f}")
    fig.suptitle("Recorded rig runs and their simulated counterparts (phfdi.rigsim: recorded commands replayed on "
                 f"{args.days} simulated days)", fontsize=11)
    fig.tight_layout(rect=(0.0, 0.0, 1.0, 0.98))
    save_figure(fig, args.figure, dpi=110)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
