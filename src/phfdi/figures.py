"""Figures of runs: one run (like the paper's Figures 19 to 26) and the overview of many (Figures 27, 28)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from phfdi_base.outputs import save_figure

from .run import Run  # noqa: E402


def _title(run: Run) -> str:
    faults = run.metadata.get("faults") or []
    if not faults:
        return f"{run.metadata.get('scenario', 'run')}: healthy valve"
    f = faults[0]
    params = ", ".join(f"{k} = {v}" for k, v in (f.get("params") or {}).items())
    return f"{run.metadata.get('scenario', 'run')}: {f['type']} ({params}) from {f['onset_s']:g} s"


def _mark_onset(ax, run: Run) -> None:
    """A dotted red line at each fault's onset within the axes' time span (none for a fault from t = 0)."""
    lo, hi = ax.get_xlim()
    for k, f in enumerate(run.metadata.get("faults") or []):
        if f["onset_s"] > 0 and lo <= f["onset_s"] <= hi:
            ax.axvline(f["onset_s"], color="tab:red", ls=":", lw=1.2, label="fault onset" if k == 0 else None)


#: the zoom on the valve shows this long a stretch (s; at most a quarter of the run): five cycles of the
#: paper loop's backlash limit cycle (about 120 s), long enough to see the command-stem gap repeat
ZOOM_S = 600.0


def zoom_window(run: Run) -> tuple[float, float]:
    """The stretch the valve zoom shows: from 100 s before a fault's onset, or the run's end when the fault
    acts from the start (or there is none), so that a healthy run is zoomed where a faulty one would be."""
    t = run.time_s
    width = min(ZOOM_S, 0.25 * float(t[-1] - t[0]))
    onsets = [f["onset_s"] for f in run.metadata.get("faults") or [] if f["onset_s"] > t[0]]
    if onsets:
        start = max(float(t[0]), min(onsets) - 100.0)
        return start, min(float(t[-1]), start + width)
    return float(t[-1]) - width, float(t[-1])


def _valve_command(run: Run) -> np.ndarray:
    """What the pH controller asks of the acid valve (older runs have only the controller output)."""
    return run["valve_command_pct"] if "valve_command_pct" in run else run["ph_controller_output_pct"]


def _plot_valve(ax, run: Run, sel: np.ndarray, gap: bool) -> None:
    """Command and stem position, drawn so the stem never hides the command: command thick and light, stem
    thin and dark on top; with ``gap`` the difference is shaded (a backlash or stiction dead band)."""
    t, command, stem = run.time_s[sel], _valve_command(run)[sel], run["valve_position_pct"][sel]
    ax.plot(t, command, color="tab:orange", lw=2.2, alpha=0.8, label="valve command (pH controller output)")
    ax.plot(t, stem, color="k", lw=0.9, label="acid valve stem position")
    if gap:
        ax.fill_between(t, command, stem, color="tab:red", alpha=0.25, lw=0, label="command - stem gap")
    ax.set_ylabel("valve command,\nstem position (% of span)")


def plot_run(run: Run, path: str | Path) -> Path:
    """pH against setpoint, the valve's command and stem position (with a zoom on the fault), level."""
    t = run.time_s
    fig = plt.figure(figsize=(13, 10), layout="constrained")
    grid = fig.add_gridspec(4, 1, height_ratios=[2, 1.3, 1.6, 1])
    ax_ph = fig.add_subplot(grid[0])
    ax_valve = fig.add_subplot(grid[1], sharex=ax_ph)
    ax_zoom = fig.add_subplot(grid[2])
    ax_level = fig.add_subplot(grid[3], sharex=ax_ph)
    ax_ph.plot(t, run["ph_measured"], color="0.7", lw=0.6, label="pH measured")
    ax_ph.plot(t, run["ph_true"], color="tab:blue", lw=1.0, label="pH in tank")
    ax_ph.plot(t, run["ph_setpoint"], color="k", ls="--", lw=1.0, label="setpoint")
    ax_ph.set_ylabel("pH (-)")
    ax_ph.set_title(_title(run), fontsize=10)
    _plot_valve(ax_valve, run, np.ones(len(t), dtype=bool), gap=False)
    a, b = zoom_window(run)
    ax_valve.axvspan(a, b, color="tab:blue", alpha=0.08, lw=0, label="zoomed below")
    _plot_valve(ax_zoom, run, (t >= a) & (t <= b), gap=True)
    ax_zoom.set_title(f"valve, {a:g} to {b:g} s (zoom)", fontsize=9)
    ax_zoom.set_xlabel("time (s)")
    ax_level.plot(t, run["level_true_cm"], color="tab:purple", lw=0.8, label="level")
    if not np.all(np.isnan(run["level_setpoint_cm"])):
        ax_level.plot(t, run["level_setpoint_cm"], color="k", ls="--", lw=0.8, label="setpoint")
    ax_level.set_ylabel("level (cm)")
    ax_level.set_xlabel("time (s)")
    for ax in (ax_ph, ax_valve, ax_zoom, ax_level):
        _mark_onset(ax, run)
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8)  # beside the data, never over it
        ax.grid(alpha=0.3)
    ax_ph.tick_params(labelbottom=False)
    ax_valve.tick_params(labelbottom=False)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_overview(runs: Sequence[Run], labels: Sequence[str], path: str | Path) -> Path:
    """pH of every run on one axis (the paper's Figure 27)."""
    fig, ax = plt.subplots(figsize=(10, 5))
    for run, lab in zip(runs, labels):
        ax.plot(run.time_s, run["ph_true"], lw=0.9, label=lab)
    ax.plot(runs[0].time_s, runs[0]["ph_setpoint"], color="k", ls="--", lw=0.8, label="setpoint")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pH (-)")
    ax.set_title("Impact of the valve nonlinearities on the closed-loop pH")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_overview_3d(runs: Sequence[Run], labels: Sequence[str], path: str | Path) -> Path:
    """Waterfall of the runs' pH (the paper's Figure 28)."""
    fig = plt.figure(figsize=(10, 6))
    ax = fig.add_subplot(projection="3d")
    for i, (run, lab) in enumerate(zip(runs, labels)):
        ax.plot(run.time_s, np.full(len(run), i), run["ph_true"], lw=0.8, label=lab)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("run")
    ax.set_yticks(range(len(labels)))
    ax.set_yticklabels(labels, fontsize=7)
    ax.set_zlabel("pH (-)")
    ax.set_title("Healthy and faulty pH responses")
    fig.tight_layout()
    path = Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
