"""The reading policy: what is repaired (and noted), what is refused.

======================================  ==========================  ==========================================
case                                    policy "run"                policy "historian"
======================================  ==========================  ==========================================
exact duplicate row                     dropped, noted              dropped, noted
repeated stamp next to a skipped one    re-spaced, noted            re-spaced, noted
other repeated stamps                   averaged, noted             averaged, noted
time going back (clock reset)           refused (one line)          new segment, noted
forward jump > 10 samples               gap (missing), noted        new segment, noted
NaN / inf / text / empty cell           missing, noted              missing, noted
bad quality flag                        missing, noted              missing, noted
MODE not automatic                      kept, noted                 kept, not judged (segments), noted
short gap                               filled only on request      filled only on request
step-hold or coarse quantisation        noted                       noted
all of a channel missing, too few rows  refused                     refused
======================================  ==========================  ==========================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime

import numpy as np

from .errors import ReadError
from .notes import places

POLICIES = ("run", "historian")
#: a forward time jump longer than this many sample intervals starts a new segment (historian policy)
CLOCK_JUMP_SAMPLES = 10
#: a stamp within this fraction of a sample interval of the one before is a repeat
REPEAT_TOLERANCE = 1e-6
#: a held (step-hold) channel repeats its previous value in more than this fraction of samples ...
HOLD_FRACTION = 0.5
#: ... in runs of at least this many samples
HOLD_RUN = 5
#: quantisation is noted when the channel's range spans at most this many steps ...
COARSE_LEVELS = 200
#: ... and it takes at least this many levels (fewer: a command or a flag, not a quantised measurement)
MIN_LEVELS = 10
#: holds are noted on channels that change at least this many times (setpoints and labels change rarely)
MIN_CHANGES = 20


@dataclass
class Rows:
    """The samples being repaired: time, values (NaN missing), source lines, mode and stamp texts."""

    path: str
    where: str
    time_s: np.ndarray
    values: dict[str, np.ndarray]
    lines: np.ndarray
    stamps: list[str] | None = None  # the time cells as written (date-time stamps), for notes
    automatic: np.ndarray | None = None
    boundaries: list[int] = field(default_factory=list)  # indices where a new segment starts
    notes: list[str] = field(default_factory=list)
    wall_clock: datetime | None = None  # the wall-clock time at 0 s (date-time or epoch stamps), else None

    def __len__(self) -> int:
        return len(self.time_s)

    def keep(self, mask: np.ndarray) -> None:
        """Keep only the rows where ``mask`` is True (boundaries move with their rows)."""
        index = np.cumsum(mask) - 1
        self.boundaries = sorted({int(index[b]) + (0 if mask[b] else 1) for b in self.boundaries
                                  if b < len(mask)} - {0})
        self.time_s, self.lines = self.time_s[mask], self.lines[mask]
        self.values = {k: v[mask] for k, v in self.values.items()}
        if self.stamps is not None:
            self.stamps = [s for s, k in zip(self.stamps, mask) if k]
        if self.automatic is not None:
            self.automatic = self.automatic[mask]

    def stamp(self, i: int) -> str:
        return self.stamps[i] if self.stamps is not None else f"{self.time_s[i]:g} s"

    def note(self, text: str) -> None:
        self.notes.append(f"{self.path}: {text}")

    def clock_segments(self) -> list[tuple[int, int]]:
        edges = [0, *self.boundaries, len(self)]
        return [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def spans(lines: np.ndarray, index: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) source lines of consecutive runs in ``index`` (sorted row indices)."""
    if len(index) == 0:
        return []
    cuts = np.flatnonzero(np.diff(index) > 1) + 1
    return [(int(lines[g[0]]), int(lines[g[-1]])) for g in np.split(index, cuts)]


def interval_s(time_s: np.ndarray) -> float:
    """Median positive interval between samples (s); 1.0 when there is none."""
    d = np.diff(time_s)
    d = d[d > 0]
    return float(np.median(d)) if len(d) else 1.0


