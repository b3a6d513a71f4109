"""Offline replay: a recorded run through the same streaming detector, as fast as the CPU allows."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from phfdi.faults import base_scenario
from phfdi.records import ReadError, read_run
from phfdi.records.record import Record
from phfdi.scenario import load_scenario
from phfdi_base.errors import UserError
from phfdi_base.spec import ScenarioSpec, validate_scenario
from wavelet_fdi.config import Calibration, DetectorSettings, load_default_calibration
from wavelet_fdi.detector import Event, StreamingDetector
from wavelet_fdi.inputs import INPUT_SIGNALS

DEFAULT_CHUNK = 4096


def detector_inputs(run: Record, feed_names: list[str], valve_feed: str) -> dict[str, np.ndarray]:
    """The signals the detector may see: measurements, commands, setpoint and the flows of feeds
    that no valve under test drives. Never the valve's own flow or position, nor ground truth
    (true pH, fault severity)."""
    if "ph_measured" not in run:
        raise UserError("run has no ph_measured signal: the detector needs the measured pH")
    cols = {}
    for name in INPUT_SIGNALS:
        if name in run:
            cols[name] = np.asarray(run[name], dtype=float)
    if "valve_command_pct" not in cols:
        if "ph_controller_output_pct" not in run:
            raise UserError("run has neither valve_command_pct nor ph_controller_output_pct: the detector "
                            "needs the pH controller output")
        cols["valve_command_pct"] = np.asarray(run["ph_controller_output_pct"], dtype=float)
    for feed in feed_names:
        if feed != valve_feed and f"{feed}_flow_ml_s" in run:
            cols[f"{feed}_flow_ml_s"] = np.asarray(run[f"{feed}_flow_ml_s"], dtype=float)
    return cols


def run_chunks(detector: StreamingDetector, run: Record, chunk: int = DEFAULT_CHUNK, flush: bool = True) -> list[Event]:
    ref = detector.reference
    cols = detector_inputs(run, ref.feed_names, ref.valve_feed)
    n = len(run)
    events: list[Event] = []
    for a in range(0, n, chunk):
        events += detector.process({k: v[a:a + chunk] for k, v in cols.items()})
    if flush:
        events += detector.flush()
    return events


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


@dataclass
class ReplayResult:
    alarms: list = field(default_factory=list)
    events: list = field(default_factory=list)
    diagnostics: dict = field(default_factory=dict)
    samples: int = 0


def replay_run(run: Record, spec: ScenarioSpec | None = None, calibration: Calibration | None = None,
               settings: DetectorSettings | None = None, chunk: int = DEFAULT_CHUNK,
               isolate: bool = True) -> ReplayResult:
    spec = spec or scenario_of(run)
    settings = settings or DetectorSettings()
    calibration = calibration or load_default_calibration(base_scenario(spec.name), settings)
    det = StreamingDetector(spec, calibration, settings, isolate=isolate)
    events = run_chunks(det, run, chunk)
    return ReplayResult(det.alarms, events, det.diagnostics(), len(run))


def shipped_physics_name(spec: ScenarioSpec | None) -> str:
    """The physics reference shipped for a scenario (``<base scenario>_physics``; the paper's for None); one line
    naming how to make one when none ships."""
    from wavelet_fdi.learned_detector import shipped_reference_path

    base = "paper" if spec is None else base_scenario(spec.name)
    name = f"{base}_physics"
    if shipped_reference_path(name) is None:
        raise UserError(f"no physics reference ships for scenario {base!r}: make one with phfdi calibrate --physics "
                        f"--scenario {base} --out REF.json and give it as the reference")
    return name


def shipped_physics_model(spec: ScenarioSpec):
    """(model, note): the multichannel detector's model with the physics reference shipped for ``spec``'s scenario,
    its model running ``spec``'s own plant (``reference_physics.follow_scenario``; the note says where it differs
    from the one calibrated on, None where it does not)."""
    from wavelet_fdi.learned_detector import LearnedModel
    from wavelet_fdi.reference_physics import follow_scenario

    return follow_scenario(LearnedModel.load(shipped_physics_name(spec)), spec)
