"""phfdi evaluate: the detector against peers on a scenario matrix, at equal false-alarm rate."""

from __future__ import annotations

import argparse

from .calibrate import add_detector_args, add_physics_args, parse_seeds, physics_design
from .common import EPILOG_FORMAT, add_overwrite_arg

EXAMPLES = """examples:
  phfdi evaluate --out out/eval                   # full matrix (about 70 runs; minutes, progress on stderr)
  phfdi evaluate --out out/eval-quick --quick     # paper severities, one seed: a smoke test
  phfdi evaluate --out out/eval-db8 --wavelet db8 --seeds 1-5 --jobs 2
  phfdi evaluate --out out/eval-level --channels ph,level   # watch the level's residual too

Ours is the multichannel detector with the scenario's physics as its reference, as
phfdi calibrate makes it (the physics detector's design; any setting
below given over it), calibrated on the --calibration-seeds' healthy runs.
Writes DIR/evaluation.md (tables), DIR/results.json (every run), DIR/reference.json
(our calibrated detector: phfdi replay RUN --reference DIR/reference.json),
DIR/peers.json (the peers' and the bands-only variant's thresholds) and figures:
delays.png, false_alarms.png, isolation.png, parameters.png,
coefficient_residuals_backlash.png.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="evaluate the fault detector against CUSUM, FOCuS, Page-Hinkley, ADWIN",
                       description="Run healthy runs and each fault at three severities with several noise seeds "
                                   "(faults at 7000 s on the paper scenario); calibrate every detector to the "
                                   "same false-alarm rate on separate healthy runs; report detection delays next "
                                   "to the CUSUM/Lorden bound, false alarms per hour, missed detections, "
                                   "isolation accuracy and parameter-estimate errors.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite_arg(p, folder=True)
    p.add_argument("--scenario", default="paper", help="scenario preset or .yaml (default paper)")
    p.add_argument("--onset", type=float, default=7000.0, metavar="S", help="fault onset (s), default 7000")
    p.add_argument("--seeds", default="1-3", help="noise seeds of the faulty runs (default 1-3)")
    p.add_argument("--healthy-seeds", default="1-8", help="noise seeds of the healthy runs (default 1-8)")
    p.add_argument("--calibration-seeds", default="1001-1016", help="seeds of the calibration runs (default 1001-1016)")
    add_physics_args(p)
    add_detector_args(p.add_argument_group(
        "multichannel detector settings given over the physics design (the design sets the wavelet, level, "
        "block, the mean and energy CUSUMs' designs and ARL0, as shown)"))
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--quick", action="store_true",
                   help="paper severities only, seed 1, healthy seed 1, four calibration runs (for tests)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from phfdi.scenario import load_scenario
    from phfdi.study.evaluation import EvalConfig, run_evaluation
    from phfdi_base.outputs import output_folder

    spec = load_scenario(args.scenario, fault="healthy")
    options, settings = physics_design(args, spec.sample_time_s)
    common = dict(scenario=args.scenario, onset_s=args.onset, settings=settings, reference_options=options,
                  jobs=args.jobs)
    if args.quick:
        cfg = EvalConfig.quick(**common)
    else:
        cfg = EvalConfig(eval_seeds=tuple(parse_seeds(args.seeds)),
                         healthy_seeds=tuple(parse_seeds(args.healthy_seeds)),
                         calibration_seeds=tuple(parse_seeds(args.calibration_seeds)), **common)
    cfg.check()  # a bad configuration is one line before the output folder is made
    output_folder(args.out, args.overwrite)  # before the evaluation's runs, not after them
    run_evaluation(cfg, args.out)
    print((Path(args.out) / "evaluation.md").read_text())
    return 0
