"""Every figure a user looks at, rendered on small inputs and read back: each axes that shows data has an x and a
y label with its unit in brackets, the figure has a title, and no label, title, tick or legend shows a code name
(``ph.R.mean_down``, ``width_pct``). Beside those common rules, each figure's own fix is checked on what it
draws (issue 24: statistics not clipped, the command visible beside the stem, one panel per run, ...)."""

from __future__ import annotations

import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.figure  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import PolyCollection, QuadMesh  # noqa: E402
from matplotlib.image import AxesImage  # noqa: E402

#: snake_case words and dotted statistic names: what code calls a thing, not what an engineer does
CODE_NAME = re.compile(r"\b[a-z][a-z0-9]*_[a-z0-9_]+\b|\.[a-z]+_[a-z]+")
UNIT = re.compile(r"\(.+\)|\[.+\]")
SHORT_PAPER = ["duration_s=1600", "setpoints.ph.changes=[{at_s: 200, value: 8.0}]"]


@pytest.fixture
def rendered(monkeypatch) -> list[matplotlib.figure.Figure]:
    """The figures saved while the test runs (they are still readable after plt.close)."""
    figures: list[matplotlib.figure.Figure] = []
    original = matplotlib.figure.Figure.savefig

    def keep(self, *args, **kwargs):
        figures.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", keep)
    return figures


def _has_data(ax) -> bool:
    if not ax.axison:
        return False
    lines = any(len(np.atleast_1d(line.get_xdata())) > 1 for line in ax.get_lines())
    return lines or bool(ax.images) or any(isinstance(c, (PolyCollection, QuadMesh)) for c in ax.collections) \
        or len(ax.patches) > 2


def _label(ax, axis: str) -> str:
    """The axes' own label or, for panels sharing that axis (stacked in time, side by side in pH), the one
    a sibling carries."""
    own = ax.get_xlabel() if axis == "x" else ax.get_ylabel()
    shared = ax.get_shared_x_axes() if axis == "x" else ax.get_shared_y_axes()
    getter = "get_xlabel" if axis == "x" else "get_ylabel"
    return own or next((getattr(s, getter)() for s in shared.get_siblings(ax) if getattr(s, getter)()), "")


def _texts(fig) -> list[str]:
    out = [fig._suptitle.get_text()] if fig._suptitle is not None else []
    for legend in fig.legends:
        out += [t.get_text() for t in legend.get_texts()]
    for ax in fig.axes:
        out += [ax.get_xlabel(), ax.get_ylabel(), ax.get_title()]
        out += [t.get_text() for t in ax.get_xticklabels() + ax.get_yticklabels()]
        if ax.get_legend() is not None:
            out += [t.get_text() for t in ax.get_legend().get_texts()]
    return out


def problems(fig) -> list[str]:
    """Every breach of the common rules in one figure."""
    out = []
    titles = [fig._suptitle.get_text() if fig._suptitle is not None else ""] + [a.get_title() for a in fig.axes]
    if not any(titles):
        out.append("no title")
    for i, ax in enumerate(fig.axes):
        if hasattr(ax, "_colorbar"):
            if not UNIT.search(ax.get_ylabel() or ax.get_xlabel()):
                out.append(f"colour bar {i} has no unit: {ax.get_ylabel()!r}")
            continue
        if not _has_data(ax):
            continue
        for axis, text in (("x", _label(ax, "x")), ("y", _label(ax, "y"))):
            if not UNIT.search(text):
                out.append(f"axes {i} ({ax.get_title()!r}): {axis} label {text!r} without a unit in brackets")
    out += [f"code name in {t!r}" for t in _texts(fig) if CODE_NAME.search(t)]
    return out


def _check_all(figures) -> None:
    assert figures, "nothing was rendered"
    for fig in figures:
        assert problems(fig) == [], problems(fig)


def _ax_titled(fig, text: str):
    return next(ax for ax in fig.axes if text in ax.get_title())


# ---- the checker itself must catch what it is for ------------------------------------------------------------
def test_the_checker_finds_a_code_name_a_missing_unit_and_a_missing_title():
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1], label="ph.R.mean_down")
    ax.set_xlabel("time")
    ax.set_ylabel("pH (-)")
    ax.legend()
    found = problems(fig)
    plt.close(fig)
    assert any("no title" in p for p in found)
    assert any("x label 'time'" in p for p in found)
    assert any("code name in 'ph.R.mean_down'" in p for p in found)


