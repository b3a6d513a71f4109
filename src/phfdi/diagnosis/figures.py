"""Figures of a diagnosis: measured vs simulated, the residual's scalogram, the candidate ranking."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pywt  # noqa: E402

from phfdi.records import Record  # noqa: E402
from phfdi_base.outputs import save_figure
from phfdi_base.signals import label, unit_of  # noqa: E402

from .model import Prediction  # noqa: E402

CWT_WAVELET = "cmor1.5-1.0"


def _shade(ax, time_s: np.ndarray, val: np.ndarray) -> None:
    """Grey spans over the held-out samples."""
    edges = np.diff(np.concatenate([[0], val.astype(int), [0]]))
    for a, b in zip(np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]):
        ax.axvspan(time_s[a], time_s[b - 1], color="0.92", zorder=0)


def _cause_text(cause: str | None) -> str:
    """A cause's catalogue name as words: 'sensor_gain+holdup' -> 'sensor gain + holdup'."""
    return (cause or "none").replace("+", " + ").replace("_", " ")


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
            ax.plot(t, extended.outputs[o], color="tab:blue", lw=1.0, ls="--", label=f"extended ({_cause_text(cause)})")
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


def cone_of_influence(time_s: np.ndarray, wavelet: str = CWT_WAVELET) -> np.ndarray:
    """The longest period (s) not reached by the record's edges at each time: the cone of influence.

    A complex Morlet ``cmorB-C`` at scale s has the envelope exp(-(t/s)^2 / B), so the power an edge leaks
    in falls by e^-2 (Torrence and Compo's e-folding time) sqrt(B) s away; at period P (s = C P) that is
    sqrt(B) C P. A period is inside the cone where both edges are farther than that.

    >>> cone_of_influence(np.arange(0.0, 5.0), "cmor1.0-1.0").tolist()
    [0.0, 1.0, 2.0, 1.0, 0.0]
    """
    w = pywt.ContinuousWavelet(wavelet)
    e_folding_per_period = np.sqrt(w.bandwidth_frequency) * w.center_frequency
    to_edge = np.minimum(time_s - time_s[0], time_s[-1] - time_s)
    return to_edge / e_folding_per_period


def _cwt_amplitude(x: np.ndarray, periods: np.ndarray, dt: float) -> np.ndarray:
    """|CWT| rescaled to the amplitude of a sine at that period (pH for a pH residual): pywt's coefficient of
    A sin(2 pi t / P) at P is about A sqrt(scale) / 2 with its L2-normalised cmor."""
    scales = pywt.central_frequency(CWT_WAVELET) * periods / dt
    coef, _ = pywt.cwt(x - np.mean(x), scales, CWT_WAVELET, sampling_period=dt, method="fft")
    return 2.0 * np.abs(coef) / np.sqrt(scales)[:, None]


def plot_scalogram(rec: Record, residual: np.ndarray, output: str, path: Path, title: str) -> Path:
    """The residual's oscillations over time and period (complex Morlet CWT, PyWavelets) as sine amplitudes,
    the record's edges' cone of influence hatched and the colour scale set by what lies inside it."""
    dt = rec.dt_s
    n = len(residual)
    # periods from 4 samples to a quarter of the record, log-spaced
    periods = np.geomspace(4 * dt, max(8 * dt, n * dt / 4), 48)
    step = max(1, n // 4000)  # the scalogram of a long record at a coarser time step
    amplitude = _cwt_amplitude(residual[::step], periods, dt * step)
    t = rec.time_s[::step]
    coi = cone_of_influence(t)
    inside = periods[:, None] <= coi[None, :]
    vmax = float(np.max(amplitude[inside])) if inside.any() else float(np.max(amplitude))
    fig, (ax0, ax) = plt.subplots(2, 1, figsize=(11, 6), sharex=True, gridspec_kw={"height_ratios": [1, 2.2]})
    ax0.plot(rec.time_s, residual, color="tab:red", lw=0.6)
    ax0.set_ylabel(f"residual\n{label(output)}")
    ax0.grid(alpha=0.3)
    ax0.set_title(title, fontsize=10)
    mesh = ax.pcolormesh(t, periods, amplitude, shading="auto", cmap="viridis", vmin=0.0, vmax=vmax)
    ax.fill_between(t, np.clip(coi, periods[0], periods[-1]), periods[-1], facecolor="white", alpha=0.45,
                    hatch="xx", edgecolor="0.4", lw=0.0, label="cone of influence: edge effects")
    ax.plot(t, np.clip(coi, periods[0], periods[-1]), color="w", lw=1.0)
    ax.set_yscale("log")
    ax.set_ylim(periods[0], periods[-1])
    ax.set_ylabel("period (s)")
    ax.set_xlabel("time (s)")
    ax.legend(loc="lower right", fontsize=8, framealpha=0.9)
    cbar = fig.colorbar(mesh, ax=[ax0, ax], shrink=0.9, pad=0.01, extend="max" if vmax < amplitude.max() else "neither")
    cbar.set_label(f"amplitude at that period ({unit_of(output)})\nscale from inside the cone")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path


def plot_ranking(report: dict, path: Path) -> Path:
    """Held-out error of every candidate (in multiples of the noise floor) against the nominal model's."""
    rows = report["ranking"] + report.get("pairs", [])[:3]
    rows = sorted(rows, key=lambda r: r["validation_rmse_over_noise"])
    names = [_cause_text(r["cause"]) for r in rows]
    vals = [r["validation_rmse_over_noise"] for r in rows]
    nominal = report["nominal"]["combined_rmse_over_noise"]
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(rows) + 2.4), layout="constrained")
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
    ax.set_ylabel("candidate cause (colour: its family)")
    ax.set_title("Candidates ranked by held-out error (orange actuator, green sensor, purple process)", fontsize=10)
    fig.legend(fontsize=8, loc="outside lower center", ncol=2)  # under the axes: the longest bars end at the right
    ax.grid(alpha=0.3, axis="x")
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
