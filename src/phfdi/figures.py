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
    for f in run.metadata.get("faults") or []:
        if f["onset_s"] > 0:
            ax.axvline(f["onset_s"], color="tab:red", ls=":", lw=1)


def plot_run(run: Run, path: str | Path) -> Path:
    """pH against setpoint, controller effort and valve position, level."""
    t = run.time_s
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True, gridspec_kw={"height_ratios": [2, 1.4, 1]})
    ax = axes[0]
    ax.plot(t, run["ph_measured"], color="0.7", lw=0.6, label="pH measured")
    ax.plot(t, run["ph_true"], color="tab:blue", lw=1.0, label="pH in tank")
    ax.plot(t, run["ph_setpoint"], color="k", ls="--", lw=1.0, label="setpoint")
    ax.set_ylabel("pH (-)")
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(_title(run), fontsize=10)
    _mark_onset(ax, run)
    ax = axes[1]
    ax.plot(t, run["ph_controller_output_pct"], color="tab:orange", lw=0.8, label="pH controller output")
    ax.plot(t, run["valve_position_pct"], color="tab:green", lw=0.8, label="acid valve position")
    ax.set_ylabel("controller effort /\nvalve position (%)")
    ax.legend(loc="upper right", fontsize=8)
    _mark_onset(ax, run)
    ax = axes[2]
    ax.plot(t, run["level_true_cm"], color="tab:purple", lw=0.8, label="level")
    if not np.all(np.isnan(run["level_setpoint_cm"])):
        ax.plot(t, run["level_setpoint_cm"], color="k", ls="--", lw=0.8, label="setpoint")
    ax.set_ylabel("level (cm)")
    ax.set_xlabel("time (s)")
    ax.legend(loc="upper right", fontsize=8)
    for a in axes:
        a.grid(alpha=0.3)
    fig.tight_layout()
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
