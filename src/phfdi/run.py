"""One description of a run: signals, units and the time base.

Shared by the simulator's output, the recorder (topic <-> signal), replay,
analysis and diagnosis. A run is a uniform time base ``time_s`` plus named
signals of the same length; names carry their unit as a suffix
(``_pct``, ``_ml_s``, ``_cm``, ``_s``) and pH signals start with ``ph``.

Files: CSV (one header line of signal names, then one row per sample) and
Parquet (columnar; units and run metadata in the schema's metadata).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from operator import itemgetter
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from phfdi_base.errors import UserError
from phfdi_base.outputs import staged
from phfdi_base.signals import unit_of


@dataclass
class Run:
    """Signals sampled on a common uniform time base.

    ``signals`` maps names to 1-D float arrays of equal length (``time_s``
    included). ``metadata`` holds the scenario, seed, sample time and what
    produced the run.
    """

    signals: dict[str, np.ndarray]
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if "time_s" not in self.signals:
            raise UserError("a run needs a time_s signal")
        n = len(self.signals["time_s"])
        for name, values in self.signals.items():
            if len(values) != n:
                raise UserError(f"signal {name!r} has {len(values)} samples, time_s has {n}")

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.signals[name]
        except KeyError:
            raise KeyError(f"run has no signal {name!r}; it has: {', '.join(self.signals)}") from None

    def __contains__(self, name: str) -> bool:
        return name in self.signals

    def __len__(self) -> int:
        return len(self.signals["time_s"])

    @property
    def names(self) -> list[str]:
        return list(self.signals)

    @property
    def time_s(self) -> np.ndarray:
        return self.signals["time_s"]

    @property
    def dt_s(self) -> float:
        t = self.time_s
        return float(t[1] - t[0]) if len(t) > 1 else float(self.metadata.get("sample_time_s", 1.0))

    def units(self) -> dict[str, str]:
        return {n: unit_of(n) for n in self.signals}

    def segment(self, t0_s: float, t1_s: float) -> "Run":
        """Samples with t0 <= t < t1."""
        m = (self.time_s >= t0_s) & (self.time_s < t1_s)
        return Run({k: v[m] for k, v in self.signals.items()}, dict(self.metadata))

    # ---- files ---------------------------------------------------------------
    def to_csv(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write as CSV (header of signal names, full float precision), atomically (phfdi_base.outputs)."""
        names = self.names
        data = np.column_stack([self.signals[n] for n in names])
        with staged(path, overwrite) as tmp:
            np.savetxt(tmp, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        return Path(path)

    def to_parquet(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write as Parquet (units in the fields' metadata, the run's metadata in the schema's), atomically."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        fields = [pa.field(n, pa.float64(), metadata={"unit": unit_of(n)}) for n in self.names]
        schema = pa.schema(fields, metadata={"phfdi_run": json.dumps(self.metadata, default=str)})
        table = pa.table({n: np.asarray(self.signals[n], dtype=float) for n in self.names}, schema=schema)
        with staged(path, overwrite) as tmp:
            pq.write_table(table, tmp)
        return Path(path)

    def save(self, path: str | Path, overwrite: bool = True) -> Path:
        """Write by extension: .csv or .parquet. The library replaces an existing file; the commands pass
        ``overwrite=args.overwrite`` (an existing file is kept without ``--overwrite``)."""
        writer = {"csv": self.to_csv, "parquet": self.to_parquet}[writable_format(path)]
        return writer(path, overwrite)


#: the formats a run is written to (the readers are registered in :mod:`phfdi.records.formats`)
WRITE_SUFFIXES = {".csv": "csv", ".parquet": "parquet", ".pq": "parquet"}


def writable_format(path: str | Path) -> str:
    """The format :meth:`Run.save` writes ``path`` in ("csv" or "parquet"); a one-line UserError for others."""
    fmt = WRITE_SUFFIXES.get(Path(path).suffix.lower())
    if fmt is None:
        raise UserError(f"cannot write a run to {path}: use a .csv or .parquet file name")
    return fmt


class RunRecorder:
    """Rows collected one sample at a time, turned into columns at the end."""

    def __init__(self, names: Iterable[str], n_samples: int = 0) -> None:
        self.names = list(names)
        self.rows: list[Mapping[str, float]] = []

    def append(self, row: Mapping[str, float]) -> None:
        self.rows.append(row)

    @property
    def n(self) -> int:
        return len(self.rows)

    def run(self, metadata: dict) -> Run:
        rows = self.rows
        if not rows:
            return Run({n: np.zeros(0) for n in self.names}, metadata)
        try:  # every row has every signal (the usual case): one C-level pass
            table = np.array(list(map(itemgetter(*self.names), rows)), dtype=float).reshape(len(rows), -1)
        except KeyError:  # some rows lack a signal: NaN there
            table = np.array([[r.get(n, math.nan) for n in self.names] for r in rows], dtype=float)
        return Run({n: table[:, i].copy() for i, n in enumerate(self.names)}, metadata)
