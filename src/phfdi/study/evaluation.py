"""Scenario-matrix evaluation of the detector against peers at equal false-alarm rate.

``phfdi evaluate`` runs: healthy runs and each fault at three severities
(the paper's in the middle) with several noise seeds, faults at ``onset_s``.
Ours is the multichannel detector (:class:`~wavelet_fdi.learned_detector.LearnedDetector`) with the scenario's
physics as its reference (kind ``physics``, :mod:`wavelet_fdi.reference_physics`), the model ``phfdi calibrate
--physics`` writes. Calibration (ours and the peers') uses healthy runs with seeds disjoint from the evaluation's.
Every peer sees the residual our detector watches (the reference's pH residual less the observer's level, over the
monitored samples, divided by its healthy RMS), and every detector is held to the same ARL0. For each faulty run
the delay bound is the time an oracle that knows the fault's noise-free residual signal s_t needs to gather
ln(ARL0) of Kullback-Leibler information, sum s_t^2 / (2 sigma^2) (the CUSUM/Lorden bound; for a constant shift
of delta sigma it is 2 ln(ARL0) / delta^2).
"""

from __future__ import annotations

import json
import math
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from phfdi.faults import catalogue
from phfdi.loop import build_parts, simulate
from phfdi.replay import scenario_for_seed
from phfdi.scenario import load_scenario
from phfdi.study.detector_figures import plot_evaluation
from phfdi_base.errors import UserError
from phfdi_base.outputs import write_text
from wavelet_fdi.calibration import tail_probability, window_maxima
from wavelet_fdi.config import ARL_WINDOW_SAMPLES, LearnedSettings
from wavelet_fdi.learned_detector import LearnedDetector, LearnedModel, calibrate_bands, run_record
from wavelet_fdi.peers import (
    DETECTORS,
    LABELS,
    PEERS,
    Peer,
    _focus_window_max,
    _page_hinkley_window_max,
    calibrate_peers,
)
from wavelet_fdi.reference_physics import PhysicsReference, design_settings

#: faults outside the fault library, as scenario fault entries, with their severities (main parameter, levels)
CUSTOM_SEVERITIES: dict[str, tuple[str, list[dict]]] = {
    # not in the paper: a degrading probe adds noise (extra standard deviation, pH); no mean change
    "probe_noise": ("std", [{"std": 0.005}, {"std": 0.01}, {"std": 0.02}]),
}


def severities() -> dict[str, tuple[str, list[dict]]]:
    """fault -> (main parameter, three severities: mild, the preset's, strong), from the fault catalogue
    (:mod:`phfdi_base.faults`; other parameters scale along where the catalogue says so), then the faults
    outside the library."""
    out = {name: (f.main.name, f.severity_params()) for name, f in catalogue().items()
           if f.preset and f.severities is not None and f.main is not None}
    return {**out, **CUSTOM_SEVERITIES}


#: faults outside the fault library, as scenario fault entries
CUSTOM_FAULTS = {"probe_noise": {"type": "sensor_noise", "where": "ph_sensor", "params": {"seed": 4242}}}
#: what isolation should answer: probe_noise is in no hypothesis, so "unknown"
EXPECTED_CLASS = {"probe_noise": "unknown"}
PAPER_SEVERITY = 1  # index of the paper's value in each list


