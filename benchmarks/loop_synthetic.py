"""Synthetic acceptance loops of loop-diagnose: truth against diagnosis, with wall time per loop.

    .venv/bin/python benchmarks/loop_synthetic.py

Prints the table of docs/loop_diagnosis.md ("Synthetic loops"): for each closed loop of
phfdi.loopdiag.synthetic.acceptance_cases the cause and parameters put in, the cause and
parameters found, the held-out NRMSE of the linear and the extended model, and the time the
diagnosis took (one process; the machine's load inflates it).
"""

from __future__ import annotations

import sys
import time

from phfdi.loopdiag.diagnose import Settings, diagnose_run
from phfdi.loopdiag.synthetic import acceptance_cases, simulate_loop, weakness_cases


def fmt(p: dict) -> str:
    return ", ".join(f"{k.replace('_pct', '')} {v:.3g}" for k, v in p.items()) or "-"


def main() -> int:
    print("| loop | put in | found | parameters found | NRMSE linear | NRMSE extended | gain % | time (s) |")
    print("|---|---|---|---|---|---|---|---|")
    wrong = 0
    cases = {**acceptance_cases(), **{f"{k} (known weakness)": v for k, v in weakness_cases().items()}}
    for name, case in cases.items():
        run = simulate_loop(case.loop)
        t0 = time.perf_counter()
        rep = diagnose_run(run, Settings())
        dt = time.perf_counter() - t0
        wrong += rep["cause"] != case.cause and "weakness" not in name
        truth = f"{case.cause} ({fmt(case.parameters)})" if case.parameters else case.cause
        ext = rep.get("nrmse_extended")
        print(f"| {name} | {truth} | {rep['cause']} | {fmt(rep['parameters'])} | {rep['nrmse_nominal']:.3f} | "
              f"{ext:.3f} | {rep['gain_percent']:.0f} | {dt:.1f} |")
    print(f"\n{wrong} of {len(acceptance_cases())} acceptance loops misnamed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
