"""Estimate numeric parameters of a nominal model from measured records (before diagnosing it).

``phfdi diagnose --calibrate KEY[=LOW:HIGH] ...`` fits scenario keys (plant
model inline: ``plant.feeds.acid.recipe.H2SO4``, ``plant.tank.volume_ml``,
``sensors.ph.lag_s``, ...) by the same least squares as the catalogue
candidates (held-out scoring, Jacobian intervals), and writes the
calibrated model as a scenario file extending the nominal one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.spec import apply_override

from .catalogue import Candidate, Param
from .fit import Fitter, Problem, one_blas_thread
from .pipeline import Options, context_for, split
from .residual import noise_floor


@dataclass
class Calibration:
    params: dict
    intervals: dict
    nominal: dict  # held-out NRMSE per output, nominal model
    calibrated: dict  # held-out NRMSE per output, calibrated model
    raw: dict
    starts: list
    records: list
    train: list
    val: list


def _get(raw: dict, keys: list[str]):
    node = raw
    for k in keys:
        try:
            node = node[int(k)] if isinstance(node, list) else node[k]
        except (KeyError, IndexError, ValueError, TypeError):
            raise UserError(f"--calibrate: no key {'.'.join(keys)!r} in the model") from None
    return node


def parse_keys(raw: dict, items: list[str]) -> list[Param]:
    """KEY or KEY=LOW:HIGH -> parameters (default bounds: the model's value / 10 .. x 10, log scale)."""
    params = []
    for item in items:
        key, _, bounds = item.partition("=")
        value = _get(raw, key.split("."))
        if not isinstance(value, (int, float)):
            raise UserError(f"--calibrate {key}: the model's value {value!r} is not a number")
        if bounds:
            try:
                lo, hi = (float(x) for x in bounds.split(":"))
            except ValueError:
                raise UserError(f"--calibrate {item!r}: bounds are LOW:HIGH, e.g. {key}=0.001:0.1") from None
            if not lo < hi:
                raise UserError(f"--calibrate {item!r}: LOW must be below HIGH")
            params.append(Param(key, lo, hi, "", log=lo > 0))
        elif value > 0:
            params.append(Param(key, value / 10.0, value * 10.0, "", log=True))
        else:
            raise UserError(f"--calibrate {key}: the model's value is {value}: give bounds, {key}=LOW:HIGH")
    return params


def calibrate(records_fit, records_val, nominal: dict, keys: list[str], opts: Options) -> Calibration:
    params = parse_keys(nominal, keys)

    def apply(raw: dict, values: dict) -> None:
        for k, v in values.items():
            apply_override(raw, k.split("."), v)

    start = {p.name: p.clip(float(_get(nominal, p.name.split(".")))) for p in params}
    grid = [start] + [{p.name: p.from_unit(u) for p in params} for u in (0.3, 0.7)]
    cand = Candidate("none", params, grid, apply, params[0].name, fixed={})
    records, train, val, _ = split(records_fit, records_val, opts.blocks)
    outputs = [o for o in ("ph_measured", "level_measured_cm") if any(o in r.outputs for r in records)]
    noise = {o: float(np.median([noise_floor(r.outputs[o]) for r in records if o in r.outputs])) for o in outputs}
    scale = {o: float(np.std(np.concatenate([r.outputs[o] for r in records if o in r.outputs]))) or 1.0
             for o in outputs}
    ctx = context_for(nominal, records, outputs)
    fitter = Fitter(Problem(records, nominal, opts.initial, train, val, noise, scale, outputs, ctx, ["sensor_bias"]))
    if opts.progress:
        opts.progress(f"calibrating {', '.join(keys)} on {len(records)} record(s)")
    with one_blas_thread():  # tiny matrices: BLAS threads only wait (fit.one_blas_thread)
        nom = fitter.nominal()
        res = fitter.fit([cand])
    for k, v in res.params.items():
        if not math.isfinite(v):
            raise UserError(f"--calibrate: {k} did not converge")
    return Calibration(res.params, res.intervals, nom.val_nrmse, res.val_nrmse, res.raw, res.starts, records,
                       train, val)
