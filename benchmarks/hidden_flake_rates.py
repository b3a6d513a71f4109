"""Pass rates of the tests that draw a fresh random seed per run (the hidden-effect tests), over many seeds.

Each test that takes the ``hidden_rng`` fixture (or the stick-slip tests' ``seed``) draws its case from a seed
(``PHFDI_HIDDEN_SEED``, else a fresh one per run). This runs the chosen tests once per seed of a reproducible list
(drawn from ``--master-seed``), each seed in its own pytest process (``-n 0 --runxfail``: an expected failure is run
and counted like any other test), and prints per test the passes, the failing seeds with their message, a 95 %
interval of the failure rate and the chance that one CI run of the whole suite fails from these tests (the
catalogue test runs twice per suite run).

    .venv/bin/python benchmarks/hidden_flake_rates.py --seeds 40 --master-seed 1
    .venv/bin/python benchmarks/hidden_flake_rates.py --tests structure --seeds 60 --master-seed 2
    # only the seeds whose catalogue draw is stiction (the test's own first draw), 30 of them
    .venv/bin/python benchmarks/hidden_flake_rates.py --tests catalogue --draws stiction --seeds 30

Run it with ``nice -n 10`` and ``OPENBLAS_NUM_THREADS=1`` on a shared machine.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scipy.stats import beta

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "diagnosis"))

from hidden_cases import CATALOGUE_CAUSES  # noqa: E402

H = "tests/diagnosis/test_hidden.py::"
S = "tests/diagnosis/test_hidden_structure.py::"
R = "tests/diagnosis/test_reference_model.py::"
L = "tests/loops/test_stickslip.py::"
#: draws a hidden-effect test of tests/diagnosis/test_hidden*.py or test_reference_model.py may take in the suite
#: (hidden_cases.HIDDEN_DRAWS)
DRAWS_IN_CI = 3
#: every test whose data depend on the per-run seed -> times it runs in one suite run
SEEDED = {
    H + "test_catalogue_effect_is_named_with_its_parameter[0]": 2,  # [1] draws the same way: one id, run twice
    H + "test_no_effect_comes_back_none": 1,
    H + "test_effect_outside_the_catalogue_is_not_explained": 1,
    H + "test_the_answer_cannot_reach_the_diagnosis": 1,
    R + "test_extended_model_as_reference_removes_the_false_alarms": 1,
    **{S + f"test_structural_effect_is_named_with_its_parameter[{c}]": 1
       for c in ("mixing_zone", "feed_delay", "pump_curve", "carbonate")},
    S + "test_no_structural_effect_comes_back_none": 1,
    **{S + f"test_dynamics_of_pump_or_probe_is_named_with_its_parameter[{c}]": 1
       for c in ("pump_lag", "sensor_second_order")},
    **{S + f"test_vessel_structure_is_named_with_its_parameter[{c}]": 1
       for c in ("tanks_in_series", "co2_absorption")},
    S + "test_flask_contents_are_named_with_their_pka_and_amount": 1,
    S + "test_no_flask_contents_with_a_fitted_start_comes_back_none": 1,
    L + "test_sticky_valves_of_hidden_size_read_as_stiction": 1,
    **{L + f"test_healthy_valves_and_a_dead_band_do_not[{c}]": 1
       for c in ("setpoint_kicks", "load_steps", "load_walk", "sine", "backlash")},
}
GROUPS = {"all": list(SEEDED), "hidden": [t for t in SEEDED if t.startswith(H)],
          "catalogue": [H + "test_catalogue_effect_is_named_with_its_parameter[0]"],
          "structure": [t for t in SEEDED if t.startswith(S)], "reference": [t for t in SEEDED if t.startswith(R)],
          "stickslip": [t for t in SEEDED if t.startswith(L)]}


def seeds(master: int, n: int, draws: list[str] | None) -> list[int]:
    """``n`` seeds from ``master``; with ``draws``, only seeds whose first draw (the catalogue test's cause,
    ``hidden_rng.choice(CATALOGUE_CAUSES)``) is one of them."""
    rng = np.random.default_rng(master)
    out: list[int] = []
    while len(out) < n:
        s = int(rng.integers(2 ** 32))
        if draws is None or str(np.random.default_rng(s).choice(CATALOGUE_CAUSES)) in draws:
            out.append(s)
    return out


def run_seed(tests: list[str], seed: int) -> dict[str, tuple[str, str]]:
    """One pytest process with PHFDI_HIDDEN_SEED=seed: test id -> (outcome, first line of the failure)."""
    with tempfile.TemporaryDirectory() as tmp:
        xml = Path(tmp) / "junit.xml"
        # one draw per test: the rate of a single draw (the suite lets a test take up to DRAWS_IN_CI draws)
        env = dict(os.environ, PHFDI_HIDDEN_SEED=str(seed), PHFDI_HIDDEN_DRAWS="1")
        subprocess.run([sys.executable, "-m", "pytest", *tests, "-n", "0", "-q", "--runxfail", "-p",
                        "no:cacheprovider", f"--junitxml={xml}", "--basetemp", str(Path(tmp) / "t")],
                       cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        out = {}
        for case in ET.parse(xml).getroot().iter("testcase"):
            path = case.get("classname", "").replace(".", "/") + ".py"
            node = f"{path}::{case.get('name')}"
            bad = case.find("failure") if case.find("failure") is not None else case.find("error")
            skip = case.find("skipped")
            if bad is not None:
                msg = (bad.get("message") or "").splitlines()[0][:300]
                out[node] = ("failed", msg)
            elif skip is not None:
                out[node] = ("skipped", (skip.get("message") or "")[:200])
            else:
                out[node] = ("passed", "")
    return out


def interval(k: int, n: int) -> tuple[float, float]:
    """Clopper-Pearson 95 % interval of a rate of k in n."""
    lo = 0.0 if k == 0 else float(beta.ppf(0.025, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(0.975, k + 1, n - k))
    return lo, hi


def report(results: dict[str, list[tuple[int, str, str]]], xfail: set[str]) -> None:
    print(f"\n{'test':78s} {'pass':>9s}  fail rate (95 % interval)")
    p_ok = 1.0
    for test, rows in results.items():
        n = len([r for r in rows if r[1] != "skipped"])
        k = sum(r[1] == "failed" for r in rows)
        lo, hi = interval(k, n) if n else (0.0, 1.0)
        mark = " (xfail in CI)" if test in xfail else ""
        print(f"{test.split('::')[-1][:78]:78s} {n - k:4d}/{n:<4d}  {100 * k / max(n, 1):5.1f} % "
              f"[{100 * lo:.1f}, {100 * hi:.1f}]{mark}")
        for seed, outcome, msg in rows:
            if outcome == "failed":
                print(f"    seed {seed}: {msg}")
        if test not in xfail and n:
            draws = 1 if test.startswith(L) else DRAWS_IN_CI  # the reference test takes fresh_draws too
            p_ok *= (1.0 - (k / n) ** draws) ** SEEDED.get(test, 1)
    print(f"\nchance that one CI run fails from these tests (point estimate, xfail excluded; the hidden-effect "
          f"tests take up to {DRAWS_IN_CI} draws, failing when all do): {100 * (1.0 - p_ok):.3f} %")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tests", nargs="*", default=["all"], help=f"test ids or groups ({', '.join(GROUPS)})")
    ap.add_argument("--seeds", type=int, default=20, help="seeds per test")
    ap.add_argument("--master-seed", type=int, default=0, help="draws the list of seeds")
    ap.add_argument("--seed-list", type=int, nargs="*", default=None, help="these seeds instead")
    ap.add_argument("--draws", nargs="*", default=None, help="only seeds whose catalogue draw is one of these causes")
    args = ap.parse_args()
    tests = [t for g in args.tests for t in GROUPS.get(g, [g])]
    xfail: set[str] = set()  # test ids marked xfail in the suite (none since the pump curve's basins, 2026-11-27)
    todo = args.seed_list if args.seed_list is not None else seeds(args.master_seed, args.seeds, args.draws)
    print(f"{len(tests)} tests x {len(todo)} seeds (master seed {args.master_seed}); cores: "
          f"{len(os.sched_getaffinity(0))}", flush=True)
    results: dict[str, list[tuple[int, str, str]]] = {t: [] for t in tests}
    t0 = time.perf_counter()
    for j, seed in enumerate(todo):
        got = run_seed(tests, seed)
        for t in tests:
            outcome, msg = got.get(t, ("failed", "not run (collection error?)"))
            results[t].append((seed, outcome, msg))
        bad = [t.split("::")[-1] for t in tests if got.get(t, ("failed",))[0] == "failed"]
        print(f"{j + 1:3d}/{len(todo)} seed {seed}: {'FAIL ' + ', '.join(bad) if bad else 'ok'} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    report(results, xfail)
    return 0


if __name__ == "__main__":
    sys.exit(main())
