"""Model diagnosis: what the nominal model gets wrong, which cause explains it, and the gain.

:func:`diagnose` takes measured records and a nominal model (a scenario
mapping) and

1. simulates the nominal model open loop on each record and analyses the
   residual (:mod:`.residual`);
2. fits every catalogue candidate (:mod:`.catalogue`, :mod:`.fit`) on the
   training samples, in worker processes, and scores it on held-out samples
   (interleaved blocks of each record, or separate validation records);
3. decides (the rules, with their thresholds in :class:`Options`):

   * a candidate *counts* when its held-out squared error is significantly
     below the nominal's (batch-means t-test, p < ``alpha``) and it lowers
     the held-out RMSE by at least ``min_gain``;
   * the winner is the counting candidate with the lowest held-out error;
     a candidate with fewer parameters that the winner does not beat
     significantly (p < 0.05) takes its place (stiction with J = 0 *is*
     backlash);
   * ``explained`` when the winner's held-out error is at the noise floor:
     within ``floor_ratio`` (1.1) times it with no gross structure left
     (structure index (Q - lags) / n <= ``floor_max_structure``), or within
     ``explained_ratio`` (1.5) times it and white (Ljung-Box p >=
     ``whiteness_alpha``);
     otherwise pairs of the best single candidates are fitted, and if none
     gets there, ``not_explained`` with the closest family and its honest
     gain;
   * ``none`` when the nominal model is already within ``explained_ratio`` of
     the noise floor, or no candidate counts and the misfit is small;
   * ``not_identifiable`` when no input moves (and the records start at rest).
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ph_plant_sim.build import build_plant, load_plant_model
from phfdi.records import Record
from phfdi_base.spec import PlantModelSpec

from .catalogue import Context
from .fit import FitResult, Fitter, Problem, fit_task, init_worker, one_blas_thread
from .model import Evaluator, Prediction
from .report import check_report, family_of
from .residual import analyse, noise_floor, significance, significance_f

UNITS = {"ph_measured": "pH", "level_measured_cm": "cm"}


@dataclass
class Options:
    """The diagnosis's choices and the decision rules' thresholds (see the module docstring).

    Examples
    --------
    >>> from phfdi.diagnosis import Options
    >>> options = Options(candidates=["backlash", "sensor_delay"], workers=1)
    >>> options.blocks, options.alpha, options.min_gain  # held-out blocks, significance, least gain
    (8, 0.01, 0.05)
    """

    initial: str = "steady"
    candidates: list[str] | None = None
    pairs: bool = True
    workers: int | None = None
    blocks: int = 8  # interleaved train/validation blocks when no validation record is given
    alpha: float = 0.01
    min_gain: float = 0.05
    explained_ratio: float = 1.5
    floor_ratio: float = 1.1  # within this of the noise floor, what structure is left is below 17 % of the error
    whiteness_alpha: float = 1e-3  # Ljung-Box p-value below which a held-out error still has structure
    # Near the floor a right model may leave mild structure (in the benchmark: index up to 0.07, Ljung-Box p down
    # to 1e-9), a wrong pair mimicking an effect gross structure (an alkaline probe error: 0.27 and 0.86). The
    # index, unlike p, does not grow with the record length.
    floor_max_structure: float = 0.15
    progress: Callable[[str], None] | None = None
    #: forward structure search: the structural candidates join the catalogue, and effects are added one at a
    #: time (the one with the largest held-out gain, all refitted jointly) while the addition counts
    structure: bool = False
    search_width: int = 6  # candidates (best single held-out gains) tried at each step of the search
    search_steps: int = 5  # at most this many effects
    groups: list[str] | None = None  # per record (fit records, then validation records): its group
    adapt: float = 0.0  # fraction of an unseen group's record on which its declared parameters are fitted
    #: fit exactly these candidates (labels) jointly and nothing else: no single-cause ranking, no search (a set
    #: chosen elsewhere, e.g. on other records); the report's structure_search is nominal -> this set, whatever
    #: its held-out score. Implies the structural candidates; ``effects_start``: its start point (default: grid)
    effects: list[str] | None = None
    effects_start: dict | None = None
    #: set the fit up from the fit records only: the candidates' search context (bounds and start points: the
    #: pH quantiles, the longest duration, the largest feed flows) and the noise unit. The validation records then
    #: enter only through the samples that set their own start (and adapt an unseen group) and the score: what a
    #: prediction benchmark needs of its held-out records (benchmarks/rig_holdout.py). Default False: from every
    #: record, as ``phfdi diagnose --validate`` does, whose validation records are a selection set by design
    setup_from_fit: bool = False


@dataclass
class Diagnosis:
    """The report (JSON-ready) and what the figures need.

    Examples
    --------
    >>> from phfdi.diagnosis import Diagnosis
    >>> Diagnosis({"verdict": "none"}).records
    []
    """

    report: dict
    records: list[Record] = field(default_factory=list)
    train: list[np.ndarray] = field(default_factory=list)
    val: list[np.ndarray] = field(default_factory=list)
    nominal: list[Prediction] = field(default_factory=list)
    extended: list[Prediction] | None = None
    extended_raw: dict | None = None
    noise: dict = field(default_factory=dict)
    extended_starts: list = field(default_factory=list)
    extended_record_raws: list = field(default_factory=list)
    structure: FitResult | None = None  # the structure search's final model (None: nominal, or no search)
    structure_preds: list[Prediction] | None = None
    singles: list[FitResult] = field(default_factory=list)  # every single candidate's fit (its held-out starts)
    search_fits: list[FitResult] = field(default_factory=list)  # every model the structure search scored
    context: Context | None = None  # the candidates' search context (bounds, start points) the fits used


def _say(opts: Options, text: str) -> None:
    if opts.progress is not None:
        opts.progress(text)


def split(records_fit: list[Record], records_val: list[Record], blocks: int):
    """Records and per-record train/validation masks."""
    if records_val:
        records = records_fit + records_val
        train = [np.ones(len(r), bool) for r in records_fit] + [np.zeros(len(r), bool) for r in records_val]
        val = [np.zeros(len(r), bool) for r in records_fit] + [np.ones(len(r), bool) for r in records_val]
        note = (f"fitted on {', '.join(r.name for r in records_fit)}; validated on "
                f"{', '.join(r.name for r in records_val)}")
        return records, train, val, note
    train, val = [], []
    for r in records_fit:
        block = (np.arange(len(r)) * blocks) // len(r)
        train.append(block % 2 == 0)
        val.append(block % 2 == 1)
    note = (f"each record cut into {blocks} interleaved blocks: blocks 1, 3, 5, ... fitted, 2, 4, 6, ... held out "
            f"(the simulation runs through all; held-out measurements are never fitted)")
    return list(records_fit), train, val, note


def context_for(nominal: dict, records: list[Record], outputs: list[str]) -> Context:
    """What the catalogue needs to set its bounds and start points: the nominal model and the data's ranges."""

    model = load_plant_model(PlantModelSpec.model_validate(nominal["plant"]))
    plant = build_plant(model)
    feeds = [f.name for f in plant.feeds]
    valve = nominal["valves"]["ph"]
    has_cmd = all("valve_command_pct" in r.inputs for r in records)
    cmd = np.concatenate([r.inputs["valve_command_pct"] for r in records]) if has_cmd else np.zeros(0)
    phs = np.concatenate([r.outputs["ph_measured"] for r in records if "ph_measured" in r.outputs] or [np.zeros(1)])
    ev = Evaluator(records[0], nominal)
    flows = ev.flows(ev.nominal_spec)[0]  # the nominal feeds' flows: the scale of a disturbance
    strength = {f.name: max(c for c in conc) if conc else 0.0 for f, conc in zip(plant.feeds, plant.feed_conc)}
    all_flows = [Evaluator(r, nominal).flows(ev.nominal_spec)[0] for r in records]
    flow_max = {f: float(max(np.max(q[:, j]) for q in all_flows)) for j, f in enumerate(feeds)}
    basic = tuple(f.name for f, conc in zip(plant.feeds, plant.feed_conc) if plant.balance.ph(conc) > 7.0)
    if plant.tank.overflow:
        volume = float(plant.tank.volume_ml)
    else:  # a gravity tank at the level that passes the mean inflow with the outlet half open
        q = max(float(np.mean(flows.sum(axis=1))), 1e-6)
        volume = max(plant.tank.outlet.level_for_flow(q, 0.5), 1.0) * plant.tank.area_cm2
    return Context(
        feeds=feeds, valve_feed=valve["feed"], valve_max_flow_ml_s=float(valve["max_flow_ml_s"]),
        overflow=plant.tank.overflow, has_command=has_cmd,
        command_pct=cmd, ph_range=(float(np.quantile(phs, 0.01)), float(np.quantile(phs, 0.99))),
        duration_s=max(float(r.time_s[-1] - r.time_s[0]) for r in records), dt_s=records[0].dt_s,
        total_inflow_ml_s=float(np.mean(flows.sum(axis=1))), feed_strength_mol_l=strength, outputs=set(outputs),
        vessel_volume_ml=volume, feed_max_flow_ml_s=flow_max, basic_feeds=basic)