@dataclass
class EvalConfig:
    scenario: str = "paper"
    onset_s: float = 7000.0
    eval_seeds: tuple[int, ...] = (1, 2, 3)
    healthy_seeds: tuple[int, ...] = tuple(range(1, 9))
    calibration_seeds: tuple[int, ...] = tuple(range(1001, 1017))
    severity_indices: tuple[int, ...] = (0, 1, 2)
    faults: tuple[str, ...] = field(default_factory=lambda: tuple(severities()))
    #: scenario key=value overrides for every run (calibration included)
    overrides: tuple[str, ...] = ()
    #: the peers' calibration window (samples): much shorter than ARL0, long against the statistics' memory (ours
    #: are measured on windows of wavelet_fdi.config.ARL_WINDOW_SAMPLES)
    window_samples: int = 1000
    #: our detector's settings: the physics detector's design (reference_physics.design_settings); the sample
    #: time is the scenario's
    settings: LearnedSettings = field(default_factory=design_settings)
    #: the physics reference's options (PhysicsReference.from_spec): the pH alone by default
    reference_options: dict = field(default_factory=lambda: {"watch_level": False})
    jobs: int = 2

    @classmethod
    def quick(cls, **kw) -> "EvalConfig":
        """Small matrix for tests: the paper severities, one seed, four calibration runs."""
        base = dict(eval_seeds=(1,), healthy_seeds=(1,), calibration_seeds=tuple(range(1001, 1005)),
                    severity_indices=(PAPER_SEVERITY,))
        base.update(kw)
        return cls(**base)

    def check(self) -> None:
        used = set(self.eval_seeds) | set(self.healthy_seeds)
        overlap = used & set(self.calibration_seeds)
        if overlap:
            raise UserError(f"evaluation seeds {sorted(overlap)} are also calibration seeds: keep them disjoint")
        known = severities()
        for f in self.faults:
            if f not in known:
                raise UserError(f"no severities defined for fault {f!r}; known: {', '.join(known)}")
        if self.settings.residual_mean_k <= 0:
            raise UserError("residual_mean_k 0: the peers' reference value and the bands-only variant are the "
                            "detector's R statistic's; give it above 0")


# ---- one run ---------------------------------------------------------------------------------
@dataclass
class Calibrated:
    """What every run is scored with: our model, its bands-only variant, the residual's healthy RMS (in the
    reference's units) and the peers' thresholds."""
    model: LearnedModel
    bands_only: LearnedModel
    sigma: float
    unit: float  # the residual's unit in pH (the scenario's pH sensor noise)
    peers: dict[str, float]  # peer -> threshold
    peer_k: float  # the peers' reference value (half the design shift, residual sigmas)
    peer_window: int  # the peers' calibration window (samples)
    adwin_note: str = ""  # why ADWIN's delta is what it is, where it could not reach the target


@dataclass
class RunTask:
    scenario: str
    fault: str  # "healthy" or a library fault
    params: dict
    seed: int
    onset_s: float
    calibrated: Calibrated
    overrides: tuple[str, ...] = ()
    keep_signals: bool = False


def _spec(scenario: str, fault: str, params: dict, seed: int, onset_s: float | None, overrides=()):
    import yaml


    base = list(overrides) + [f"seed={seed}"]
    if fault == "healthy":
        return load_scenario(scenario, fault="healthy", overrides=base)
    if fault in CUSTOM_FAULTS:
        entry = dict(CUSTOM_FAULTS[fault], onset_s=onset_s)
        entry["params"] = {**entry["params"], **params}
        text = yaml.safe_dump([entry], default_flow_style=True).strip()
        return load_scenario(scenario, fault="healthy", overrides=base + [f"faults={text}"])
    return load_scenario(scenario, fault=fault, overrides=base + [f"faults.0.params.{k}={v}" for k, v in params.items()],
                         onset_s=onset_s)


def noise_free_ph(spec, ph_true: np.ndarray, t: np.ndarray) -> np.ndarray:
    """What the pH probe would read without measurement noise (its delay, lag and faults kept,
    noise faults removed)."""

    quiet = spec.model_copy(deep=True)
    quiet.sensors.ph.noise_std = 0.0
    quiet.faults = [f for f in quiet.faults if f.type != "sensor_noise"]
    chain = build_parts(quiet).process.ph_sensor
    chain.reset(float(ph_true[0]))
    return np.array([chain.step(float(x), float(tt)) for x, tt in zip(ph_true.tolist(), t.tolist())])


