"""Nested selection: choose the single cause and the structure on the training records only, then predict.

:func:`diagnose` scores its fits on its validation records and *selects* on them (the single-cause winner, each
step of the structure search and when it stops): there the validation records are a validation set by design.
A record that is to measure prediction must not take part in any choice. :func:`select` makes every choice on
the training records alone, by an inner leave-one-record-out; :func:`predict` then fits the chosen models on all
training records and scores them on the held-out record, whose measurements only ever enter as the samples that
set its start (and, for a group absent from the fit, its declared per-group parameters) and as the score.

Inner protocol (why leave-one-record-out and not the interleaved blocks of one record): the question asked of the
held-out record is prediction *across* records (another run, perhaps another day, its start and an unseen day's
reagents set from its first samples), so the inner folds ask the same question of each training record in turn:
fit on the others, validate on it under the same start/adapt rules (:meth:`Fitter.validate`). Interleaved blocks
test prediction within a record, where a per-record parameter (the flask's contents) or a record-specific fit of a
shared one is seen on both sides of the split and so favoured; it is cheaper (one fit per candidate instead of one
per training record) but answers a different question. The inner errors of all folds are pooled (per-sample
squared errors concatenated, the same noise unit: every inner fold sees the same records), and the choices use the
pipeline's own rules on the pooled errors: the best single cause is the lowest pooled error; the forward search
adds the candidate of lowest pooled error among the ``search_width`` compatible ones ranked by pooled single error,
refits all chosen jointly in every inner fold (from that fold's previous model and single fit), and stops when the
addition does not count (:func:`pipeline._counts`: p < ``alpha`` and gain >= ``min_gain``) on the pooled errors.

Examples
--------
>>> from phfdi.diagnosis.nested import pooled_cost
>>> import numpy as np
>>> round(pooled_cost([np.array([1.0, 3.0]), np.array([2.0])]), 3)  # mean of every inner held-out sample
2.0
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Callable

import numpy as np

from phfdi.records import Record

from .calibrate import Calibration, calibrate
from .fit import FitResult
from .pipeline import Diagnosis, Options, _compatible, _counts, diagnose


@dataclass
class Selection:
    """What the inner folds chose, and the pooled inner held-out errors behind each choice (noise units^2)."""

    best_single: str | None
    chosen: list[str]
    singles: dict[str, float]  # label -> pooled inner held-out cost
    nominal: float
    path: list[dict]  # per step: model, pooled cost, gain, p, accepted
    stopped: str
    inner_records: list[str]
    seconds: float = 0.0
    fits: int = 0


@dataclass
class Prediction:
    """The chosen models fitted on all training records and scored on the held-out one."""

    diagnosis: Diagnosis  # nominal and every single cause fitted on the training records (scored held out)
    best_single: FitResult | None
    structure: FitResult | None  # the chosen set (None: nominal)
    chain: list[FitResult] = field(default_factory=list)  # chosen[:1], chosen[:2], ...: the joint refits


def pooled_cost(sqs: list[np.ndarray]) -> float:
    """Mean of the per-sample squared errors of every inner fold together."""
    sq = np.concatenate(sqs) if sqs else np.zeros(0)
    return float(np.mean(sq)) if len(sq) else math.inf


def _pool(fits: list[FitResult], noises: list[float]) -> FitResult:
    """One pseudo-fit whose held-out errors are the inner folds' together (in the first fold's noise unit), for
    the pipeline's decision rules (``_counts``)."""
    ref = noises[0]
    sqs = [f.val_sq * (n / ref) ** 2 for f, n in zip(fits, noises)]
    return dataclasses.replace(fits[0], val_sq=np.concatenate(sqs), val_cost=pooled_cost(sqs),
                               val_lag1=float(np.mean([f.val_lag1 for f in fits])),
                               n_params=max(f.n_params for f in fits),
                               val_by_record={k: v for f in fits for k, v in f.val_by_record.items()})


def _inner_options(opts: Options, say: Callable[[str], None] | None, groups: list[str] | None,
                   **kw) -> Options:
    return dataclasses.replace(opts, structure=True, search_steps=0, pairs=False, groups=groups, progress=say,
                               **kw)


