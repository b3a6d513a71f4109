"""Reading a bag of the node graph back as a run (MCAP or rosbag2 folder), without the project's other readers.

The lowest floor of the bag code: :mod:`phfdi.records` reads bags through it, and :mod:`phfdi.bagio` (which also
reads run files through :mod:`phfdi.records`) builds on it, so the two never import each other in a circle.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from phfdi.records.record import Record
from phfdi_base import topics as T
from phfdi_base.errors import UserError
from phfdi_base.signals import SIGNALS
from phfdi_base.stamps import time_ns, times_on_grid_s

RUN_METADATA = "phfdi_run"


# ---- source positions a bag of a measured record keeps -------------------------------------
def line_runs(lines: np.ndarray) -> list[list[int]]:
    """Source positions compactly: [index, line] where a run of consecutive lines starts (a bag of a record
    carries them, so alarms from its replay name the source file's lines)."""
    lines = np.asarray(lines, dtype=np.int64)
    if not len(lines):
        return []
    starts = np.concatenate([[0], np.flatnonzero(np.diff(lines) != 1) + 1])
    return [[int(i), int(lines[i])] for i in starts]


def lines_from_runs(runs: list[list[int]], n: int) -> np.ndarray:
    """The ``n`` source positions :func:`line_runs` compacted."""
    out = np.zeros(n, dtype=np.int64)
    bounds = [*(int(i) for i, _ in runs), n]
    for (i, first), end in zip(runs, bounds[1:]):
        out[int(i):end] = int(first) + np.arange(end - int(i))
    return out


# ---- run <-> bag --------------------------------------------------------------------
def _feed_names(names) -> list[str]:
    return [n[: -len("_flow_ml_s")] for n in names if n.endswith("_flow_ml_s") and n != "outlet_flow_ml_s"]


def run_signal_names(feeds: list[str]) -> list[str]:
    """Signal order of a closed-loop run (as phfdi.loop.signal_names)."""
    names = [s.name for s in SIGNALS]
    i = names.index("outlet_valve_position_pct")
    return names[:i] + [f"{f}_flow_ml_s" for f in feeds] + names[i:]


def _extract(topic: str, msg, row: dict) -> None:
    """The run signals one message carries."""
    if topic == T.MEASUREMENT.name:
        row["ph_measured"], row["level_measured_cm"] = msg.ph, msg.level_cm
    elif topic == T.CONTROLLER.name:
        row["ph_setpoint"], row["ph_controller_output_pct"] = msg.ph_setpoint, msg.ph_output_pct
        row["level_setpoint_cm"], row["level_controller_output_pct"] = msg.level_setpoint_cm, msg.level_output_pct
    elif topic == T.VALVE_STATE.name:
        row["valve_command_pct"], row["valve_position_pct"] = msg.ph_command_pct, msg.ph_position_pct
        row["outlet_valve_position_pct"] = msg.outlet_position_pct
        row["_valve_fault_severity"] = msg.ph_fault_severity
    elif topic == T.PLANT_STATE.name:
        row["ph_true"], row["level_true_cm"] = msg.ph, msg.level_cm
        for name, q in zip(msg.feed_names, msg.feed_flows_ml_s):
            row[f"{name}_flow_ml_s"] = float(q)
        row["outlet_flow_ml_s"] = msg.outlet_flow_ml_s
        row["_sensor_fault_severity"] = msg.sensor_fault_severity


#: topics that carry run signals (the rest: /clock, /diagnostics, /fault_alarm)
_RUN_TOPICS = (T.MEASUREMENT, T.CONTROLLER, T.VALVE_STATE, T.PLANT_STATE)


def read_metadata(path: Path) -> dict[str, dict[str, str]]:
    """MCAP metadata records by name (empty for a file without a summary)."""
    from mcap.reader import make_reader

    out = {}
    try:
        with open(path, "rb") as f:
            for rec in make_reader(f).iter_metadata():
                out[rec.name] = dict(rec.metadata)
    except Exception:  # noqa: BLE001 - unfinished file: no metadata index
        pass
    return out


def load_bag(path: str | Path) -> Record:
    """A run from a bag of the graph (.mcap file or rosbag2 folder).

    Bag topics map onto the run's signals (``/plant/measurement.ph`` ->
    ``ph_measured``, ...; the table is in docs/ros_graph.md); the time base is
    the stamps of /plant/measurement. ``fault_severity`` is the larger of the
    pH valve's and the sensors' severity, as in :func:`phfdi.loop.tick`.
    Samples a topic lacks (a recovered bag's last sample) are NaN.
    """
    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    if path.suffix.lower() != ".mcap" and not (path / "metadata.yaml").exists():
        raise UserError(f"cannot read a run from {path}: expected .mcap, .csv or .parquet")
    from rosbags.highlevel import AnyReader

    rows: dict[int, dict] = defaultdict(dict)
    measured: set[int] = set()
    seen: dict[str, set[int]] = defaultdict(set)  # stamps taken per topic
    repeated: dict[str, int] = defaultdict(int)
    feeds: list[str] | None = None
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic in {t.name for t in _RUN_TOPICS}]
            if not any(c.topic == T.MEASUREMENT.name for c in conns):
                raise UserError(f"{path}: no {T.MEASUREMENT.name} topic: not a bag of the phfdi graph")
            for conn, _t, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                ns = time_ns(msg.stamp)
                if ns in seen[conn.topic]:  # the first of a stamp is what the graph's lock-step nodes took
                    repeated[conn.topic] += 1
                    continue
                seen[conn.topic].add(ns)
                _extract(conn.topic, msg, rows[ns])
                if conn.topic == T.MEASUREMENT.name:
                    measured.add(ns)
                elif feeds is None and conn.topic == T.PLANT_STATE.name:
                    feeds = list(msg.feed_names)  # the plant's feed order
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags, mcap and zstd raise many types (even MemoryError) on damage
        raise UserError(f"{path}: cannot read the bag ({type(exc).__name__}: {_one_line(exc)}); if its recorder "
                        f"was killed, run: phfdi bag recover {path} FIXED.mcap") from None
    metadata = _run_metadata(path)
    if repeated:  # before: the last message of a stamp silently replaced the first
        metadata["notes"] = [f"{path}: {sum(repeated.values())} message(s) repeat a stamp already seen ("
                             + ", ".join(f"{t} {n}" for t, n in repeated.items()) + "): the first of each stamp "
                             "is kept, as the graph's nodes take it (two runs in one bag, or a stray publisher "
                             "on the graph's domain)"]
    stamps = sorted(measured)
    time_s = times_on_grid_s(stamps, metadata.get("sample_time_s"))  # k * dt exactly as the simulation
    names = run_signal_names(feeds or [])
    signals = {n: np.full(len(stamps), np.nan) for n in names}
    signals["time_s"] = np.asarray(time_s, dtype=float)
    for i, ns in enumerate(stamps):
        row = rows[ns]
        for n, v in row.items():
            if n in signals:
                signals[n][i] = v
        sev = [row[k] for k in ("_valve_fault_severity", "_sensor_fault_severity") if k in row]
        signals["fault_severity"][i] = max(sev) if sev else math.nan
    return Record.of(signals, metadata)


