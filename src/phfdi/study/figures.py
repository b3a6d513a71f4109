"""Figures of the offline analysis, numbered after the paper's (Figures 27 to 61). Every axis has units."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pywt  # noqa: E402

from phfdi_base.outputs import save_figure

from .multisignal import Multisignal  # noqa: E402
from .residuals import moving_rms

COLOURS = {"healthy": "tab:green", "backlash": "tab:blue", "friction": "tab:red", "deadzone": "tab:purple",
           "saturation": "tab:orange"}
_OTHER = ["tab:brown", "tab:pink", "tab:gray", "tab:olive", "tab:cyan"]


def colour(label: str, classes: Sequence[str] = ()) -> str:
    if label in COLOURS:
        return COLOURS[label]
    extra = [c for c in classes if c not in COLOURS]
    return _OTHER[extra.index(label) % len(_OTHER)] if label in extra else "k"


def _save(fig, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def _plot_rows(ax, t: np.ndarray, rows: np.ndarray, labels: Sequence[str], classes: Sequence[str],
               lw: float = 0.6, legend: bool = True, alpha: float = 0.8) -> None:
    """Rows as lines coloured by class: one LineCollection per class (35 rows draw as 5 artists)."""
    from matplotlib.collections import LineCollection

    rows = np.atleast_2d(rows)
    for lab in dict.fromkeys(labels):
        idx = [i for i, x in enumerate(labels) if x == lab]
        segs = [np.column_stack([t, rows[i]]) for i in idx]
        ax.add_collection(LineCollection(segs, colors=colour(lab, classes), linewidths=lw, alpha=alpha, label=lab))
    ax.autoscale_view()
    if legend:
        ax.legend(fontsize=7, ncol=min(5, len(set(labels))), loc="best")
    ax.grid(alpha=0.3)


def _ylabel(ms: Multisignal) -> str:
    return f"{ms.signal.replace('_', ' ')} ({ms.unit})"


# ---- Section 6 -----------------------------------------------------------------------------------
def multisignal_overview(ms: Multisignal, path: Path) -> Path:
    """Figure 27: every row on one axis."""
    fig, ax = plt.subplots(figsize=(10, 4.5))
    _plot_rows(ax, ms.time_s, ms.data, ms.labels, ms.classes)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(_ylabel(ms))
    ax.set_title(f"Multisignal: {ms.shape[0]} rows x {ms.shape[1]} samples")
    return _save(fig, path)


def multisignal_surface(ms: Multisignal, path: Path) -> Path:
    """Figure 28: the rows as a surface."""
    fig = plt.figure(figsize=(10, 6))
    ax = fig.add_subplot(projection="3d")
    tt, rr = np.meshgrid(ms.time_s, np.arange(ms.shape[0]))
    ax.plot_surface(tt, rr, ms.data, cmap="viridis", linewidth=0, antialiased=False, rstride=1, cstride=4)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("row (index)")
    ax.set_zlabel(_ylabel(ms))
    ax.set_title("Multisignal as a surface (rows grouped by class)")
    return _save(fig, path)


def wavelet_functions(wavelet: str, path: Path) -> Path:
    """Figure 29: scaling function and wavelet."""
    w = pywt.Wavelet(wavelet)
    phi, psi, x = w.wavefun(level=10)[:3]
    fig, axes = plt.subplots(1, 2, figsize=(9, 3.2))
    for ax, y, name in ((axes[0], phi, "scaling function phi"), (axes[1], psi, "wavelet psi")):
        ax.plot(x, y, color="k", lw=1)
        ax.set_xlabel("t (samples)")
        ax.set_ylabel(f"{name.split()[-1]}(t) (1)")
        ax.set_title(f"{wavelet}: {name}")
        ax.grid(alpha=0.3)
    return _save(fig, path)


def approximations(ms: Multisignal, approx: np.ndarray, level: int, path: Path) -> Path:
    """Figure 30: the rows (top) and their approximations at ``level`` (bottom)."""
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True, sharey=True)
    _plot_rows(axes[0], ms.time_s, ms.data, ms.labels, ms.classes)
    axes[0].set_title("Original signals")
    _plot_rows(axes[1], ms.time_s, approx, ms.labels, ms.classes, legend=False)
    axes[1].set_title(f"Approximations at level {level}")
    for ax in axes:
        ax.set_ylabel(_ylabel(ms))
    axes[1].set_xlabel("time (s)")
    return _save(fig, path)


def approximation_groups(ms: Multisignal, approx: np.ndarray, level: int, groups: Sequence[Sequence[str]],
                         path: Path) -> Path:
    """Figure 31: signals and approximations, one column per group of classes."""
    groups = [list(g) for g in groups if any(lab in ms.labels for lab in g)]
    rest = [c for c in ms.classes if not any(c in g for g in groups)]
    groups = groups + [rest] if rest else groups
    fig, axes = plt.subplots(2, len(groups), figsize=(5 * len(groups), 6.5), sharex=True, squeeze=False)
    for c, group in enumerate(groups):
        idx = [i for i, lab in enumerate(ms.labels) if lab in group]
        _plot_rows(axes[0, c], ms.time_s, ms.data[idx], [ms.labels[i] for i in idx], ms.classes)
        _plot_rows(axes[1, c], ms.time_s, approx[idx], [ms.labels[i] for i in idx], ms.classes, legend=False)
        axes[0, c].set_title(f"signals: {', '.join(group)}", fontsize=9)
        axes[1, c].set_title(f"approximations at level {level}", fontsize=9)
        axes[1, c].set_xlabel("time (s)")
        for r in range(2):
            axes[r, c].set_ylabel(_ylabel(ms))
    return _save(fig, path)


def denoising(ms: Multisignal, denoised: dict[int, np.ndarray], path: Path, edge_fraction: float) -> Path:
    """Figure 32: denoised rows at each level and their residuals, with a zoom on the record's start."""
    levels = sorted(denoised)
    fig, axes = plt.subplots(3, len(levels), figsize=(5.5 * len(levels), 9), squeeze=False)
    m = max(2, int(round(2 * edge_fraction * ms.shape[1])))
    for c, lev in enumerate(levels):
        d = denoised[lev]
        _plot_rows(axes[0, c], ms.time_s, d, ms.labels, ms.classes, legend=(c == 0))
        axes[0, c].set_title(f"denoised at level {lev}")
        _plot_rows(axes[1, c], ms.time_s[:m], ms.data[:, :m], ms.labels, ms.classes, legend=False, alpha=0.25)
        _plot_rows(axes[1, c], ms.time_s[:m], d[:, :m], ms.labels, ms.classes, legend=False, lw=1.0)
        axes[1, c].set_title(f"start of the record (first {100 * 2 * edge_fraction:g} %): measured (faint), denoised")
        axes[1, c].title.set_fontsize(8)
        _plot_rows(axes[2, c], ms.time_s, ms.data - d, ms.labels, ms.classes, legend=False, lw=0.4)
        axes[2, c].set_title(f"residuals (measured - denoised), level {lev}")
        for r in range(3):
            axes[r, c].set_xlabel("time (s)")
            axes[r, c].set_ylabel(_ylabel(ms) if r < 2 else f"residual ({ms.unit})")
    return _save(fig, path)