# ---- the steps, in order ----------------------------------------------------------------
def drop_exact_duplicates(rows: Rows) -> None:
    """A row equal to the one before in time and every value (and mode) is dropped."""
    if len(rows) < 2:
        return
    same = rows.time_s[1:] == rows.time_s[:-1]
    for v in rows.values.values():
        a, b = v[1:], v[:-1]
        same &= (a == b) | (np.isnan(a) & np.isnan(b))
    if rows.automatic is not None:
        same &= rows.automatic[1:] == rows.automatic[:-1]
    dup = np.flatnonzero(same) + 1
    if len(dup):
        rows.note(f"{places(rows.where, spans(rows.lines, dup))}: {len(dup)} exact duplicate "
                  f"{'row' if len(dup) == 1 else 'rows'} of the row before, dropped")
        mask = np.ones(len(rows), bool)
        mask[dup] = False
        rows.keep(mask)


def split_backwards(rows: Rows, policy: str) -> None:
    """Time going back: refused under ``run``, a new segment under ``historian``."""
    back = np.flatnonzero(np.diff(rows.time_s) < 0) + 1
    if len(back) == 0:
        return
    i = int(back[0])
    why = "clock reset" if rows.time_s[i] <= rows.time_s[0] else "out of order"
    if policy == "run":
        raise ReadError(rows.path, f"time goes back from {rows.stamp(i - 1)} to {rows.stamp(i)} ({why}); "
                                   f"split the file", line=int(rows.lines[i]), where=rows.where)
    for j in back.tolist():
        rows.note(f"{rows.where} {rows.lines[j]}: time goes back from {rows.stamp(j - 1)} to {rows.stamp(j)}; "
                  f"a new segment starts here")
    rows.boundaries = sorted(set(rows.boundaries) | {int(j) for j in back})


def respace_repeats(rows: Rows) -> None:
    """A repeated stamp next to a skipped one (30, 31, 31, 33) is moved into the gap (30, 31, 32, 33)."""
    fixed: list[int] = []
    for a, b in rows.clock_segments():
        t = rows.time_s[a:b]  # a view: edits land in rows.time_s
        dt = interval_s(t)
        for i in np.flatnonzero(np.diff(t) <= REPEAT_TOLERANCE * dt) + 1:
            if t[i] - t[i - 1] > REPEAT_TOLERANCE * dt:
                continue  # already moved by an earlier repair
            if i + 1 < len(t) and abs(t[i + 1] - t[i] - 2 * dt) <= 0.25 * dt:
                t[i] += dt
                fixed.append(a + int(i))
            elif i >= 2 and abs(t[i - 1] - t[i - 2] - 2 * dt) <= 0.25 * dt:
                t[i - 1] -= dt
                fixed.append(a + int(i))
    if fixed:
        pairs = [(int(rows.lines[i - 1]), int(rows.lines[i])) for i in fixed]
        rows.note(f"{places(rows.where, pairs)}: repeated stamp {rows.stamp(fixed[0] - 1)} next to a skipped one "
                  f"({len(fixed)} {'time' if len(fixed) == 1 else 'times'}), re-spaced by one sample interval")


def average_repeats(rows: Rows) -> None:
    """Rows that still share a stamp become one row: values averaged (NaN ignored), mode automatic if all are."""
    rep = np.flatnonzero(np.diff(rows.time_s) == 0) + 1
    rep = np.array([i for i in rep if i not in set(rows.boundaries)], dtype=int)
    if len(rep) == 0:
        return
    group = np.cumsum(np.concatenate([[True], np.diff(rows.time_s) != 0]) | np.isin(np.arange(len(rows)),
                                                                                    rows.boundaries)) - 1
    for name, v in rows.values.items():
        rows.values[name] = _group_mean(v, group)
    if rows.automatic is not None:
        rows.automatic = np.bincount(group, weights=(~rows.automatic).astype(float))[group] == 0
    ids = np.unique(group[rep])
    groups = [(int(rows.lines[np.argmax(group == g)]), int(rows.lines[len(group) - 1 - np.argmax(group[::-1] == g)]))
              for g in ids[:3]]
    rows.note(f"{places(rows.where, groups, len(ids))}: {len(ids)} {'stamp' if len(ids) == 1 else 'stamps'} repeated in "
              f"{len(ids) + len(rep)} rows with different values (first {rows.stamp(int(rep[0]))}), averaged into "
              f"one sample each")
    mask = np.ones(len(rows), bool)
    mask[rep] = False
    rows.keep(mask)


