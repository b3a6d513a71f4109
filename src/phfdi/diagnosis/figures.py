"""Figures of a diagnosis: measured vs simulated, the residual's scalogram, the candidate ranking."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pywt  # noqa: E402

from phfdi_base.outputs import save_figure
from phfdi_base.signals import label  # noqa: E402

from .data import Record  # noqa: E402
from .model import Prediction  # noqa: E402

CWT_WAVELET = "cmor1.5-1.0"


def _shade(ax, time_s: np.ndarray, val: np.ndarray) -> None:
    """Grey spans over the held-out samples."""
    edges = np.diff(np.concatenate([[0], val.astype(int), [0]]))
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]):
        ax.axvspan(time_s[a], time_s[b - 1], color="0.92", zorder=0)


def plot_fit(rec: Record, nominal: Prediction, extended: Prediction | None, val: np.ndarray, path: Path,
             cause: str | None = None) -> Path:
    """Each measured output with the nominal (and extended) simulation, and the residuals."""
    outs = [o for o in ("ph_measured", "level_measured_cm") if o in rec.outputs]
    fig, axes = plt.subplots(2 * len(outs), 1, figsize=(11, 3.2 * len(outs) + 1.5), sharex=True,
                             gridspec_kw={"height_ratios": [2, 1] * len(outs)})
    t = rec.time_s
    for i, o in enumerate(outs):
        ax, axr = axes[2 * i], axes[2 * i + 1]
        _shade(ax, t, val)
        _shade(axr, t, val)
        ax.plot(t, rec.outputs[o], color="0.55", lw=0.7, label="measured")
        ax.plot(t, nominal.outputs[o], color="tab:red", lw=1.0, label="nominal model")
        axr.plot(t, rec.outputs[o] - nominal.outputs[o], color="tab:red", lw=0.7, label="nominal")
        if extended is not None:
            ax.plot(t, extended.outputs[o], color="tab:blue", lw=1.0, ls="--", label=f"extended ({cause})")
            axr.plot(t, rec.outputs[o] - extended.outputs[o], color="tab:blue", lw=0.7, label="extended")
        ax.set_ylabel(label(o))
        axr.set_ylabel(f"residual\n{label(o)}")
        axr.axhline(0.0, color="k", lw=0.5)
        ax.legend(loc="upper right", fontsize=8)
        axr.legend(loc="upper right", fontsize=8)
        ax.grid(alpha=0.3)
        axr.grid(alpha=0.3)
    axes[0].set_title(f"{rec.name}: measured vs simulated (grey: held-out samples)", fontsize=10)
    axes[-1].set_xlabel("time (s)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_scalogram(rec: Record, residual: np.ndarray, output: str, path: Path, title: str) -> Path:
    """|continuous wavelet transform| of a residual over time and period (complex Morlet, PyWavelets)."""
    dt = rec.dt_s
    n = len(residual)
    # periods from 4 samples to a quarter of the record, log-spaced
    periods = np.geomspace(4 * dt, max(8 * dt, n * dt / 4), 48)
    centre = pywt.central_frequency(CWT_WAVELET)
    scales = centre * periods / dt
    step = max(1, n // 4000)  # the scalogram of a long record at a coarser time step
    x = residual[::step]
    coef, _ = pywt.cwt(x - np.mean(x), scales / step, CWT_WAVELET, sampling_period=dt * step, method="fft")
    power = np.abs(coef)
    fig, (ax0, ax) = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [1, 2.2]})
    ax0.plot(rec.time_s, residual, color="tab:red", lw=0.6)
    ax0.set_ylabel(f"residual\n{label(output)}")
    ax0.grid(alpha=0.3)
    ax0.set_title(title, fontsize=10)
    t = rec.time_s[::step]
    mesh = ax.pcolormesh(t, periods, power, shading="auto", cmap="viridis")
    ax.set_yscale("log")
    ax.set_ylabel("period (s)")
    ax.set_xlabel("time (s)")
    cbar = fig.colorbar(mesh, ax=[ax0, ax], shrink=0.9, pad=0.01)
    cbar.set_label(f"|W| ({label(output).split('(')[-1].rstrip(')')})")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_ranking(report: dict, path: Path) -> Path:
    """Held-out error of every candidate (in multiples of the noise floor) against the nominal model's."""
    rows = report["ranking"] + report.get("pairs", [])[:3]
    rows = sorted(rows, key=lambda r: r["validation_rmse_over_noise"])
    names = [r["cause"] for r in rows]
    vals = [r["validation_rmse_over_noise"] for r in rows]
    nominal = report["nominal"]["combined_rmse_over_noise"]
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(rows) + 1.8))
    colours = {"actuator": "tab:orange", "sensor": "tab:green", "process": "tab:purple"}
    ax.barh(range(len(rows)), vals, color=[colours.get(r["family"].split("+")[0], "0.5") for r in rows])
    ax.axvline(nominal, color="tab:red", lw=1.2, label=f"nominal model ({nominal:.3g})")
    ax.axvline(report["thresholds"]["explained_ratio"], color="k", ls="--", lw=1.0,
               label=f"explained (noise floor x {report['thresholds']['explained_ratio']:g})")
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xscale("log" if max(vals + [nominal]) / max(min(vals), 1e-9) > 30 else "linear")
    ax.set_xlabel("held-out RMS error / noise floor (1)")
    ax.set_title("Candidates ranked by held-out error (orange actuator, green sensor, purple process)", fontsize=10)
    ax.legend(fontsize=8, loc="lower right")
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
