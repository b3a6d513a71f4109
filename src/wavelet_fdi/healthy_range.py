"""What a reference's healthy runs covered, channel by channel, and where a record leaves it.

A reference, learned or physical, is fitted where its healthy runs went; beyond that it extrapolates, and a
residual there says as much about the reference as about the plant. On the pH rig every false alarm of a
reference calibrated on three runs fell where a pump ran at a setting none of them had (docs/detector.md,
"leave-two-out"). :func:`healthy_ranges` keeps, per channel, the range of the healthy values (exact zeros apart:
a pump or valve that is off is a state of its own, not the bottom of its range) and :func:`outside_ranges`
reports the share of a record's rows beyond it, so that ``phfdi replay`` can say so beside the alarms.

Examples
--------
>>> import numpy as np
>>> healthy = [np.array([[0.0, 7.0], [3.6, 6.5], [3.6, 4.0]])]
>>> ranges = healthy_ranges(healthy, ["acid_flow_ml_s", "ph"])
>>> ranges["acid_flow_ml_s"]
{'min': 3.6, 'max': 3.6, 'zero': True}
>>> watched = np.array([[0.0, 7.0], [4.3, 5.0], [4.3, 3.9]])
>>> [(o["channel"], round(o["share"], 2), o["max"]) for o in outside_ranges(ranges, watched, ["acid_flow_ml_s", "ph"])]
[('acid_flow_ml_s', 0.67, 4.3)]
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from phfdi_base.errors import UserError

#: a value counts as outside when it lies beyond the healthy range by more than this share of the range's width,
#: or of a tenth of its magnitude where the range is narrow (a pump with one setting): readings' own jitter and
#: a setting's rounding stay inside
TOLERANCE = 0.05


def healthy_ranges(runs: Sequence[np.ndarray], channels: Sequence[str]) -> dict[str, dict]:
    """Per channel: ``min`` and ``max`` of the finite non-zero healthy values (None when there are none) and
    ``zero``, whether any healthy value was exactly 0. ``runs``: arrays (rows, len(channels))."""
    rows = [np.asarray(r, dtype=float).reshape(len(r), len(channels)) for r in runs if len(r)]
    x = np.vstack(rows) if rows else np.empty((0, len(channels)))
    out: dict[str, dict] = {}
    for i, name in enumerate(channels):
        v = x[:, i][np.isfinite(x[:, i])]
        nonzero = v[v != 0.0]
        out[name] = {"min": float(nonzero.min()) if len(nonzero) else None,
                     "max": float(nonzero.max()) if len(nonzero) else None, "zero": bool(np.any(v == 0.0))}
    return out


def checked_ranges(obj, where: str) -> dict[str, dict]:
    """Ranges read from a file: each channel's ``min`` and ``max`` numbers (or both None), ``zero`` true or false;
    anything else is one UserError naming the channel."""
    if not isinstance(obj, dict):
        raise UserError(f"{where}: expected a mapping channel -> {{min, max, zero}}")
    out = {}
    for name, r in obj.items():
        try:
            lo, hi, zero = r["min"], r["max"], r["zero"]
            if (lo is None) != (hi is None) or not isinstance(zero, bool):
                raise ValueError("min and max both numbers or both null, zero true or false")
            if lo is not None:
                lo, hi = float(lo), float(hi)
                if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                    raise ValueError("min <= max, both finite")
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(f"{where}: channel {name!r}: {exc}") from None
        out[str(name)] = {"min": lo, "max": hi, "zero": zero}
    return out


def _tolerance(lo: float, hi: float) -> float:
    return TOLERANCE * max(hi - lo, 0.1 * max(abs(lo), abs(hi)))


def _beyond(ranges: dict[str, dict], x: np.ndarray, channels: Sequence[str]):
    """(channel, its values, mask of the rows outside its healthy range) for each channel the ranges know."""
    for i, name in enumerate(channels):
        r = ranges.get(name)
        if r is None or len(x) == 0:
            continue
        v = x[:, i]
        zero = v == 0.0
        if r["min"] is None:  # only zeros (or nothing) were healthy
            beyond = ~zero
        else:
            tol = _tolerance(r["min"], r["max"])
            beyond = (v < r["min"] - tol) | (v > r["max"] + tol)
        yield name, v, np.isfinite(v) & beyond & ~(zero & r["zero"])


def outside_masks(ranges: dict[str, dict], x: np.ndarray, channels: Sequence[str]) -> dict[str, np.ndarray]:
    """Per channel the ranges know, which rows of ``x`` (rows, len(channels)) leave its healthy range."""
    return {name: bad for name, _, bad in _beyond(ranges, np.asarray(x, dtype=float), channels)}


def outside_ranges(ranges: dict[str, dict], x: np.ndarray, channels: Sequence[str]) -> list[dict]:
    """The channels of ``x`` (rows, len(channels)) whose finite values leave their healthy range: each as
    ``channel``, ``share`` of the rows outside, the record's ``min`` and ``max`` there and the ``healthy`` range.
    Channels the ranges do not know are skipped (a reference file from before they were kept has none)."""
    watch = RangeWatch(ranges, channels)
    watch.update(x)
    return watch.summary()


class RangeWatch:
    """:func:`outside_ranges` for a stream taken in chunks (the detector node): the same summary at any time.

    Examples
    --------
    >>> import numpy as np
    >>> watch = RangeWatch({"flow": {"min": 1.0, "max": 2.0, "zero": True}}, ["flow"])
    >>> [o["channel"] for o in watch.update(np.array([[1.5], [0.0]]))], watch.update(np.array([[3.0]]))[0]["max"]
    ([], 3.0)
    >>> watch.update(np.array([[4.0]])), round(watch.summary()[0]["share"], 2)  # said once: not new any more
    ([], 0.5)
    """

    def __init__(self, ranges: dict[str, dict], channels: Sequence[str]) -> None:
        self.ranges, self.channels = ranges, list(channels)
        self.rows = 0
        self._outside: dict[str, dict] = {}  # channel -> count, min, max so far

    def update(self, x: np.ndarray) -> list[dict]:
        """Take the next rows; returns the channels that left their range for the first time (summary form)."""
        x = np.asarray(x, dtype=float).reshape(-1, len(self.channels))
        self.rows += len(x)
        new = []
        for name, v, bad in _beyond(self.ranges, x, self.channels):
            if not bad.any():
                continue
            o = self._outside.get(name)
            lo, hi, n = float(v[bad].min()), float(v[bad].max()), int(bad.sum())
            if o is None:
                self._outside[name] = {"count": n, "min": lo, "max": hi}
                new.append(name)
            else:
                o.update(count=o["count"] + n, min=min(o["min"], lo), max=max(o["max"], hi))
        return [o for o in self.summary() if o["channel"] in new]

    def summary(self) -> list[dict]:
        """Each channel outside so far: ``channel``, ``share`` of the rows (``rows`` of ``of``), ``min`` and ``max``
        of its values there, and its ``healthy`` range."""
        return [{"channel": name, "share": o["count"] / self.rows, "rows": o["count"], "of": self.rows,
                 "min": o["min"], "max": o["max"], "healthy": dict(self.ranges[name])}
                for name in self.channels if (o := self._outside.get(name)) is not None]


def span(o: dict) -> str:
    """The values a channel took outside its range: one number, or "lowest to highest"."""
    return f"{o['min']:.4g}" if o["min"] == o["max"] else f"{o['min']:.4g} to {o['max']:.4g}"


def healthy_span(h: dict) -> str:
    """What the healthy runs had, from a channel's range: "0 or 1.29 to 3.87" (0: a pump or valve off)."""
    seen = ["0"] if h["zero"] else []
    if h["min"] is not None:
        seen.append(span(h))
    return " or ".join(seen) or "none"


WHAT_IT_MEANS = "a fault, or an operation the calibration never saw (the reference extrapolates there; an alarm " \
                "may be its own)"


def describe(o: dict) -> str:
    """One line for a channel outside its healthy range over a record."""
    return (f"{o['channel']} left the range of the reference's healthy runs in {o['rows']} of {o['of']} rows "
            f"({100 * o['share']:.2g} %; {span(o)}, healthy: {healthy_span(o['healthy'])}): {WHAT_IT_MEANS}")


def describe_first(o: dict) -> str:
    """One line for a channel leaving its healthy range for the first time in a stream (in a chunk that ends at
    sample ``of``)."""
    return (f"{o['channel']} left the range of the reference's healthy runs by sample {o['of']} ({span(o)}, "
            f"healthy: {healthy_span(o['healthy'])}): {WHAT_IT_MEANS}")