def _group_mean(v: np.ndarray, group: np.ndarray) -> np.ndarray:
    ok = ~np.isnan(v)
    total = np.bincount(group, weights=np.where(ok, v, 0.0))
    count = np.bincount(group, weights=ok.astype(float))
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / np.maximum(count, 1), np.nan)
    return mean[group]


def split_jumps(rows: Rows, policy: str) -> None:
    """Forward jumps: a new segment (historian) or a gap (run), noted either way."""
    found = []
    for a, b in rows.clock_segments():
        t = rows.time_s[a:b]
        dt = interval_s(t)
        for i in np.flatnonzero(np.diff(t) > 1.5 * dt) + 1:
            found.append((a + int(i), float(t[i] - t[i - 1]), dt))
    if not found:
        return
    jumps = [f for f in found if f[1] > CLOCK_JUMP_SAMPLES * f[2]]
    if policy == "historian" and jumps:
        rows.boundaries = sorted(set(rows.boundaries) | {i for i, _, _ in jumps})
        for k, gap, _ in jumps[:3]:
            rows.note(f"{rows.where} {rows.lines[k]}: time jumps {gap:g} s ahead (from {rows.stamp(k - 1)}); "
                      f"a new segment starts here")
        if len(jumps) > 3:
            rows.note(f"{len(jumps) - 3} more time jumps start new segments")
        found = [f for f in found if f not in jumps]
    if found:
        missing = sum(int(round(g / dt)) - 1 for _, g, dt in found)
        k, gap, _ = max(found, key=lambda f: f[1])
        rows.note(f"{places(rows.where, [(int(rows.lines[j - 1]), int(rows.lines[j])) for j, _, _ in found])}: "
                  f"{len(found)} {'gap' if len(found) == 1 else 'gaps'} in time, about {missing} samples missing "
                  f"(longest {gap:g} s after {rows.stamp(k - 1)})")


def note_holds_and_steps(rows: Rows, units: dict[str, str], columns: dict[str, str]) -> None:
    """Note channels that hold their value (step-hold / compressed exports) or are coarsely quantised."""
    for name, v in rows.values.items():
        x = v[~np.isnan(v)]
        if len(x) < 3 or np.ptp(x) == 0:
            continue
        same = np.diff(x) == 0
        longest = _longest(same) + 1
        if same.mean() > HOLD_FRACTION and longest >= HOLD_RUN and (~same).sum() >= MIN_CHANGES:
            rows.note(f"column {columns[name]!r}: {100 * same.mean():.0f} % of samples repeat the one before, up to "
                      f"{longest} in a row (step-hold or compressed export)")
        step = _quantum(x)
        if step is not None:
            unit = units.get(name, "")
            unit = "" if unit == "1" else f" {unit}"
            rows.note(f"column {columns[name]!r}: quantised in steps of {step:.6g}{unit} ({len(np.unique(x))} levels)")


def _longest(mask: np.ndarray) -> int:
    if not mask.any():
        return 0
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return int(np.max(np.flatnonzero(d == -1) - np.flatnonzero(d == 1)))


def _quantum(x: np.ndarray) -> float | None:
    """The step of a coarsely quantised signal (every difference a multiple of it), else None."""
    levels = np.unique(x)
    if len(levels) < MIN_LEVELS or len(x) < 2 * len(levels):
        return None  # few levels (a command, a flag) or each value once (a ramp): not a quantised measurement
    d = np.diff(levels)
    q = float(d.min())
    if q <= 0 or np.ptp(x) / q > COARSE_LEVELS:
        return None
    ratio = d / q
    return q if np.allclose(ratio, np.round(ratio), atol=1e-3) else None