def _identifiable(records: list[Record], initial: str, noise: dict) -> str | None:
    """Why nothing can be identified, or None."""
    moving = [r for r in records if not r.constant_inputs()]
    if moving:
        return None
    names = ", ".join(sorted({k for r in records for k in r.inputs}))
    if initial == "steady":
        return (f"every input ({names}) is constant over the data and the model starts at rest: the data cannot "
                f"tell one model from another, so no cause is named (give a record in which the inputs move, or "
                f"--initial fit for a record that starts away from steady state)")
    for r in records:
        for o, y in r.outputs.items():
            if float(np.std(y)) > 3.0 * noise.get(o, 0.0):
                return None
    return (f"every input ({names}) is constant and no output moves beyond its noise: nothing to identify, "
            f"no cause is named")


def diagnose(records_fit: list[Record], records_val: list[Record], nominal: dict, model_name: str,
             options: Options | None = None) -> Diagnosis:
    """Diagnose the nominal model on measured records (the steps and rules of the module docstring).

    Parameters
    ----------
    records_fit : list of Record
        Records the candidates are fitted on (held-out blocks of them score the fits when
        ``records_val`` is empty).
    records_val : list of Record
        Records that only score the fits.
    nominal : dict
        The nominal model, a scenario mapping with its plant inline (:func:`nominal_raw`).
    model_name : str
        Its name, for the report.
    options : Options, optional

    Returns
    -------
    Diagnosis

    Examples
    --------
    >>> import numpy as np
    >>> from phfdi.diagnosis import diagnose, make_record, nominal_raw
    >>> noise = np.random.default_rng(0).normal(0.0, 0.01, 600)
    >>> at_rest = make_record({"time_s": np.arange(600.0), "acid_flow_ml_s": np.full(600, 9.82),
    ...                        "ph_measured": 12.0 + noise}, "at_rest")
    >>> report = diagnose([at_rest], [], nominal_raw("paper"), "paper").report
    >>> report["verdict"], report["cause"]  # no input moves: no record can tell models apart
    ('not_identifiable', 'none')
    """
    with one_blas_thread():  # tiny matrices, thousands of times: BLAS threads only wait (fit.one_blas_thread)
        return _diagnose(records_fit, records_val, nominal, model_name, options)


