"""Scenario-matrix evaluation of the detector against peers at equal false-alarm rate.

``phfdi evaluate`` runs: healthy runs and each fault at three severities
(the paper's in the middle) with several noise seeds, faults at ``onset_s``.
Calibration (ours and the peers') uses healthy runs with seeds disjoint from
the evaluation's. Every detector sees the same residual stream (our
reference model's pH residual over the monitored samples) and is held to the
same ARL0. For each faulty run the delay bound is the time an oracle that
knows the fault's noise-free residual signal s_t needs to gather ln(ARL0) of
Kullback-Leibler information, sum s_t^2 / (2 sigma^2) (the CUSUM/Lorden
bound; for a constant shift of delta sigma it is 2 ln(ARL0) / delta^2).
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

from phfdi.calibration import healthy_traces, scenario_for_seed
from phfdi.faults import catalogue
from phfdi.loop import build_parts, simulate
from phfdi.replay import run_chunks
from phfdi.scenario import load_scenario
from phfdi.study.detector_figures import plot_evaluation
from phfdi_base.errors import UserError
from phfdi_base.outputs import write_text
from wavelet_fdi.calibration import calibrate_from_traces, statistic_increments, tail_probability, window_maxima
from wavelet_fdi.config import Calibration, DetectorSettings
from wavelet_fdi.detector import StreamingDetector
from wavelet_fdi.peers import (
    DETECTORS,
    LABELS,
    PEERS,
    Peer,
    _focus_window_max,
    _page_hinkley_window_max,
    calibrate_peers,
)
from wavelet_fdi.statistics import CusumBank

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
    #: calibration window (samples): much shorter than ARL0, long against the statistics' memory
    window_samples: int = 1000
    settings: DetectorSettings = field(default_factory=DetectorSettings)
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


# ---- one run ---------------------------------------------------------------------------------
@dataclass
class RunTask:
    scenario: str
    fault: str  # "healthy" or a library fault
    params: dict
    seed: int
    onset_s: float
    settings: DetectorSettings
    calibration: Calibration
    peers: dict[str, float]  # peer -> threshold
    bands_only: dict[str, float]  # thresholds of the paper's bands without R (detection-only ablation)
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


def alarm_positions(z: np.ndarray, h: np.ndarray, clear_samples: int, quiet_samples: int | None = None,
                    clear_fraction: float = 0.5) -> list[int]:
    """Alarms of a union of CUSUMs on increments z (n, N): the detector's raise/confirm/clear logic
    (a crossing within clear_samples of the previous one confirms the alarm instead of raising one, unless the
    alarm cleared before it: every statistic below clear_fraction of its threshold for quiet_samples)."""

    out: list[int] = []
    pos, last, active, loud_last = 0, -1, False, -1
    n = z.shape[1]
    bank = CusumBank(z.shape[0])
    while pos < n:
        end = min(n, pos + 65536)
        s = bank.update(z[:, pos:end], pos)
        over = np.flatnonzero((s > h[:, None]).any(axis=0))
        stop = end if not len(over) else pos + int(over[0]) + 1  # values after a crossing are restarted
        if quiet_samples is not None:
            gi = np.arange(pos, stop)
            loud = (s[:, :stop - pos] >= clear_fraction * h[:, None]).any(axis=0)
            last_loud = np.maximum.accumulate(np.where(loud, gi, loud_last))
            if active and ((gi - last_loud >= quiet_samples) & (gi > last)).any():
                active = False
            loud_last = int(last_loud[-1])
        if not len(over):
            pos = end
            continue
        x = stop - 1
        if not active or x - last > clear_samples:
            out.append(x)
        last, active = x, True
        bank.restart(x)
        pos = x + 1
    return out


def evaluate_run(task: RunTask) -> dict:
    """Simulate one run, run our detector and the peers on its residual, compute the bound."""


    spec = _spec(task.scenario, task.fault, task.params, task.seed, task.onset_s, task.overrides)
    run = simulate(spec)
    det = StreamingDetector(spec, task.calibration, task.settings, isolate=True, record_trace=True)
    run_chunks(det, run)
    tr = det.trace()
    sigma = task.calibration.sigma["ph"]["raw"]
    mon = tr["ph_monitored"]
    t_mon = tr["time_s"][mon]
    u = tr["ph_residual"][mon] / sigma
    onset = task.onset_s if task.fault != "healthy" else None
    rec: dict = {"fault": task.fault, "params": task.params, "seed": task.seed, "onset_s": onset,
                 "monitored_s": float(len(t_mon) * spec.sample_time_s),
                 "monitored_before_onset_s": float(np.sum(t_mon < onset) * spec.sample_time_s) if onset else
                 float(len(t_mon) * spec.sample_time_s)}
    rec["alarms"] = {"wavelet": [a.summary() for a in det.alarms]}
    bands = replace(task.settings, raw_band=False)
    names = bands.statistic_names()
    z = np.vstack([statistic_increments(tr, n, task.calibration.sigma, bands) for n in names])
    h = np.array([task.bands_only[n] for n in names])
    rec["alarms"]["wavelet_bands"] = [{"detection_time": float(t_mon[p])}
                                      for p in alarm_positions(z, h, det.clear_samples, det.quiet_samples,
                                                                 det.settings.clear_fraction)]
    for name in PEERS:
        pos = Peer(name, task.peers[name], 0.5 * task.settings.mean_shift_sigma).alarms(u)
        rec["alarms"][name] = [{"detection_time": float(t_mon[p])} for p in pos]
    if onset is None:  # held-out healthy data: window maxima to check the false-alarm calibration
        rec["window_maxima"] = heldout_maxima(tr, u, task)
    if onset is not None:
        clean = noise_free_ph(spec, run["ph_true"], run.time_s)
        signal = (clean - tr["ph_predicted"])[mon] / sigma
        rho = 1.0 + (task.params["std"] / sigma) ** 2 if task.fault == "probe_noise" else 1.0
        rec["bound_delay_s"], rec["snr_delta"] = bound_delay(signal, t_mon, onset, task.settings.arl0_samples, rho)
    if task.keep_signals:
        rec["signals"] = {"time_s": tr["time_s"], "ph_measured": tr["ph_measured"], "ph_predicted": tr["ph_predicted"]}
    return rec


def heldout_maxima(tr: dict, u: np.ndarray, task: RunTask) -> dict[str, list]:
    """Window maxima (calibration windows) of every statistic on a healthy run."""

    window = task.calibration.window_samples
    k = 0.5 * task.settings.mean_shift_sigma
    out: dict[str, list] = {}
    for prefix, settings in (("wavelet", task.settings), ("wavelet_bands", replace(task.settings, raw_band=False))):
        for name in settings.statistic_names():
            z = statistic_increments(tr, name, task.calibration.sigma, settings)
            out[f"{prefix}:{name}"] = window_maxima(z, window).tolist()
    out["cusum"] = np.maximum(window_maxima(u - k, window), window_maxima(-u - k, window)).tolist()
    windows = [u[i:i + window] for i in range(0, len(u) - window + 1, window)]
    out["focus"] = [_focus_window_max(w) for w in windows]
    out["page_hinkley"] = [_page_hinkley_window_max(w, k) for w in windows]
    return out


def heldout_arl(records: list[dict], summary_thresholds: dict, window: int) -> dict[str, float | None]:
    """ARL0 (samples) of each detector estimated on the held-out healthy runs at its calibrated threshold(s):
    L / P(window max > h), from the same tail fit; a union sums its statistics' probabilities."""

    pooled: dict[str, list] = {}
    for r in records:
        for key, vals in r.get("window_maxima", {}).items():
            pooled.setdefault(key, []).extend(vals)
    out: dict[str, float | None] = {}
    for d in DETECTORS:
        th = summary_thresholds[d]
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
def _calibration_trace(args) -> dict:
    scenario, seed, settings, overrides = args

    tr = healthy_traces(scenario_for_seed(scenario, overrides), [seed], settings)[0]
    keep = ("ph_residual", "level_residual_cm", "ph_monitored", "level_monitored", "ph_coefficients",
            "level_coefficients")
    return {k: tr[k] for k in keep}


