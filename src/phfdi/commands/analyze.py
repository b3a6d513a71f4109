"""phfdi analyze: the paper's offline multisignal wavelet analysis (Sections 6 and 7), claim by claim."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .common import EPILOG_FORMAT, Progress, add_overwrite_arg

EXAMPLES = """examples:
  phfdi analyze --out out/analysis                      # simulate the paper's 35 runs + Section 7 runs (about a minute)
  phfdi analyze --out out/analysis --save-runs --jobs 2 # also keep the runs (Parquet) for re-analysis
  phfdi analyze --out out/again --bags out/analysis/runs/section6/*.parquet \\
                --section7-bags out/analysis/runs/section7/*.parquet
  phfdi analyze --out out/rig --bags rig/*.mcap --labels healthy,healthy,backlash --signal ph_measured

Writes DIR/REPORT.md (each claim of the paper beside our measured number and a verdict),
DIR/results.json and PNG figures numbered after the paper's (fig27 ... fig61).
Section 6 set: healthy loop and backlash, friction, dead-zone, saturation, 7 variants each
(severity x0.8..1.2, noise seeds), faults from t = 0 as in the paper's Section 5 figures.
Section 7: backlash and friction from 7000 s against healthy runs.
"""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("analyze", help="offline multisignal wavelet analysis of the paper's Sections 6 and 7",
                       description="Decompose, denoise, compress and cluster a multisignal of healthy and faulty "
                                   "pH responses, find variance change points and wavelet-coefficient residuals "
                                   "of faulty runs, and write REPORT.md with the paper's claims beside ours. "
                                   "Simulates the paper's data set unless run files or bags are given.",
                       epilog=EXAMPLES, formatter_class=EPILOG_FORMAT)
    p.add_argument("--out", required=True, help="output folder (REPORT.md, results.json, figures)")
    add_overwrite_arg(p, folder=True)
    p.add_argument("--bags", nargs="+", default=None, metavar="FILE",
                   help="runs to analyse instead of simulating: .csv/.parquet run files or bags")
    p.add_argument("--section7-bags", nargs="+", default=None, metavar="FILE",
                   help="runs for Section 7 (faulty runs with their onset, healthy runs); default: from --bags")
    p.add_argument("--labels", default=None,
                   help="comma-separated class of each --bags file (default: from the run's metadata or file name)")
    p.add_argument("--signal", default="ph_measured", help="signal analysed (default: ph_measured)")
    p.add_argument("--samples", type=int, default=1440, help="samples per row after resampling (default: 1440)")
    p.add_argument("--variants", type=int, default=7, help="simulated variants per class (default: 7)")
    p.add_argument("--onset", type=float, default=0.0, metavar="S",
                   help="fault onset of the Section 6 runs (s, default 0: faults act all along)")
    p.add_argument("--section7-onset", type=float, default=7000.0, metavar="S",
                   help="fault onset of the Section 7 runs (s, default 7000)")
    p.add_argument("--scenario", default="paper", help="scenario preset or .yaml for simulated runs (default: paper)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a scenario key of every simulated run, e.g. --set sensors.ph.noise_std=0.02")
    p.add_argument("--jobs", type=int, default=1, help="simulation processes (default: 1)")
    p.add_argument("--wavelet", default="sym4", help="wavelet of the row decomposition (default: sym4)")
    p.add_argument("--level", type=int, default=7, help="decomposition level (default: 7)")
    p.add_argument("--clusters", default="3", help="number of clusters, or 'auto' (silhouette) (default: 3)")
    p.add_argument("--save-runs", action="store_true", help="write simulated runs to DIR/runs/section{6,7}/")
    p.add_argument("--no-figures", action="store_true", help="skip the PNG figures")
    p.add_argument("--json", action="store_true", help="print the claim table as JSON")
    p.set_defaults(func=run)


def _say(text: str) -> None:
    print(f"analyze: {text}", file=sys.stderr, flush=True)


def load_runs(paths: list[str]) -> list:
    """Runs (.csv, .parquet or .mcap bags) read by phfdi.records under the run policy; repairs noted on stderr."""
    from phfdi.records import read_run

    from .common import print_notes

    runs = []
    for path in paths:
        runs.append(read_run(path))
        print_notes("analyze", runs[-1].metadata["notes"])
    return runs


def run_label(run, path: str) -> str:
    """Class of a run: its metadata's label or fault type, 'healthy' if it has no fault, else the file stem."""
    meta = run.metadata or {}
    if meta.get("label"):
        return str(meta["label"])
    faults = meta.get("faults")
    if isinstance(faults, list):
        if not faults:
            return "healthy"
        kind = faults[0].get("type", "fault")
        return {"coulomb_viscous_friction": "friction"}.get(kind, kind)
    return Path(path).stem.split("-")[0].split("_")[0]


def _onset(run) -> float | None:
    faults = (run.metadata or {}).get("faults") or []
    return float(faults[0]["onset_s"]) if faults and faults[0].get("onset_s", 0) > 0 else None


def section7_pairs(runs: list, labels: list[str], signal: str, opts):
    """Each faulty run with a known onset > 0 against healthy runs: its twin (same seed if known, else the
    first healthy run), a reference and a calibration run (two other healthy runs), when there are any."""
    from phfdi.study.analysis import analyze_pair

    healthy = [r for r, lab in zip(runs, labels) if lab == "healthy"]
    faulty = [(r, lab) for r, lab in zip(runs, labels) if lab != "healthy" and _onset(r) is not None]
    if not healthy or not faulty:
        return []
    pairs = []
    for run, lab in faulty:
        seed = run.metadata.get("seed")
        twin = next((h for h in healthy if h.metadata.get("seed") == seed), healthy[0])
        others = [h for h in healthy if h is not twin and len(h) == len(run)]
        if len(twin) != len(run):
            continue
        ref, cal = (others[0], others[1]) if len(others) >= 2 else (None, None)
        pairs.append(analyze_pair(lab, twin, run, _onset(run), ref, cal, signal, opts))
    return pairs


@dataclass
class _RunSets:
    """The Section 6 runs (with their classes and row names) and the Section 7 runs, and where they came from."""

    runs6: list
    labels6: list[str]
    names6: list[str]
    runs7: list
    labels7: list[str]
    data_text: str
    t_sim: float = 0.0


def run(args: argparse.Namespace) -> int:
    from phfdi.study.paperset import PAPER_GROUPING
    from phfdi.study.report import section6_claims, section7_claims, write_all
    from phfdi_base.outputs import output_folder

    out = output_folder(args.out, args.overwrite)  # before the simulations, not after them
    opts = _options(args)
    t_start = time.perf_counter()
    sets = _read_runs(args) if args.bags else _simulate_runs(args, out)
    ms = _multisignal(args, sets)
    command = "phfdi analyze " + " ".join(shlex.quote(a) for a in sys.argv[2:]) if sys.argv[1:2] == ["analyze"] \
        else "phfdi analyze --out " + str(out)
    context = {"command": command, "data": sets.data_text,
               "timings": f"simulation {sets.t_sim:.1f} s" if sets.t_sim else ""}
    result = write_all(ms, lambda: section7_pairs(sets.runs7, sets.labels7, args.signal, opts), out, opts, context,
                       PAPER_GROUPING, figures_on=not args.no_figures, say=_say)
    claims = section6_claims(ms, result["section6"], opts) + section7_claims(result["section7"], opts)
    if args.json:
        print(json.dumps([vars(c) for c in claims], indent=2))
    else:
        for c in claims:
            short = c.verdict.split("; ")[0].split(". Why")[0]
            print(f"[{c.where}] {short if len(short) <= 110 else short[:107] + '...'}")
        print(f"wrote {out / 'REPORT.md'}, results.json and {len(result['files'])} figures "
              f"({time.perf_counter() - t_start:.0f} s; {result['timings']})")
    return 0


def _options(args: argparse.Namespace):
    """The analysis options from the command line, each checked (UserError naming the option)."""
    import pywt

    from phfdi.study.analysis import Options
    from phfdi_base.errors import UserError

    if args.samples < 16:
        raise UserError(f"--samples {args.samples}: need at least 16")
    try:
        max_level = pywt.dwt_max_level(args.samples, pywt.Wavelet(args.wavelet).dec_len)
    except ValueError as exc:
        raise UserError(f"--wavelet {args.wavelet}: {exc}") from None
    if not 1 <= args.level <= max_level:
        raise UserError(f"--level {args.level}: must be 1..{max_level} for {args.samples} samples with {args.wavelet}")
    if args.clusters != "auto" and not (args.clusters.isdigit() and int(args.clusters) >= 1):
        raise UserError(f"--clusters {args.clusters}: give a positive integer or 'auto'")
    return Options(wavelet=args.wavelet, level=args.level,
                   denoise_levels=tuple(sorted({max(1, args.level - 2), args.level})),
                   n_clusters=None if args.clusters == "auto" else int(args.clusters))


def _read_runs(args: argparse.Namespace) -> _RunSets:
    """The runs of ``--bags`` (and ``--section7-bags``) with their classes."""
    from phfdi_base.errors import UserError

    runs6 = load_runs(args.bags)
    labels6 = args.labels.split(",") if args.labels else [run_label(r, p) for r, p in zip(runs6, args.bags)]
    if len(labels6) != len(runs6):
        raise UserError(f"--labels gives {len(labels6)} labels for {len(runs6)} files")
    names6 = [Path(p).stem for p in args.bags]
    runs7 = load_runs(args.section7_bags) if args.section7_bags else runs6
    labels7 = [run_label(r, p) for r, p in zip(runs7, args.section7_bags)] if args.section7_bags else labels6
    data_text = (f"{len(runs6)} run files: " + ", ".join(f"`{p}` ({lab})" for p, lab in zip(args.bags, labels6))
                 + (f"; Section 7 from {len(runs7)} files" if args.section7_bags else ""))
    return _RunSets(runs6, labels6, names6, runs7, labels7, data_text)


def _simulate_runs(args: argparse.Namespace, out: Path) -> _RunSets:
    """The paper's Section 6 and 7 runs, simulated (and saved with ``--save-runs``)."""
    from phfdi.study.paperset import section6_variants, section7_variants, simulate_variants

    v6 = section6_variants(args.variants, args.onset)
    v7 = section7_variants(args.section7_onset)
    _say(f"simulating {len(v6)} Section 6 runs and {len(v7)} Section 7 runs ({args.scenario}, {args.jobs} job(s))")
    t0 = time.perf_counter()
    runs = simulate_variants(v6 + v7, args.scenario, args.overrides, args.jobs,
                             Progress("analyze: simulating", enabled=True))
    t_sim = time.perf_counter() - t0
    runs6, runs7 = runs[:len(v6)], runs[len(v6):]
    labels6, names6 = [v.label for v in v6], [v.name for v in v6]
    labels7 = [v.label for v in v7]
    if args.save_runs:
        for sub, vs, rs in (("section6", v6, runs6), ("section7", v7, runs7)):
            for v, r in zip(vs, rs):
                r.save(out / "runs" / sub / f"{v.name}.parquet")
        _say(f"runs written to {out / 'runs'}/")
    factors = sorted({round(v.factor, 3) for v in v6 if v.label != "healthy"})
    data_text = (f"Simulated with `phfdi.loop.simulate` on scenario `{args.scenario}`"
                 + (f" (overrides: {', '.join(args.overrides)})" if args.overrides else "") +
                 f". Section 6: {len(v6)} runs = {len(set(labels6))} classes x {args.variants} variants; "
                 f"variant i has noise seed {v6[0].seed}+i and the fault's severity x{factors[0]:g}..{factors[-1]:g} "
                 f"({', '.join(f'{f:g}' for f in factors)}); faults act from {args.onset:g} s "
                 "(the paper's Section 5 responses that Section 6 analyses). Section 7: backlash and friction "
                 f"from {args.section7_onset:g} s with seed {v7[0].seed}, their healthy twin (same seed), a "
                 f"healthy reference (seed {v7[-2].seed}) and a healthy calibration run (seed {v7[-1].seed}). "
                 f"Rows: `{args.signal}` averaged over {args.samples} equal bins of the run.")
    return _RunSets(runs6, labels6, names6, runs7, labels7, data_text, t_sim)


def _multisignal(args: argparse.Namespace, sets: _RunSets):
    """The Section 6 runs as a multisignal of ``--samples`` bins of ``--signal`` per row."""
    import numpy as np

    from phfdi.study.multisignal import from_runs
    from phfdi_base.errors import UserError

    for r, lab in zip(sets.runs6, sets.labels6):
        if args.signal not in r:
            raise UserError(f"run {lab!r} has no signal {args.signal!r}; it has: {', '.join(r.names)}")
    info = [{"seed": r.metadata.get("seed"), "severity_factor": r.metadata.get("severity_factor")} for r in sets.runs6]
    info = [{k: v for k, v in d.items() if v is not None} for d in info]
    try:
        ms = from_runs(sets.runs6, sets.labels6, args.signal, args.samples, sets.names6, info=info)
    except ValueError as exc:
        raise UserError(f"cannot build the multisignal: {exc}") from None
    if not np.all(np.isfinite(ms.data)):
        raise UserError(f"{args.signal} has no finite samples in some runs")
    if ms.shape[0] < 2:
        raise UserError("the analysis needs at least two runs")
    return ms
