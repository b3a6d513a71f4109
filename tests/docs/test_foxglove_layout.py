"""The shipped Foxglove layout (config/foxglove_layout.json) plots what the live view serves, nothing else.

Every message path of a panel names a channel of :mod:`phfdi_base.live_view` and a field of its schema, the
ratio plot has one series per statistic of the default detector and the line at 1, the alarm indicator has a
rule for every state, and every panel is placed.
"""

from __future__ import annotations

import json
from pathlib import Path

from phfdi_base import live_view
from wavelet_fdi.learned_detector import LearnedDetector, LearnedModel

LAYOUT = Path(__file__).resolve().parents[2] / "config" / "foxglove_layout.json"


def _layout() -> dict:
    return json.loads(LAYOUT.read_text())


def _paths(config: dict) -> list[str]:
    out = []
    for panel_id, panel in config.items():
        if panel_id.startswith("Plot!"):
            out += [p["value"] for p in panel["paths"]]
        elif panel_id.startswith("Indicator!"):
            out.append(panel["path"])
    return out


def _split(path: str) -> tuple[str, list[str]]:
    """'/detector/monitor.ratio.ph_R_mean_up' -> ('/detector/monitor', ['ratio', 'ph_R_mean_up'])."""
    topic = next(t for t in sorted(live_view.SCHEMAS, key=len, reverse=True) if path.startswith(t + "."))
    return topic, path[len(topic) + 1:].split(".")


def test_every_path_names_a_served_channel_and_a_field_of_its_schema():
    paths = _paths(_layout()["configById"])
    assert paths
    for path in paths:
        topic, fields = _split(path)
        props = live_view.SCHEMAS[topic]["properties"]
        assert fields[0] in props, path
        if len(fields) > 1:  # a key of the ratio object
            assert fields[0] == "ratio" and len(fields) == 2, path


def test_the_ratio_plot_has_every_default_statistic_and_the_line_at_one():
    plot = _layout()["configById"]["Plot!ratios"]
    values = {p["value"] for p in plot["paths"]}
    default = LearnedModel.load("paper_physics")  # the loop graph's default detector's reference
    keys = {live_view.statistic_key(n) for n in LearnedDetector(default).stat_names}
    assert values == {f"{live_view.MONITOR}.ratio.{k}" for k in keys} | {f"{live_view.MONITOR}.limit"}


def test_the_alarm_indicator_has_a_rule_for_every_state():
    rules = _layout()["configById"]["Indicator!alarm"]["rules"]
    assert {r["rawValue"] for r in rules} == set(live_view.ALARM_STATES.values())


def test_every_panel_is_placed_once():
    layout = _layout()
    placed: list[str] = []

    def walk(node) -> None:
        if isinstance(node, str):
            placed.append(node)
        else:
            walk(node["first"])
            walk(node["second"])

    walk(layout["layout"])
    assert sorted(placed) == sorted(layout["configById"])
