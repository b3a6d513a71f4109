"""The extended model written by `phfdi diagnose` as the detector's reference: `phfdi replay --reference MODEL.yaml`.

A process effect (drawn at random; the diagnosis does not see which) is hidden in a short closed-loop record;
the diagnosis extends the model; a second record of the same plant (other noise, other setpoint steps) is
replayed through the physics-reference detector with the nominal model and with the extended one.
"""

import copy
import json

import numpy as np

from .hidden_cases import fresh_draws, make_case

DURATION_S = 1200.0  # the detector's 600 s warm-up, then 600 s watched
#: effects of the process and the valve's size: what a healthy reference models (fault blocks it does not)
OTHER_RECORDS = 3  # fresh records of the same plant each reference is judged on
PROCESS_CAUSES = ("buffer", "reagent_concentration", "holdup", "valve_gain")


def _alarms(run_cli, *argv) -> list:
    status, out, err = run_cli("replay", *map(str, argv), "--json", "--no-isolation")
    assert status == 0, err
    return json.loads(out)["alarms"]


@fresh_draws
def test_extended_model_as_reference_removes_the_false_alarms(hidden_rng, diagnose_json, run_cli, tmp_path):
    """Judged over OTHER_RECORDS fresh records, not one: on a weak draw (a buffer with pKa near 11, above most of
    the operating range) the nominal reference raises one alarm on a record and the detector's own false-alarm
    chance (the exact truth as reference raises none on the same records) can match it. One record made the test
    fail 3 times in 124 seeds; the sum over three records is the claim a user cares about (fewer alarms per hour).
    Up to three drawn effects, as every hidden-effect test (hidden_cases.fresh_draws): a weak buffer near pKa 11 can
    still be fitted off its pKa-amount valley with intervals that exclude the truth (seed 1569714666, 1 in 6 seeds
    on 2026-12-06: pKa 10.72 [10.7, 10.8] for 10.35), and its extended model then misses another operation of the
    plant; three draws all failing by chance is below 1 in 1000 at a per-draw rate under 10 %."""
    cause = str(hidden_rng.choice(PROCESS_CAUSES))
    again = copy.deepcopy(hidden_rng)
    case = make_case(hidden_rng, cause, "closed", tmp_path / "fit", DURATION_S)
    rep = diagnose_json("--data", case.path, "--model", "paper", "--out", tmp_path / "report")
    # an extended model is written when the winning candidate counts (significant held-out gain); whether the
    # residual is also white ("explained") is the diagnosis tests' business, not the reference's
    assert rep.get("extended_model"), f"{cause}: {rep['verdict']}: {rep['reason']}"
    model = tmp_path / "report" / "extended_model.yaml"
    assert str(model) == rep["extended_model"]
    nominal, extended = [], []
    for k in range(OTHER_RECORDS):
        draw = copy.deepcopy(again)  # the same effect's parameters; noise and setpoints from hidden_rng
        other = make_case(draw, cause, "closed", tmp_path / f"other{k}", DURATION_S, fresh=hidden_rng)
        assert other.params == case.params and other.path.read_text() != case.path.read_text()
        nominal.append(len(_alarms(run_cli, other.path)))
        extended.append(len(_alarms(run_cli, other.path, "--reference", model)))
    assert sum(nominal), f"{cause} {case.params}: the nominal reference should call the unmodelled plant a fault"
    assert sum(extended) < sum(nominal), f"{cause} {case.params}: alarms nominal {nominal}, extended {extended}"


def test_model_reference_bad_uses_are_one_line(run_cli, tmp_path):
    rec = make_case(np.random.default_rng(0), "none", "closed", tmp_path / "d", 200.0).path
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nplant: [1, 2\n")
    good = tmp_path / "good.yml"
    good.write_text("extends: paper\nname: paper-copy\n")
    for argv, words in ((["replay", rec, "--reference", bad], str(bad)),
                        (["replay", rec, "--reference", tmp_path / "none.yaml"], "none.yaml"),
                        (["replay", rec, "--reference", "paper.yaml", "--scenario", "paper"], "not both"),
                        (["replay", "x.mcap", "--live", "--reference", "m.yml"], "offline"),
                        (["replay", rec, "--reference", good, "--refit-rows", "10"], "learned")):
        status, out, err = run_cli(*map(str, argv))
        assert status == 2 and words in err and len(err.strip().splitlines()) == 1, (argv, err)
        assert "Traceback" not in err


def test_a_models_fault_blocks_are_named_not_modelled(run_cli, tmp_path):
    rec = make_case(np.random.default_rng(1), "none", "closed", tmp_path / "d", DURATION_S).path
    model = tmp_path / "m.yaml"
    model.write_text("extends: paper\nname: paper-extended-stiction\n"
                     "faults: [{type: stiction, params: {s_pct: 3.0, j_pct: 1.0}}]\n"
                     "sensors: {ph: {noise_std: 0.01, extra: [{type: sensor_bias, params: {bias: 0.3}}]}}\n")
    status, out, err = run_cli("replay", rec, "--reference", model, "--json", "--no-isolation")
    assert status == 0, err
    assert "sensor effects (stiction, ph sensor sensor_bias) are not part of the healthy reference" in err
    assert json.loads(out)["alarms"] == []  # a healthy record: the reference ignored the stiction and the bias
