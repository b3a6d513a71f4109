"""The one in-memory record of the project: a run the simulators make, a file the reader reads.

A record is a time base ``time_s`` plus named signals of the same length; names carry their unit as a suffix
(``_pct``, ``_ml_s``, ``_cm``, ``_s``) and pH signals start with ``ph``. Read from a file
(:func:`~phfdi.records.read_record`) it keeps every repair made and where each sample came from; made by a
simulator (:meth:`Record.of`) it is a run on a uniform time base. Files it is written to: CSV (one header line
of signal names, then one row per sample) and Parquet (units and the run's metadata in the schema's
metadata), atomically.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Mapping

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.outputs import staged
from phfdi_base.signals import unit_of

from .cells import iso_stamp
from .columns import OUTPUTS, is_input
from .errors import ReadError
from .formats import writable_format
from .notes import places
from .policy import interval_s, spans


@dataclass
class Record:
    """Samples of one file in the project's names and units.

    ``time_s`` in seconds (not necessarily uniform; see :meth:`on_grid`); ``signals`` name -> float array
    with NaN where a sample is missing; ``lines`` the source line (text), row (Parquet) or sample (bag)
    of each sample, ``where`` which of the three; ``columns`` signal -> the file's column name;
    ``automatic`` True where the controller was in automatic (None: no MODE column);
    ``boundaries`` indices where a new segment starts (historian policy: clock resets and jumps);
    ``grid_s`` the step of the uniform grid the samples were put on by a reader that states one (the model
    diagnosis's, :func:`phfdi.diagnosis.make_record`), else None: :attr:`dt_s` is then the median interval.

    ``uniform``: made as a run on a uniform time base (:meth:`of`: a simulator's run, or :meth:`to_run` of a
    read record), whose :attr:`dt_s` is its first interval (``metadata["sample_time_s"]`` with one sample).

    Made by :func:`~phfdi.records.read_record` or, from signals, by :meth:`of`; :meth:`to_run` gives it as a run
    (one segment, its notes and units in the metadata). ``record["time_s"]`` is the time base as any signal.
    The model diagnosis reads the same record on its uniform grid, split into :attr:`inputs` and :attr:`outputs`.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from phfdi.records import read_record
    >>> path = Path(tempfile.mkdtemp()) / "run.csv"
    >>> _ = path.write_text("time_s,ph_measured\\n0,7.0\\n1,7.1\\n2,7.2\\n")
    >>> record = read_record(path)
    >>> len(record), record.names, record.units
    (3, ['ph_measured'], {'ph_measured': 'pH'})
    >>> run = record.to_run()
    >>> run["time_s"], run.metadata["units"]
    (array([0., 1., 2.]), {'ph_measured': 'pH'})
    """

    path: str
    time_s: np.ndarray
    signals: dict[str, np.ndarray]
    units: dict[str, str]
    columns: dict[str, str]
    lines: np.ndarray
    where: str = "line"
    policy: str = "run"
    notes: list[str] = field(default_factory=list)
    automatic: np.ndarray | None = None
    boundaries: list[int] = field(default_factory=list)
    metadata: dict = field(default_factory=dict)
    #: the wall-clock time at ``time_s`` 0 when the time column holds date-time or epoch stamps (None: the
    #: record's own seconds only); :func:`~phfdi.records.cells.iso_stamp` turns a time into its stamp
    wall_clock: datetime | None = None
    grid_s: float | None = None
    uniform: bool = False

    @classmethod
    def of(cls, signals: Mapping[str, np.ndarray], metadata: dict | None = None) -> "Record":
        """A run made from signals (``time_s`` among them, every signal as long), the way the simulators, the bag
        reader and the loop diagnosis's windows make one. ``metadata``: scenario, seed, sample time, what made it
        (its ``source`` names the record). A one-line UserError when ``time_s`` is missing or a length differs.

        >>> run = Record.of({"time_s": np.arange(3.0), "ph_measured": np.array([7.0, 7.1, 7.2])}, {"seed": 1})
        >>> run.names, run.dt_s, run.units, len(run)
        (['ph_measured'], 1.0, {'ph_measured': 'pH'}, 3)
        >>> Record.of({"time_s": np.arange(3.0), "pv": np.zeros(2)})
        Traceback (most recent call last):
        ...
        phfdi_base.errors.UserError: signal 'pv' has 2 samples, time_s has 3
        """
        if "time_s" not in signals:
            raise UserError("a run needs a time_s signal")
        time_s = signals["time_s"]
        n = len(time_s)
        for name, values in signals.items():
            if len(values) != n:
                raise UserError(f"signal {name!r} has {len(values)} samples, time_s has {n}")
        metadata = {} if metadata is None else metadata
        named = {k: v for k, v in signals.items() if k != "time_s"}
        return cls(str(metadata.get("source", "run")), time_s, named, {k: unit_of(k) for k in named},
                   {k: k for k in named}, np.arange(1, n + 1), "sample", metadata=metadata, uniform=True)

    def __len__(self) -> int:
        return len(self.time_s)

    def __getitem__(self, name: str) -> np.ndarray:
        """A signal by name, ``time_s`` included."""
        if name == "time_s":
            return self.time_s
        try:
            return self.signals[name]
        except KeyError:
            raise KeyError(f"run has no signal {name!r}; it has: {', '.join(['time_s', *self.signals])}") from None

    def __contains__(self, name: str) -> bool:
        return name == "time_s" or name in self.signals

    @property
    def name(self) -> str:
        """What reports call the record: the file (or label) it was made from."""
        return self.path

    @property
    def names(self) -> list[str]:
        return list(self.signals)

    @property
    def inputs(self) -> dict[str, np.ndarray]:
        """The signals that drive the plant (controller outputs, feed flows), in the record's order."""
        return {k: v for k, v in self.signals.items() if is_input(k)}

    @property
    def outputs(self) -> dict[str, np.ndarray]:
        """The measured outputs (pH, level), in the record's order."""
        return {k: v for k, v in self.signals.items() if k in OUTPUTS}

    def constant_inputs(self) -> bool:
        """True when no input moves (nothing excites the plant)."""
        for v in self.inputs.values():
            scale = max(1.0, float(np.max(np.abs(v))))
            if float(np.max(v) - np.min(v)) > 1e-6 * scale:
                return False
        return True

    @property
    def channels(self) -> tuple[str, ...]:
        """The signals' names in order: the columns of :attr:`x`."""
        return tuple(self.signals)

    @property
    def x(self) -> np.ndarray:
        """The signals as one matrix (samples x :attr:`channels`, NaN where missing): the rows a detector takes.
        A new array at each call; :meth:`select` orders the channels."""
        if not self.signals:
            return np.empty((len(self), 0))
        return np.column_stack([np.asarray(v, dtype=float) for v in self.signals.values()])

    def stamp(self, t_s: float | None) -> str | None:
        """The ISO 8601 stamp of ``t_s`` seconds of this record (None without a wall clock)."""
        return iso_stamp(self.wall_clock, t_s)

    def when(self, t_s: float) -> str:
        """``t_s`` for people: seconds, and the stamp when the record has a wall clock."""
        stamp = self.stamp(t_s)
        return f"{t_s:g} s" + (f" ({stamp})" if stamp else "")

    @property
    def missing(self) -> dict[str, np.ndarray]:
        """Per channel, True where the sample is missing."""
        return {k: np.isnan(v) for k, v in self.signals.items()}

    @property
    def dt_s(self) -> float:
        """The sample interval (s): the grid's step on a stated grid (``grid_s``), a run's first interval
        (``uniform``), else the median interval."""
        if self.grid_s is not None:
            return self.grid_s
        if self.uniform:
            t = self.time_s
            return float(t[1] - t[0]) if len(t) > 1 else float(self.metadata.get("sample_time_s", 1.0))
        return interval_s(self.time_s)

    # ---- reporting ------------------------------------------------------------------------
    def note_lines(self) -> list[str]:
        """Every repair and observation, one line each (for stderr and reports)."""
        return list(self.notes)

    def summary(self) -> dict:
        """What was read, for JSON output: file, rows, channels with units and missing counts, segments, notes."""
        return {"file": self.path, "policy": self.policy, "samples": len(self),
                "time_s": [float(self.time_s[0]), float(self.time_s[-1])] if len(self) else None,
                "channels": {k: {"column": self.columns.get(k, k), "unit": self.units.get(k, ""),
                                 "missing": int(np.isnan(v).sum())} for k, v in self.signals.items()},
                "segments": len(self.boundaries) + 1, "notes": self.note_lines()}

    # ---- conversions ----------------------------------------------------------------------
    def to_run(self) -> "Record":
        """This record as a run (:meth:`of`): copies of its samples, NaN where missing, its source, notes and units
        in the metadata; one segment only."""
        if self.boundaries:
            raise ReadError(self.path, f"{len(self.boundaries) + 1} segments (the clock resets or jumps); "
                                       f"take one with segments()")
        meta = {**self.metadata, "source": self.path, "notes": self.note_lines(), "units": dict(self.units)}
        return Record.of({"time_s": self.time_s.copy(), **{k: v.copy() for k, v in self.signals.items()}}, meta)

    def segment(self, t0_s: float, t1_s: float) -> "Record":
        """Samples with t0 <= t < t1 (a run of their own, the metadata copied)."""
        m = (self.time_s >= t0_s) & (self.time_s < t1_s)
        return Record.of({"time_s": self.time_s[m], **{k: v[m] for k, v in self.signals.items()}},
                         dict(self.metadata))

    # ---- files ----------------------------------------------------------------------------
    def to_csv(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write as CSV (header of signal names, ``time_s`` first, full float precision), atomically
        (:mod:`phfdi_base.outputs`)."""
        names = ["time_s", *self.names]
        data = np.column_stack([self[n] for n in names])
        with staged(path, overwrite) as tmp:
            np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        return Path(path)

    def to_parquet(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write as Parquet (units in the fields' metadata, the metadata in the schema's), atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        names = ["time_s", *self.names]
        fields = [pa.field(n, pa.float64(), metadata={"unit": unit_of(n)}) for n in names]
        schema = pa.schema(fields, metadata={"phfdi_run": json.dumps(self.metadata, default=str)})
        table = pa.table({n: np.asarray(self[n], dtype=float) for n in names}, schema=schema)
        with staged(path, overwrite) as tmp:
            pq.write_table(table, tmp)
        return Path(path)

    def save(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write by extension: .csv or .parquet. The library replaces an existing file; the commands pass
        ``overwrite=args.overwrite`` (an existing file is kept without ``--overwrite``)."""
        writer = {"csv": self.to_csv, "parquet": self.to_parquet}[writable_format(path)]
        return writer(path, overwrite)

    def select(self, channels: list[str] | tuple[str, ...]) -> "Record":
        """Only these channels (in this order)."""
        return replace(self, signals={c: self.signals[c] for c in channels},
                       units={c: self.units.get(c, "") for c in channels})

    def subset(self, index: np.ndarray | slice, **changes) -> "Record":
        """The samples at ``index`` (a slice or an index array) as a record of their own, notes kept."""
        auto = None if self.automatic is None else self.automatic[index]
        return replace(self, time_s=self.time_s[index], lines=self.lines[index], automatic=auto,
                       signals={k: v[index] for k, v in self.signals.items()}, notes=list(self.notes), **changes)

    def slice(self, start: int, stop: int, name: str | None = None) -> "Record":
        """Samples ``start:stop`` as a record of their own (copies), renamed ``name`` when given."""
        start, stop, _ = slice(start, stop).indices(len(self))
        part = self.subset(slice(start, stop), boundaries=[b - start for b in self.boundaries if start < b < stop],
                           **({"path": name} if name else {}))
        return replace(part, time_s=part.time_s.copy(), lines=part.lines.copy(),
                       signals={k: v.copy() for k, v in part.signals.items()})

    def segments(self, automatic_only: bool = True, min_samples: int = 1) -> list["Record"]:
        """Stretches on one clock (and, with a MODE column, in automatic), each a record of its own."""
        out = []
        edges = [0, *self.boundaries, len(self)]
        for a, b in zip(edges[:-1], edges[1:]):
            keep = np.ones(b - a, bool) if self.automatic is None or not automatic_only else self.automatic[a:b]
            padded = np.diff(np.concatenate([[0], keep.astype(np.int8), [0]]))
            for s, e in zip(np.flatnonzero(padded == 1), np.flatnonzero(padded == -1)):
                if e - s >= min_samples:
                    seg = self.subset(slice(a + s, a + e), boundaries=[])
                    if e - s < len(self):
                        first, last = self.lines[a + s], self.lines[a + e - 1]
                        seg.notes.append(f"{self.path}: segment {self.where}s {first}-{last} ({e - s} samples)")
                    out.append(seg)
        return out

    def longest_segment(self, automatic_only: bool = True) -> "Record":
        """The longest segment; a :class:`ReadError` when none is left."""
        segs = self.segments(automatic_only)
        if not segs:
            raise ReadError(self.path, "no usable stretch: the controller is never in automatic"
                            if self.automatic is not None else "no sample left")
        return max(segs, key=len)

    def on_grid(self, dt_s: float | None = None) -> "Record":
        """Samples on the uniform grid t0 + k dt (nearest within dt/2); empty slots missing, extra samples dropped."""
        if self.boundaries:
            raise ValueError("on_grid needs one segment: call segments() first")
        dt = float(dt_s or self.dt_s)
        slot = np.round((self.time_s - self.time_s[0]) / dt).astype(np.int64)
        first = np.concatenate([[True], slot[1:] != slot[:-1]])
        n = int(slot[-1]) + 1
        if n > max(10 * len(self), len(self) + 1000):
            raise ReadError(self.path, f"a {dt:g} s grid over {self.time_s[0]:g}..{self.time_s[-1]:g} s would hold "
                                       f"{n:.3g} slots for {len(self)} samples (the time jumps): split the record")
        notes = list(self.notes)
        if not first.all():
            notes.append(f"{self.path}: {int((~first).sum())} samples share a {dt:g} s grid slot with the one before, "
                         f"dropped (first at {self.where} {self.lines[np.argmin(first)]})")
        empty = n - int(first.sum())
        if empty:
            notes.append(f"{self.path}: {empty} slots of the {dt:g} s grid have no sample: missing")
        idx = slot[first]

        def put(v: np.ndarray, fill: float) -> np.ndarray:
            out = np.full(n, fill, dtype=v.dtype if v.dtype != bool else bool)
            out[idx] = v[first]
            return out

        return replace(self, time_s=self.time_s[0] + dt * np.arange(n), lines=put(self.lines, 0),
                       signals={k: put(v, np.nan) for k, v in self.signals.items()}, notes=notes,
                       automatic=None if self.automatic is None else put(self.automatic, False))

    def filled(self, max_gap_s: float, channels: list[str] | None = None) -> "Record":
        """Interior gaps of at most ``max_gap_s`` seconds filled by linear interpolation in time (noted)."""
        signals, notes = dict(self.signals), list(self.notes)
        dt = self.dt_s
        for name in channels or self.names:
            v = signals[name]
            bad = np.isnan(v)
            if not bad.any() or bad.all():
                continue
            d = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
            starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
            inner = (starts > 0) & (stops < len(v))
            short = inner & ((self.time_s[np.minimum(stops, len(v) - 1)] - self.time_s[np.maximum(starts - 1, 0)]
                              - dt) <= max_gap_s + 1e-9 * dt)
            if not short.any():
                continue
            fill = np.concatenate([np.arange(a, b) for a, b in zip(starts[short], stops[short])])
            good = ~bad
            v = v.copy()
            v[fill] = np.interp(self.time_s[fill], self.time_s[good], v[good])
            signals[name] = v
            where = places(self.where, [(int(self.lines[a]), int(self.lines[b - 1]))
                                        for a, b in zip(starts[short], stops[short])])
            notes.append(f"{self.path}: {where}, column {self.columns.get(name, name)!r}: {len(fill)} missing samples "
                         f"in {int(short.sum())} gap(s) of up to {max_gap_s:g} s filled by linear interpolation")
        return replace(self, signals=signals, notes=notes)

    def refuse_empty(self, channel: str) -> "Record":
        """This record, or a :class:`ReadError` when ``channel`` has no value at all."""
        if np.isnan(self.signals[channel]).all():
            raise ReadError(self.path, f"no usable value in any of the {len(self)} rows (all missing)",
                            line=int(self.lines[0]) if len(self) else None,
                            column=self.columns.get(channel, channel), where=self.where)
        return self

    def refuse_missing(self, channel: str, hint: str = "") -> "Record":
        """This record, or a :class:`ReadError` naming the first missing sample of ``channel``."""
        bad = np.flatnonzero(np.isnan(self.signals[channel]))
        if len(bad):
            where = places(self.where, spans(self.lines, bad))
            raise ReadError(self.path, f"{len(bad)} missing {'value' if len(bad) == 1 else 'values'} ({where})"
                            + (f"; {hint}" if hint else ""), line=int(self.lines[bad[0]]),
                            column=self.columns.get(channel, channel), where=self.where)
        return self
