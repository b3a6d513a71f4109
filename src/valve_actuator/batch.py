"""Many position blocks over the same command sequence at once (a fit's grid of block parameters).

:func:`positions` gives, for each block, its stem positions over the command ``u`` from rest on
``u[0]``: row i is what ``blocks[i].reset(u[0])`` and then ``blocks[i].step`` sample by sample
return, with the same arithmetic in the same order, so the rows equal those runs bit for bit
(tests/core/test_valve_batch.py). The static blocks (dead-zone, saturation, quantization) are
evaluated on the whole (block, sample) array; backlash and Kano stiction keep one state per block
and step through the samples together, one numpy operation across all blocks per sample instead of
one Python call per block and sample. Any other block is stepped as it is.

Why: fitting a valve model to a loop record scans hundreds of parameter values, and stepping each
block in Python took about half of a loop's diagnosis time.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from .blocks import Backlash, DeadZone, Quantization, Saturation, Stiction


def positions(blocks: Sequence, u: np.ndarray) -> np.ndarray:
    """Stem positions (len(blocks), len(u)) of each block run over the command ``u`` (% of span),
    starting at rest on ``u[0]``. The blocks are reset; their state afterwards is undefined."""
    u = np.asarray(u, dtype=float)
    out = np.empty((len(blocks), len(u)))
    by_kind: dict[type, list[int]] = {}
    for i, b in enumerate(blocks):
        by_kind.setdefault(type(b), []).append(i)
    for kind, idx in by_kind.items():
        run = _RUNNERS.get(kind, _stepped)
        out[idx] = run([blocks[i] for i in idx], u)
    return out


def _col(blocks: Sequence, name: str) -> np.ndarray:
    return np.array([float(getattr(b, name)) for b in blocks])[:, None]


def _stepped(blocks: Sequence, u: np.ndarray) -> np.ndarray:
    out = np.empty((len(blocks), len(u)))
    xs = u.tolist()
    for row, b in zip(out, blocks):
        b.reset(xs[0])
        step = b.step
        row[:] = [step(x, 0.0) for x in xs]
    return out


def _deadzone(blocks: Sequence[DeadZone], u: np.ndarray) -> np.ndarray:
    half = 0.5 * _col(blocks, "width_pct") * _col(blocks, "severity")
    c = np.array([float(u[0]) if b.center_pct is None else float(b.center_pct) for b in blocks])[:, None]
    x = u[None, :]
    e = x - c
    return np.where(e > half, x - half, np.where(e < -half, x + half, c))


def _saturation(blocks: Sequence[Saturation], u: np.ndarray) -> np.ndarray:
    s = _col(blocks, "severity")
    lo = s * _col(blocks, "low_pct")
    hi = 100.0 + s * (_col(blocks, "high_pct") - 100.0)
    return np.minimum(np.maximum(u[None, :], lo), hi)


def _quantization(blocks: Sequence[Quantization], u: np.ndarray) -> np.ndarray:
    q = _col(blocks, "step_pct") * _col(blocks, "severity")
    c = _col(blocks, "offset_pct")
    x = np.broadcast_to(u[None, :], (len(blocks), len(u)))
    qs = np.where(q > 0.0, q, 1.0)
    # Python's round() and np.rint both round half to even
    return np.where(q > 0.0, c + q * np.rint((x - c) / qs), x)


def _backlash(blocks: Sequence[Backlash], u: np.ndarray) -> np.ndarray:
    half = (0.5 * _col(blocks, "width_pct") * _col(blocks, "severity"))[:, 0]
    out = np.empty((len(blocks), len(u)))
    y = np.full(len(blocks), float(u[0]))
    for k, x in enumerate(u.tolist()):
        e = x - y
        y = np.where(e > half, x - half, np.where(e < -half, x + half, y))
        out[:, k] = y
    return out


def _stiction(blocks: Sequence[Stiction], u: np.ndarray) -> np.ndarray:
    """Kano et al. (2004), as :meth:`Stiction.step`, one state per block.

    The command is the same for every block, so its change ``du`` is a scalar; "keeps moving"
    (``du * d > 0``) is then ``d == sign(du)`` for the moving blocks, and the jump
    ``d * 0.5 * (S - J)`` is +-``0.5 * (S - J)`` exactly. A slip needs ``|e| > threshold >= 0``,
    which already implies ``e != 0``."""
    sev = _col(blocks, "severity")[:, 0]
    big_s = _col(blocks, "s_pct")[:, 0] * sev
    big_j = _col(blocks, "j_pct")[:, 0] * sev
    half = 0.5 * (big_s - big_j)  # == (d * 0.5) * (S - J) for d = 1, and its negative for d = -1
    m = len(blocks)
    out = np.empty((m, len(u)))
    xs = u.tolist()
    u_prev = xs[0]
    y = np.full(m, u_prev)
    u_s = np.full(m, u_prev)
    d = np.zeros(m)  # direction of the last motion: -1, 0, +1 (an int in the block; exact as a float)
    moving = np.zeros(m, dtype=bool)  # not stuck
    for k, x in enumerate(xs):
        du = x - u_prev
        if moving.any():
            keeps = moving & (d == (1.0 if du > 0.0 else -1.0)) if du != 0.0 else np.zeros(m, dtype=bool)
            if keeps.any():
                y = np.where(keeps, x - half if du > 0.0 else x + half, y)
            # command stopped or reversed: the valve sticks where it is
            u_s = np.where(moving & ~keeps, u_prev, u_s)
            moving = keeps
        e = x - u_s
        direction = np.sign(e)
        slips = (np.abs(e) > np.where(direction == d, big_j, big_s)) & ~moving
        if slips.any():
            d = np.where(slips, direction, d)
            moving = moving | slips
            y = np.where(slips, x - direction * half, y)
        u_prev = x
        out[:, k] = y
    return out


_RUNNERS: dict[type, Callable[[Sequence, np.ndarray], np.ndarray]] = {
    DeadZone: _deadzone, Saturation: _saturation, Quantization: _quantization, Backlash: _backlash,
    Stiction: _stiction}
