"""Hide an effect in simulated measurements; `phfdi diagnose` must find it from the data alone.

Each test draws its case at random (a fresh seed per run, printed, and
reproducible with PHFDI_HIDDEN_SEED): the effect from the catalogue within
the bounds of hidden_cases.BOUNDS, its parameters, closed- or open-loop
excitation, the noise. Only the data file (neutral name, historian columns,
no metadata) and the nominal model name reach the diagnosis, through the
command line.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from phfdi.diagnosis.extend import load_model_file
from phfdi.diagnosis.report import CAUSES, check_report
from phfdi.loop import simulate_open_loop
from phfdi.records import read_run
from phfdi.records.record import Record
from phfdi.scenario import load_scenario
from phfdi_base.spec import validate_scenario

from .hidden_cases import CATALOGUE_CAUSES, COLUMNS, fresh_draws, make_case

DURATION_S = 1700.0
PACKAGE = Path(__file__).resolve().parents[2] / "src" / "phfdi" / "diagnosis"


def _diagnose(diagnose_json, case, tmp_path) -> dict:
    rep = diagnose_json("--data", case.path, "--model", "paper", "--out", tmp_path / "report")
    check_report(rep)
    return rep


def _what(case) -> str:
    return f"hidden {case.cause} {case.params} ({case.excitation} loop)"


@pytest.mark.parametrize("draw", range(2))
@fresh_draws
def test_catalogue_effect_is_named_with_its_parameter(hidden_rng, diagnose_json, tmp_path, draw):
    cause = str(hidden_rng.choice(CATALOGUE_CAUSES))
    excitation = str(hidden_rng.choice(["closed", "open"]))
    case = make_case(hidden_rng, cause, excitation, tmp_path / "data", DURATION_S)
    rep = _diagnose(diagnose_json, case, tmp_path)
    assert rep["verdict"] == "explained", f"{_what(case)}: {rep['reason']}"
    assert rep["cause"] == cause, f"{_what(case)}: named {rep['cause']} ({rep['reason']})"
    assert rep["family"] == CAUSES[cause]
    fitted = rep["parameters"][case.main]
    assert abs(fitted - case.value) <= case.tolerance, \
        f"{_what(case)}: {case.main} = {fitted:.4g}, true {case.value:.4g} +- {case.tolerance:.3g}"
    assert rep["gain_percent"] > 0 and rep["nrmse_extended"] < rep["nrmse_nominal"]
    # the extended model is a scenario the simulator loads, and it is what was scored
    path = Path(rep["extended_model"])
    assert load_scenario(str(path)).name.startswith("paper-extended")
    assert rep["extended_model_check"]["ok"]
    # the named cause is the best-ranked one, or (the pipeline's parsimony rule) a candidate with fewer
    # parameters than the best that is not significantly worse on the held-out blocks
    top = rep["ranking"][0]
    named = next(r for r in rep["ranking"] if r["cause"] == cause)
    assert top["cause"] in rep["cause"].split("+") or rep["pairs"] or named["n_params"] < top["n_params"], \
        f"{_what(case)}: named {cause} ({named['n_params']} parameters) over {top['cause']} ({top['n_params']})"


@fresh_draws
def test_no_effect_comes_back_none(hidden_rng, diagnose_json, tmp_path):
    case = make_case(hidden_rng, "none", str(hidden_rng.choice(["closed", "open"])), tmp_path / "data", DURATION_S)
    rep = _diagnose(diagnose_json, case, tmp_path)
    assert rep["verdict"] == "none", f"{_what(case)}: {rep['verdict']} {rep['cause']}: {rep['reason']}"
    assert rep["cause"] == "none" and rep["family"] == "none"
    assert "extended_model" not in rep and not (tmp_path / "report" / "extended_model.yaml").exists()


@fresh_draws
def test_effect_outside_the_catalogue_is_not_explained(hidden_rng, diagnose_json, tmp_path):
    # The probe's alkaline error only under closed-loop excitation: the open-loop steps visit pH above 10 too
    # briefly, and a buffer with a probe gain error then reproduces it to the noise floor with a white error
    # (benchmarks/diagnose_hidden.py, docs/diagnosis.md): the data cannot tell them apart there.
    cause, excitation = [("alkaline_error", "closed"), ("periodic_flow", "closed"),
                         ("periodic_flow", "open")][hidden_rng.integers(3)]
    case = make_case(hidden_rng, cause, excitation, tmp_path / "data", DURATION_S)
    rep = _diagnose(diagnose_json, case, tmp_path)
    assert rep["verdict"] == "not_explained", f"{_what(case)}: {rep['verdict']} {rep['cause']}: {rep['reason']}"
    # the nearest family is the data's answer (a pH-dependent probe error is often closest to a buffer,
    # which bends the titration curve in one pH range), so it is only required to be named when some candidate
    # gets closer to the data than the nominal model (by more than 0.1 %: a fit that went back to the nominal
    # model is no cause). When none does (a periodic feed disturbance often: no catalogue entry moves the
    # held-out error), there is no nearest family and the honest answer is 'none'
    closer = [r for r in rep["ranking"] if r["gain_percent"] > 0.1]
    if closer:
        assert set(rep["family"].split("+")) <= {"actuator", "sensor", "process"}
    else:
        assert rep["family"] == "none" and "no catalogue candidate" in rep["reason"]
        assert rep["gain_percent"] is None and rep["nrmse_extended"] is None and "extended_model" not in rep
    # honest gain: the numbers it reports are what the nominal model scores on the held-out blocks,
    # recomputed here with the project's own open-loop simulation
    if closer:
        assert rep["gain_percent"] == pytest.approx(100 * (1 - rep["nrmse_extended"] / rep["nrmse_nominal"]),
                                                    rel=1e-9)
    data = read_run(case.path)
    inputs = Record.of({k: data[k] for k in ("time_s", "valve_command_pct", "level_controller_output_pct")})
    spec = load_scenario("paper", overrides=["sensors.ph.noise_std=0", "sensors.level.noise_std=0"])
    sim = simulate_open_loop(spec, inputs)
    held_out = (np.arange(len(data)) * 8 // len(data)) % 2 == 1
    e = data["ph_measured"][held_out] - sim["ph_measured"][held_out]
    nrmse = np.sqrt(np.mean(e ** 2)) / np.std(data["ph_measured"])
    assert rep["nrmse_nominal"] == pytest.approx(nrmse, rel=0.1)
    if rep.get("extended_model"):
        raw = load_model_file(rep["extended_model"])
        raw["sensors"]["ph"]["noise_std"] = raw["sensors"]["level"]["noise_std"] = 0.0
        # open loop needs no setpoint, but the loop's construction checks one: the data's starting pH
        raw["setpoints"]["ph"] = {"initial": 10.0}
        raw["min_actuator_margin_pct"] = 0.0
        ext = validate_scenario(raw)
        sim_ext = simulate_open_loop(ext, inputs)
        e_ext = data["ph_measured"][held_out] - sim_ext["ph_measured"][held_out]
        assert rep["nrmse_extended"] == pytest.approx(np.sqrt(np.mean(e_ext ** 2)) / np.std(data["ph_measured"]),
                                                      rel=0.25, abs=0.003)


@fresh_draws
def test_the_answer_cannot_reach_the_diagnosis(hidden_rng, tmp_path):
    """The data file holds historian columns only; the diagnosis code reads no run metadata nor test code."""
    case = make_case(hidden_rng, str(hidden_rng.choice(CATALOGUE_CAUSES)), "closed", tmp_path / "d", 600.0)
    header = case.path.read_text().splitlines()[0].split(",")
    assert header == COLUMNS and case.path.name == "record.csv"
    meta = read_run(case.path).metadata
    assert meta["source"] == str(case.path) and set(meta) <= {"source", "notes", "units", "encoding", "delimiter"}
    for src in PACKAGE.glob("*.py"):
        tree = ast.parse(src.read_text())
        names = {getattr(n, "module", None) or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert not any("hidden" in n or "tests" in n for n in names), src
        assert ".metadata" not in src.read_text(), f"{src.name} reads run metadata"