def _inner_singles(records: list[Record], groups: list[str] | None, nominal: dict, model_name: str,
                   opts: Options) -> list[Diagnosis]:
    """Every single candidate fitted on all training records but one and scored on that one, in turn."""
    out = []
    for j, held in enumerate(records):
        fit = [r for i, r in enumerate(records) if i != j]
        g = None if groups is None else [x for i, x in enumerate(groups) if i != j] + [groups[j]]
        say = _prefixed(opts, f"inner {j + 1}/{len(records)}, {held.name[:22]} held out")
        _note(opts, f"inner fold {j + 1}/{len(records)}: fit on {len(fit)}, validate on {held.name}")
        out.append(diagnose(fit, [held], nominal, model_name, _inner_options(opts, say, g)))
    return out


def _prefixed(opts: Options, prefix: str) -> Callable[[str], None] | None:
    if opts.progress is None:
        return None
    progress = opts.progress
    return lambda text: progress(f"{prefix}: {text}")


def _note(opts: Options, text: str) -> None:
    if opts.progress is not None:
        opts.progress(text)


def _joint_start(current: FitResult, single: FitResult, label: str, cause: str) -> dict:
    """Start of a joint refit as the pipeline's search makes it: the model so far and the added single's fit."""
    start = dict(current.params)
    start.update({f"{label}.{k}": v for k, v in single.params.items()})
    start.update({f"{cause}.{k}": v for k, v in single.params.items()})
    return start


def select(records: list[Record], groups: list[str] | None, nominal: dict, model_name: str,
           opts: Options) -> Selection:
    """The best single cause and the structure, chosen by inner leave-one-record-out on ``records`` only.

    ``opts`` as for :func:`diagnose` (candidates, initial, adapt, alpha, min_gain, search_width, search_steps,
    workers, progress); ``groups`` one per record. Nothing else is read: a held-out record cannot be passed.
    """
    t0 = time.perf_counter()
    inner = _inner_singles(records, groups, nominal, model_name, opts)
    noises = [d.noise[d.report["main_output"]] for d in inner]
    by_fold = [{r.label: r for r in d.singles} for d in inner]
    labels = [lab for lab in by_fold[0] if all(lab in f for f in by_fold)]
    pooled = {lab: _pool([f[lab] for f in by_fold], noises) for lab in labels}
    noms = [d.search_fits[0] for d in inner]
    nom = _pool(noms, noises)
    best_single = min(labels, key=lambda lab: pooled[lab].val_cost) if labels else None
    chosen, path, stopped, fits = _forward(records, groups, nominal, model_name, opts, inner, by_fold, pooled,
                                           noises, noms)
    return Selection(best_single, chosen, {lab: pooled[lab].val_cost for lab in labels}, nom.val_cost, path,
                     stopped, [r.name for r in records], time.perf_counter() - t0, fits)


def _forward(records, groups, nominal, model_name, opts, inner, by_fold, pooled, noises, noms):
    """The pipeline's forward selection (``_structure_search``) on the pooled inner held-out errors."""
    shim = SimpleNamespace(candidates={lab: r for lab, r in pooled.items()})  # .cause and .variant, as _compatible
    by_gain = sorted(pooled, key=lambda lab: pooled[lab].val_cost)
    current, current_folds, chosen = _pool(noms, noises), list(noms), []
    path: list[dict] = [{"model": "nominal", "cost": current.val_cost, "accepted": True}]
    stopped, fits = f"at most {opts.search_steps} effects (search_steps)", 0
    for step in range(opts.search_steps):
        options = [lab for lab in by_gain if _compatible(lab, chosen, shim)][: opts.search_width]  # type: ignore
        if not options:
            stopped = "no candidate left to add"
            break
        tried: dict[str, list[FitResult]] = {}
        for lab in options:
            if not chosen:
                tried[lab] = [f[lab] for f in by_fold]
                continue
            _note(opts, f"inner search step {step + 1}: {' + '.join(chosen)} + {lab} in {len(records)} inner folds")
            tried[lab] = [_refit_inner(records, groups, nominal, model_name, opts, j, chosen + [lab],
                                       _joint_start(current_folds[j], by_fold[j][lab], lab, pooled[lab].cause))
                          for j in range(len(records))]
            fits += len(records)
        best_lab = min(tried, key=lambda lab: _pool(tried[lab], noises).val_cost)
        best = _pool(tried[best_lab], noises)
        counts, p, gain = _counts(best, current, opts)
        entry = {"model": "+".join(chosen + [best_lab]), "cost": best.val_cost, "gain": gain, "p": p,
                 "accepted": counts, "tried": {lab: _pool(v, noises).val_cost for lab, v in tried.items()}}
        path.append(entry)
        if not counts:
            stopped = (f"adding {best_lab} does not count on the pooled inner held-out error: gain "
                       f"{100 * gain:+.1f} % (p = {p:.2g}); needs >= {100 * opts.min_gain:.0f} % at p < {opts.alpha}")
            break
        chosen, current, current_folds = chosen + [best_lab], best, tried[best_lab]
        _note(opts, f"inner search: + {best_lab} (pooled inner gain {100 * gain:+.1f} %, p = {p:.2g})")
    return chosen, path, stopped, fits


