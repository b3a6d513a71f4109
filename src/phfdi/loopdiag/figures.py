"""One figure per loop: time trends, the PV-OP and OP-dPV plots, and the fitted valve models over them.

* top: PV and SP against time with the linear model and the best valve model; OP with the stem
  position of the fitted Kano stiction model (and of the named valve model);
* bottom left: PV against OP with Choudhury's fitted ellipse (band-passed signals, shifted to the
  measured means) and the Kano model's PV against OP;
* bottom middle: PV's change per sample against OP (the valve-position proxy of Kano's method for
  a level loop's inflow, the jumps of a slipping valve), with the Kano model's;
* bottom right: the Kano block's stem position against OP (its stick-slip characteristic, S and J).
"""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from phfdi.records.record import Record  # noqa: E402
from phfdi_base.outputs import save_figure

from .bicoherence import ellipse_points  # noqa: E402
from .diagnose import Evidence  # noqa: E402
from .identify import Split  # noqa: E402


def _conic(rep: dict) -> np.ndarray | None:
    d = ((rep.get("indicators") or {}).get("ellipse_apparent_stiction") or {}).get("detail") or {}
    try:
        return np.array([d[f"conic_{k}"] for k in "abcdef"], float)
    except (KeyError, TypeError):
        return None


def plot_loop(run: Record, ev: Evidence, rep: dict, out_dir: str | Path) -> Path:
    """Write ``<out_dir>/<file stem>[_<loop tag>].png`` and return its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    op = run["op_pct"]
    unit, op_unit = _units(run)
    fig = plt.figure(figsize=(13, 9))
    gs = fig.add_gridspec(3, 3, height_ratios=[2.2, 1.4, 2.4])
    ax_pv = fig.add_subplot(gs[0, :])
    ax_op = fig.add_subplot(gs[1, :], sharex=ax_pv)
    ax_xy = fig.add_subplot(gs[2, 0])
    ax_dpv = fig.add_subplot(gs[2, 1])
    ax_stem = fig.add_subplot(gs[2, 2])
    kano = next((c for c in ev.causes if c.cause == "stiction"), None) if ev.identifiable else None
    _plot_trends(ax_pv, ax_op, run, ev, kano, unit, op_unit)
    _mark_slips(ax_pv, run, rep)
    _plot_pv_against_op(ax_xy, run, rep, kano, unit, op_unit)
    _plot_dpv_against_op(ax_dpv, run, kano, unit, op_unit)
    _plot_stem(ax_stem, op, kano, op_unit)
    fig.suptitle(_title(rep), fontsize=10)
    fig.tight_layout()
    path = out_dir / f"{_file_stem(rep)}.png"
    save_figure(fig, path, dpi=80)
    plt.close(fig)
    return path


def _plot_trends(ax_pv, ax_op, run: Record, ev: Evidence, kano, unit: str, op_unit: str) -> None:
    """PV and SP with the linear and valve models (top), OP with the models' stem positions (middle)."""
    t_min = run.time_s / 60.0
    ax_pv.plot(t_min, run["pv"], color="k", lw=0.7, label="PV measured")
    if "sp" in run:
        ax_pv.plot(t_min, run["sp"], color="0.5", ls="--", lw=0.8, label="SP")
    ax_op.plot(t_min, run["op_pct"], color="tab:green", lw=0.8, label="OP (controller output)")
    if ev.identifiable:
        nom = ev.nominal
        ax_pv.plot(t_min, nom.y_model, color="tab:blue", lw=0.8,
                   label=f"linear {nom.structure} (held-out NRMSE {nom.nrmse_validation:.2f})")
        chosen = ev.chosen()
        if chosen is not None and chosen is not kano:
            ax_pv.plot(t_min, chosen.model.y_model, color="tab:purple", lw=0.8,
                       label=f"with {chosen.cause} (held-out NRMSE {chosen.model.nrmse_validation:.2f})")
            ax_op.plot(t_min, chosen.position, color="tab:purple", lw=0.8, label=f"stem, {chosen.cause} model")
    if kano is not None:
        s, j = kano.parameters["s_pct"], kano.parameters["j_pct"]
        ax_pv.plot(t_min, kano.model.y_model, color="tab:red", lw=0.9,
                   label=f"with Kano stiction S {s:.2g}, J {j:.2g} (held-out NRMSE {kano.model.nrmse_validation:.2f})")
        ax_op.plot(t_min, kano.position, color="tab:red", lw=0.9, label="stem, Kano stiction model")
    split = Split.of(len(run))
    for ax in (ax_pv, ax_op):
        ax.axvline(t_min[split.n_train], color="tab:green", ls=":", lw=1)
    ax_pv.text(t_min[split.n_train], ax_pv.get_ylim()[1], " held-out part", va="top", fontsize=8, color="tab:green")
    ax_pv.set_ylabel(f"PV ({unit})")
    ax_pv.tick_params(labelbottom=False)  # the time axis is read under OP, the panel below
    ax_op.set_ylabel(f"OP, stem ({op_unit})")
    ax_op.set_xlabel("time (min)")
    ax_pv.legend(fontsize=7, loc="best")
    ax_op.legend(fontsize=7, loc="best")