def bound_delay(signal: np.ndarray, t: np.ndarray, onset_s: float, arl0: float,
                variance_ratio: float = 1.0) -> tuple[float | None, float]:
    """(delay of the KL-information bound in s, effective SNR delta over that delay).

    Per sample after the onset the oracle gains s^2 / 2 (mean signal s in
    sigma) plus (rho - 1 - ln rho) / 2 (noise variance multiplied by rho).
    """
    after = t >= onset_s
    s = signal[after]
    tt = t[after]
    rho = variance_ratio
    info = np.cumsum(0.5 * s * s + 0.5 * (rho - 1.0 - math.log(rho)))
    hit = np.flatnonzero(info >= math.log(arl0))
    if not len(hit):
        return None, float(np.sqrt(np.mean(s * s))) if len(s) else math.nan
    j = int(hit[0])
    return float(tt[j] - onset_s), float(np.sqrt(np.mean(s[: j + 1] ** 2)))


def run_detector(model: LearnedModel, t: np.ndarray, rows: np.ndarray, record_trace: bool = False,
                 alarms: bool = True) -> LearnedDetector:
    """A whole run through a fresh detector (``learned_detector.run_record``), the detector after it."""
    return run_record(model, t, rows, record_trace=record_trace, alarms=alarms)[2]


def run_rows(run, channels) -> tuple[np.ndarray, np.ndarray]:
    """A simulated run's time and the reference's channels."""
    return np.asarray(run.time_s, float), np.column_stack([np.asarray(run[c], float) for c in channels])


def monitored(det: LearnedDetector) -> tuple[np.ndarray, np.ndarray]:
    """(mask of the monitored samples, the watched pH residual less the observer's level): after the warm-up,
    where the residual is neither missing nor held."""
    res = det.trace()["residual"][:, 0]
    mask = (np.arange(len(res)) >= det.fill_samples) & np.isfinite(res)
    return mask, res


def alarm_summary(a: dict) -> dict:
    """One alarm of ours as the tables read it: detection, onset (the namer's fitted onset where it gives one, else
    the statistic's), the statistic, and the named fault."""
    iso = a.get("isolation") or {}
    onset = (iso.get("evidence") or {}).get("onset_fit_s")  # the namer's fitted onset, as the physics detector's
    if onset is None:
        onset = a["onset_time"] if a.get("onset_time") is not None else a["detection_time"]
    return {"detection_time": float(a["detection_time"]), "onset_time": float(onset),
            "statistic": a["statistic"], "fault_class": iso.get("fault_class", "pending"),
            "confidence": iso.get("confidence"), "parameter": iso.get("parameter")}


def evaluate_run(task: RunTask) -> dict:
    """Simulate one run, run our detector (and its bands-only variant) and the peers on its residual, compute
    the bound."""
    cal = task.calibrated
    spec = _spec(task.scenario, task.fault, task.params, task.seed, task.onset_s, task.overrides)
    run = simulate(spec)
    t, rows = run_rows(run, cal.model.channels)
    det = run_detector(cal.model, t, rows, record_trace=True)
    mon, res = monitored(det)
    t_mon = t[mon]
    u = res[mon] / cal.sigma
    onset = task.onset_s if task.fault != "healthy" else None
    dt = spec.sample_time_s
    rec: dict = {"fault": task.fault, "params": task.params, "seed": task.seed, "onset_s": onset,
                 "monitored_s": float(len(t_mon) * dt),
                 "monitored_before_onset_s": float(np.sum(t_mon < onset) * dt) if onset else float(len(t_mon) * dt)}
    bands = run_detector(cal.bands_only, t, rows, record_trace=onset is None)
    rec["alarms"] = {"wavelet": [alarm_summary(a) for a in det.alarms],
                     "wavelet_bands": [{"detection_time": float(a["detection_time"])} for a in bands.alarms]}
    for name in PEERS:
        pos = Peer(name, cal.peers[name], cal.peer_k).alarms(u)
        rec["alarms"][name] = [{"detection_time": float(t_mon[p])} for p in pos]
    unit = cal.unit
    predicted = run["ph_measured"] - res * unit  # the model's pH prediction plus the observer's level
    if onset is None:  # held-out healthy data: window maxima to check the false-alarm calibration
        rec["window_maxima"] = heldout_maxima({"wavelet": det, "wavelet_bands": bands}, u, task)
    else:
        clean = noise_free_ph(spec, run["ph_true"], run.time_s)
        signal = (clean - predicted)[mon] / (cal.sigma * unit)
        rho = 1.0 + (task.params["std"] / (cal.sigma * unit)) ** 2 if task.fault == "probe_noise" else 1.0
        rec["bound_delay_s"], rec["snr_delta"] = bound_delay(signal, t_mon, onset, cal.model.settings.arl0_samples,
                                                             rho)
    if task.keep_signals:
        rec["signals"] = {"time_s": t, "ph_measured": np.asarray(run["ph_measured"], float),
                          "ph_predicted": predicted}
    return rec