def _diagnose(records_fit: list[Record], records_val: list[Record], nominal: dict, model_name: str,
              options: Options | None = None) -> Diagnosis:
    opts = options or Options()
    t_start = time.perf_counter()
    for rec in records_fit + records_val:
        _drop_unknown_feeds(rec, nominal)
    records, train, val, split_note = split(records_fit, records_val, opts.blocks)
    outputs = [o for o in ("ph_measured", "level_measured_cm") if any(o in r.outputs for r in records)]
    setup = list(records_fit) if opts.setup_from_fit and records_fit else records  # Options.setup_from_fit
    noise = {o: float(np.median([noise_floor(r.outputs[o]) for r in setup if o in r.outputs])) for o in outputs}
    scale = {o: float(np.std(np.concatenate([r.outputs[o] for r in records if o in r.outputs]))) or 1.0
             for o in outputs}
    notes = [f"{r.name}: {n}" for r in records for n in r.notes] + [split_note]
    why = _identifiable(records, opts.initial, noise)
    if why is not None:
        report = _not_identifiable(_base_report(model_name, records, outputs, noise, notes), why)
        return Diagnosis(check_report(report), records, train, val, noise=noise)
    ctx = context_for(nominal, setup, outputs)
    problem = Problem(records, nominal, opts.initial, train, val, noise, scale, outputs, ctx, opts.candidates,
                      structure=opts.structure or opts.effects is not None, groups=opts.groups, adapt=opts.adapt)
    local = Fitter(problem)
    _say(opts, "simulating the nominal model")
    nom = local.nominal()
    nominal_preds = [local.predict(i, nominal, nom.starts[i]) for i in range(len(records))]
    misfit = _misfit(records, nominal_preds, outputs, noise)
    labels = sorted(local.candidates, key=lambda lab: _cost_rank(local.candidates[lab]))
    if opts.effects is not None:
        unknown = [lab for lab in opts.effects if lab not in local.candidates]
        if unknown:
            raise ValueError(f"effects {unknown} are not candidates here (known: {', '.join(labels)})")
        labels = []
    _say(opts, f"fitting {len(labels)} candidates ({len(set(c.cause for c in local.candidates.values()))} causes)")
    results, pairs, search = _run_fits(problem, labels, nom, opts, local)
    report = _decide(nom, results, pairs, local, opts)
    winner: FitResult | None = report.pop("_winner")
    extended_preds = None
    if winner is not None and report.get("_write"):
        extended_preds = [local.predict(i, _raw_of(winner, i), winner.starts[i]) for i in range(len(records))]
    report.pop("_write", None)
    base = _base_report(model_name, records, outputs, noise, notes)
    base.update(report)
    base["misfit"] = misfit
    _describe_fit(base, nom, winner if extended_preds is not None else None, outputs, noise, opts, local, records)
    structure_final, structure_preds = _structure_result(base, search, nom, outputs, opts, local, len(records))
    base["seconds"] = time.perf_counter() - t_start
    base["candidates_fitted"] = len(results) + len(pairs) + (search["fits"] if search else 0)
    d = Diagnosis(check_report(base), records, train, val, nominal_preds, extended_preds,
                  winner.raw if winner is not None and extended_preds is not None else None, noise,
                  winner.starts if winner is not None else [])
    d.extended_record_raws = [_raw_of(winner, i) for i in range(len(records))] if extended_preds else []
    d.structure = structure_final
    d.structure_preds = structure_preds
    d.singles = list(results)
    d.search_fits = [s["fit"] for s in search["path"]] if search is not None else []
    d.context = ctx
    return d


