"""Figures of runs: one run (like the paper's Figures 19 to 26) and the overview of many (Figures 27, 28)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import FuncFormatter  # noqa: E402

from phfdi_base.outputs import save_figure

from .records.record import Record  # noqa: E402

_SUFFIX_UNITS = (("_per_s", "1/s"), ("_ml_s", "mL/s"), ("_pct", "%"), ("_s", "s"))


def param_text(fault_type: str, name: str, value: object, unit: str = "") -> str:
    """A fault parameter as an engineer writes it: ``width 0.7 % of span`` for ``width_pct = 0.7`` (the unit
    from the fault catalogue, found by block or preset name, else ``unit``, else from the name's suffix).

    >>> param_text("no_such_block", "delay_s", 10.0), param_text("no_such_block", "s_pct", 1.5)
    ('delay 10 s', 'S 1.5 %')
    """
    from phfdi_base.faults import FAULTS

    base = name
    for suffix, suffix_unit in _SUFFIX_UNITS:
        if name.endswith(suffix):
            unit, base = unit or suffix_unit, name[: -len(suffix)]
            break
    for fault in FAULTS.values():
        if fault_type in (fault.block, fault.name) and any(p.name == name for p in fault.params):
            unit = fault.param(name).unit
    base = base.upper() if len(base) == 1 else base.replace("_", " ")  # Kano's S and J
    number = f"{value:g}" if isinstance(value, (int, float)) else str(value)
    return f"{base} {number} {unit}".rstrip()


def _fault_text(fault: dict) -> str:
    """'backlash (width 0.7 % of span)' for a run's fault entry."""
    params = ", ".join(param_text(fault["type"], k, v) for k, v in (fault.get("params") or {}).items())
    name = fault["type"].replace("_", " ")
    return f"{name} ({params})" if params else name


def _title(run: Record) -> str:
    faults = run.metadata.get("faults") or []
    if not faults:
        return f"{run.metadata.get('scenario', 'run')}: healthy valve"
    return f"{run.metadata.get('scenario', 'run')}: {_fault_text(faults[0])} from {faults[0]['onset_s']:g} s"


def _mark_onset(ax, run: Record) -> None:
    """A dotted red line at each fault's onset within the axes' time span (none for a fault from t = 0)."""
    lo, hi = ax.get_xlim()
    for k, f in enumerate(run.metadata.get("faults") or []):
        if f["onset_s"] > 0 and lo <= f["onset_s"] <= hi:
            ax.axvline(f["onset_s"], color="tab:red", ls=":", lw=1.2, label="fault onset" if k == 0 else None)


#: the zoom on the valve shows this long a stretch (s; at most a quarter of the run): five cycles of the
#: paper loop's backlash limit cycle (about 120 s), long enough to see the command-stem gap repeat
ZOOM_S = 600.0


def zoom_window(run: Record) -> tuple[float, float]:
    """The stretch the valve zoom shows: from 100 s before a fault's onset, or the run's end when the fault
    acts from the start (or there is none), so that a healthy run is zoomed where a faulty one would be."""
    t = run.time_s
    width = min(ZOOM_S, 0.25 * float(t[-1] - t[0]))
    onsets = [f["onset_s"] for f in run.metadata.get("faults") or [] if f["onset_s"] > t[0]]
    if onsets:
        start = max(float(t[0]), min(onsets) - 100.0)
        return start, min(float(t[-1]), start + width)
    return float(t[-1]) - width, float(t[-1])


def _valve_command(run: Record) -> np.ndarray:
    """What the pH controller asks of the acid valve (older runs have only the controller output)."""
    return run["valve_command_pct"] if "valve_command_pct" in run else run["ph_controller_output_pct"]


def _plot_valve(ax, run: Record, sel: np.ndarray, gap: bool) -> None:
    """Command and stem position, drawn so the stem never hides the command: command thick and light, stem
    thin and dark on top; with ``gap`` the difference is shaded (a backlash or stiction dead band)."""
    t, command, stem = run.time_s[sel], _valve_command(run)[sel], run["valve_position_pct"][sel]
    ax.plot(t, command, color="tab:orange", lw=2.2, alpha=0.8, label="valve command (pH controller output)")
    ax.plot(t, stem, color="k", lw=0.9, label="acid valve stem position")
    if gap:
        ax.fill_between(t, command, stem, color="tab:red", alpha=0.25, lw=0, label="command - stem gap")
    ax.set_ylabel("valve command,\nstem position (% of span)")


def plot_run(run: Record, path: str | Path) -> Path:
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


def _run_label(run: Record, name: str) -> str:
    """A run's fault and size for a panel or row title, e.g. 'backlash (width 0.7 % of span)' (else its name)."""
    faults = run.metadata.get("faults") or []
    return _fault_text(faults[0]) if faults else name.replace("_", " ")


#: the overview's numbers are over the run's last stretch of this length (s; at most a fifth of the run), after
#: the paper run's setpoint change has settled
SETTLED_S = 2000.0


def _settled_range(run: Record) -> str:
    """pH minus setpoint over the run's last stretch (SETTLED_S), as 'min to max' (the limit cycle or offset)."""
    settled_s = min(SETTLED_S, 0.2 * float(run.time_s[-1] - run.time_s[0]))
    keep = run.time_s >= run.time_s[-1] - settled_s
    dev = run["ph_true"][keep] - run["ph_setpoint"][keep]
    return f"pH - setpoint {np.min(dev):+.2f} to {np.max(dev):+.2f} over the last {settled_s:g} s"


def plot_overview(runs: Sequence[Record], labels: Sequence[str], path: str | Path) -> Path:
    """The pH of every run in its own panel, all on the same axes, each over the healthy run (the paper's
    Figure 27 as small multiples: seven overlaid traces hide one another)."""
    n_cols = 2
    n_rows = (len(runs) + n_cols - 1) // n_cols
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(12, 2.3 * n_rows + 0.8), sharex=True, sharey=True,
                             squeeze=False, layout="constrained")
    healthy = next((r for r, lab in zip(runs, labels) if lab == "healthy"), None)
    for ax, run, lab in zip(axes.flat, runs, labels):
        if healthy is not None and run is not healthy:
            ax.plot(healthy.time_s, healthy["ph_true"], color="0.6", lw=0.8, label="healthy run")
        ax.plot(run.time_s, run["ph_true"], color="tab:blue", lw=0.8, label="pH in tank")
        ax.plot(run.time_s, run["ph_setpoint"], color="k", ls="--", lw=0.8, label="setpoint")
        ax.set_title(f"{_run_label(run, lab)}\n{_settled_range(run)}", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in axes.flat[len(runs):]:
        ax.axis("off")
    for ax in axes[:, 0]:
        ax.set_ylabel("pH (-)")
    for ax in axes.flat[len(runs) - n_cols:len(runs)]:  # the lowest panel of each column carries the time axis
        ax.set_xlabel("time (s)")
        ax.tick_params(labelbottom=True)
    handles, names = axes.flat[min(1, len(runs) - 1)].get_legend_handles_labels()
    fig.legend(handles, names, loc="outside lower center", ncol=3, fontsize=8)
    fig.suptitle("Impact of the valve nonlinearities on the closed-loop pH (one panel per run, shared axes)",
                 fontsize=10)
    path = Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


#: the map's time bins per run: each cell is the largest deviation in its bin (100 s of the paper's 10000 s run,
#: about one limit cycle), so a cycle shows as its amplitude instead of aliasing into stripes
MAP_BINS = 100
MAP_FLOOR_PH = 0.01  # the colour scale's bottom: the probe's noise is about this size


def _peak_deviation(run: Record, edges: np.ndarray) -> np.ndarray:
    """Largest |pH in tank - setpoint| in each time bin [edges[i], edges[i+1])."""
    dev = np.abs(run["ph_true"] - run["ph_setpoint"])
    idx = np.clip(np.searchsorted(run.time_s, edges[:-1]), 0, len(dev) - 1)
    return np.maximum.reduceat(dev, idx)


def plot_overview_map(runs: Sequence[Record], labels: Sequence[str], path: str | Path) -> Path:
    """How far each run's pH strays from its setpoint, one row per run against time, on a log colour scale
    (the paper's Figure 28, a 3-D waterfall, as a map that reads at a glance: where each run leaves its
    setpoint and by how much)."""
    from matplotlib.colors import LogNorm

    t = runs[0].time_s
    bin_s = float(t[-1] - t[0]) / MAP_BINS
    edges = float(t[0]) + bin_s * np.arange(MAP_BINS + 1)
    rows = np.maximum(np.vstack([_peak_deviation(r, edges) for r in runs]), MAP_FLOOR_PH)
    fig, ax = plt.subplots(figsize=(12, 0.45 * len(runs) + 2.2), layout="constrained")
    image = ax.imshow(rows, aspect="auto", cmap="magma_r", interpolation="nearest",
                      norm=LogNorm(MAP_FLOOR_PH, max(1.0, float(rows.max()))),
                      extent=(float(edges[0]), float(edges[-1]), len(runs) - 0.5, -0.5))
    ax.set_yticks(range(len(runs)))
    ax.set_yticklabels([_run_label(r, lab) for r, lab in zip(runs, labels)], fontsize=8)
    ax.set_ylabel("run (fault, size)")
    ax.set_xlabel("time (s)")
    bar = fig.colorbar(image, ax=ax, pad=0.01, extend="min")
    bar.set_label(f"largest |pH in tank - setpoint|\nper {bin_s:.3g} s (pH)")
    bar.ax.yaxis.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    ax.set_title("Healthy and faulty pH responses: how far the pH strays from its setpoint", fontsize=10)
    path = Path(path)
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path