def _mark_slips(ax, run: Record, rep: dict) -> None:
    """Triangles on PV where the stick-slip index found a slip ending a stuck section (its first 20)."""
    detail = ((rep.get("indicators") or {}).get("stick_slip") or {}).get("detail") or {}
    times = detail.get("slip_times_s") or []
    if not times:
        return
    t = run.time_s
    idx = np.clip(np.searchsorted(t - t[0], times), 0, len(t) - 1)
    ax.plot(t[idx] / 60.0, run["pv"][idx], "v", color="tab:orange", ms=6, ls="none",
            label=f"slip after a stuck section ({detail.get('slips', len(times))}, stick-slip index)")
    ax.legend(fontsize=7, loc="best")


def _plot_pv_against_op(ax, run: Record, rep: dict, kano, unit: str, op_unit: str) -> None:
    """PV against OP with Choudhury's fitted ellipse and the Kano model's PV."""
    op = run["op_pct"]
    ax.plot(op, run["pv"], color="0.35", lw=0.5, label="measured")
    coef = _conic(rep)
    if coef is not None:
        ex, ey = ellipse_points(coef)
        d = rep["indicators"]["ellipse_apparent_stiction"]["detail"]
        ax.plot(ex + d["op_mean"], ey + d["pv_mean"], color="tab:orange", lw=1.2,
                label=f"ellipse, apparent stiction {d['apparent_stiction_op']:.2g}")
    if kano is not None:
        ax.plot(op, kano.model.y_model, color="tab:red", lw=0.8, alpha=0.8, label="Kano model")
    ax.set_xlabel(f"OP ({op_unit})")
    ax.set_ylabel(f"PV ({unit})")
    ax.set_title("PV against OP", fontsize=9)
    ax.legend(fontsize=7, loc="best")


def _plot_dpv_against_op(ax, run: Record, kano, unit: str, op_unit: str) -> None:
    """PV's change per sample against OP, measured and from the Kano model."""
    op = run["op_pct"]
    ax.plot(op[1:], np.diff(run["pv"]), ".", color="0.35", ms=2, label="measured")
    if kano is not None:
        ax.plot(op[1:], np.diff(kano.model.y_model), ".", color="tab:red", ms=2, label="Kano model")
    ax.set_xlabel(f"OP ({op_unit})")
    ax.set_ylabel(f"PV change per sample ({unit})")
    ax.set_title("PV change against OP", fontsize=9)
    ax.legend(fontsize=7, loc="best")


def _plot_stem(ax, op: np.ndarray, kano, op_unit: str) -> None:
    """The Kano block's stem position against OP (its stick-slip characteristic)."""
    if kano is not None:
        s, j = kano.parameters["s_pct"], kano.parameters["j_pct"]
        ax.plot(op, kano.position, color="tab:red", lw=0.8)
        ax.set_title(f"Kano model: stem against OP (S {s:.2g}, J {j:.2g})", fontsize=9)
    else:
        ax.text(0.5, 0.5, "no valve model (OP hardly moves)", ha="center", va="center",
                transform=ax.transAxes, fontsize=9)
        ax.set_title("Kano model: stem against OP", fontsize=9)
    ax.set_xlabel(f"OP ({op_unit})")
    ax.set_ylabel(f"stem position ({op_unit})")


def _units(run: Record) -> tuple[str, str]:
    """PV's unit as the record gives it, else 'as recorded'; OP in % of span when it stays within 0-100."""
    op = run["op_pct"]
    unit = (run.metadata.get("units") or {}).get("pv", "") or "as recorded"
    op_unit = "% of span" if np.min(op) >= 0 and np.max(op) <= 100 else "as recorded"
    return unit, op_unit


def _title(rep: dict) -> str:
    """The loop's one verdict (the valve-model fit is in the legends, as evidence)."""
    verdict = rep.get("loop_verdict") or {}
    return f"{rep.get('loop_tag')}: {verdict.get('summary', 'no verdict')}"


def plot_record(run: Record, rep: dict, out_dir: str | Path) -> Path:
    """A record with no stiction score (PV frozen, not a closed loop): PV, SP and OP against time under
    its verdict. Written and returned as :func:`plot_loop`'s."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    op = run["op_pct"]
    unit, op_unit = _units(run)
    fig, (ax_pv, ax_op) = plt.subplots(2, 1, figsize=(13, 6), sharex=True, height_ratios=[2, 1.4])
    t_min = run.time_s / 60.0
    ax_pv.plot(t_min, run["pv"], color="k", lw=0.7, label="PV measured")
    if "sp" in run:
        ax_pv.plot(t_min, run["sp"], color="0.5", ls="--", lw=0.8, label="SP")
    ax_op.plot(t_min, op, color="tab:green", lw=0.8, label="OP (controller output)")
    ax_pv.set_ylabel(f"PV ({unit})")
    ax_op.set_ylabel(f"OP ({op_unit})")
    ax_op.set_xlabel("time (min)")
    ax_pv.legend(fontsize=7, loc="best")
    ax_op.legend(fontsize=7, loc="best")
    fig.suptitle(_title(rep), fontsize=10)
    fig.tight_layout()
    path = out_dir / f"{_file_stem(rep)}.png"
    save_figure(fig, path, dpi=80)
    plt.close(fig)
    return path


def _file_stem(rep: dict) -> str:
    """The loop's file stem, with its tag unless the stem holds it already (safe characters only)."""
    stem_name = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(str(rep.get("file") or "loop")).stem)
    tag = rep.get("loop_tag")
    if tag and tag not in stem_name:
        stem_name += "_" + re.sub(r"[^A-Za-z0-9_.-]+", "_", str(tag))
    return stem_name