# ---- phfdi demo: run.png and detection.png ------------------------------------------------------------------------
@pytest.fixture(scope="module")
def short_backlash():
    from phfdi.commands.demo import _offline
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    run = simulate(load_scenario("paper", fault="backlash", overrides=SHORT_PAPER, onset_s=1000.0))
    return run, _offline(run, record_trace=True)


def test_demo_figures(tmp_path, rendered, short_backlash):
    from phfdi.commands.demo import _figures

    run, det = short_backlash
    assert det.alarms, "the short backlash run must raise an alarm for the zoom"
    _figures(run, det, tmp_path)
    assert (tmp_path / "run.png").stat().st_size > 0 and (tmp_path / "detection.png").stat().st_size > 0
    _check_all(rendered)
    run_fig, det_fig = rendered
    zoom = _ax_titled(run_fig, "(zoom)")
    command, stem = zoom.get_lines()[:2]
    assert command.get_color() != stem.get_color() and command.get_linewidth() > stem.get_linewidth()
    gap = np.abs(np.asarray(command.get_ydata()) - np.asarray(stem.get_ydata()))
    assert gap.max() > 0.1  # the backlash dead band shows in the zoom (% of span)
    assert any("gap" in c.get_label() for c in zoom.collections)
    ratio_axes = [ax for ax in det_fig.axes if "threshold" in ax.get_ylabel()]
    assert len(ratio_axes) == 2
    for ax in ratio_axes:
        assert ax.get_yscale() == "log"
        top = ax.get_ylim()[1]
        assert all(np.nanmax(line.get_ydata()) <= top for line in ax.get_lines() if len(line.get_ydata()) > 2)
    legend = [t.get_text() for t in det_fig.legends[0].get_texts()]
    assert "pH residual: mean shift down" in " ".join(legend) and "alarm" in legend
    assert "fault onset (injected)" in legend
    assert all(ax.get_legend() is None for ax in det_fig.axes)  # one legend, under the panels


# ---- phfdi paper-runs: overview.png, overview_map.png ---------------------------------------------------------
def test_paper_runs_overview_is_one_panel_per_run_and_a_map(tmp_path, rendered):
    from phfdi.figures import plot_overview, plot_overview_map
    from phfdi.loop import simulate
    from phfdi.scenario import load_scenario

    faults = ["healthy", "backlash", "saturation"]
    runs = [simulate(load_scenario("paper", fault=f, overrides=SHORT_PAPER, onset_s=None if f == "healthy" else 0.0))
            for f in faults]
    plot_overview(runs, faults, tmp_path / "overview.png")
    plot_overview_map(runs, faults, tmp_path / "overview_map.png")
    _check_all(rendered)
    overview, pmap = rendered
    panels = [ax for ax in overview.axes if _has_data(ax)]
    assert len(panels) == len(runs)
    assert all(p.get_shared_y_axes().joined(panels[0], p) for p in panels)
    assert "backlash (width 0.7 % of span)" in " ".join(ax.get_title() for ax in panels)
    (image,) = [im for ax in pmap.axes for im in ax.images if isinstance(im, AxesImage)]
    rows = image.get_array()
    assert rows.shape[0] == len(runs)
    assert rows[2, -1] > 10 * rows[0, -1]  # the saturated run stays far from its setpoint, the healthy one not


# ---- phfdi evaluate: delays and coefficient residuals ----------------------------------------------------------
def _summary() -> dict:
    delay = {"wavelet": 23.0, "wavelet_bands": 43.0, "cusum": 22.0, "focus": None, "page_hinkley": 2600.0,
             "adwin": 25.0}
    rows = [{"fault": "backlash", "param": "width_pct", "value": v, "delay": dict(delay), "bound_s": 25.0}
            for v in (0.35, 0.7)]
    rows.append({"fault": "probe_noise", "param": "std", "value": 0.01, "delay": dict(delay), "bound_s": None})
    return {"rows": rows, "arl0_samples": 1e5}