def heldout_maxima(ours: dict[str, LearnedDetector], u: np.ndarray, task: RunTask) -> dict[str, list]:
    """Window maxima of every statistic on a healthy run: ours (and the bands-only variant's) on the windows their
    thresholds were measured on, each statistic's increments after the warm-up; the peers' on theirs."""
    out: dict[str, list] = {}
    for prefix, det in ours.items():
        z = det.trace()["increments"][det.fill_samples:]
        for j, name in enumerate(det.stat_names):
            out[f"{prefix}:{name}"] = window_maxima(z[:, j], ARL_WINDOW_SAMPLES).tolist()
    window, k = task.calibrated.peer_window, task.calibrated.peer_k
    out["cusum"] = np.maximum(window_maxima(u - k, window), window_maxima(-u - k, window)).tolist()
    windows = [u[i:i + window] for i in range(0, len(u) - window + 1, window)]
    out["focus"] = [_focus_window_max(w) for w in windows]
    out["page_hinkley"] = [_page_hinkley_window_max(w, k) for w in windows]
    return out


def heldout_arl(records: list[dict], summary_thresholds: dict, peer_window: int) -> dict[str, float | None]:
    """ARL0 (samples) of each detector estimated on the held-out healthy runs at its calibrated threshold(s):
    window / P(window max > h), from the same tail fit; a union sums its statistics' probabilities."""

    pooled: dict[str, list] = {}
    for r in records:
        for key, vals in r.get("window_maxima", {}).items():
            pooled.setdefault(key, []).extend(vals)
    out: dict[str, float | None] = {}
    for d in DETECTORS:
        th = summary_thresholds[d]
        window = ARL_WINDOW_SAMPLES if isinstance(th, dict) else peer_window
        try:
            if isinstance(th, dict):
                p = sum(tail_probability(np.array(pooled[f"{d}:{n}"]), h) for n, h in th.items())
            elif d in pooled:
                p = tail_probability(np.array(pooled[d]), th)
            else:
                out[d] = None
                continue
        except (KeyError, UserError):
            out[d] = None
            continue
        out[d] = window / p if p and math.isfinite(p) and p > 0 else None
    return out


# ---- calibration of everyone on the same healthy runs --------------------------------------
def _healthy_run(args) -> tuple[np.ndarray, np.ndarray]:
    scenario, seed, overrides, channels = args
    return run_rows(simulate(scenario_for_seed(scenario, overrides)(seed)), channels)


def _healthy_residual(args) -> np.ndarray:
    """A calibration run's monitored residual through the calibrated detector (no alarms, as calibrated)."""
    model, t, rows = args
    mask, res = monitored(run_detector(model, t, rows, record_trace=True, alarms=False))
    return res[mask]


