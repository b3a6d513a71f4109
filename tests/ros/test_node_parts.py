"""A node's part of the scenario: what the launcher writes is what a node reads, without the schema library.

The launcher validates the scenario once (pydantic); a launched node reads it back as attribute views
(``read_part(..., validate=False)``) and builds its part from them with the same core factories. These tests
require the views to read exactly as the validated models and the detector's reference, given the launcher's
starting point, to start where it would have solved itself.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from phfdi.ros.parts import make_part
from phfdi_base.errors import UserError
from phfdi_base.parts import MODEL_KEY, SpecView, read_part, write_part
from phfdi_base.ros.env import DISCOVERY_PROFILE, graph_env
from phfdi_base.spec import ScenarioSpec

SCENARIOS = [("paper", "backlash"), ("paper", "stiction"), ("paper", None)]


@pytest.fixture(scope="module", params=SCENARIOS, ids=lambda p: f"{p[0]}-{p[1]}")
def written(request, tmp_path_factory):
    scenario, fault = request.param
    part = make_part(scenario, fault, ["duration_s=600", "setpoints.ph.changes.0.at_s=200"], 300.0)
    path = write_part(tmp_path_factory.mktemp("part") / "part.json", part)
    return part, path


def test_the_views_read_as_the_validated_models(written):
    part, path = written
    view = read_part(path, validate=False)
    assert isinstance(view.scenario, SpecView) and isinstance(view.plant_model, SpecView)
    assert view.scenario.model_dump() == part.scenario.model_dump(mode="json")
    assert view.plant_model.model_dump() == part.plant_model.model_dump(mode="json")
    assert view.start == part.start
    # what the cores read, attribute by attribute
    assert view.scenario.valves.ph.feed == part.scenario.valves.ph.feed
    assert [f.params for f in view.scenario.faults] == [f.params for f in part.scenario.faults]
    assert view.scenario.setpoints.ph.changes[0].at_s == part.scenario.setpoints.ph.changes[0].at_s
    assert view.scenario.model_copy(update={"faults": []}).faults == [] and view.scenario.faults == (
        read_part(path, validate=False).scenario.faults)


def test_validating_read_gives_the_models_back(written):
    part, path = written
    again = read_part(path)
    assert isinstance(again.scenario, ScenarioSpec) and again.scenario == part.scenario
    assert again.plant_model == part.plant_model


def test_a_node_process_reads_its_part_without_pydantic_or_scipy(written):
    _, path = written
    probe = ("import sys, json; from phfdi_base.parts import read_part; "
             f"p = read_part({str(path)!r}, validate=False); "
             "from ph_plant_sim.build import build_plant, load_plant_model; build_plant(load_plant_model(p.plant_model)); "
             "from valve_actuator.build import build_valves; s = p.start; "
             "build_valves(p.scenario, s.valve_command_pct, s.outlet_command_pct); "
             "from pi_controllers.build import build_controllers; "
             "build_controllers(p.scenario, s.valve_command_pct, s.outlet_command_pct, s.ph, s.level_cm); "
             "print(json.dumps([m for m in ('pydantic', 'scipy') if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout) == []


def test_a_broken_or_unmarked_part_is_validated_or_refused(tmp_path, written):
    part, path = written
    data = json.loads(path.read_text())
    assert data["scenario"][MODEL_KEY] == "ScenarioSpec"
    unmarked = tmp_path / "unmarked.json"  # e.g. written by hand: validated whatever the reader asked
    unmarked.write_text(json.dumps(dict(data, scenario=part.scenario.model_dump(mode="json"))))
    assert isinstance(read_part(unmarked, validate=False).scenario, ScenarioSpec)
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"start": data["start"]}))
    with pytest.raises(UserError, match="not a node part"):
        read_part(broken, validate=False)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(dict(data, scenario=dict(part.scenario.model_dump(mode="json"), duration_s=-1))))
    with pytest.raises(UserError, match="duration_s"):
        read_part(bad, validate=False)


def test_the_detector_reference_starts_where_it_would_have_solved(written):
    from wavelet_fdi.reference import HealthyReference, KnownStart

    part, path = written
    view = read_part(path, validate=False)
    solved = HealthyReference(part.scenario)
    given = HealthyReference(view.scenario, KnownStart(view.start, view.plant_model))
    assert given.start == solved.start
    assert given.plant.ph == solved.plant.ph and given.plant.level_cm == solved.plant.level_cm


def test_graph_processes_get_the_discovery_profile_unless_one_is_set():
    assert graph_env(70, {})["FASTRTPS_DEFAULT_PROFILES_FILE"] == str(DISCOVERY_PROFILE)
    assert DISCOVERY_PROFILE.exists() and "initialAnnouncements" in DISCOVERY_PROFILE.read_text()
    own = graph_env(70, {"FASTDDS_DEFAULT_PROFILES_FILE": "/my/profile.xml"})
    assert "FASTRTPS_DEFAULT_PROFILES_FILE" not in own and own["FASTDDS_DEFAULT_PROFILES_FILE"] == "/my/profile.xml"