def test_evaluation_figures(tmp_path, rendered):
    from phfdi.study.detector_figures import plot_coefficient_residuals, plot_delays
    from wavelet_fdi.reference_physics import design_settings

    plot_delays(_summary(), tmp_path / "delays.png")
    t = np.arange(2048.0)
    measured = 12.0 + 0.05 * np.sin(2 * np.pi * t / 64) * (t > 1024) + 0.01 * np.random.default_rng(1).normal(size=t.size)
    signals = {"time_s": t, "ph_measured": measured, "ph_predicted": np.full(t.size, 12.0)}
    plot_coefficient_residuals(signals, design_settings(), tmp_path / "coef.png", "Backlash at 1024 s", 1024.0)
    _check_all(rendered)
    delays, coef = rendered
    for ax in (a for a in delays.axes if _has_data(a)):
        top = ax.get_ylim()[1]
        assert all(bar.get_height() <= top for bar in ax.patches if np.isfinite(bar.get_height()))
        assert ax.get_legend() is None
        assert not any("times" in t.get_text() or "^" in t.get_text() for t in ax.get_yticklabels())
    assert "width 0.35 % of span" in [t.get_text() for t in delays.axes[0].get_xticklabels()]
    a3_measured = next(ax for ax in coef.axes if ax.get_ylabel().startswith("A3"))
    assert abs(np.median(a3_measured.get_lines()[0].get_ydata()) - 12.0) < 0.1  # in pH, not 2.83 x pH
    assert any(line.get_xdata()[0] == 1024.0 for line in a3_measured.get_lines()[1:])  # the onset marked


# ---- phfdi diagnose: scalogram (cone of influence), fit, ranking -----------------------------------------------
def test_scalogram_hatches_the_cone_and_scales_colour_from_inside_it(tmp_path, rendered):
    from phfdi.diagnosis import make_record
    from phfdi.diagnosis.figures import plot_scalogram

    t = np.arange(2000.0)
    sine = 0.2 * np.sin(2 * np.pi * t / 50.0)
    near_edge = sine + np.where(t >= 1970.0, 3.0, 0.0)  # a step 30 s from the end: its long periods reach the edge
    for name, residual in (("sine", sine), ("edge", near_edge)):
        rec = make_record({"time_s": t, "acid_flow_ml_s": np.full(t.size, 9.8), "ph_measured": 8.0 + residual}, name)
        plot_scalogram(rec, residual, "ph_measured", tmp_path / f"{name}.png", f"{name}: residual and its scalogram")
    _check_all(rendered)
    meshes = [next(c for ax in fig.axes if not hasattr(ax, "_colorbar") for c in ax.collections
                   if isinstance(c, QuadMesh)) for fig in rendered]
    assert 0.17 < meshes[0].get_clim()[1] < 0.23  # a 0.2 pH sine reads as 0.2 pH
    edge_max = float(np.max(meshes[1].get_array()))
    assert meshes[1].get_clim()[1] < 0.75 * edge_max  # what lies outside the cone does not set the scale
    for fig in rendered:
        assert any(c.get_hatch() for ax in fig.axes for c in ax.collections if isinstance(c, PolyCollection))


def test_fit_and_ranking(tmp_path, rendered):
    from phfdi.diagnosis import make_record
    from phfdi.diagnosis.figures import plot_fit, plot_ranking
    from phfdi.diagnosis.model import Prediction

    t = np.arange(200.0)
    rec = make_record({"time_s": t, "acid_flow_ml_s": np.full(t.size, 9.8), "ph_measured": 8.0 + 0.01 * np.sin(t)}, "rig")
    pred = Prediction({"ph_measured": np.full(t.size, 8.0)}, np.full(t.size, 8.0), np.zeros((t.size, 1)), ["acid"])
    plot_fit(rec, pred, pred, t > 150, tmp_path / "fit.png", "sensor_gain+holdup")
    report = {"ranking": [{"cause": "sensor_delay", "family": "sensor", "validation_rmse_over_noise": 1.0},
                          {"cause": "coulomb_viscous_friction", "family": "actuator", "validation_rmse_over_noise": 4.0}],
              "pairs": [{"cause": "sensor_gain+holdup", "family": "sensor+process", "validation_rmse_over_noise": 3.0}],
              "nominal": {"combined_rmse_over_noise": 12.0}, "thresholds": {"explained_ratio": 1.5}}
    plot_ranking(report, tmp_path / "ranking.png")
    _check_all(rendered)


# ---- phfdi loop-diagnose ---------------------------------------------------------------------------------------
def test_loop_figure(tmp_path, rendered):
    from phfdi.loopdiag import SyntheticLoop, diagnose_run, simulate_loop

    run = simulate_loop(SyntheticLoop(valve=("stiction", {"s_pct": 3.0, "j_pct": 1.0}), duration_s=3000.0))
    rep = diagnose_run(run, figure_dir=str(tmp_path))
    assert Path(rep["figure"]).is_file()
    _check_all(rendered)
    (fig,) = rendered
    assert fig._suptitle.get_text() == f"{rep['loop_tag']}: {rep['loop_verdict']['summary']}"
    assert any(ax.get_ylabel().startswith("PV (") for ax in fig.axes)
