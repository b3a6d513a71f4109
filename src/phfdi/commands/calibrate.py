"""phfdi calibrate: detector thresholds for a false-alarm target, from healthy runs."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .common import (
    EPILOG_FORMAT,
    Progress,
    add_overwrite_arg,
    add_record_args,
    column_map_from_args,
    plant_runs_on,
    print_notes,
    store_column_map,
)

EXAMPLES = """examples:
  phfdi calibrate --out my_physics.json                    # paper scenario: its physics reference, sym4 L3, ARL0 1e5
  phfdi calibrate --wavelet db8 --level 4 --out db8.json
  phfdi calibrate --scenario my_loop.yaml --seeds 2001-2032 --arl0 1e6 --out my_loop.json
  phfdi calibrate --scenario my_loop.yaml --runs healthy1.parquet healthy2.parquet --out plant.json
  phfdi calibrate --scenario my_loop.yaml --runs h1.csv h2.csv --map plant_columns.yaml --out plant.json
  phfdi calibrate --learn healthy.csv --rows 400 --exclude anomaly,changepoint --out ref.json
  phfdi calibrate --learn export.csv --from 2020-03-09T11:14:34 --to 2020-03-09T11:21:13 --map tags.yaml --out ref.json
  phfdi calibrate --learn healthy.csv --rows 400 --form oe --correction-samples 100 --out ref.json
  phfdi calibrate --estimator runs/*.csv --map ph_rig --repeat-probability 0 --out rig.json  # no repeats test
  phfdi calibrate --estimator ../shared/data/ph_rig/2025.02.24-*.csv --model rig_flask --map ph_rig --out rig.json
  (then: phfdi replay RUN --reference FILE.json, phfdi launch --detector-param reference=FILE.json)

Without --learn or --estimator, the scenario's healthy plant and valves are
calibrated as the physics reference of the multichannel detector (docs/detector.md,
"The paper's physics as a reference kind"), on the --seeds' healthy runs or on
--runs: the physics detector's design (wavelet sym4, level 3, ARL0 1e5, ...)
carried over, the band noise and every threshold measured on the healthy runs
for --arl0; any detector option given sets that setting over the design.
The seeds default to 1001-1016, disjoint from the evaluation's (1-99). The
shipped one for the paper scenario is paper_physics (made with the defaults).
Recorded runs are read under the reading policy of docs/records.md (--map,
--column, --encoding as in phfdi replay); every repair is printed as a note.
Before 2026-12-07 this wrote the physics detector's .yaml calibration (for
replay --calibration); that detector was retired. --physics is the same mode.

--learn fits a learned healthy reference (no plant model needed) on the first
--rows rows of a measured record (all of them by default), or on the rows from
--from to --to (seconds of the record's time, or ISO 8601 stamps when it has a
date-time column; both ends included): every channel
predicted from its own past and the other channels (ARX, ridge), the wavelet
bands of the residuals and their healthy noise per band; phfdi replay FILE
--reference ref.json then watches any record with those columns. Channels:
every column but time and --exclude, or the ones a --map/--column names.

--estimator fits the estimator reference (docs/detector.md, "The real pH rig") on
healthy runs of a plant with pumped feeds of strong acid and base into an overflow
vessel: a Kalman filter on the reaction invariant, driven by the measured pH and
pump flows, its strengths, volume and noise model fitted by the innovations'
likelihood, the residual's healthy bands measured on the same runs (--open-loop:
the same physics simulated, never corrected). --model gives the feeds and first
guesses; the channels are the model's feeds' flows (<feed>_flow_ml_s) and
ph_measured, so a --map is needed for other column names (ph_rig is shipped).
phfdi replay RUN --map ph_rig --reference rig.json watches a run with it.

Every detector setting is an option of its own, --NAME VALUE, derived from its
one declaration (docs/detector.md, "Detector settings"); one detector runs every
reference kind, and a setting not given keeps the design of the kind being
calibrated: the physics reference's design or the detector's own defaults (each
option's help shows both), or the estimator's (docs/detector.md). --channels is
the physics reference's own option. The old form --learned KEY=VALUE is still
read with --learn and --estimator.
"""


def parse_seeds(text: str) -> list[int]:
    """'1001-1016' or '1,2,5' -> list of seeds."""
    from phfdi_base.errors import UserError

    out: list[int] = []
    try:
        for part in text.split(","):
            if "-" in part:
                a, b = part.split("-", 1)
                out.extend(range(int(a), int(b) + 1))
            elif part.strip():
                out.append(int(part))
    except ValueError:
        raise UserError(f"--seeds expects a list like 1001-1016 or 3,4,9, got {text!r}") from None
    if not out or any(s < 0 for s in out):
        raise UserError(f"--seeds expects non-negative seeds, got {text!r}")
    return out


def _shown(value) -> str:
    """A setting's default as the help shows it."""
    return ",".join(value) if isinstance(value, tuple) else f"{value:g}" if isinstance(value, float) else str(value)


def physics_design_defaults() -> dict:
    """The settings the physics reference's design (``reference_physics.design_settings``) sets otherwise than the
    multichannel detector's own defaults: name -> its value there."""
    from dataclasses import asdict

    from wavelet_fdi.config import LearnedSettings
    from wavelet_fdi.reference_physics import design_settings

    plain, physics = asdict(LearnedSettings()), asdict(design_settings(1.0))
    return {k: v for k, v in physics.items() if v != plain[k] and k != "sample_time_s"}


def add_detector_args(p) -> None:
    """Every setting of the multichannel detector (physics, learned and estimator references alike) as an option
    ``--NAME VALUE`` of ``p`` (a parser or an argument group), from its one declaration
    (``wavelet_fdi.config.LearnedSettings``), with no argparse default: a setting not given keeps its default (the
    physics reference's design, or the detector's own, both in the help), and :func:`given_settings` can tell what
    was given."""
    from wavelet_fdi.config import LearnedSettings, setting_specs

    physics = physics_design_defaults()
    for s in setting_specs(of=LearnedSettings):
        default = f"default {_shown(s.default)}" + (f"; the physics reference's design: {_shown(physics[s.name])}"
                                                    if s.name in physics else "")
        metavar = "SAMPLES" if s.name == "arl0_samples" else s.name.split("_")[-1].upper()
        p.add_argument(s.flag, dest=s.name, type=s.type, default=None, metavar=metavar, help=f"{s.help} ({default})")


def add_physics_args(p) -> None:
    """The physics reference's own option: the residual channels it watches."""
    p.add_argument("--channels", default=None, metavar="ph[,level]",
                   help="residual channels the physics reference watches: ph, or ph,level (the level's too, where "
                        "a controller holds it) (default ph)")


def physics_watches_level(args: argparse.Namespace) -> bool:
    """``--channels``: ph (default) or ph,level; anything else is one line."""
    from phfdi_base.errors import UserError

    given = getattr(args, "channels", None)
    channels = tuple(c.strip() for c in (given or "ph").split(",") if c.strip())
    if channels not in (("ph",), ("ph", "level"), ("level", "ph")):
        raise UserError(f"--channels {given}: use ph, or ph,level")
    return "level" in channels


def given_settings(args: argparse.Namespace) -> dict:
    """The multichannel detector's settings given as options (name -> value)."""
    from wavelet_fdi.config import LearnedSettings, setting_specs

    return {s.name: getattr(args, s.name) for s in setting_specs(of=LearnedSettings)
            if getattr(args, s.name, None) is not None}


def learned_settings_from_args(args: argparse.Namespace, base=None):
    """The learned (or, from ``base``, the estimator's) detector settings: those given as options, then those of the
    old ``--learned KEY=VALUE`` form (still read, with a note), the others ``base``'s or the defaults."""
    from dataclasses import asdict

    from phfdi_base.errors import UserError
    from wavelet_fdi.config import LearnedSettings

    given = given_settings(args)
    pairs = getattr(args, "learned", None) or []
    if pairs:
        print("note: --learned KEY=VALUE is the old form of --KEY VALUE (e.g. --mean-h 8)", file=sys.stderr)
    old = asdict(learned_settings(pairs))
    from_pairs = {pair.partition("=")[0] for pair in pairs}
    both = sorted(from_pairs & set(given))
    if both:
        raise UserError(f"{', '.join(both)} given both as an option and with --learned: give each once")
    d = asdict(base or LearnedSettings())
    d.update(given)
    d.update({k: old[k] for k in from_pairs})
    return LearnedSettings.from_dict(d)


def learned_settings(pairs: list[str], base=None):
    """LearnedSettings from the old ``--learned KEY=VALUE`` pairs (numbers, or text for the wavelet and form)."""
    from dataclasses import asdict

    from phfdi_base.errors import UserError
    from wavelet_fdi.config import LearnedSettings

    d = asdict(base or LearnedSettings())
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or key not in d:
            raise UserError(f"--learned {pair!r}: use KEY=VALUE with KEY one of {', '.join(d)}")
        kind = type(d[key])
        try:
            d[key] = value if kind is str else kind(float(value)) if kind is int else float(value)
        except ValueError:
            raise UserError(f"--learned {pair!r}: {key} must be a number") from None
    return LearnedSettings.from_dict(d)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("calibrate", help="calibrate the fault detector's reference and thresholds on healthy runs",
                       description="Simulate a scenario healthy with several noise seeds (or read recorded healthy "
                                   "runs), measure the physics reference's residual noise per wavelet band and set "
                                   "each CUSUM threshold so that the detector's average run length to a false alarm "
                                   "is the target. Writes the reference (.json) the detector loads. With --learn: "
                                   "fit a learned healthy reference on a measured healthy record instead (any "
                                   "channels, no plant model); with --estimator: the rig's estimator reference.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--scenario", default="paper", help="scenario preset or .yaml (default paper)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key (as in phfdi simulate)")
    p.add_argument("--seeds", default="1001-1016", help="noise seeds of the healthy runs (default 1001-1016)")
    p.add_argument("--runs", nargs="+", default=None, metavar="FILE",
                   help="calibrate on these recorded healthy runs (.csv, .parquet, .mcap) instead of simulating; "
                        "--scenario is then the plant's model")
    add_detector_args(p.add_argument_group(
        "detector settings (every reference kind; the physics reference's design sets some otherwise, as shown)"))
    add_record_args(p)
    g = p.add_argument_group("learned reference (measured records, no plant model)")
    g.add_argument("--learn", default=None, metavar="RECORD",
                   help="fit a learned healthy reference on this healthy record (.csv, .parquet, .mcap)")
    g.add_argument("--rows", type=int, default=None, metavar="N", help="with --learn: the first N rows only")
    g.add_argument("--from", dest="start", default=None, metavar="T",
                   help="with --learn: healthy rows from T on: seconds of the record's time (as replay prints "
                        "them) or an ISO 8601 stamp (2020-03-09T11:20:00) when the record has a date-time column")
    g.add_argument("--to", dest="end", default=None, metavar="T",
                   help="with --learn: healthy rows up to T (included), as --from")
    g.add_argument("--exclude", default="", metavar="COLS", help="with --learn: columns that are not channels, "
                   "comma-separated (e.g. labels)")
    g.add_argument("--learned", action="append", default=[], metavar="KEY=VALUE",
                   help="the old form of a learned or estimator detector setting's option: --learned mean_h=8 is "
                        "--mean-h 8 (still read, with a note)")
    g = p.add_argument_group("estimator reference (a vessel with pumped feeds of strong acid and base)")
    g.add_argument("--estimator", nargs="+", default=None, metavar="RUN",
                   help="fit the estimator reference on these healthy runs (.csv, .parquet, .mcap)")
    g.add_argument("--model", default="rig_flask", help="with --estimator: the plant model giving the feeds and "
                   "first guesses (preset or .yaml; default rig_flask)")
    g.add_argument("--open-loop", action="store_true",
                   help="with --estimator: simulate the model from each run's first pH, never correct it")
    g = p.add_argument_group("physics reference kind (the scenario's model in the multichannel detector)")
    add_physics_args(g)
    g.add_argument("--physics", action="store_true",
                   help="the default without --learn or --estimator (kept for the command lines that name it): the "
                        "scenario's healthy plant and valves as the physics reference, on the --seeds' healthy runs "
                        "or on --runs")
    p.add_argument("--out", required=True, help="file to write (.json)")
    add_overwrite_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from phfdi_base.outputs import refuse_existing

    refuse_existing(args.out, args.overwrite)  # before any fitting
    check_settings_given(args)
    if args.estimator:
        return run_estimator(args)
    if args.learn:
        return run_learn(args)
    return run_physics(args)


def check_settings_given(args: argparse.Namespace) -> None:
    """--channels is the physics reference's own option, and --learned (the old KEY=VALUE form) is read by --learn
    and --estimator only: one line when given with the other modes."""
    from phfdi_base.errors import UserError

    if not (args.learn or args.estimator):
        if args.learned:  # the old form is read by --learn and --estimator only
            raise UserError(f"--learned {args.learned[0]}: give a setting of the physics reference as its own "
                            f"option (--NAME VALUE; phfdi calibrate --help)")
        return
    if args.channels is not None:
        raise UserError("--channels sets the physics reference (phfdi calibrate without --learn or --estimator)")


def physics_design(args: argparse.Namespace, sample_time_s: float):
    """The physics reference's options (``PhysicsReference.from_spec``) and the multichannel detector's settings
    with the physics detector's design (``reference_physics.design_settings``), any setting given as an option set
    over it."""
    from wavelet_fdi.reference_physics import design_settings

    options = dict(watch_level=physics_watches_level(args))
    return options, design_settings(sample_time_s, **given_settings(args))


def run_physics(args: argparse.Namespace) -> int:
    """The scenario's physics as a reference kind of the multichannel detector, calibrated on healthy runs."""
    from phfdi.loop import simulate
    from phfdi.replay import load_any, scenario_for_seed
    from phfdi.scenario import load_scenario
    from phfdi_base.errors import UserError
    from wavelet_fdi.learned_detector import calibrate_bands
    from wavelet_fdi.reference_physics import PhysicsReference

    if not args.out.endswith(".json"):
        old = " (the physics detector's .yaml calibration was retired with it on 2026-12-07)" \
            if args.out.endswith((".yaml", ".yml")) else ""
        raise UserError(f"--out {args.out}: a physics reference is written as .json{old}")
    if args.rows is not None or args.exclude or args.start or args.end:
        raise UserError("--rows, --from, --to and --exclude go with --learn (a physics reference is calibrated on whole runs)")
    spec = load_scenario(args.scenario, fault="healthy", overrides=args.overrides)
    options, settings = physics_design(args, spec.sample_time_s)
    ref = PhysicsReference.from_spec(spec, **options)
    cmap = column_map_from_args(args)
    runs = []
    if args.runs:
        sources = list(args.runs)
        for path in args.runs:
            run = load_any(path, cmap, args.encoding)
            print_notes("calibrate", run.metadata.get("notes", []))
            runs.append(run)
    else:
        seeds = parse_seeds(args.seeds)
        make = scenario_for_seed(args.scenario, args.overrides)
        progress = Progress(f"simulate {len(seeds)} healthy runs", enabled=True)
        for i, seed in enumerate(seeds):
            runs.append(simulate(make(seed)))
            progress((i + 1) / len(seeds))
        sources = [f"seed {seed}" for seed in seeds]
    missing = sorted({c for run in runs for c in ref.channels if c not in run})
    if missing:
        raise UserError(f"the healthy runs lack {', '.join(missing)} (the physics reference reads "
                        f"{', '.join(ref.channels)}; --map names other columns)")
    rows = [(run.time_s, np.column_stack([np.asarray(run[c], float) for c in ref.channels])) for run in runs]
    model = calibrate_bands(ref, rows, settings, {"runs": sources, "scenario": spec.name})
    model.save(args.out, overwrite=args.overwrite)
    print(f"physics reference of scenario {spec.name} on {len(runs)} healthy runs: watches "
          f"{', '.join(model.residual_channels)}; {settings.wavelet} level {settings.level}, ARL0 "
          f"{settings.arl0_samples:g} samples")
    for name, h in zip(model.residual_channels, model.band_sigma):
        print(f"  {name:22s} healthy RMS per band ({', '.join(settings.bands())}): "
              + " ".join(f"{v:.3f}" for v in h))
    for name, h in model.thresholds.items():
        print(f"  {name:28s} threshold {h:8.2f}")
    print(f"wrote {args.out}")
    return 0


def run_learn(args: argparse.Namespace) -> int:
    from phfdi.learned import learn_from, read_measured, training_rows
    from phfdi_base.errors import UserError

    if args.runs:
        raise UserError("--learn and --runs are two different calibrations: give one")
    if not args.out.endswith(".json"):
        raise UserError(f"--out {args.out}: a learned reference is written as .json")
    settings = learned_settings_from_args(args)
    rec = read_measured(args.learn, column_map_from_args(args),
                        exclude=[c.strip() for c in args.exclude.split(",") if c.strip()], encoding=args.encoding)
    print_notes("calibrate", rec.notes)
    part = training_rows(rec, args.rows, args.start, args.end)
    model = learn_from(rec, part, settings)
    store_column_map(args, model)
    model.save(args.out, overwrite=args.overwrite)
    s, src = model.settings, model.source
    print(f"learned reference on {src['rows']} healthy rows of {args.learn} ({rec.where}s {src['first_row']}-"
          f"{src['last_row']}, {rec.when(src['from_s'])} to {rec.when(src['to_s'])}): {len(model.channels)} channels, "
          f"{s.form} form, {s.lags} own lags + the other channels (ridge), {s.wavelet} level {s.level}, "
          f"sample time {s.sample_time_s:g} s")
    print(f"  {'channel':28s} {'residual/std':>12s}  healthy RMS per band ({', '.join(s.bands())})")
    for c, name in enumerate(model.channels):
        print(f"  {name:28s} {model.reference.residual_sigma[c]:12.3f}  "
              + " ".join(f"{v:6.2f}" for v in model.band_sigma[c]))
    print_healthy_ranges(model)
    print(f"wrote {args.out}")
    return 0


def run_estimator(args: argparse.Namespace) -> int:
    from phfdi.estimator import ESTIMATOR_SETTINGS, fit_estimator, identifiability_notes, start_from_model
    from phfdi.learned import read_measured
    from phfdi_base.errors import UserError
    from wavelet_fdi.config import LearnedSettings

    if args.learn or args.runs:
        raise UserError("--estimator, --learn and --runs are different calibrations: give one")
    if not args.out.endswith(".json"):
        raise UserError(f"--out {args.out}: an estimator reference is written as .json")
    if args.rows is not None or args.exclude or args.start or args.end:
        raise UserError("--rows, --from, --to and --exclude go with --learn (--estimator fits on whole runs)")
    start = start_from_model(args.model, correct=not args.open_loop)
    cmap = column_map_from_args(args)
    records = [read_measured(p, cmap, channels=list(start.channels)) for p in args.estimator]
    for r in records:
        print_notes("calibrate", r.notes)
    with plant_runs_on(", ".join(args.estimator)):
        model = fit_estimator(records, start, learned_settings_from_args(args, LearnedSettings(**ESTIMATOR_SETTINGS)),
                              progress=lambda msg: print(f"phfdi calibrate: {msg} ...", file=sys.stderr, flush=True))
    store_column_map(args, model)
    ref = model.reference
    # a strength or volume at a bound was refused before the folds (phfdi.estimator.refuse_unidentified); a noise
    # term at a bound is said
    print_notes("calibrate", identifiability_notes(ref))  # type: ignore[arg-type]
    model.save(args.out, overwrite=args.overwrite)
    kind = "open-loop simulation" if args.open_loop else "estimator"
    print(f"{kind} reference on {len(records)} healthy runs ({model.source['rows']} rows), "
          f"sample time {model.settings.sample_time_s:g} s; fitted by the innovations' likelihood:")
    for f in ref.feeds:  # type: ignore[attr-defined]
        print(f"  {f.channel:24s} strength {f.strength_mM:9.3f} mM of charge ({'base' if f.strength_mM > 0 else 'acid'})")
    print(f"  {'volume':24s} {ref.volume_ml:9.0f} mL")  # type: ignore[attr-defined]
    for k, v in ref.noise.__dict__.items():  # type: ignore[attr-defined]
        print(f"  {k:24s} {v:9.4g}")
    print(f"  strengths adapt with a time constant of {ref.adapt_time_constant_s:g} s of pump-on time "  # type: ignore[attr-defined]
          f"(every {ref.block_samples} samples)")  # type: ignore[attr-defined]
    print(f"  healthy RMS per band ({', '.join(model.settings.bands())}): "
          + " ".join(f"{v:.2f}" for v in model.band_sigma[0])
          + f" (from {model.source.get('bands_from', 'the runs themselves')})")
    print_confirmation(ref, model.settings)
    print_healthy_ranges(model)
    print(f"wrote {args.out}")
    return 0


def print_confirmation(ref, settings=None) -> None:
    """The fault confirmation's margin and its design (an estimator reference), and the feed checks' level."""
    conf = getattr(ref, "confirm", None) or {}
    if not conf.get("thresholds"):
        return
    tails = conf["null_tail"]
    first = {k: v for k, v in conf["thresholds"].items() if not k.startswith("change@")}
    later = {k[7:]: v for k, v in conf["thresholds"].items() if k.startswith("change@")}
    margins = " or ".join(f"its {k} statistic exceeds {v:.2f}" for k, v in first.items())
    if later:
        margins += (f"; a deviation still up and not confirmed is looked at again {', '.join(later)} samples after "
                    f"its detection, each look's change over its window against its own margin "
                    f"({', '.join(f'{v:.2f}' for v in later.values())})")
    n = min(t["n"] for t in tails.values())
    print(f"  fault confirmation: a deviation is a fault alarm when the innovations' change against the run's own "
          f"past says so ({margins}) and a probe fault explains it better than any feed's apparent strength; "
          f"healthy operation exceeds each margin with probability {conf['alpha_per_test']:g} "
          f"(at least {n} null values each, from {'each run held out' if conf.get('held_out') else 'the one run itself'}); "
          f"else it is a deviation outside calibration (WARN)")
    per_sample = getattr(settings, "against_feed_per_sample", 0.0)
    if per_sample:
        from wavelet_fdi.feed_checks import level

        print(f"  feed checks: a reading that moves against the only feed that runs (up while acid alone runs, down "
              f"while base alone runs) by t > {level(per_sample):.2f} is a fault alarm, a probe offset or drift: no "
              f"healthy vessel gives it; a healthy sample passes that level with probability {per_sample:g} "
              f"(wavelet_fdi.feed_checks states the assumptions)")
    if not conf.get("held_out"):
        print("  note: one calibration run: the scales and the margin come from that run itself, not from a day it did "
              "not see; calibrate on two runs or more to measure them across days")


def print_healthy_ranges(model) -> None:
    """What the healthy runs covered per channel: beyond it, replay notes that the reference extrapolates."""
    from wavelet_fdi.healthy_range import healthy_span

    ranges = model.source.get("healthy_ranges") or {}
    if ranges:
        print("  healthy ranges (phfdi replay notes a record beyond them: the reference extrapolates there): "
              + "; ".join(f"{c} {healthy_span(r)}" for c, r in ranges.items()))