def calibrate_all(cfg: EvalConfig, pool, say: Callable[[str], None]) -> Calibrated:
    """Our detector, its bands-only variant and the peers, calibrated on the same healthy runs."""
    spec = scenario_for_seed(cfg.scenario, cfg.overrides)(cfg.calibration_seeds[0])
    reference = PhysicsReference.from_spec(spec, **cfg.reference_options)
    settings = replace(cfg.settings, sample_time_s=spec.sample_time_s)
    say(f"calibration: {len(cfg.calibration_seeds)} healthy runs (seeds {cfg.calibration_seeds[0]}.."
        f"{cfg.calibration_seeds[-1]})")
    runs = list(pool.map(_healthy_run, [(cfg.scenario, s, cfg.overrides, reference.channels)
                                         for s in cfg.calibration_seeds]))
    source = {"seeds": list(cfg.calibration_seeds), "scenario": spec.name}
    say("calibration: our detector's band scales and thresholds, and without R (bands only)")
    model = calibrate_bands(reference, runs, settings, source)
    bands_only = calibrate_bands(reference, runs, replace(settings, residual_mean_k=0.0), source)
    streams = list(pool.map(_healthy_residual, [(model, t, rows) for t, rows in runs]))
    sigma = float(np.sqrt(np.mean(np.concatenate(streams) ** 2)))
    say("calibration: peers on the same residual streams")
    k = settings.residual_mean_k
    peers = calibrate_peers([x / sigma for x in streams], settings.arl0_samples, k, cfg.window_samples,
                            progress=lambda name: say(f"  calibrated {name}"))
    return Calibrated(model, bands_only, sigma, float(reference.noise[0]), {name: peers[name]["threshold"] for name in PEERS}, k,
                      cfg.window_samples, peers.get("adwin", {}).get("note", ""))


# ---- the matrix ------------------------------------------------------------------------------
def tasks(cfg: EvalConfig, cal: Calibrated) -> list[RunTask]:
    out = [RunTask(cfg.scenario, "healthy", {}, s, cfg.onset_s, cal, cfg.overrides) for s in cfg.healthy_seeds]
    for fault in cfg.faults:
        _, levels = severities()[fault]
        for i in cfg.severity_indices:
            for s in cfg.eval_seeds:
                keep = i == PAPER_SEVERITY and s == cfg.eval_seeds[0] and fault == "backlash"
                out.append(RunTask(cfg.scenario, fault, levels[i], s, cfg.onset_s, cal, cfg.overrides,
                                   keep_signals=keep))
    return out


def run_evaluation(cfg: EvalConfig, out_dir: str | Path, progress: Callable[[str], None] | None = None) -> dict:
    """Calibrate, run the matrix, write DIR/evaluation.md, DIR/results.json, DIR/reference.json (our calibrated
    detector: ``phfdi replay RUN --reference DIR/reference.json``), DIR/peers.json and the figures."""
    cfg.check()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    with ProcessPoolExecutor(max_workers=max(1, cfg.jobs)) as pool:
        cal = calibrate_all(cfg, pool, say)
        cal.model.save(out / "reference.json")
        write_text(out / "peers.json", json.dumps(_peers_file(cal), indent=1), overwrite=True)
        todo = tasks(cfg, cal)
        say(f"evaluation: {len(todo)} runs")
        records = []
        for i, rec in enumerate(pool.map(evaluate_run, todo)):
            records.append(rec)
            say(f"  [{i + 1}/{len(todo)}] {rec['fault']} {rec['params']} seed {rec['seed']}")
    signals = next((r.pop("signals") for r in records if "signals" in r), None)
    summary = summarise(records, cfg, cal)
    write_text(out / "results.json", json.dumps({"config": _config_dict(cfg), "summary": summary,
                                                 "runs": records}, indent=1, default=_json_default), overwrite=True)
    write_text(out / "evaluation.md", markdown(summary, cfg), overwrite=True)

    plot_evaluation(summary, records, out, signals, cal.model.settings)
    say(f"wrote {out / 'evaluation.md'}, results.json, reference.json, peers.json and figures")
    return summary


def _peers_file(cal: Calibrated) -> dict:
    """The peers' thresholds and what they are calibrated on, and the bands-only variant's thresholds."""
    return {"residual_sigma": cal.sigma, "residual_unit": "the scenario's pH sensor noise",
            "reference_value_k": cal.peer_k, "window_samples": cal.peer_window,
            "arl0_samples": cal.model.settings.arl0_samples, "thresholds": cal.peers,
            "wavelet_bands": cal.bands_only.thresholds}


def _config_dict(cfg: EvalConfig) -> dict:
    d = asdict(cfg)
    d["settings"] = asdict(cfg.settings)
    return d