def _not_identifiable(report: dict, why: str) -> dict:
    """The report when no record can tell one model from another (``why`` says so)."""
    report.update({"verdict": "not_identifiable", "cause": "none", "family": "none", "parameters": {},
                   "confidence": None, "nrmse_nominal": None, "nrmse_extended": None, "gain_percent": None,
                   "ranking": [], "reason": why})
    return report


def _describe_fit(base: dict, nom: FitResult, winner: FitResult | None, outputs: list[str], noise: dict,
                  opts: Options, local: Fitter, records: list[Record]) -> None:
    """Add to the report the nominal fit, the thresholds, the winner's gain per output (``winner``: None when no
    extended model is written), what was skipped and the record groups."""
    base["nominal"] = {"validation": _val_summary(nom, noise), "train_sse": nom.train_sse,
                       "combined_rmse_over_noise": math.sqrt(nom.val_cost),
                       "initial_ph": [s.ph for s in nom.starts] if opts.initial == "fit" else None}
    base["initial"] = opts.initial
    base["thresholds"] = {"alpha": opts.alpha, "min_gain": opts.min_gain, "explained_ratio": opts.explained_ratio,
                          "floor_ratio": opts.floor_ratio,
                          "floor_max_structure": opts.floor_max_structure, "whiteness_alpha": opts.whiteness_alpha}
    if winner is not None:
        base["gain_by_output"] = {o: {"nominal": nom.val_nrmse[o], "extended": winner.val_nrmse[o],
                                      "gain_percent": 100.0 * (1.0 - winner.val_nrmse[o] / nom.val_nrmse[o])
                                      if nom.val_nrmse[o] else None} for o in outputs}
    base["skipped"] = local.skipped
    if opts.groups is not None:
        base["groups"] = {r.name: g for r, g in zip(records, opts.groups)}
        base["adapt"] = opts.adapt


def _structure_result(base: dict, search: dict | None, nom: FitResult, outputs: list[str], opts: Options,
                      local: Fitter, n_records: int) -> tuple[FitResult | None, list[Prediction] | None]:
    """The structure search's report entry, its final model and that model's predictions (None without one)."""
    if search is None:
        return None, None
    base["structure_search"] = _search_report(search, nom, main=outputs[0], opts=opts)
    final = search["final"]
    if final is None:
        return None, None
    return final, [local.predict(i, _raw_of(final, i), final.starts[i]) for i in range(n_records)]


def _raw_of(r: FitResult, i: int) -> dict:
    """The model a fit simulated on record i (per-group parameters differ between records)."""
    return r.record_raws[i] if r.record_raws else r.raw


def _drop_unknown_feeds(rec: Record, nominal: dict) -> None:
    """Flows of feeds the model does not have are not inputs of it: set aside, and said."""
    feeds = set(nominal["plant"]["feeds"])
    valve_feed = nominal["valves"]["ph"]["feed"]
    for name in [k for k in rec.inputs if k.endswith("_flow_ml_s")]:
        feed = name[: -len("_flow_ml_s")]
        if feed not in feeds:
            del rec.inputs[name]
            rec.notes.append(f"{name} ignored: the model has no feed {feed!r}")
        elif feed == valve_feed and "valve_command_pct" in rec.inputs:
            rec.notes.append(f"{name} not used as an input: the model's valve delivers it from valve_command_pct "
                             f"(so the valve can be diagnosed)")


def _base_report(model_name: str, records: list[Record], outputs: list[str], noise: dict, notes: list[str]) -> dict:
    return {"model": model_name,
            "data": [{"name": r.name, "samples": len(r), "sample_time_s": r.dt_s,
                      "duration_s": float(r.time_s[-1] - r.time_s[0]), "inputs": sorted(r.inputs),
                      "outputs": sorted(r.outputs)} for r in records],
            "outputs": outputs, "main_output": outputs[0], "noise_floor": noise, "notes": notes}


def _cost_rank(c) -> tuple:
    order = {"flows": 0, "chemistry": 1, "sensor": 2}
    return (order[c.stage], -len(c.starts), c.label)


def _misfit(records, preds, outputs, noise) -> list[dict]:
    out = []
    for rec, pred in zip(records, preds):
        for o in outputs:
            if o not in rec.outputs:
                continue
            a = analyse(rec.outputs[o], pred.outputs[o], rec.time_s, rec.inputs, noise[o], UNITS[o])
            a.update({"record": rec.name, "output": o})
            out.append(a)
    return out


def _val_summary(r: FitResult, noise: dict) -> dict:
    return {o: {"rmse": r.val_rmse[o], "nrmse": r.val_nrmse[o],
                "rmse_over_noise": r.val_rmse[o] / noise[o] if math.isfinite(r.val_rmse[o]) else None}
            for o in r.val_rmse}