def compression(ms: Multisignal, compressed: np.ndarray, nonzero_pct: np.ndarray, retain: float, path: Path) -> Path:
    """Figure 33: original and compressed rows and the residuals."""
    fig, axes = plt.subplots(3, 1, figsize=(10, 8.5), sharex=True)
    _plot_rows(axes[0], ms.time_s, ms.data, ms.labels, ms.classes)
    axes[0].set_title("Original signals")
    _plot_rows(axes[1], ms.time_s, compressed, ms.labels, ms.classes, legend=False)
    axes[1].set_title(f"Compressed: {100 * retain:g} % of the energy kept with "
                      f"{np.min(nonzero_pct):.2f} - {np.max(nonzero_pct):.2f} % of the coefficients")
    _plot_rows(axes[2], ms.time_s, ms.data - compressed, ms.labels, ms.classes, legend=False, lw=0.4)
    axes[2].set_title("Residuals (original - compressed)")
    axes[0].set_ylabel(_ylabel(ms))
    axes[1].set_ylabel(_ylabel(ms))
    axes[2].set_ylabel(f"residual ({ms.unit})")
    axes[2].set_xlabel("time (s)")
    return _save(fig, path)


def nonzero_bars(ms: Multisignal, raw: np.ndarray, centred: np.ndarray, retain: float, paper_pct: float,
                 path: Path) -> Path:
    """Figure 34: percentage of non-zero coefficients per row."""
    fig, ax = plt.subplots(figsize=(10, 4))
    idx = np.arange(ms.shape[0])
    ax.bar(idx - 0.2, raw, width=0.4, color=[colour(lab, ms.classes) for lab in ms.labels], label="as recorded")
    ax.bar(idx + 0.2, centred, width=0.4, color=[colour(lab, ms.classes) for lab in ms.labels], alpha=0.45,
           hatch="//", label="each row about its mean")
    ax.axhline(paper_pct, color="k", ls="--", lw=1, label=f"paper: about {paper_pct:g} %")
    ax.set_xticks(idx)
    ax.set_xticklabels(ms.names, rotation=90, fontsize=6)
    ax.set_xlabel("row (signal)")
    ax.set_ylabel("non-zero coefficients (%)")
    ax.set_title(f"Coefficients kept to retain {100 * retain:g} % of the energy")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    return _save(fig, path)