def _one_line(exc: BaseException, limit: int = 160) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _run_metadata(path: Path) -> dict:
    """The run's metadata record (scenario, seed, sample time); a damaged one is a UserError, not a guess."""
    text = read_metadata(path).get(RUN_METADATA, {}).get("json", "{}")
    try:
        metadata = json.loads(text)
    except ValueError as exc:
        raise UserError(f"{path}: the bag's run metadata ({RUN_METADATA}) is damaged ({exc})") from None
    if not isinstance(metadata, dict):
        raise UserError(f"{path}: the bag's run metadata ({RUN_METADATA}) is not a mapping")
    metadata.update({"source": str(path), "mode": "graph"})
    return metadata


def has_topic(path: str | Path, topic: str) -> bool:
    """Whether the bag has ``topic`` (False for a bag that cannot be read: its reader says why)."""
    from rosbags.highlevel import AnyReader

    try:
        with AnyReader([Path(path)]) as reader:
            return any(c.topic == topic for c in reader.connections)
    except Exception:  # noqa: BLE001 - rosbags, mcap and zstd raise many types on damage
        return False


def load_measured_bag(path: str | Path) -> tuple[dict[str, np.ndarray], np.ndarray, str, dict]:
    """A measured record's bag (``phfdi bag from-csv``: one MeasuredSample per row on /measured/sample) as columns:
    ``time_s`` (the record's own time: the stamps plus the metadata's ``time_origin_s``) and one per channel; with
    the source record's line numbers and what they count when the bag keeps them, else the bag's sample numbers."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    stamps: list[int] = []
    values: list[np.ndarray] = []
    names: list[str] | None = None
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic == T.MEASURED_SAMPLE.name]
            for conn, _t, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                if names is None:
                    names = [str(n) for n in msg.names]
                elif list(msg.names) != names:
                    raise UserError(f"{path}: sample {len(stamps) + 1} of {T.MEASURED_SAMPLE.name} names other "
                                    f"channels ({', '.join(msg.names)}) than the first ({', '.join(names)})")
                stamps.append(time_ns(msg.stamp))
                values.append(np.asarray(msg.values, dtype=float))
    except UserError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags, mcap and zstd raise many types on damage
        raise UserError(f"{path}: cannot read the bag ({type(exc).__name__}: {_one_line(exc)}); if its writer "
                        f"was killed, run: phfdi bag recover {path} FIXED.mcap") from None
    if not stamps or names is None:
        raise UserError(f"{path}: the bag holds no sample of {T.MEASURED_SAMPLE.name}")
    metadata = _run_metadata(path)
    metadata["mode"] = "measured"
    x = np.vstack(values)
    columns = {"time_s": np.asarray(stamps, dtype=np.int64) / 1e9 + float(metadata.get("time_origin_s") or 0.0)}
    columns.update({n: x[:, i] for i, n in enumerate(names)})
    runs = metadata.get("source_lines")
    if runs:
        return columns, lines_from_runs(runs, len(stamps)), str(metadata.get("source_where", "line")), metadata
    return columns, np.arange(1, len(stamps) + 1), "sample", metadata