def _workers(opts: Options, tasks: int) -> int:
    n = opts.workers or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)
    return max(1, min(n, tasks))


def _run_fits(problem: Problem, labels: list[str], nom: FitResult, opts: Options, local: Fitter):
    """Fit every candidate; when the best leaves structure, try pairs of the best ones."""
    workers = _workers(opts, len(labels))

    def run_all(pool, jobs: list[tuple]) -> list[FitResult]:
        weights = [local.budget([local.candidates[x] for x in args[0]], *args[1:]) for _, args in jobs]
        progress = _Progress(opts, [" + ".join(args[0]) for _, args in jobs], weights, workers if pool else 1)
        out: list[FitResult | None] = [None] * len(jobs)
        if pool is None:
            for j, (fn, args) in enumerate(jobs):
                progress.started(j)
                out[j] = _local_call(local, fn, args)
                progress.done(j, out[j])
            return out
        # longest first (the fits differ 100-fold in cost): two workers finish together
        order = sorted(range(len(jobs)), key=lambda j: -weights[j])
        futures = {pool.submit(jobs[j][0], *jobs[j][1]): j for j in order}
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, timeout=_HEARTBEAT_S, return_when=FIRST_COMPLETED)
            for fut in finished:
                j = futures[fut]
                out[j] = fut.result()
                progress.done(j, out[j])
            if not finished:  # the pool takes jobs in submission order: the oldest unfinished ones run
                progress.heartbeat(sorted((futures[f] for f in pending), key=order.index)[:workers])
        return out  # in the order of the jobs, whatever the order they finished in

    if opts.effects is not None:
        return [], [], _given_effects(opts, nom, local)
    pool = None if workers == 1 else ProcessPoolExecutor(max_workers=workers, initializer=init_worker,
                                                         initargs=(problem,))
    try:
        results = run_all(pool, [(fit_task, ([lab],)) for lab in labels])
        named = set(opts.candidates or [])
        # the single-cause answer keeps its catalogue; structural candidates join it when named (--candidates)
        singles = [r for r in results if not local.candidates[r.label].structural or local.candidates[r.label].cause in named]
        pair_tasks = _pair_tasks(singles, nom, opts)
        pairs = []
        if pair_tasks:
            _say(opts, f"fitting {len(pair_tasks)} pairs (the best single candidate leaves structure)")
            pairs = run_all(pool, [(fit_task, (labs, starts)) for labs, starts in pair_tasks])
        search = _structure_search(results, nom, opts, local, lambda jobs: run_all(pool, jobs)) \
            if opts.structure else None
    finally:
        if pool is not None:
            pool.shutdown()
    return singles, pairs, search


_HEARTBEAT_S = 20.0  # a line at least this often while fits run (some take minutes)


class _Progress:
    """Progress of a batch of fits on stderr: each fit as it finishes (fit i of n, its time, elapsed), the
    estimated time left, and while none finishes, which fits are running.

    The estimate weighs each fit by its evaluation budget (:meth:`Fitter.budget`; fits differ 100-fold):
    time so far x budget left / budget done. It is an estimate: a fit usually stops before its budget.
    """

    def __init__(self, opts: Options, labels: list[str], weights: list[float], workers: int) -> None:
        self.opts, self.labels, self.weights, self.workers = opts, labels, weights, workers
        self.t0 = time.perf_counter()
        self.n_done = 0
        self.w_done = 0.0
        self.started_at: dict[int, float] = {}

    def started(self, j: int) -> None:
        self.started_at[j] = time.perf_counter()

    def _eta(self) -> str:
        left = sum(self.weights) - self.w_done
        if self.w_done <= 0 or left <= 0:
            return ""
        return f", about {_duration(self.elapsed() * left / self.w_done)} left"

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def done(self, j: int, r: FitResult) -> None:
        self.n_done += 1
        self.w_done += self.weights[j]
        _say(self.opts, f"  {self.n_done}/{len(self.labels)} {r.label}: held-out error {math.sqrt(r.val_cost):.3g} "
                        f"x noise ({r.seconds:.1f} s; {_duration(self.elapsed())} elapsed{self._eta()})")

    def heartbeat(self, running: list[int]) -> None:
        names = ", ".join(self.labels[j] for j in running) or "waiting for a worker"
        _say(self.opts, f"  ... {self.n_done}/{len(self.labels)} done, running: {names} "
                        f"({_duration(self.elapsed())} elapsed{self._eta()})")


def _duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 90:
        return f"{seconds:.0f} s"
    return f"{int(seconds // 60)} min {int(seconds % 60):02d} s"


#: causes that set one thing of the model (a second variant would overwrite the first)
_VESSEL = {"mixing_zone", "tanks_in_series", "co2_absorption"}
_EXCLUSIVE = {"tanks_in_series", "co2_absorption", "flask_contents", "mixing_zone", "holdup", "valve_gain",
              "sensor_gain", "sensor_bias", "two_point_calibration",
              "sensor_lag", "sensor_delay", "probe_asymmetric_lag", "sensor_drift", "sensor_second_order"}