def calibrate_all(cfg: EvalConfig, pool, say: Callable[[str], None]) -> tuple[Calibration, dict]:

    say(f"calibration: {len(cfg.calibration_seeds)} healthy runs (seeds {cfg.calibration_seeds[0]}.."
        f"{cfg.calibration_seeds[-1]})")
    traces = list(pool.map(_calibration_trace, [(cfg.scenario, s, cfg.settings, cfg.overrides)
                                                 for s in cfg.calibration_seeds]))
    dt = scenario_for_seed(cfg.scenario, cfg.overrides)(cfg.calibration_seeds[0]).sample_time_s
    cal = calibrate_from_traces(traces, cfg.settings, cfg.scenario, dt, cfg.calibration_seeds, cfg.window_samples)
    bands = calibrate_from_traces(traces, replace(cfg.settings, raw_band=False), cfg.scenario, dt,
                                  cfg.calibration_seeds, cfg.window_samples)
    sigma = cal.sigma["ph"]["raw"]
    streams = [t["ph_residual"][t["ph_monitored"]] / sigma for t in traces]
    say("calibration: peers on the same residual streams")
    peers = calibrate_peers(streams, cfg.settings.arl0_samples, 0.5 * cfg.settings.mean_shift_sigma,
                            cal.window_samples, progress=lambda name: say(f"  calibrated {name}"))
    peers["wavelet_bands"] = {"thresholds": bands.thresholds, "method": "as ours, paper bands only"}
    cal.peers = peers
    return cal, peers


