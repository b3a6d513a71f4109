"""Figures of the evaluation and of the paper's coefficient residuals (Section 7, Figures 50-55)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from phfdi_base.outputs import save_figure
from wavelet_fdi.config import DetectorSettings
from wavelet_fdi.filterbank import coefficient_residuals
from wavelet_fdi.isolation import classes
from wavelet_fdi.peers import DETECTORS, LABELS
from wavelet_fdi.statistics import CusumBank

COLORS = {"wavelet": "tab:blue", "wavelet_bands": "tab:cyan", "cusum": "tab:orange", "focus": "tab:green",
          "page_hinkley": "tab:red", "adwin": "tab:purple"}


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_delays(summary: dict, path: Path) -> Path:
    faults = list(dict.fromkeys(r["fault"] for r in summary["rows"]))
    cols = 3
    rows = (len(faults) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(14, 4 * rows), squeeze=False)
    width = 0.8 / len(DETECTORS)
    for ax, fault in zip(axes.flat, faults):
        mine = [r for r in summary["rows"] if r["fault"] == fault]
        x = np.arange(len(mine))
        for j, d in enumerate(DETECTORS):
            vals = [r["delay"][d] if r["delay"][d] is not None else np.nan for r in mine]
            ax.bar(x + (j - len(DETECTORS) / 2 + 0.5) * width, vals, width, color=COLORS[d], label=LABELS[d])
        bounds = [r["bound_s"] if r["bound_s"] is not None else np.nan for r in mine]
        ax.plot(x, bounds, "k_", ms=30, mew=2, label="bound (oracle)")
        ax.set_xticks(x)
        ax.set_xticklabels([f"{r['param']}\n= {r['value']:g}" for r in mine], fontsize=8)
        ax.set_yscale("log")
        ax.set_ylabel("detection delay (s)")
        ax.set_title(fault)
        ax.grid(alpha=0.3, axis="y")
    for ax in list(axes.flat)[len(faults):]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.suptitle(f"Detection delay at equal false-alarm rate (ARL0 = {summary['arl0_samples']:g} samples); "
                 "missing bar: missed", fontsize=10)
    return _save(fig, path)


def plot_false_alarms(summary: dict, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4))
    vals = [summary["false_per_hour"][d] or 0.0 for d in DETECTORS]
    ax.bar([LABELS[d] for d in DETECTORS], vals, color=[COLORS[d] for d in DETECTORS])
    for i, d in enumerate(DETECTORS):
        ax.text(i, vals[i], f"{summary['false_alarms'][d]}", ha="center", va="bottom", fontsize=9)
    target = 3600.0 / summary["arl0_samples"]  # 1 s samples
    ax.axhline(target, color="k", ls="--", lw=1, label=f"target 1/ARL0 ({target:.3f} per hour at 1 s)")
    ax.set_ylabel("false alarms per hour (1/h)")
    ax.set_title(f"False alarms over {summary['healthy_hours']:.1f} h of healthy operation (counts on bars)")
    ax.legend(fontsize=8)
    ax.tick_params(axis="x", labelsize=8)
    return _save(fig, path)


def plot_isolation(summary: dict, path: Path) -> Path:

    faults = list(dict.fromkeys(r["fault"] for r in summary["rows"]))
    cols = list(classes()) + ["pending"]
    m = np.zeros((len(faults), len(cols)))
    for r in summary["rows"]:
        for c in r["classes"]:
            m[faults.index(r["fault"]), cols.index(c) if c in cols else -1] += 1
    fig, ax = plt.subplots(figsize=(9, 4.5))
    ax.imshow(m, cmap="Blues")
    for i in range(m.shape[0]):
        for j in range(m.shape[1]):
            if m[i, j]:
                ax.text(j, i, f"{int(m[i, j])}", ha="center", va="center", fontsize=9)
    ax.set_xticks(range(len(cols)))
    ax.set_xticklabels(cols, rotation=30, fontsize=8)
    ax.set_yticks(range(len(faults)))
    ax.set_yticklabels(faults, fontsize=8)
    ax.set_xlabel("class given by isolation (-)")
    ax.set_ylabel("injected fault (-)")
    ax.set_title("Isolation: runs per injected fault and diagnosed class")
    return _save(fig, path)


def plot_parameters(summary: dict, path: Path) -> Path:
    faults = list(dict.fromkeys(r["fault"] for r in summary["rows"]))
    fig, axes = plt.subplots(1, len(faults), figsize=(3.2 * len(faults), 3.4), squeeze=False)
    for ax, fault in zip(axes[0], faults):
        mine = [r for r in summary["rows"] if r["fault"] == fault]
        lo = min(r["value"] for r in mine)
        hi = max(r["value"] for r in mine)
        for r in mine:
            ax.plot([r["value"]] * len(r["estimates"]), r["estimates"], "o", color="tab:blue")
        span = np.linspace(0.8 * lo, 1.2 * hi, 2)
        ax.plot(span, span, "k--", lw=0.8)
        unit = "s" if mine[0]["param"].endswith("_s") else "% of span"
        ax.set_xlabel(f"true {mine[0]['param']} ({unit})", fontsize=8)
        ax.set_ylabel(f"estimated ({unit})", fontsize=8)
        ax.set_title(fault, fontsize=9)
        ax.grid(alpha=0.3)
    return _save(fig, path)


def plot_coefficient_residuals(signals: dict, settings: DetectorSettings, path: Path, title: str) -> Path:
    """Paper Figures 50-55: D1..DJ, AJ of the measured and predicted pH, and their differences."""
    t = signals["time_s"]
    ok = np.isfinite(signals["ph_predicted"]) & np.isfinite(signals["ph_measured"])
    res = coefficient_residuals(signals["ph_measured"][ok], signals["ph_predicted"][ok],
                                settings.wavelet, settings.level)
    bands = settings.bands()
    fig, axes = plt.subplots(len(bands), 3, figsize=(14, 2.2 * len(bands)), sharex=True)
    t0, t1 = float(t[ok][0]), float(t[ok][-1])
    for i, b in enumerate(bands):
        for j, key in enumerate(("measured", "predicted", "residual")):
            c = res[key][b]
            ax = axes[i, j]
            ax.plot(np.linspace(t0, t1, len(c)), c, lw=0.6, color="tab:red" if key == "residual" else "tab:blue")
            ax.set_ylabel(f"{'Res' if key == 'residual' else ''}{b} (pH)", fontsize=8)
            if i == 0:
                ax.set_title({"measured": "measured pH", "predicted": "healthy prediction",
                              "residual": "coefficient residual (measured - predicted)"}[key], fontsize=9)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def plot_evaluation(summary: dict, records: list[dict], out: Path, signals: dict | None,
                    settings: DetectorSettings) -> list[Path]:
    paths = [plot_delays(summary, out / "delays.png"), plot_false_alarms(summary, out / "false_alarms.png"),
             plot_isolation(summary, out / "isolation.png"), plot_parameters(summary, out / "parameters.png")]
    if signals is not None:
        paths.append(plot_coefficient_residuals(
            signals, settings, out / "coefficient_residuals_backlash.png",
            f"Backlash at 7000 s: {settings.wavelet} level-{settings.level} DWT (pywt.wavedec) of the measured pH, "
            f"the healthy model's prediction and their difference (paper Figures 50-55)"))
    return paths


def statistic_paths(increments: np.ndarray, thresholds: np.ndarray, start: int = 0) -> np.ndarray:
    """The CUSUM statistics (N, n_statistics) from a trace's increments, all restarted after every
    threshold crossing, as the detector runs them (without its resets at gaps)."""

    n, m = increments.shape
    bank = CusumBank(m)
    out = np.zeros((n, m))
    a = start
    while a < n:
        s = bank.update(increments[a:].T, a).T
        over = np.flatnonzero((s > thresholds[None, :]).any(axis=1))
        if not len(over):
            out[a:] = s
            break
        c = int(over[0])
        out[a:a + c + 1] = s[:c + 1]
        bank.restart(a + c)
        a += c + 1
    return out


class _Unlabelled:
    """An axes whose axvline adds no legend entry."""

    def __init__(self, ax) -> None:
        self.ax = ax

    def axvline(self, *args, label=None, **kw):
        return self.ax.axvline(*args, **kw)

    def grid(self, *args, **kw):
        return self.ax.grid(*args, **kw)


def plot_detection(trace: dict, names: list[str], thresholds: np.ndarray, sigma_ph: float, alarms: list,
                   path: Path, title: str, true_onsets_s: list[float] = ()) -> Path:
    """Measured pH against the healthy reference's prediction, the residual, and every CUSUM statistic
    over its threshold, with the fault onset, the estimated onset and the alarm marked; left the whole
    run, right around the first alarm."""
    t = trace["time_s"]
    ratio = statistic_paths(trace["increments"], thresholds) / thresholds[None, :]
    fig, axes = plt.subplots(3, 2, figsize=(14, 8.5), sharex="col", gridspec_kw={"width_ratios": [1.4, 1]})
    first = alarms[0] if alarms else None
    if first is not None:
        lo = first.onset_time_s - 300.0
        hi = (first.isolation_time_s or first.detection_time_s) + 200.0
    else:
        lo, hi = float(t[0]), float(t[-1])
    for col, (a, b) in enumerate(((float(t[0]), float(t[-1])), (lo, hi))):
        sel = (t >= a) & (t <= b)
        ax = axes[0, col]
        ax.plot(t[sel], trace["ph_measured"][sel], color="0.6", lw=0.6, label="measured")
        ax.plot(t[sel], trace["ph_predicted"][sel], color="tab:blue", lw=0.9, label="healthy reference model")
        ax.set_ylabel("pH (-)")
        ax = axes[1, col]
        ax.plot(t[sel], trace["ph_residual"][sel], color="tab:red", lw=0.6, label="residual (measured - predicted)")
        for sign in (-3, 3):
            ax.axhline(sign * sigma_ph, color="k", ls=":", lw=0.8, label="+-3 healthy sigma" if sign > 0 else None)
        ax.set_ylabel("pH residual (pH)")
        ax = axes[2, col]
        for j, name in enumerate(names):
            ax.plot(t[sel], ratio[sel, j], lw=0.8, label=name)
        ax.axhline(1.0, color="k", lw=1.0, label="threshold")
        ax.set_ylabel("CUSUM statistic / threshold (-)")
        ax.set_xlabel("time (s)")
        ax.set_ylim(0.0, 1.6)
        for i, row in enumerate(axes[:, col]):
            if i:  # the events are marked in every panel, named in the top one
                row = _Unlabelled(row)
            for k, onset in enumerate(true_onsets_s):
                if a <= onset <= b:
                    row.axvline(onset, color="tab:red", ls=":", lw=1.2, label="fault injected" if k == 0 else None)
            for k, al in enumerate(alarms):
                if a <= al.detection_time_s <= b:
                    row.axvline(al.detection_time_s, color="k", ls="--", lw=1.0, label="alarm" if k == 0 else None)
                onset = al.onset_refined_s if al.onset_refined_s is not None else al.onset_time_s
                if a <= onset <= b and col == 1:
                    row.axvline(onset, color="tab:orange", ls="-.", lw=1.0,
                                label="estimated onset" if k == 0 else None)
                if al.isolation_time_s is not None and a <= al.isolation_time_s <= b and col == 1:
                    row.axvline(al.isolation_time_s, color="tab:green", ls="--", lw=1.0,
                                label=f"diagnosis: {al.fault_class}" if k == 0 else None)
            row.grid(alpha=0.3)
    for row in range(3):
        axes[row, 1].legend(fontsize=7, loc="upper left", ncol=2, framealpha=0.8)
    axes[0, 0].set_title("whole run", fontsize=10)
    axes[0, 1].set_title("around the first alarm" if first else "(no alarm)", fontsize=10)
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)