def _compatible(label: str, chosen: list[str], local: Fitter) -> bool:
    c = local.candidates[label]
    for other in chosen:
        o = local.candidates[other]
        if other == label or (o.cause == c.cause and (c.cause in _EXCLUSIVE or not c.variant)):
            return False
        if len({o.cause, c.cause} & _VESSEL) > 1:
            return False  # one vessel structure at a time (phfdi_base.spec: mixing, series, air exchange)
        if {o.cause, c.cause} <= {"sensor_bias", "two_point_calibration"} or \
                {o.cause, c.cause} <= {"sensor_gain", "two_point_calibration"}:
            return False  # the same probe calibration twice
    return True


def _structure_search(singles: list[FitResult], nom: FitResult, opts: Options, local: Fitter, run) -> dict:
    """Forward selection: add the candidate with the largest held-out gain, refit all selected jointly, stop when
    the next addition does not count (significant at ``alpha`` and at least ``min_gain``) against the model so
    far. Each step tries the ``search_width`` candidates of best single held-out gain that fit with the chosen."""
    by_gain = sorted(singles, key=lambda r: r.val_cost)
    params_of = {r.label: r.params for r in singles}
    current, chosen = nom, []
    path = [{"model": "nominal", "fit": nom}]
    fits = 0
    stopped = f"at most {opts.search_steps} effects (--search-steps)"
    for step in range(opts.search_steps):
        options = [r.label for r in by_gain if _compatible(r.label, chosen, local)][: opts.search_width]
        if not options:
            stopped = "no candidate left to add"
            break
        if not chosen:
            tried = [r for r in singles if r.label in options]
        else:
            jobs = []
            for lab in options:
                start = dict(current.params)
                start.update({f"{lab}.{k}": v for k, v in params_of[lab].items()})
                start.update({f"{local.candidates[lab].cause}.{k}": v for k, v in params_of[lab].items()})
                jobs.append((fit_task, (chosen + [lab], [start])))
            _say(opts, f"structure search step {step + 1}: {' + '.join(chosen)} + one of {len(jobs)} candidates")
            tried = run(jobs)
            fits += len(tried)
        best = min(tried, key=lambda r: r.val_cost)
        counts, p, gain = _counts(best, current, opts)
        added = best.label.split("+")[-1]
        if not counts:
            stopped = (f"adding {added} does not count: held-out gain {100 * gain:+.1f} % (p = {p:.2g}); "
                       f"needs >= {100 * opts.min_gain:.0f} % at p < {opts.alpha}")
            path.append({"model": best.label, "fit": best, "rejected": True, "p": p, "gain": gain})
            break
        chosen = chosen + [added]
        current = best
        path.append({"model": best.label, "fit": best, "p": p, "gain": gain})
        _say(opts, f"  + {added}: held-out error {math.sqrt(best.val_cost):.3g} x noise ({100 * gain:+.1f} %)")
    return {"path": path, "final": current if chosen else None, "chosen": chosen, "stopped": stopped, "fits": fits}


def _given_effects(opts: Options, nom: FitResult, local: Fitter) -> dict:
    """``Options.effects``: the given set fitted jointly in this process, reported as a search path of one step
    that is kept whatever its held-out score (the choice was made elsewhere)."""
    chosen = list(opts.effects or [])
    path: list[dict] = [{"model": "nominal", "fit": nom}]
    final = None
    if chosen:
        _say(opts, f"fitting the given effects jointly: {' + '.join(chosen)}")
        final = local.fit([local.candidates[x] for x in chosen],
                          [opts.effects_start] if opts.effects_start is not None else None)
        _, p, gain = _counts(final, nom, opts)
        path.append({"model": final.label, "fit": final, "p": p, "gain": gain})
    return {"path": path, "final": final, "chosen": chosen, "fits": len(path) - 1,
            "stopped": "the given effects (Options.effects): no selection"}


def _search_report(search: dict, nom: FitResult, main: str, opts: Options) -> dict:
    steps = []
    for s in search["path"]:
        r: FitResult = s["fit"]
        steps.append({"model": s["model"], "accepted": not s.get("rejected", False),
                      "nrmse_validation": r.val_nrmse.get(main), "validation_rmse_over_noise": math.sqrt(r.val_cost),
                      "gain_percent_vs_previous": 100.0 * s["gain"] if "gain" in s else None,
                      "p_value_vs_previous": s.get("p"), "parameters": r.params,
                      "confidence_intervals": r.intervals, "n_params": r.n_params, "bic": r.bic,
                      "fitted_where": r.fitted_where, "nrmse_by_record": _per_record(r)})
    final = search["final"]
    return {"path": steps, "chosen": search["chosen"], "stopped": search["stopped"],
            "nrmse_nominal": nom.val_nrmse.get(main),
            "nrmse_final": final.val_nrmse.get(main) if final is not None else nom.val_nrmse.get(main),
            "nrmse_by_record_nominal": _per_record(nom)}