def clusters(ms: Multisignal, labels: Sequence[int] | np.ndarray, title: str, path: Path) -> Path:
    """Figure 35: the rows of each cluster."""
    codes = np.asarray(labels)
    k = int(codes.max()) + 1
    fig, axes = plt.subplots(k, 1, figsize=(10, 2.4 * k + 0.6), sharex=True, sharey=True, squeeze=False)
    for c in range(k):
        idx = np.nonzero(codes == c)[0]
        ax = axes[c, 0]
        _plot_rows(ax, ms.time_s, ms.data[idx], [ms.labels[i] for i in idx], ms.classes)
        ax.set_title(f"cluster {c + 1}: {len(idx)} rows", fontsize=9)
        ax.set_ylabel(_ylabel(ms))
    axes[-1, 0].set_xlabel("time (s)")
    fig.suptitle(title, fontsize=10)
    return _save(fig, path)


def partition(classes: Sequence[str], table: np.ndarray, title: str, path: Path) -> Path:
    """Figure 36: how many rows of each class fall in each cluster."""
    table = np.asarray(table)
    fig, ax = plt.subplots(figsize=(7, 3.8))
    bottom = np.zeros(table.shape[0])
    x = np.arange(table.shape[0])
    for j, cls in enumerate(classes):
        ax.bar(x, table[:, j], bottom=bottom, color=colour(cls, classes), label=cls)
        bottom += table[:, j]
    ax.set_xticks(x)
    ax.set_xticklabels([f"cluster {c + 1}" for c in x])
    ax.set_xlabel("cluster (number)")
    ax.set_ylabel("rows (count)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    return _save(fig, path)


def dendrogram(z: np.ndarray, names: Sequence[str], title: str, path: Path) -> Path:
    from scipy.cluster.hierarchy import dendrogram as scipy_dendrogram

    fig, ax = plt.subplots(figsize=(10, 4.2))
    scipy_dendrogram(z, labels=list(names), ax=ax, leaf_font_size=6, color_threshold=0.7 * np.max(z[:, 2]))
    ax.set_xlabel("row (signal)")
    ax.set_ylabel("Ward linkage distance (feature units)")
    ax.set_title(title, fontsize=9)
    return _save(fig, path)


def severity(sev: dict[str, Any], level: int, unit: str, path: Path) -> Path:
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, d in sev.items():
        ax.plot(d["factors"], d["res_a_rms"], "o-", color=colour(label), label=f"{label} (Spearman {d['spearman']:.2f})")
    ax.set_xlabel("severity factor (x the paper's fault size) (1)")
    ax.set_ylabel(f"RMS of Res{level}A ({unit})")
    ax.set_yscale("log")
    ax.set_title(f"Level-{level} approximation residual against the same-noise healthy row")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return _save(fig, path)


# ---- Section 7 -----------------------------------------------------------------------------------
def _onset(ax, onset_s: float | None) -> None:
    if onset_s is not None:
        ax.axvline(onset_s, color="tab:red", ls=":", lw=1.2, label="fault onset")


def healthy_and_faulty(pair: Any, unit: str, path: Path) -> Path:
    """Figures 40, 41 (runs) and 42, 43 (output residual)."""
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    axes[0].plot(pair.time_s, pair.healthy, color="tab:green", lw=0.6, label="healthy")
    axes[0].plot(pair.time_s, pair.faulty, color=colour(pair.fault), lw=0.6, label=pair.fault)
    _onset(axes[0], pair.onset_s)
    axes[0].set_ylabel(f"{pair.signal.replace('_', ' ')} ({unit})")
    axes[0].set_title(f"Healthy and faulty runs: {pair.fault}")
    axes[0].legend(fontsize=8)
    axes[1].plot(pair.time_s, pair.faulty - pair.healthy, color="k", lw=0.6)
    _onset(axes[1], pair.onset_s)
    axes[1].set_ylabel(f"residual faulty - healthy ({unit})")
    axes[1].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    return _save(fig, path)


def reconstruction(pair: Any, wavelet: str, unit: str, path: Path) -> Path:
    """Figures 49, 56: the faulty signal and its reconstruction from the level-3 coefficients."""
    rs = pair.twin[wavelet]
    coeffs = [rs.faulty[f"A{rs.level}"]] + [rs.faulty[f"D{j}"] for j in range(rs.level, 0, -1)]
    rec = pywt.waverec(coeffs, rs.wavelet, mode=rs.mode)[: len(pair.faulty)]
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), sharex=True)
    axes[0].plot(pair.time_s, pair.faulty, color=colour(pair.fault), lw=0.6)
    axes[0].set_title(f"Faulty signal ({pair.fault})")
    axes[1].plot(pair.time_s, rec, color="k", lw=0.6)
    axes[1].set_title(f"Reconstructed from its level-{rs.level} {rs.wavelet} coefficients")
    axes[2].plot(pair.time_s, rec - pair.faulty, color="k", lw=0.6)
    axes[2].set_title(f"Reconstruction error (largest {rs.reconstruction_error:.1e} {unit})")
    for ax in axes[:2]:
        ax.set_ylabel(f"pH signal ({unit})")
    axes[2].set_ylabel(f"error ({unit})")
    axes[2].set_xlabel("time (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    return _save(fig, path)


def band_panels(rs: Any, which: str, title: str, unit: str, path: Path, onset_s: float | None = None,
                thresholds: dict[str, float] | None = None, window: int = 1,
                alarms: dict[str, float | None] | None = None) -> Path:
    """Figures 50, 51, 57 (coefficients D1, D2, D3, A3) and 52-55, 58-61 (their residuals).

    With ``thresholds`` the detector's statistic (trailing RMS over ``window``
    coefficients) is drawn over the residual, with its threshold and first alarm.
    """

    data = getattr(rs, which)
    bands = [f"D{j}" for j in range(1, rs.level + 1)] + [f"A{rs.level}"]
    fig, axes = plt.subplots(len(bands), 1, figsize=(10, 2.1 * len(bands) + 0.6), sharex=True)
    for ax, b in zip(axes, bands):
        ax.plot(rs.times_s[b], data[b], color="0.55" if thresholds else "k", lw=0.5,
                label="residual" if thresholds else None)
        _onset(ax, onset_s)
        if thresholds is not None:
            stat = np.abs(data[b]) if window <= 1 else moving_rms(data[b], window)
            ax.plot(rs.available_s[b], stat, color="tab:blue", lw=0.8, label=f"trailing RMS ({window} coefficients)")
            ax.axhline(thresholds[b], color="tab:orange", ls="--", lw=1, label="alarm threshold")
            if alarms and alarms.get(b) is not None:
                ax.axvline(alarms[b], color="tab:orange", lw=1.5, label="first alarm")
            ax.legend(fontsize=6, loc="upper left")
        name = f"Res{b[1:]}{b[0]}" if which == "residual" else b
        ax.set_ylabel(f"{name} ({unit})")
        ax.grid(alpha=0.3)
    axes[0].set_title(title, fontsize=10)
    axes[-1].set_xlabel("time (s)")
    return _save(fig, path)


def change_points(pair: Any, unit: str, path: Path) -> Path:
    """The faulty signal with the variance change points of each input marked."""
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(pair.time_s, pair.faulty, color=colour(pair.fault), lw=0.5, label=f"{pair.fault} run")
    _onset(ax, pair.onset_s)
    styles = ["tab:blue", "tab:purple", "k"]
    for cp, c in zip(pair.change_points, styles):
        for i, t in enumerate(cp.faulty_s):
            ax.axvline(t, color=c, ls="--", lw=1, label=cp.input if i == 0 else None)
    ax.set_xlabel("time (s)")
    ax.set_ylabel(f"{pair.signal.replace('_', ' ')} ({unit})")
    ax.set_title("Variance change points (wvarchg) found in each input")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return _save(fig, path)
