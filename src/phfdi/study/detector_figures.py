"""Figures of the evaluation and of the paper's coefficient residuals (Section 7, Figures 50-55)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from phfdi_base.outputs import save_figure
from wavelet_fdi.config import LearnedSettings
from wavelet_fdi.filterbank import coefficient_residuals
from wavelet_fdi.isolation import classes
from wavelet_fdi.peers import DETECTORS, LABELS
from wavelet_fdi.statistics import CusumBank, parse_statistic

COLORS = {"wavelet": "tab:blue", "wavelet_bands": "tab:cyan", "cusum": "tab:orange", "focus": "tab:green",
          "page_hinkley": "tab:red", "adwin": "tab:purple"}


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
    return path


#: units of the evaluation's own faults, which the fault catalogue does not hold
EVALUATION_UNITS = {("probe_noise", "std"): "pH"}


def _delay_bars(ax, mine: list[dict], width: float) -> None:
    """One group of bars per severity, one bar per detector; a cross at the bottom where a detector missed
    every run (its mean delay is None)."""
    x = np.arange(len(mine))
    for j, d in enumerate(DETECTORS):
        offset = (j - len(DETECTORS) / 2 + 0.5) * width
        vals = np.array([r["delay"][d] if r["delay"][d] is not None else np.nan for r in mine])
        ax.bar(x + offset, vals, width, color=COLORS[d], label=LABELS[d])
        missed = np.isnan(vals)
        ax.plot(x[missed] + offset, np.full(missed.sum(), DELAY_FLOOR_S * 1.4), "x", color=COLORS[d], ms=7,
                mew=2)
    bounds = [r["bound_s"] if r["bound_s"] is not None else np.nan for r in mine]
    ax.plot(x, bounds, "k_", ms=30, mew=2)
    # legend entries drawn apart: a 30-point marker overruns its label, a cross takes one detector's colour
    ax.plot([], [], "k-", lw=2, label="bound (oracle)")
    ax.plot([], [], "x", color="0.3", ms=7, mew=2, label="missed in every run (cross in the detector's colour)")


DELAY_FLOOR_S = 0.5  # the log axes' bottom: below the 1 s sample time, so a 1 s bar still shows


def plot_delays(summary: dict, path: Path) -> Path:
    """Mean detection delay per fault and severity, every detector, with the oracle bound: one panel per
    fault on one shared log axis, one legend under the panels."""
    from phfdi.figures import param_text

    faults = list(dict.fromkeys(r["fault"] for r in summary["rows"]))
    cols = 3
    rows = (len(faults) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(14, 3.6 * rows + 0.8), squeeze=False, sharey=True,
                             layout="constrained")
    delays = [v for r in summary["rows"] for v in list(r["delay"].values()) + [r["bound_s"]] if v]
    top = 2.0 * max(delays, default=10.0)
    for ax, fault in zip(axes.flat, faults):
        mine = [r for r in summary["rows"] if r["fault"] == fault]
        _delay_bars(ax, mine, 0.8 / len(DETECTORS))
        ax.set_xticks(np.arange(len(mine)))
        ax.set_xticklabels([param_text(fault, r["param"], r["value"], EVALUATION_UNITS.get((fault, r["param"]), ""))
                            for r in mine], fontsize=8)
        ax.set_xlabel("fault size (unit on each tick)", fontsize=8)
        ax.set_yscale("log")
        ax.set_ylim(DELAY_FLOOR_S, top)
        plain_log_ticks(ax)
        ax.set_title(fault.replace("_", " "), fontsize=10)
        ax.grid(alpha=0.3, axis="y", which="major")
    for ax in axes[:, 0]:
        ax.set_ylabel("detection delay (s)")
    for ax in list(axes.flat)[len(faults):]:
        ax.axis("off")
    _figure_legend(fig, axes)
    fig.suptitle(f"Detection delay after the onset at equal false-alarm rate (ARL0 = {summary['arl0_samples']:g} "
                 "samples), mean over the seeds that detected", fontsize=10)
    save_figure(fig, path, dpi=110)  # not _save: its tight_layout would replace the constrained layout
    plt.close(fig)
    return path


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


def band_gain(band: str) -> float:
    """An orthonormal DWT's gain on level j (a sine in D_j, a constant in A_J: 2^(j/2)); dividing by it makes
    a band's coefficients read as the pH amplitude of that band's part of the signal.

    >>> band_gain("D2"), round(band_gain("A3"), 3)
    (2.0, 2.828)
    """
    return 2.0 ** (0.5 * int(band[1:]))


def plot_coefficient_residuals(signals: dict, settings: LearnedSettings, path: Path, title: str,
                               onset_s: float | None = None) -> Path:
    """Paper Figures 50-55: D1..DJ, AJ of the measured and predicted pH, and their differences, each band
    divided by its gain 2^(j/2) so that it reads in pH (A3 is then the local mean pH, not 2.8 times it)."""
    t = signals["time_s"]
    ok = np.isfinite(signals["ph_predicted"]) & np.isfinite(signals["ph_measured"])
    res = coefficient_residuals(signals["ph_measured"][ok], signals["ph_predicted"][ok],
                                settings.wavelet, settings.level)
    bands = settings.bands()
    fig, axes = plt.subplots(len(bands), 3, figsize=(14, 2.2 * len(bands) + 0.6), sharex=True, layout="constrained")
    t0, t1 = float(t[ok][0]), float(t[ok][-1])
    titles = {"measured": "measured pH", "predicted": "healthy model's prediction",
              "residual": "coefficient residual (measured - predicted)"}
    for i, b in enumerate(bands):
        for j, key in enumerate(("measured", "predicted", "residual")):
            c = res[key][b] / band_gain(b)
            ax = axes[i, j]
            ax.plot(np.linspace(t0, t1, len(c)), c, lw=0.6, color="tab:red" if key == "residual" else "tab:blue")
            if onset_s is not None:
                ax.axvline(onset_s, color="k", ls=":", lw=1.2, label="fault onset")
            ax.set_ylabel(f"{'Res' if key == 'residual' else ''}{b} / {band_gain(b):.3g} (pH)", fontsize=8)
            if i == 0:
                ax.set_title(titles[key], fontsize=9)
            ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)")
    if onset_s is not None:
        axes[0, 0].legend(fontsize=7, loc="lower left")
    fig.suptitle(title + "\neach band divided by its gain 2^(j/2), so it reads in pH", fontsize=10)
    save_figure(fig, path, dpi=110)  # not _save: its tight_layout would replace the constrained layout
    plt.close(fig)
    return path


def plot_evaluation(summary: dict, records: list[dict], out: Path, signals: dict | None,
                    settings: LearnedSettings) -> list[Path]:
    paths = [plot_delays(summary, out / "delays.png"), plot_false_alarms(summary, out / "false_alarms.png"),
             plot_isolation(summary, out / "isolation.png"), plot_parameters(summary, out / "parameters.png")]
    if signals is not None:
        onset = next((r["onset_s"] for r in records if r["fault"] == "backlash"), None)
        when = f" at {onset:g} s" if onset is not None else ""
        paths.append(plot_coefficient_residuals(
            signals, settings, out / "coefficient_residuals_backlash.png",
            f"Backlash{when}: {settings.wavelet} level-{settings.level} DWT (pywt.wavedec) of the measured pH, "
            f"the healthy model's prediction and their difference (paper Figures 50-55)", onset))
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


STATISTIC_KINDS = {"mean_up": "mean shift up", "mean_down": "mean shift down", "energy": "variance increase",
                   "energy_down": "variance decrease", "aj_energy": "variance increase"}
CHANNEL_NAMES = {"ph": "pH", "level": "level", "ph_measured": "pH", "level_measured_cm": "level"}
#: the statistic panels draw each statistic's peak over this many bins (whole run, around the alarm): after an
#: alarm the detector restarts its statistics at every crossing, which drawn sample by sample is a solid block
PEAK_BINS = (100, 300)
RATIO_FLOOR = 0.05  # the log scale's bottom: under 5 % of its threshold a statistic is healthy noise


def statistic_label(name: str, sample_time_s: float) -> str:
    """A statistic's code name (``ph.D2.energy``) as an engineer reads it: signal, band with its periods,
    and what the statistic watches for.

    >>> statistic_label("ph.R.mean_down", 1.0)
    'pH residual: mean shift down'
    >>> statistic_label("ph.D2.energy", 1.0)
    'pH residual, D2 band (periods 4-8 s): variance increase'
    >>> statistic_label("ph.A3.mean_up", 1.0)
    'pH residual, A3 band (periods over 16 s): mean shift up'
    """
    channel, band, kind = parse_statistic(name)
    what = STATISTIC_KINDS.get(kind, kind.replace("_", " "))
    signal = f"{CHANNEL_NAMES.get(channel, channel)} residual"
    if band == "R":
        return f"{signal}: {what}"
    j = int(band[1:])
    # D_j holds periods 2^j..2^(j+1) samples, A_J everything slower than D_J
    if band.startswith("D"):
        periods = f"periods {2 ** j * sample_time_s:g}-{2 ** (j + 1) * sample_time_s:g} s"
    else:
        periods = f"periods over {2 ** (j + 1) * sample_time_s:g} s"
    return f"{signal}, {band} band ({periods}): {what}"


#: statistic line colours: none of the event markers' (red onset, black alarm, orange estimated onset, green
#: diagnosis), so a statistic is never mistaken for an event
STATISTIC_COLOURS = ["tab:purple", "tab:cyan", "tab:brown", "tab:pink", "tab:olive", "navy", "tab:gray",
                     "gold", "teal"]


def peak_per_bin(time_s: np.ndarray, values: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Each column's maximum over ``n_bins`` consecutive bins of rows, with each bin's first time.

    >>> t, v = peak_per_bin(np.arange(6.0), np.array([[0.0], [2.0], [1.0], [0.0], [0.5], [3.0]]), 3)
    >>> t.tolist(), v[:, 0].tolist()
    ([0.0, 2.0, 4.0], [2.0, 1.0, 3.0])
    """
    starts = np.unique(np.linspace(0, len(time_s), min(n_bins, len(time_s)), endpoint=False).astype(int))
    return time_s[starts], np.maximum.reduceat(values, starts, axis=0)