def _per_record(r: FitResult) -> dict:
    return getattr(r, "val_by_record", {}) or {}


def _local_call(local: Fitter, fn, args) -> FitResult:
    labs, *rest = args
    return local.fit([local.candidates[x] for x in labs], *rest)


def _explained(r: FitResult, opts: Options) -> bool:
    """At the noise floor: held-out RMS error within ``floor_ratio`` of it and no gross structure left (index
    <= ``floor_max_structure``), or within ``explained_ratio`` of it and white (Ljung-Box p >= ``whiteness_alpha``)."""
    ratio = math.sqrt(r.val_cost)
    return ((ratio <= opts.floor_ratio and r.val_structure <= opts.floor_max_structure)
            or (ratio <= opts.explained_ratio and r.val_whiteness_p >= opts.whiteness_alpha))


def _best_per_cause(results: list[FitResult]) -> list[FitResult]:
    best: dict[str, FitResult] = {}
    for r in results:
        if r.cause not in best or r.val_cost < best[r.cause].val_cost:
            best[r.cause] = r
    return sorted(best.values(), key=lambda r: r.val_cost)


def _counts(r: FitResult, ref: FitResult, opts: Options) -> tuple[bool, float, float]:
    """(counts, p-value, RMSE gain) of a candidate against a reference on held-out samples.

    The p-value is the smaller of two tests (batch means, robust to coloured errors but weak when few
    stretches carry the misfit; F with the candidate's error as noise model, strong when it leaves white
    noise), times two for the choice (Bonferroni).
    """
    p = min(1.0, 2.0 * min(significance(ref.val_sq, r.val_sq),
                           significance_f(ref.val_sq, r.val_sq, r.val_lag1, max(r.n_params - ref.n_params, 1))))
    gain = 1.0 - math.sqrt(r.val_cost / ref.val_cost) if ref.val_cost > 0 else 0.0
    return p < opts.alpha and gain >= opts.min_gain, p, gain


def _pair_tasks(results: list[FitResult], nom: FitResult, opts: Options) -> list[tuple[list[str], list[dict]]]:
    if not opts.pairs:
        return []
    ranked = _best_per_cause(results)
    if not ranked or math.sqrt(nom.val_cost) <= opts.explained_ratio:
        return []
    best = ranked[0]
    if _explained(best, opts) or not _counts(best, nom, opts)[0]:
        return []
    top = [r for r in ranked[:4] if _counts(r, nom, opts)[0]]
    tasks = []
    for i in range(len(top)):
        for j in range(i + 1, len(top)):
            a, b = top[i], top[j]
            start = dict(a.params)
            start.update(b.params)
            tasks.append(([a.label, b.label], [start]))
    return tasks


def _entry(r: FitResult, nom: FitResult, main: str, noise: dict, opts: Options) -> dict:
    counts, p, gain = _counts(r, nom, opts)
    params = dict(r.params)
    return {"cause": r.cause, "family": family_of(r.cause), "parameters": params,
            "confidence_intervals": r.intervals, "fixed": r.fixed, "main_parameter": r.main,
            "identified": r.identified, "nrmse_validation": r.val_nrmse.get(main),
            "nrmse_validation_by_output": r.val_nrmse,
            "validation_rmse_over_noise": math.sqrt(r.val_cost), "validation_whiteness_p": r.val_whiteness_p,
            "validation_structure": r.val_structure,
            "gain_percent": 100.0 * gain, "p_value_vs_nominal": p, "counts": counts,
            "aic": r.aic, "bic": r.bic, "n_params": r.n_params, "seconds": r.seconds,
            "nrmse_by_record": r.val_by_record}


