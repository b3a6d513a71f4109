"""Offline replay's reading side: a recorded run as the detector takes it, its scenario, and the physics reference
shipped for that scenario (the detector itself is ``wavelet_fdi.learned_detector``, one for every command)."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from phfdi.faults import base_scenario
from phfdi.records import ReadError, read_run
from phfdi.records.record import Record
from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from phfdi_base.spec import ScenarioSpec, validate_scenario


def scenario_of(run: Record, fallback: str = "paper") -> ScenarioSpec:
    """The run's own scenario (simulated runs carry it), faults removed by the detector; else a preset."""
    spec = run.metadata.get("spec") if isinstance(run.metadata, dict) else None
    if isinstance(spec, dict):
        return validate_scenario(spec, source="run metadata")
    return load_scenario(fallback, fault="healthy")


def load_any(path: str | Path, column_map=None, encoding: str | None = None) -> Record:
    """A run read by :func:`phfdi.records.read_run` (.csv, .parquet or an .mcap bag; repairs in
    ``metadata["notes"]``) that the detector can replay: it needs ph_measured and the pH controller output
    (valve_command_pct or ph_controller_output_pct), by name or through ``column_map``."""

    run = read_run(path, column_map, encoding=encoding, required=("ph_measured",))
    if not {"valve_command_pct", "ph_controller_output_pct"} & set(run.names):
        pumps = sorted(n for n in run.names if n.endswith("_flow_ml_s"))
        hint = (f"; this record has pump flows ({', '.join(pumps)}): fit the estimator reference on healthy runs "
                f"(phfdi calibrate --estimator RUN... --map MAP --out rig.json) and replay with --reference rig.json"
                if pumps else "")
        raise ReadError(path, "no valve command (valve_command_pct or ph_controller_output_pct): the detector "
                              "needs the pH controller output; map it with --column valve_command_pct=COLUMN" + hint,
                        line=1 if "delimiter" in run.metadata else None)  # a text file's header line
    return run


def scenario_for_seed(scenario: str, overrides: Sequence[str] = ()) -> Callable[[int], ScenarioSpec]:
    """The healthy scenario with each noise seed (the healthy runs a calibration is measured on)."""
    def spec(seed: int) -> ScenarioSpec:
        return load_scenario(scenario, fault="healthy", overrides=list(overrides) + [f"seed={seed}"])

    return spec


def shipped_physics_name(spec: ScenarioSpec | None) -> str:
    """The physics reference shipped for a scenario (``<base scenario>_physics``; the paper's for None); one line
    naming how to make one when none ships."""
    from wavelet_fdi.learned_detector import shipped_reference_path

    base = "paper" if spec is None else base_scenario(spec.name)
    name = f"{base}_physics"
    if shipped_reference_path(name) is None:
        raise UserError(f"no physics reference ships for scenario {base!r}: make one with phfdi calibrate "
                        f"--scenario {base} --out REF.json and give it as the reference")
    return name


def shipped_physics_model(spec: ScenarioSpec):
    """(model, note): the multichannel detector's model with the physics reference shipped for ``spec``'s scenario,
    its model running ``spec``'s own plant (``reference_physics.follow_scenario``; the note says where it differs
    from the one calibrated on, None where it does not)."""
    from wavelet_fdi.learned_detector import LearnedModel
    from wavelet_fdi.reference_physics import follow_scenario

    return follow_scenario(LearnedModel.load(shipped_physics_name(spec)), spec)
