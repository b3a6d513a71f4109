"""One figure per loop: PV against the linear and the extended model, OP against the stem position."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from phfdi.run import Run  # noqa: E402

from .diagnose import Evidence  # noqa: E402
from .identify import Split  # noqa: E402


def plot_loop(run: Run, ev: Evidence, rep: dict, out_dir: str | Path) -> Path:
    """Write ``<out_dir>/<file stem>.png`` and return its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    t_min = run.time_s / 60.0
    split = Split.of(len(run))
    fig, (ax_pv, ax_op) = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True, gridspec_kw={"height_ratios": [3, 2]})
    unit = (run.metadata.get("units") or {}).get("pv", "")
    ax_pv.plot(t_min, run["pv"], color="k", lw=0.7, label="PV measured")
    if "sp" in run:
        ax_pv.plot(t_min, run["sp"], color="0.5", ls="--", lw=0.8, label="SP")
    if ev.identifiable:
        nom = ev.nominal
        worse = ", worse than 'PV stays' (1.00)" if nom.nrmse_validation > 1.0 else ""
        ax_pv.plot(t_min, nom.y_model, color="tab:blue", lw=0.9,
                   label=f"linear {nom.structure} (held-out NRMSE {nom.nrmse_validation:.2f}{worse})")
        chosen = ev.chosen()
        if chosen is not None:
            ax_pv.plot(t_min, chosen.model.y_model, color="tab:red", lw=0.9,
                       label=f"with {chosen.cause} (held-out NRMSE {chosen.model.nrmse_validation:.2f})")
            ax_op.plot(t_min, chosen.position, color="tab:red", lw=0.9, label=f"stem position, {chosen.cause} model")
    for ax in (ax_pv, ax_op):
        ax.axvline(t_min[split.n_train], color="tab:green", ls=":", lw=1)
    ax_pv.text(t_min[split.n_train], ax_pv.get_ylim()[1], " held-out part", va="top", fontsize=8, color="tab:green")
    ax_op.plot(t_min, run["op_pct"], color="tab:green", lw=0.8, label="OP (controller output)")
    ax_pv.set_ylabel(f"PV ({unit})" if unit else "PV")
    ax_op.set_ylabel("OP, stem (% of span)")
    ax_op.set_xlabel("time (min)")
    ax_pv.legend(fontsize=8, loc="best")
    ax_op.legend(fontsize=8, loc="best")
    title = f"{rep['loop_tag']}: {rep['verdict']}"
    if rep["cause"] != "none":
        title += f", {rep['cause']}"
    ax_pv.set_title(title)
    fig.tight_layout()
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(str(rep.get("file") or "loop")).stem)
    path = out_dir / f"{stem}.png"
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
