"""Answers of the loop diagnosis on a fixed set of synthetic loops, to check that making it faster
changes none of them (tests/loops/test_fast_paths.py).

The loops are the ten acceptance cases and six loops of the classifier's training generator, their
specifications stored in ``data/speed_reference.json`` with a digest of the simulated record, so
that a later change of the generator does not change the set; and four records stored as they are
(``data/near_ties/``, drawn by the generator with seed 99), on which the quantisation fit's grid
holds different stem paths whose criteria agree to 1e-14: there a criterion computed with other
rounding (another summation order, lfilter for the FFT) picks another grid point and, on one of
them, another cause, so they check that the search keeps the old arithmetic bit for bit. Each record holds, at full
precision, what the diagnosis computes: every indicator's value and decision, the classifier's
feature vector, every valve model's parameters and held-out NRMSE, the Hammerstein cause and
verdict, Kano's S and J.

The reference was written by the code before the batched grid search (commit in the JSON). If an
indicator's *definition* changes on purpose, rewrite it with the new code and say so in the commit:

    .venv/bin/python -m tests.loops.speed_reference      # writes tests/loops/data/speed_reference.json
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from phfdi.loopdiag.diagnose import Settings, report
from phfdi.loopdiag.features import loop_evidence
from phfdi.loopdiag.synthetic import SyntheticLoop, acceptance_cases, simulate_loop

PATH = Path(__file__).parent / "data" / "speed_reference.json"


def spec_to_json(spec: SyntheticLoop) -> dict:
    return dataclasses.asdict(spec)


def spec_from_json(d: dict) -> SyntheticLoop:
    d = dict(d)
    if d.get("valve") is not None:
        d["valve"] = (d["valve"][0], dict(d["valve"][1]))
    d["setpoint_steps"] = [tuple(s) for s in d["setpoint_steps"]]
    d["load_steps"] = [tuple(s) for s in d["load_steps"]]
    return SyntheticLoop(**d)


def simulate(entry: dict):
    """The entry's loop record: simulated from its specification, or read from its stored file."""
    if "csv" in entry:
        import gzip
        import tempfile

        from phfdi.loopdiag.readers import read_loop

        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / Path(entry["csv"]).name.removesuffix(".gz")
            path.write_bytes(gzip.decompress((PATH.parent / entry["csv"]).read_bytes()))
            return read_loop(str(path))
    run = simulate_loop(spec_from_json(entry["spec"]))
    run.metadata["process_type"] = entry["process_type"]
    return run


def digest(run) -> str:
    h = hashlib.sha256()
    for k in ("op_pct", "pv", "sp"):
        h.update(np.ascontiguousarray(run[k], dtype=float).tobytes())
    return h.hexdigest()


def answers(run) -> dict:
    """Everything the diagnosis of one loop computes, at full precision (JSON floats round-trip)."""
    settings = Settings()
    le = loop_evidence(run, settings)
    rep = report(run, le.evidence, settings)
    ev = le.evidence
    st = next((c for c in ev.causes if c.cause == "stiction"), None) if ev.identifiable else None
    return {
        "features": [float(v) for v in le.features],
        "measured": le.measured,
        "indicators": {k: {"value": None if v.value is None else float(v.value), "decision": v.decision}
                       for k, v in le.indicators.items()},
        "cause": rep["cause"], "verdict": rep["verdict"], "family": rep["family"],
        "gain_percent": rep.get("gain_percent"),
        "nrmse_nominal": None if not ev.identifiable else float(ev.nrmse_nominal),
        "ranking": [{"cause": c.cause, "parameters": {k: float(v) for k, v in c.parameters.items()},
                     "nrmse_validation": float(c.model.nrmse_validation),
                     "nrmse_train": float(c.model.nrmse_train)} for c in ev.causes],
        "kano": None if st is None else {k: float(v) for k, v in st.parameters.items()},
        "oscillation": rep["oscillation"],
    }


def reference_entries() -> list[dict]:
    """The fixed loops: the acceptance cases and six fresh draws of the training generator."""
    from phfdi.loopdiag.training import draw_loops

    out = []
    for name, case in acceptance_cases().items():
        pt = "integrating" if case.loop.process == "integrating" else "self_regulating"
        out.append({"name": name, "spec": spec_to_json(case.loop), "process_type": pt})
    for loop, _run in draw_loops(6, 2026, "SPEEDREF"):
        out.append({"name": loop.group, "spec": spec_to_json(loop.spec), "process_type": loop.process_type})
    return out


def main() -> int:
    stored = [e for e in json.loads(PATH.read_text())["loops"] if "csv" in e] if PATH.exists() else []
    entries = reference_entries() + [{"name": e["name"], "csv": e["csv"]} for e in stored]
    for e in entries:
        run = simulate(e)
        e["digest"] = digest(run)
        e["answers"] = answers(run)
        print(e["name"], e["answers"]["cause"], e["answers"]["verdict"], file=sys.stderr)
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    PATH.write_text(json.dumps({"written_by_commit": commit, "loops": entries}, indent=1) + "\n")
    print(f"wrote {PATH}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
