"""What no fitted model reproduces in a held-out pH record, in numbers.

Given the measured pH of a held-out record and the predictions of every model fitted without it (the nominal
model, each catalogue candidate, each step of the structure search, a black box), :func:`evidence` measures the
features a pH record is made of and how close the *best* of those models gets to each:

* **pH bands** of the measured pH (acidic < 5, transition 5..9, basic > 9): the share of the best model's squared
  error in each band, and the lowest RMSE any model reaches there (a band where even the best is far off holds a
  feature no candidate reproduces: in the transition band, the titration curve's shape);
* **timing**: each crossing of pH 7 by the measured pH against the nearest crossing in the same direction of the
  prediction (s; no crossing at all is reported as such), and the time shift of the prediction that lowers its RMSE
  most (within +-``max_shift_s``), with the RMSE after that shift: a large gain from shifting is a dead time or a
  holdup error, a small one means the error is in amplitude or shape;
* **shape**: how long each passage through pH 5..9 takes, measured and predicted: a measured passage much longer
  than the model's is a flatter titration curve, i.e. buffering the model lacks (a strong acid - strong base
  passes pH 5..9 with a few micromoles per litre);
* **amplitude**: the measured and predicted pH span (2nd..98th percentile) and, at the end of the record, the mean
  error over its last fifth (an offset or a drift the dynamics do not remove).

All on the scored samples only (those that set the record's start, or were adapted on, are excluded). The
functions are plain numpy; :func:`figure` draws the measured and best predictions and the RMSE per band.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from phfdi_base.outputs import save_figure

BANDS = (("acidic pH < 5", -np.inf, 5.0), ("transition pH 5-9", 5.0, 9.0), ("basic pH > 9", 9.0, np.inf))
MIN_BAND_SAMPLES = 10


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2))) if len(a) else math.nan


def crossings(t: np.ndarray, y: np.ndarray, level: float = 7.0, hysteresis: float = 0.5) -> list[tuple[float, int]]:
    """Times (s, linearly interpolated) and directions (+1 up, -1 down) at which ``y`` crosses ``level``; a
    crossing counts once ``y`` has been at least ``hysteresis`` beyond the level on the other side (the probe's
    ripple near the level does not make many)."""
    out: list[tuple[float, int]] = []
    side = 0  # -1 below level - hysteresis, +1 above level + hysteresis
    for k in range(len(y)):
        if y[k] > level + hysteresis:
            new = 1
        elif y[k] < level - hysteresis:
            new = -1
        else:
            continue
        if side != 0 and new != side:
            # the last sample on the old side of ``level`` before k: interpolate the crossing there
            j = k
            while j > 0 and (y[j - 1] - level) * new > 0:
                j -= 1
            j = max(j, 1)
            y0, y1 = y[j - 1], y[j]
            frac = 0.0 if y1 == y0 else (level - y0) / (y1 - y0)
            out.append((float(t[j - 1] + min(max(frac, 0.0), 1.0) * (t[j] - t[j - 1])), new))
        side = new
    return out


def passages(t: np.ndarray, y: np.ndarray, low: float = 5.0, high: float = 9.0) -> list[tuple[float, int]]:
    """Durations (s) and directions of complete passages through [low, high]: from the last sample beyond one
    edge to the first beyond the other (a visit that returns to the side it came from is not a passage)."""
    out: list[tuple[float, int]] = []
    last_side, t_left = 0, None
    for k in range(len(y)):
        side = -1 if y[k] < low else (1 if y[k] > high else 0)
        if side == 0:
            continue
        if last_side != 0 and side != last_side and t_left is not None:
            out.append((float(t[k] - t_left), side))
        last_side, t_left = side, float(t[k])
    return out


def best_shift(t: np.ndarray, y: np.ndarray, pred: np.ndarray, mask: np.ndarray, dt: float,
               max_shift_s: float = 60.0) -> tuple[float, float]:
    """The delay (s; positive: the prediction comes late, shift it earlier) that minimises the RMSE over the
    scored samples, and that RMSE."""
    n = int(round(max_shift_s / dt))
    best = (0.0, rmse(pred[mask], y[mask]))
    idx = np.flatnonzero(mask)
    for s in range(-n, n + 1):
        j = idx + s
        ok = (j >= 0) & (j < len(pred))
        if ok.sum() < 0.8 * len(idx):
            continue
        e = rmse(pred[j[ok]], y[idx[ok]])
        if e < best[1] - 1e-12:
            best = (s * dt, e)
    return best


@dataclass
class RunEvidence:
    run: str
    best_model: str
    best_nrmse: float
    band_share: dict[str, float]  # share of the best model's squared error in each band
    band_samples: dict[str, int]
    band_rmse_best_any: dict[str, tuple[str, float]]  # per band: the model with the lowest RMSE there, and it
    band_rmse: dict[str, dict[str, float]]  # model -> band -> RMSE (the models of the figure)
    crossings_measured: list[tuple[float, int]]
    crossing_error_s: dict[str, list[float | None]]  # model -> per measured crossing: predicted - measured (s)
    shift_s: float
    rmse_shifted: float
    rmse_best: float
    passages_measured: list[float]
    passages_model: dict[str, list[float]]
    span_measured: float
    span_model: dict[str, float]
    end_offset: dict[str, float]  # mean (predicted - measured) over the last fifth of the scored samples
    notes: list[str] = field(default_factory=list)


def evidence(fold: dict, figure_models: tuple[str, ...] = ("nominal", "structure", "black_box")) -> RunEvidence:
    """The features of one held-out record (a fold written by ``benchmarks/rig_holdout.py --predictions``)."""
    t = np.asarray(fold["time_s"], float)
    y = np.asarray(fold["measured"], float)
    mask = np.asarray(fold["scored"], bool)
    dt = float(fold["dt_s"])
    preds = {k: np.asarray(v, float) for k, v in fold["predictions"].items()}
    spread = float(np.std(y[mask])) or 1.0
    nrmse = {k: rmse(p[mask], y[mask]) / spread for k, p in preds.items()}
    best = min(nrmse, key=nrmse.get)
    pb = preds[best]
    err2 = (pb - y) ** 2
    total = float(np.sum(err2[mask])) or 1.0
    share, counts, best_any, by_model = {}, {}, {}, {m: {} for m in (*figure_models, best)}
    for name, lo, hi in BANDS:
        m = mask & (y >= lo) & (y < hi)
        counts[name] = int(m.sum())
        share[name] = float(np.sum(err2[m])) / total
        if m.sum() < MIN_BAND_SAMPLES:
            continue
        per = {k: rmse(p[m], y[m]) for k, p in preds.items()}
        k_best = min(per, key=per.get)
        best_any[name] = (k_best, per[k_best])
        for k in by_model:
            if k in preds:
                by_model[k][name] = per[k]
    ts, ys = t[mask], y[mask]
    cm = crossings(ts, ys)
    cross_err: dict[str, list] = {}
    for k, p in preds.items():
        cp = crossings(ts, p[mask])
        errs = []
        for tc, d in cm:
            same = [tp for tp, dp in cp if dp == d]
            errs.append(min((tp - tc for tp in same), key=abs) if same else None)
        cross_err[k] = errs
    shift, e_shift = best_shift(t, y, pb, mask, dt)
    pas = {k: [d for d, _ in passages(ts, p[mask])] for k, p in preds.items()}
    last = np.flatnonzero(mask)[-max(1, int(mask.sum()) // 5):]
    q = (2, 98)
    return RunEvidence(
        run=fold["run"], best_model=best, best_nrmse=nrmse[best], band_share=share, band_samples=counts,
        band_rmse_best_any=best_any, band_rmse=by_model, crossings_measured=cm, crossing_error_s=cross_err,
        shift_s=shift, rmse_shifted=e_shift, rmse_best=rmse(pb[mask], y[mask]),
        passages_measured=[d for d, _ in passages(ts, ys)], passages_model=pas,
        span_measured=float(np.diff(np.percentile(ys, q))[0]),
        span_model={k: float(np.diff(np.percentile(p[mask], q))[0]) for k, p in preds.items()},
        end_offset={k: float(np.mean(p[last] - y[last])) for k, p in preds.items()})


def best_crossing_error(ev: RunEvidence) -> tuple[str, float | None]:
    """The model whose pH-7 crossings come closest to the measured ones (mean |error| over the measured
    crossings; a model missing one is not eligible), and that mean."""
    best: tuple[str, float | None] = ("-", None)
    for k, errs in ev.crossing_error_s.items():
        if not errs or any(e is None for e in errs):
            continue
        m = float(np.mean(np.abs(errs)))
        if best[1] is None or m < best[1]:
            best = (k, m)
    return best


def _fmt(x: float | None, spec: str = ".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def table(evs: list[RunEvidence]) -> str:
    """Markdown: per held-out run, what the best fitted model (any of them) still misses."""
    lines = ["| held-out run | best model (held-out NRMSE) | its error share acidic / transition / basic | "
             "lowest RMSE any model reaches per band, pH (acidic / transition / basic) | pH-7 crossings: measured, "
             "closest model's mean timing error (s) | best shift of the best model (s): RMSE before -> after (pH) "
             "| passage pH 5-9 measured vs best model (s) | span p2-p98 measured vs best (pH) | end offset of "
             "the best (pH) |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for ev in evs:
        names = [b[0] for b in BANDS]
        shares = " / ".join(f"{100 * ev.band_share[n]:.0f} %" if ev.band_samples[n] else "-" for n in names)
        band_best = " / ".join(_fmt(ev.band_rmse_best_any[n][1]) if n in ev.band_rmse_best_any else "-"
                               for n in names)
        k, m = best_crossing_error(ev)
        n_cross = len(ev.crossings_measured)
        cross = f"{n_cross}" + (f", {_fmt(m, '.0f')} ({k})" if m is not None else
                                (", no model crosses at each" if n_cross else ""))
        pm = ev.passages_measured
        pb = ev.passages_model.get(ev.best_model, [])
        pas = (f"{_fmt(float(np.median(pm)), '.0f')} vs {_fmt(float(np.median(pb)), '.0f') if pb else 'none'}"
               if pm else "-")
        lines.append(
            f"| {ev.run} | {ev.best_model} ({ev.best_nrmse:.3f}) | {shares} | {band_best} | {cross} | "
            f"{ev.shift_s:+.0f}: {ev.rmse_best:.2f} -> {ev.rmse_shifted:.2f} | {pas} | "
            f"{ev.span_measured:.2f} vs {ev.span_model[ev.best_model]:.2f} | {ev.end_offset[ev.best_model]:+.2f} |")
    return "\n".join(lines)


def figure(folds: list[dict], evs: list[RunEvidence], path, models=("nominal", "structure", "black_box")) -> None:
    """Per held-out run: measured pH and the predictions (time, s); RMSE per pH band (pH) of each model and of
    the best model in that band."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(folds)
    fig, axes = plt.subplots(n, 2, figsize=(13, 2.9 * n), gridspec_kw={"width_ratios": [3, 1.3]}, squeeze=False)
    colours = {"nominal": "tab:gray", "structure": "tab:blue", "black_box": "tab:orange"}
    for row, (fold, ev) in enumerate(zip(folds, evs)):
        ax, bx = axes[row]
        t = np.asarray(fold["time_s"], float)
        mask = np.asarray(fold["scored"], bool)
        ax.plot(t, fold["measured"], "k", lw=1.2, label="measured")
        for k in models:
            if k in fold["predictions"]:
                ax.plot(t, fold["predictions"][k], color=colours.get(k), lw=1, label=k.replace("_", " "))
        if ev.best_model not in models:
            ax.plot(t, fold["predictions"][ev.best_model], "g--", lw=1, label=f"best: {ev.best_model}")
        ax.axvspan(t[0], t[np.argmax(mask)], color="0.9", label="not scored (sets the start)")
        ax.set_ylabel("pH")
        ax.set_xlabel("time since the record's start (s)")
        ax.set_title(f"held out: {ev.run}", fontsize=9)
        ax.set_ylim(1.5, 13)
        ax.legend(fontsize=7, ncol=3, loc="best")
        names = [b[0] for b in BANDS]
        x = np.arange(len(names))
        series = [(k, [ev.band_rmse.get(k, {}).get(nm, np.nan) for nm in names]) for k in models]
        series.append(("lowest of all models", [ev.band_rmse_best_any[nm][1] if nm in ev.band_rmse_best_any
                                                else np.nan for nm in names]))
        w = 0.8 / len(series)
        for j, (k, vals) in enumerate(series):
            bx.bar(x + (j - (len(series) - 1) / 2) * w, vals, w, color=colours.get(k, "tab:green"),
                   label=k.replace("_", " "))
        bx.set_xticks(x, [nm.replace(" pH", "\npH") for nm in names], fontsize=7)
        bx.set_ylabel("RMSE in band (pH)")
        bx.set_xlabel("measured pH band")
        if row == 0:
            bx.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)
    plt.close(fig)