def _decide(nom: FitResult, results: list[FitResult], pairs: list[FitResult], local: Fitter,
            opts: Options) -> dict:
    main = local.p.outputs[0]
    noise = local.p.noise
    ranked = _best_per_cause(results)
    ranking = [_entry(r, nom, main, noise, opts) for r in ranked]
    pair_entries = [_entry(r, nom, main, noise, opts) for r in sorted(pairs, key=lambda r: r.val_cost)]
    nom_ratio = math.sqrt(nom.val_cost)
    counting = [r for r in ranked if _counts(r, nom, opts)[0]]
    out: dict = {"ranking": ranking, "pairs": pair_entries, "_winner": None}
    nominal_main = nom.val_nrmse.get(main)

    def finish(verdict: str, winner: FitResult | None, confidence: float | None, reason: str, write: bool):
        out.update({"verdict": verdict, "reason": reason, "confidence": confidence,
                    "nrmse_nominal": nominal_main})
        if winner is None:
            out.update({"cause": "none", "family": "none", "parameters": {}, "confidence_intervals": {},
                        "nrmse_extended": None, "gain_percent": None})
        else:
            ext = winner.val_nrmse.get(main)
            out.update({"cause": winner.cause, "family": family_of(winner.cause), "parameters": winner.params,
                        "confidence_intervals": winner.intervals, "fixed": winner.fixed,
                        "nrmse_extended": ext,
                        "gain_percent": 100.0 * (1.0 - ext / nominal_main) if nominal_main else None,
                        "validation_rmse_over_noise": math.sqrt(winner.val_cost)})
            out["_winner"] = winner
        out["_write"] = write
        return out

    if nom_ratio <= opts.explained_ratio:
        conf = _none_confidence(nom, ranked, opts)
        return finish("none", None, conf,
                      f"the nominal model's held-out error is {nom_ratio:.2f} x the noise floor (at most "
                      f"{opts.explained_ratio} counts as noise): nothing significant to explain", False)
    if not counting:
        # the closest cause is the one that lowers the held-out error most; a fit that went back to the nominal
        # model (a zero flow, a unit gain) is no cause
        improving = [r for r in ranked if r.val_cost < nom.val_cost * (1.0 - 1e-3) ** 2]
        conf = _none_confidence(nom, ranked, opts)
        if not improving:
            best = f"; best: {ranked[0].cause} ({100 * _counts(ranked[0], nom, opts)[2]:+.1f} %)" if ranked else ""
            return finish("not_explained", None, conf,
                          f"the nominal model misses ({nom_ratio:.2f} x the noise floor held out) and no catalogue "
                          f"candidate lowers its held-out error{best}; no extended model is claimed", False)
        closest = improving[0]
        c, p, gain = _counts(closest, nom, opts)
        return finish("not_explained", closest, conf,
                      f"the nominal model misses ({nom_ratio:.2f} x the noise floor held out) but no candidate "
                      f"lowers the held-out error significantly by {100 * opts.min_gain:.0f} % or more; closest: "
                      f"{closest.cause} ({100 * gain:+.1f} %, p = {p:.2g}); no extended model is claimed", False)
    winner = _parsimonious(counting, opts)
    pool = [winner] + [p for p in pairs if _counts(p, winner, opts)[0]]
    best_pair = min((p for p in pool[1:]), key=lambda r: r.val_cost, default=None)
    explained = _explained(winner, opts)
    if not explained and best_pair is not None:
        winner = best_pair
        explained = _explained(winner, opts)
    runner = next((r for r in ranked if r.cause != winner.cause and r.cause not in winner.cause.split("+")), None)
    conf = 1.0 - _better_p(winner, runner) if runner is not None else 1.0 - _better_p(winner, nom)
    ratio = math.sqrt(winner.val_cost)
    gain = 100.0 * (1.0 - winner.val_nrmse[main] / nominal_main) if nominal_main else math.nan
    margin = ""
    if runner is not None:
        margin = (f"; runner-up {runner.cause} ({math.sqrt(runner.val_cost):.2f} x noise, "
                  f"confidence {conf:.2f} that {winner.cause} is better)")
    if explained:
        return finish("explained", winner, conf,
                      f"{winner.cause} brings the held-out error from {nom_ratio:.2f} to {ratio:.2f} x the noise "
                      f"floor ({gain:+.0f} % NRMSE on {main}){margin}", True)
    why = (f"its error still has structure (Ljung-Box p = {winner.val_whiteness_p:.2g})"
           if ratio <= opts.explained_ratio else "stays above the noise floor")
    return finish("not_explained", winner, conf,
                  f"no candidate explains the misfit: the closest, {winner.cause}, lowers the held-out error "
                  f"from {nom_ratio:.2f} to {ratio:.2f} x noise ({gain:+.0f} % NRMSE on {main}) but {why}"
                  f"{margin}", True)


def _parsimonious(counting: list[FitResult], opts: Options) -> FitResult:
    """Best held-out error, unless a simpler candidate is not significantly worse."""
    best = counting[0]
    simpler = [r for r in counting[1:] if r.n_params < best.n_params and _better_p(best, r) >= 0.05]
    return min(simpler, key=lambda r: (r.n_params, r.val_cost)) if simpler else best


def _better_p(a: FitResult, b: FitResult) -> float:
    """p-value that ``a`` is not better than ``b`` on held-out samples (both tests, Bonferroni)."""
    return min(1.0, 2.0 * min(significance(b.val_sq, a.val_sq),
                              significance_f(b.val_sq, a.val_sq, a.val_lag1, max(a.n_params - b.n_params, 1))))


def _none_confidence(nom: FitResult, ranked: list[FitResult], opts: Options) -> float | None:
    if not ranked:
        return None
    return 1.0 - _margin_p(nom, ranked[0], opts.min_gain)


def _margin_p(nom: FitResult, cand: FitResult, min_gain: float) -> float:
    """p-value that the candidate lowers the squared error by at least the margin ((1 - g)^2 of nominal's)."""
    keep = (1.0 - min_gain) ** 2
    # H0 for "none": the candidate's squared error is below keep * nominal's; reject it when it is not
    return significance(cand.val_sq, nom.val_sq * keep)