def _json_default(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    return str(x)


# ---- summary -------------------------------------------------------------------------------------
def first_after(alarms: list[dict], onset: float) -> dict | None:
    return next((a for a in alarms if a["detection_time"] >= onset), None)


def summarise(records: list[dict], cfg: EvalConfig, cal: Calibrated) -> dict:
    # healthy operation, each noise realisation once: a faulty run is its seed's healthy run until
    # the onset, so its pre-onset part counts only when that seed has no healthy run
    hours = 0.0
    false = {d: 0 for d in DETECTORS}
    healthy_seeds = {r["seed"] for r in records if r["fault"] == "healthy"}
    segments = [r for r in records if r["fault"] == "healthy"]
    for r in records:
        if r["fault"] != "healthy" and r["seed"] not in healthy_seeds:
            healthy_seeds.add(r["seed"])
            segments.append(r)
    for r in segments:
        hours += r["monitored_before_onset_s"] / 3600.0
        limit = r["onset_s"] if r["onset_s"] is not None else math.inf
        for d in DETECTORS:
            false[d] += sum(1 for a in r["alarms"][d] if a["detection_time"] < limit)
    rows = []
    for fault in cfg.faults:
        pname, levels = severities()[fault]
        for i in cfg.severity_indices:
            runs = [r for r in records if r["fault"] == fault and r["params"] == levels[i]]
            row = {"fault": fault, "param": pname, "value": levels[i][pname],
                   "paper": i == PAPER_SEVERITY and fault not in CUSTOM_FAULTS, "expected": EXPECTED_CLASS.get(fault, fault),
                   "runs": len(runs), "delay": {}, "missed": {}, "early": {}}
            for d in DETECTORS:
                delays, missed, early = [], 0, 0
                for r in runs:
                    early += sum(1 for a in r["alarms"][d] if a["detection_time"] < r["onset_s"])
                    a = first_after(r["alarms"][d], r["onset_s"])
                    if a is None:
                        missed += 1
                    else:
                        delays.append(a["detection_time"] - r["onset_s"])
                row["delay"][d] = float(np.mean(delays)) if delays else None
                row["missed"][d] = missed
                row["early"][d] = early
            bounds = [r["bound_delay_s"] for r in runs if r.get("bound_delay_s") is not None]
            row["bound_s"] = float(np.mean(bounds)) if bounds else None
            row["bound_missing"] = sum(1 for r in runs if r.get("bound_delay_s") is None)
            row["snr_delta"] = float(np.mean([r["snr_delta"] for r in runs])) if runs else None
            classes, estimates, onsets = [], [], []
            for r in runs:
                a = first_after(r["alarms"]["wavelet"], r["onset_s"])
                if a is None:
                    continue
                classes.append(a["fault_class"])
                onsets.append(a["onset_time"] - r["onset_s"])
                p = a.get("parameter")
                if a["fault_class"] == fault and p and p.get("name") == pname:
                    estimates.append(p["value"])
            row["classes"] = classes
            row["correct"] = sum(1 for c in classes if c == row["expected"])
            row["estimates"] = estimates
            row["param_rel_error"] = (float(np.mean([abs(e - levels[i][pname]) / abs(levels[i][pname])
                                                     for e in estimates])) if estimates else None)
            row["onset_error_s"] = float(np.mean(np.abs(onsets))) if onsets else None
            rows.append(row)
    thresholds = {"wavelet": cal.model.thresholds, "wavelet_bands": cal.bands_only.thresholds, **cal.peers}
    return {"rows": rows, "heldout_arl0": heldout_arl(records, thresholds, cal.peer_window),
            "false_alarms": false, "healthy_hours": hours,
            "false_per_hour": {d: false[d] / hours if hours else None for d in DETECTORS},
            "arl0_samples": cal.model.settings.arl0_samples, "thresholds": thresholds,
            "sigma_ph": cal.sigma * cal.unit,
            "watched": list(cal.model.residual_channels), "adwin_note": cal.adwin_note}


def _fmt(x, spec: str = ".0f", none: str = "-") -> str:
    return none if x is None else format(x, spec)


def markdown(summary: dict, cfg: EvalConfig) -> str:
    s = cfg.settings
    lines = [f"# Detector evaluation: {cfg.scenario} scenario, faults at {cfg.onset_s:g} s", "",
             f"ARL0 = {summary['arl0_samples']:g} samples for every detector (thresholds calibrated on healthy seeds "
             f"{cfg.calibration_seeds[0]}..{cfg.calibration_seeds[-1]}; evaluation seeds {list(cfg.eval_seeds)}, "
             f"healthy seeds {list(cfg.healthy_seeds)}). Ours: the multichannel detector with the scenario's physics "
             f"as its reference (phfdi calibrate; reference.json), {s.wavelet} level {s.level}, watching "
             f"{', '.join(summary['watched'])}. Residual noise sigma = {summary['sigma_ph']:.4f} pH.", "",
             "## Detection delay (s after the onset; mean over the seeds that detected; +N missed)", "",
             "| fault | parameter | " + " | ".join(LABELS[d] for d in DETECTORS) + " | bound | delta |",
             "|---|---|" + "---:|" * (len(DETECTORS) + 2)]
    for r in summary["rows"]:
        cells = []
        for d in DETECTORS:
            c = _fmt(r["delay"][d])
            if r["missed"][d]:
                c += f" (+{r['missed'][d]} missed)"
            if r["early"][d]:
                c += f" [{r['early'][d]} early]"
            cells.append(c)
        bound = _fmt(r["bound_s"]) + (f" (+{r['bound_missing']})" if r["bound_missing"] else "")
        star = " (paper)" if r["paper"] else ""
        lines.append(f"| {r['fault']} | {r['param']} = {r['value']:g}{star} | " + " | ".join(cells)
                     + f" | {bound} | {_fmt(r['snr_delta'], '.2f')} |")
    lines += ["", "bound: delay of an oracle that knows the fault's noise-free residual (KL information "
              "ln ARL0); delta: RMS of that residual over the bound's interval, in sigma; "
              "[N early]: alarms before the onset in the faulty runs of this row (a faulty run is the healthy "
              "run of its seed until the onset: the same false alarms as in the table below).", "",
              f"## False alarms ({summary['healthy_hours']:.1f} h of monitored healthy operation, each noise "
              "seed once)", "",
              "| detector | threshold | false alarms | per hour | ARL0 estimated on these runs (samples) |",
              "|---|---:|---:|---:|---:|"]
    for d in DETECTORS:
        th = summary["thresholds"][d]
        th_s = ", ".join(f"{k.split('.', 1)[1]} {v:.1f}" for k, v in th.items()) if isinstance(th, dict) else (
            f"delta {th:.3g}" if d == "adwin" else f"{th:.2f}")
        lines.append(f"| {LABELS[d]} | {th_s} | {summary['false_alarms'][d]} | "
                     f"{_fmt(summary['false_per_hour'][d], '.3f')} | {_fmt(summary['heldout_arl0'][d], '.2g')} |")
    lines += ["", f"Target: ARL0 = {summary['arl0_samples']:g} samples, {3600.0 / summary['arl0_samples']:.3f} "
              "false alarms per hour at 1 s. The ARL0 column re-fits the calibration's window-maximum tails on "
              "the held-out healthy runs (a union of statistics sums their probabilities, so it is a lower "
              "estimate); ADWIN's delta was set by counting its alarms and has no such statistic."]
    if summary["adwin_note"]:
        lines += ["", f"ADWIN: {summary['adwin_note']}."]
    lines += ["", "## Isolation and parameter estimates (ours)", "",
              "| fault | parameter | correct | classes given | estimates | mean relative error | onset error (s) |",
              "|---|---|---:|---|---|---:|---:|"]
    for r in summary["rows"]:
        classes = ", ".join(f"{c} {r['classes'].count(c)}" for c in sorted(set(r["classes"]))) or "-"
        est = ", ".join(f"{e:.3g}" for e in r["estimates"]) or "-"
        lines.append(f"| {r['fault']} | {r['param']} = {r['value']:g} | {r['correct']}/{r['runs']} "
                     f"({r['expected']}) | {classes} | "
                     f"{est} | {_fmt(r['param_rel_error'], '.1%')} | {_fmt(r['onset_error_s'], '.0f')} |")
    return "\n".join(lines) + "\n"