def _refit_inner(records, groups, nominal, model_name, opts, j: int, effects: list[str], start: dict) -> FitResult:
    fit = [r for i, r in enumerate(records) if i != j]
    g = None if groups is None else [x for i, x in enumerate(groups) if i != j] + [groups[j]]
    d = diagnose(fit, [records[j]], nominal, model_name,
                 _inner_options(opts, None, g, effects=effects, effects_start=start))
    assert d.structure is not None
    return d.structure


def predict(train: list[Record], held: Record, groups: list[str] | None, nominal: dict, model_name: str,
            opts: Options, sel: Selection) -> Prediction:
    """Fit the nominal model, every single cause and the chosen structure on ``train``; score them on ``held``.

    ``groups``: the training records' then the held-out record's. The single causes are all fitted and scored
    (for the record and for comparison), but which one is "best" and which set is "the structure" come from
    ``sel``, made without ``held``. The structure is refitted as the search built it: chosen[:1] (the single
    fit), then chosen[:k] from chosen[:k-1]'s parameters and chosen[k-1]'s single fit.
    """
    d = diagnose(train, [held], nominal, model_name, _inner_options(opts, _prefixed(opts, "outer"), groups))
    singles = {r.label: r for r in d.singles}
    best = singles.get(sel.best_single) if sel.best_single else None
    chain: list[FitResult] = []
    for k, lab in enumerate(sel.chosen):
        if k == 0:
            chain.append(singles[lab])
            continue
        start = _joint_start(chain[-1], singles[lab], lab, singles[lab].cause)
        _note(opts, f"outer: fitting the chosen {' + '.join(sel.chosen[:k + 1])} on the training records")
        dk = diagnose(train, [held], nominal, model_name,
                      _inner_options(opts, None, groups, effects=sel.chosen[: k + 1], effects_start=start))
        assert dk.structure is not None
        chain.append(dk.structure)
    return Prediction(d, best, chain[-1] if chain else None, chain)


@dataclass
class Fold:
    """One outer fold: the nominal model the fold starts from, the choice and the prediction."""

    nominal: dict  # the fold's nominal model (calibrated on the training records, or the one given)
    calibration: Calibration | None  # None: the nominal model as given
    selection: Selection
    prediction: Prediction


def outer_fold(train: list[Record], held: Record, groups: list[str] | None, nominal: dict, model_name: str,
               opts: Options, calibrate_keys: list[str] | None = None,
               calibrate_on: list[Record] | None = None) -> Fold:
    """One fold of a leave-one-record-out prediction: everything fitted or chosen on ``train`` only.

    With ``calibrate_keys`` (``KEY[=LOW:HIGH]`` as ``phfdi diagnose --calibrate``), the nominal model's keys are
    first estimated on ``train`` by :func:`phfdi.diagnosis.calibrate.calibrate`, the code ``--calibrate`` runs
    (interleaved blocks of the training records, from the values in ``nominal``; one value per key for all
    records: calibration has no groups), and the selection and the prediction start from that calibrated model.
    ``calibrate_on``: the training records as the calibration reads them (e.g. at their own sampling where the
    fits use a resampled copy); default ``train``.
    Then :func:`select` on ``train`` and :func:`predict` of ``held``. With ``opts.setup_from_fit`` the fits'
    search bounds and noise unit also come from the training records only (:class:`Options`); without it, the
    prediction's bounds see ``held`` (the benchmark's behaviour before 2026-11-27).
    """
    cal = None
    if calibrate_keys:
        _note(opts, f"calibrating the nominal model on the {len(train)} training records")
        cal = calibrate(list(train if calibrate_on is None else calibrate_on), [], nominal, calibrate_keys, opts)
        nominal = cal.raw
        _note(opts, "calibrated: " + ", ".join(f"{k} {v:.4g} [{cal.intervals[k][0]:.4g}, {cal.intervals[k][1]:.4g}]"
                                               if k in cal.intervals else f"{k} {v:.4g}" for k, v in cal.params.items()))
    sel = select(train, None if groups is None else groups[:-1], nominal, model_name, opts)
    pred = predict(train, held, groups, nominal, model_name, opts, sel)
    return Fold(nominal, cal, sel, pred)