# ---- the matrix ------------------------------------------------------------------------------
def tasks(cfg: EvalConfig, cal: Calibration, peers: dict) -> list[RunTask]:
    thresholds = {k: peers[k]["threshold"] for k in PEERS}
    bands = peers["wavelet_bands"]["thresholds"]
    out = [RunTask(cfg.scenario, "healthy", {}, s, cfg.onset_s, cfg.settings, cal, thresholds, bands, cfg.overrides)
           for s in cfg.healthy_seeds]
    for fault in cfg.faults:
        _, levels = severities()[fault]
        for i in cfg.severity_indices:
            for s in cfg.eval_seeds:
                keep = i == PAPER_SEVERITY and s == cfg.eval_seeds[0] and fault == "backlash"
                out.append(RunTask(cfg.scenario, fault, levels[i], s, cfg.onset_s, cfg.settings, cal, thresholds,
                                   bands, cfg.overrides, keep_signals=keep))
    return out


def run_evaluation(cfg: EvalConfig, out_dir: str | Path, progress: Callable[[str], None] | None = None) -> dict:
    """Calibrate, run the matrix, write DIR/evaluation.md, DIR/results.json and the figures."""
    cfg.check()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda msg: print(msg, file=sys.stderr, flush=True))
    with ProcessPoolExecutor(max_workers=max(1, cfg.jobs)) as pool:
        cal, peers = calibrate_all(cfg, pool, say)
        cal.save(out / "calibration.yaml")
        todo = tasks(cfg, cal, peers)
        say(f"evaluation: {len(todo)} runs")
        records = []
        for i, rec in enumerate(pool.map(evaluate_run, todo)):
            records.append(rec)
            say(f"  [{i + 1}/{len(todo)}] {rec['fault']} {rec['params']} seed {rec['seed']}")
    signals = next((r.pop("signals") for r in records if "signals" in r), None)
    summary = summarise(records, cfg, cal, peers)
    write_text(out / "results.json", json.dumps({"config": _config_dict(cfg), "summary": summary,
                                                 "runs": records}, indent=1, default=_json_default), overwrite=True)
    write_text(out / "evaluation.md", markdown(summary, cfg, cal, peers), overwrite=True)

    plot_evaluation(summary, records, out, signals, cfg.settings)
    say(f"wrote {out / 'evaluation.md'}, results.json and figures")
    return summary


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


def summarise(records: list[dict], cfg: EvalConfig, cal: Calibration, peers: dict) -> dict:
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
    thresholds = {"wavelet": cal.thresholds, "wavelet_bands": peers["wavelet_bands"]["thresholds"],
                  **{k: peers[k]["threshold"] for k in PEERS}}
    return {"rows": rows, "heldout_arl0": heldout_arl(records, thresholds, cal.window_samples),
            "false_alarms": false, "healthy_hours": hours,
            "false_per_hour": {d: false[d] / hours if hours else None for d in DETECTORS},
            "arl0_samples": cfg.settings.arl0_samples, "thresholds": thresholds,
            "sigma_ph": cal.sigma["ph"]["raw"], "adwin_note": peers.get("adwin", {}).get("note", "")}


def _fmt(x, spec: str = ".0f", none: str = "-") -> str:
    return none if x is None else format(x, spec)


def markdown(summary: dict, cfg: EvalConfig, cal: Calibration, peers: dict) -> str:
    s = cfg.settings
    lines = [f"# Detector evaluation: {cfg.scenario} scenario, faults at {cfg.onset_s:g} s", "",
             f"ARL0 = {s.arl0_samples:g} samples for every detector (thresholds calibrated on healthy seeds "
             f"{cfg.calibration_seeds[0]}..{cfg.calibration_seeds[-1]}; evaluation seeds {list(cfg.eval_seeds)}, "
             f"healthy seeds {list(cfg.healthy_seeds)}). Ours: {s.wavelet} level {s.level}, channels "
             f"{', '.join(s.channels)}. Residual noise sigma = {summary['sigma_ph']:.4f} pH.", "",
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
