"""The diagnosis repeats exactly whatever the number of worker processes, and says how far it is."""

from __future__ import annotations

import numpy as np
import test_structure_search as ss  # a rig-like run with a feed dead time and a reagent strength off

from phfdi.diagnosis.model import nominal_raw
from phfdi.diagnosis.pipeline import Options, _duration, _Progress, diagnose


def _run(workers: int, lines: list[str]):
    rng = np.random.default_rng(5)
    fit = [ss.record(rng, "dayA-1", 0.9, 8.0)]
    val = [ss.record(rng, "dayA-2", 0.9, 8.0)]
    return diagnose(fit, val, nominal_raw("rig_flask", ss.NOMINAL), "rig_flask",
                    Options(candidates=["feed_delay", "sensor_lag", "reagent_concentration"], pairs=False,
                            workers=workers, progress=lines.append)).report


def test_same_answer_with_one_or_two_workers_and_progress_per_fit():
    one, two = [], []
    a, b = _run(1, one), _run(2, two)
    key = lambda rep: [(r["cause"], r["parameters"], r["validation_rmse_over_noise"]) for r in rep["ranking"]]  # noqa: E731
    assert key(a) == key(b)  # exactly: every process starts its solves from the same nominal trajectory
    assert (a["verdict"], a["cause"]) == (b["verdict"], b["cause"])
    assert a["cause"] in ("feed_delay", "reagent_concentration")
    for lines in (one, two):
        done = [x for x in lines if x.strip().split(" ")[0].count("/") == 1 and "held-out error" in x]
        n = len(a["ranking"]) + 1  # causes ranked, plus the second feed's variant of each per-feed cause
        assert len(done) >= n and done[-1].strip().startswith(f"{len(done)}/{len(done)} ")
        assert "elapsed" in done[0] and "left" in done[0]  # a time estimate once one fit is done


def test_progress_estimate_weighs_fits_by_budget_and_heartbeat_names_running_fits():
    lines: list[str] = []
    p = _Progress(Options(progress=lines.append), ["cheap", "dear"], [1.0, 9.0], workers=1)
    p.t0 -= 10.0  # 10 s elapsed when the cheap fit (a tenth of the budget) is done: 90 s left

    class R:
        label, val_cost, seconds = "cheap", 4.0, 10.0

    p.done(0, R())
    assert "1/2 cheap" in lines[-1] and "about 1 min 30 s left" in lines[-1]
    p.heartbeat([1])
    assert "running: dear" in lines[-1] and "1/2 done" in lines[-1]
    assert _duration(125) == "2 min 05 s"