def plain_log_ticks(ax, axis: str = "y") -> None:
    """Log-axis ticks at 1, 2, 5 x 10^n written as plain numbers (0.02, 5, 200) instead of 2 x 10^-2."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    target = ax.yaxis if axis == "y" else ax.xaxis
    target.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    target.set_major_formatter(FuncFormatter(lambda v, _pos: f"{v:g}"))
    target.set_minor_formatter(NullFormatter())


def _zoom_window(time_s: np.ndarray, alarms: list) -> tuple[float, float]:
    """From 300 s before the first alarm's onset estimate to 200 s after its diagnosis (the whole run
    without an alarm)."""
    if not alarms:
        return float(time_s[0]), float(time_s[-1])
    first = alarms[0]
    return first.onset_time_s - 300.0, (first.isolation_time_s or first.detection_time_s) + 200.0


def _plot_ph(ax, time_s: np.ndarray, trace: dict, sel: np.ndarray) -> None:
    ax.plot(time_s, trace["ph_measured"][sel], color="0.6", lw=0.6, label="pH measured")
    ax.plot(time_s, trace["ph_predicted"][sel], color="tab:blue", lw=0.9, label="pH, healthy reference model")
    ax.set_ylabel("pH (-)")


def _plot_residual(ax, time_s: np.ndarray, residual: np.ndarray, sigma_ph: float) -> None:
    ax.plot(time_s, residual, color="tab:red", lw=0.6, label="pH residual (measured - predicted)")
    for sign in (-3, 3):
        ax.axhline(sign * sigma_ph, color="k", ls=":", lw=0.8, label="+-3 healthy sigma" if sign > 0 else None)
    ax.set_ylabel("pH residual (pH)")


def _plot_ratios(ax, time_s: np.ndarray, ratio: np.ndarray, labels: list[str], alarmed: str | None,
                 n_bins: int) -> None:
    """Every statistic over its threshold on a log scale, as its peak per bin (see PEAK_BINS)."""
    t_bin, peak = peak_per_bin(time_s, ratio, n_bins)
    peak = np.maximum(peak, RATIO_FLOOR)
    for j, lab in enumerate(labels):
        first = lab == alarmed
        ax.plot(t_bin, peak[:, j], drawstyle="steps-post", color=STATISTIC_COLOURS[j % len(STATISTIC_COLOURS)],
                lw=1.6 if first else 0.8, zorder=3 if first else 2,
                label=f"{lab} (raised the alarm)" if first else lab)
    top = max(2.0, 1.5 * float(np.max(peak))) if peak.size else 2.0
    ax.axhline(1.0, color="k", lw=1.2, label="threshold (statistic = threshold)")
    ax.axhspan(1.0, top, color="tab:red", alpha=0.06, lw=0)
    ax.set_yscale("log")
    ax.set_ylim(RATIO_FLOOR, top)
    plain_log_ticks(ax)
    ax.set_ylabel(f"CUSUM statistic / threshold (-)\npeak per {(time_s[-1] - time_s[0]) / n_bins:.3g} s, log scale")
    ax.set_xlabel("time (s)")


def _mark_events(ax, a: float, b: float, true_onsets_s, alarms: list, detail: bool) -> None:
    """Fault onset and alarms in [a, b]; in the detail panels the estimated onset and the diagnosis too."""
    for onset in true_onsets_s:
        if a <= onset <= b:
            ax.axvline(onset, color="tab:red", ls=":", lw=1.4, label="fault onset (injected)")
    for al in alarms:
        if a <= al.detection_time_s <= b:
            ax.axvline(al.detection_time_s, color="k", ls="--", lw=1.0, label="alarm")
        onset = al.onset_refined_s if al.onset_refined_s is not None else al.onset_time_s
        if detail and a <= onset <= b:
            ax.axvline(onset, color="tab:orange", ls="-.", lw=1.0, label="estimated onset")
        if detail and al.isolation_time_s is not None and a <= al.isolation_time_s <= b:
            ax.axvline(al.isolation_time_s, color="tab:green", ls="--", lw=1.0, label=f"diagnosis: {al.fault_class}")
    ax.grid(alpha=0.3)


def _figure_legend(fig, axes) -> None:
    """One legend under the panels (each label once), so no legend covers data."""
    handles: dict[str, object] = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(lab, h)
    fig.legend(list(handles.values()), list(handles), loc="outside lower center", ncol=3, fontsize=8)


def plot_detection(trace: dict, names: list[str], thresholds: np.ndarray, sigma_ph: float, alarms: list,
                   path: Path, title: str, true_onsets_s: Sequence[float] = ()) -> Path:
    """Measured pH against the healthy reference's prediction, the residual, and every CUSUM statistic
    as a ratio to its threshold (log scale, a line at 1), with the fault onset, the estimated onset and the
    alarm marked; left the whole run, right around the first alarm. ``trace["ratio"]``, where given, is each
    statistic over its threshold as the detector ran it; else it is rebuilt from the increments."""
    t = trace["time_s"]
    ratio = trace["ratio"] if "ratio" in trace else statistic_paths(trace["increments"], thresholds) / thresholds[None, :]
    sample_time_s = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
    labels = [statistic_label(n, sample_time_s) for n in names]
    alarmed = statistic_label(alarms[0].statistic, sample_time_s) if alarms else None
    fig, axes = plt.subplots(3, 2, figsize=(14, 10), sharex="col", width_ratios=[1.4, 1], layout="constrained")
    for col, (a, b) in enumerate(((float(t[0]), float(t[-1])), _zoom_window(t, alarms))):
        sel = (t >= a) & (t <= b)
        _plot_ph(axes[0, col], t[sel], trace, sel)
        _plot_residual(axes[1, col], t[sel], trace["ph_residual"][sel], sigma_ph)
        _plot_ratios(axes[2, col], t[sel], ratio[sel], labels, alarmed, PEAK_BINS[col])
        for ax in axes[:, col]:
            _mark_events(ax, a, b, true_onsets_s, alarms, detail=col == 1)
    axes[0, 0].set_title("whole run", fontsize=10)
    axes[0, 1].set_title("around the first alarm" if alarms else "(no alarm)", fontsize=10)
    _figure_legend(fig, axes)
    fig.suptitle(title, fontsize=10)
    path = Path(path)
    save_figure(fig, path, dpi=110)  # not _save: its tight_layout would replace the constrained layout
    plt.close(fig)
    return path
