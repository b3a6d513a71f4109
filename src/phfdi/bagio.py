"""Bags (MCAP files, ros2 profile) and runs: write, read, inspect, recover.

A bag of the graph holds one channel per topic of :mod:`phfdi_base.topics`
(cdr messages, ``ros2msg`` schemas, the offered QoS and type hash in the
channel metadata as rosbag2 writes them), every message logged at its
simulated time stamp, the run's metadata (scenario, seed, faults) in an MCAP
metadata record named ``phfdi_run`` and, written at close, rosbag2's own
metadata record ``rosbag2`` (:mod:`phfdi.rosbag2_meta`; what ``ros2 bag
info``/``play`` read from a bare .mcap). rosbags (AnyReader and its rosbag2
Reader), mcap-ros2-support and Foxglove read it.

- :class:`BagWriter`: what the recorder node and :func:`write_run` write with;
  small chunks (16 KB) so that a killed writer leaves recoverable chunks.
- :func:`load_run`: bag (or .csv / .parquet run file) -> :class:`phfdi.records.Record`
  with the run's signal names and units on the simulated time base.
- :func:`write_run`: a run (a Record) -> bag with the graph's topics (for replay).
- :func:`bag_info` and :func:`recover`: ``phfdi bag info`` / ``phfdi bag recover``.
- :func:`check_not_recording`: is another process writing this bag (the writer's lock)?

A :class:`BagWriter` holds an exclusive ``flock`` on its file from before the
file is truncated until it is closed, so a second writer of the same path is
refused (:class:`BagBusyError`) without touching the first one's data. A write
that fails (a full disk: ENOSPC; a file size limit: EFBIG; any OSError) cuts
the file back to the end of the last record written whole and ends the
writer: the file then holds every chunk completed before, readable by
:func:`bag_info` and restorable by :func:`recover`.

No rclpy here: messages are decoded with rosbags from the bag's own schemas.
"""

from __future__ import annotations

import contextlib
import fcntl
import io
import json
import math
import os
import stat
import sys
import time
from collections import defaultdict
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Iterator

import numpy as np

from phfdi.records.record import Record
from phfdi_base import topics as T
from phfdi_base.errors import UserError
from phfdi_base.outputs import staged
from phfdi_base.stamps import join_ns, record_stamps_ns, seconds_to_ns, split_ns
from wavelet_fdi.alarm_messages import to_dict as alarm_message_dict

from . import __version__, rosbag2_meta
from .bagread import RUN_METADATA, _feed_names, _one_line, read_metadata, run_signal_names

INTERFACES_PACKAGE = "phfdi_interfaces"
DEFAULT_CHUNK_BYTES = 16 * 1024


# ---- message definitions --------------------------------------------------------------
def _msg_dirs() -> list[Path]:
    """Where phfdi_interfaces' .msg files are: this checkout, then installed prefixes."""
    dirs = [Path(__file__).resolve().parents[2] / "interfaces" / INTERFACES_PACKAGE / "msg"]
    prefixes = [p for p in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if p] + [sys.prefix]
    dirs += [Path(p) / "share" / INTERFACES_PACKAGE / "msg" for p in prefixes]
    return [d for d in dirs if d.is_dir()]


@lru_cache(maxsize=1)
def typestore():
    """rosbags type store: ROS 2 Jazzy's standard types plus phfdi_interfaces."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    dirs = _msg_dirs()
    if not dirs:
        raise UserError(f"cannot find the {INTERFACES_PACKAGE} message definitions (run scripts/setup.sh)")
    types: dict = {}
    for f in sorted(dirs[0].glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(encoding="utf-8"), f"{INTERFACES_PACKAGE}/msg/{f.stem}"))
    store.register(types)
    return store


def schema_text(msgtype: str) -> str:
    """Full ros2msg definition of a type (dependencies appended after '=' * 80 lines)."""
    return typestore().generate_msgdef(msgtype, ros_version=2)[0]


def qos_metadata(qos: dict = T.DATA_QOS) -> str:
    """A channel's ``offered_qos_profiles`` as rosbag2 (Jazzy, metadata version 9) writes it."""
    return rosbag2_meta.qos_yaml(rosbag2_meta.offered_qos(qos))


def type_hash(msgtype: str) -> str:
    """The type's RIHS01 hash (``topic_type_hash``), as rclpy's discovery reports it for the same type."""
    return typestore().hash_rihs01(msgtype)


# ---- writing ------------------------------------------------------------------------
class BagBusyError(UserError):
    """Another process holds the bag's lock: it is recording that file now."""


class BagExistsError(UserError):
    """The bag exists and the writer was not told to replace it."""


#: how long a writer retries a lock held by someone else before it refuses: :func:`check_not_recording` takes
#: the lock for microseconds to test it, which must not make a recorder starting at that moment fail
LOCK_RETRY_S = 0.5


def _lock_holder(fd: int) -> int | None:
    """PID of the process holding a flock on this file, from /proc/locks (Linux; None if not found)."""
    st = os.fstat(fd)
    dev = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return None
    for line in lines:  # "1: FLOCK  ADVISORY  WRITE 4711 00:2d:1234 0 EOF"
        fields = line.split()
        if "FLOCK" in fields and dev in fields and "->" not in fields:
            try:
                return int(fields[fields.index(dev) - 1])
            except ValueError:
                return None
    return None


#: what a writer that finds its file being recorded is told to do
GIVE_ANOTHER_NAME = "give another name, or stop that recording first"


def busy_message(path: str | Path, pid: int | None, advice: str = GIVE_ANOTHER_NAME) -> str:
    who = f"another process (pid {pid})" if pid else "another process"
    return f"{path}: {who} is recording this bag now; {advice}"


def _lock(fd: int, path: str | Path, how: int = fcntl.LOCK_EX, retry_s: float = LOCK_RETRY_S,
          advice: str = GIVE_ANOTHER_NAME) -> None:
    """Take ``how`` (flock) on ``fd`` without blocking, retrying for ``retry_s``; :class:`BagBusyError` if
    another process keeps it."""
    deadline = time.monotonic() + retry_s
    while True:
        try:
            fcntl.flock(fd, how | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() >= deadline:
                raise BagBusyError(busy_message(path, _lock_holder(fd), advice)) from None
            time.sleep(0.02)


def check_not_recording(path: str | Path, advice: str = GIVE_ANOTHER_NAME) -> None:
    """:class:`BagBusyError` (one line, ending in ``advice``) if a writer holds ``path``'s lock; nothing if the
    file does not exist.

    The test takes a shared lock for an instant and releases it (a writer retries for :data:`LOCK_RETRY_S`,
    so the test never makes one fail)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # NONBLOCK: a FIFO must not hang here
    except FileNotFoundError:
        return
    except OSError:
        return  # not ours to judge here: the writer says what is wrong with the path
    try:
        if stat.S_ISREG(os.fstat(fd).st_mode):
            _lock(fd, path, fcntl.LOCK_SH, retry_s=0.0, advice=advice)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


@contextlib.contextmanager
def bag_lock(path: str | Path) -> Iterator[None]:
    """Hold ``path``'s writer lock (exclusive) for a block: e.g. while the launcher recovers a bag in place,
    so that it never touches a file another recorder has taken since."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        _lock(fd, path)
        yield
    finally:
        os.close(fd)  # releases the lock


class _Unbuffered(io.RawIOBase):
    """A file the MCAP writer cannot buffer: each finished chunk reaches the OS at once.

    (mcap wraps raw files in a BufferedWriter; a killed recorder would then
    lose complete chunks still in that buffer.) Opened without O_TRUNC and
    locked first (exclusive flock, held until closed): a second writer of the
    same path is refused before it can truncate the first one's file.

    Each ``write`` call of the MCAP writer is whole records; a call that fails
    (ENOSPC, EFBIG, EIO...) is cut off again (``ftruncate`` to where the call
    started), so the file ends at a record boundary, after the last complete
    chunk and its index records.
    """

    def __init__(self, path: Path, overwrite: bool = True) -> None:
        # O_EXCL when it may not replace a file: "exists?" and "create" in one step, no window for another writer
        flags = os.O_WRONLY | os.O_CREAT | os.O_NONBLOCK | os.O_CLOEXEC | (0 if overwrite else os.O_EXCL)
        try:
            fd = os.open(path, flags, 0o644)
        except FileExistsError:
            check_not_recording(path)  # busy: say so, it is the more useful answer
            raise BagExistsError(f"{path} exists; give --overwrite to replace it") from None
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise UserError(f"{path}: not a regular file; give a .mcap file name to write")
            _lock(fd, path)
            os.ftruncate(fd, 0)  # only now: the file is ours
        except BaseException:
            os.close(fd)
            raise
        self._fd = fd
        self._pos = 0

    def write(self, data) -> int:
        view = memoryview(data)
        start = self._pos
        try:
            while view:
                n = os.write(self._fd, view)
                view = view[n:]
                self._pos += n
        except OSError:
            with contextlib.suppress(OSError):  # shrinking needs no space; if it fails the scan still stops there
                os.ftruncate(self._fd, start)
                self._pos = start
            raise
        return len(data)

    def tell(self) -> int:
        return self._pos

    def writable(self) -> bool:
        return True

    def flush(self) -> None:
        pass

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)  # releases the lock
            self._fd = -1
        super().close()


class _NotRaw:
    """Hide the raw file's type so that mcap.writer.Writer does not add a buffer."""

    def __init__(self, raw: _Unbuffered) -> None:
        self.raw = raw
        self.write = raw.write
        self.tell = raw.tell
        self.flush = raw.flush


@dataclass
class BagWriter:
    """MCAP writer with the ros2 profile: one channel per topic, cdr payloads.

    Holds the file's lock from open to close (:class:`BagBusyError` if another
    writer has it). After an OSError from a write, a flush or the finish, the
    writer is spent: ``error`` holds the cause, the file ends after its last
    complete record, and :meth:`close` only releases the file (finishing would
    write to the same full disk)."""

    path: Path
    chunk_size: int = DEFAULT_CHUNK_BYTES
    compression: str = "zstd"
    counts: dict[str, int] = field(default_factory=lambda: defaultdict(int))
    #: replace an existing file (False: :class:`BagExistsError`; a file being recorded: always :class:`BagBusyError`)
    overwrite: bool = True
    #: the file's name in its rosbag2 metadata, when it is written under a staging name and renamed after
    file_name: str | None = None

    def __post_init__(self) -> None:
        from mcap.writer import CompressionType, Writer

        self.path = Path(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if self.compression not in kinds:
            raise UserError(f"compression {self.compression!r}: use zstd, lz4 or none")
        self.error: OSError | None = None
        self.closed = False
        self._raw = _Unbuffered(self.path, self.overwrite)
        self._writer = Writer(_NotRaw(self._raw), chunk_size=self.chunk_size, compression=kinds[self.compression])
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._topic_of: dict[int, str] = {}
        self._topics: dict[str, tuple[str, list[dict], str]] = {}  # topic -> type, offered QoS, type hash
        self._first_ns: int | None = None  # log time range, for the rosbag2 metadata written at close
        self._last_ns: int | None = None
        try:
            with self._guard():
                self._writer.start(profile="ros2", library=f"phfdi {__version__}")
        except OSError:
            self.discard()  # not even the header fits: leave no empty file behind
            raise

    @contextlib.contextmanager
    def _guard(self) -> Iterator[None]:
        """Run a write of the MCAP writer; an OSError spends the writer (see the class) and goes on up."""
        if self.error is not None:
            raise self.error
        try:
            yield
        except OSError as exc:
            self.error = exc
            raise

    def add_topic(self, topic: str, msgtype: str, qos: dict = T.DATA_QOS) -> int:
        """Register a topic (idempotent); returns its channel id."""
        if topic in self._channels:
            return self._channels[topic]
        profiles = rosbag2_meta.offered_qos(qos)
        digest = type_hash(msgtype)
        with self._guard():
            if msgtype not in self._schemas:
                self._schemas[msgtype] = self._writer.register_schema(msgtype, "ros2msg",
                                                                      schema_text(msgtype).encode())
            # the channel metadata rosbag2's MCAP plugin writes (MCAPStorage::create_topic)
            cid = self._writer.register_channel(topic, "cdr", self._schemas[msgtype],
                                                {"offered_qos_profiles": rosbag2_meta.qos_yaml(profiles),
                                                 "topic_type_hash": digest})
        self._channels[topic] = cid
        self._topics[topic] = (msgtype, profiles, digest)
        self._topic_of[cid] = topic
        return cid

    def write(self, channel_id: int, stamp_ns: int, cdr: bytes) -> None:
        """One message, logged (and published) at its simulated time stamp."""
        with self._guard():
            self._writer.add_message(channel_id, log_time=stamp_ns, data=cdr, publish_time=stamp_ns)
        self.counts[self._topic_of[channel_id]] += 1
        if self._first_ns is None or stamp_ns < self._first_ns:
            self._first_ns = stamp_ns
        if self._last_ns is None or stamp_ns > self._last_ns:
            self._last_ns = stamp_ns

    def rosbag2_record(self) -> dict[str, str]:
        """The ``rosbag2`` metadata record of what was written so far (:func:`close` writes it)."""
        topics = [rosbag2_meta.TopicStats(name, msgtype, profiles, digest, self.counts.get(name, 0))
                  for name, (msgtype, profiles, digest) in self._topics.items()]
        return rosbag2_meta.metadata_record(self.file_name or self.path.name, topics, self._first_ns, self._last_ns)

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        with self._guard():
            self._writer.add_metadata(name, data)

    def flush(self) -> None:
        """Close the chunk in progress and hand it to the OS (crash safety in slow runs)."""
        with self._guard():
            self._writer.flush()

    def discard(self) -> None:
        """Remove the file (still holding its lock, so only ours) and release it: for a bag that could not
        even start, which holds nothing worth keeping."""
        if not self.closed:
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()
            self._raw.close()
            self.closed = True

    def close(self) -> None:
        """Finish the file (rosbag2's metadata record, summary and footer) and release it; after a failed write
        only release it. An OSError of the finish itself spends the writer and goes on up, the file released.

        The ``rosbag2`` record is written here, as rosbag2 does (it holds the final counts): a file whose writer
        was killed lacks it, and its summary; :func:`recover` writes both."""
        if self.closed:
            return
        try:
            if self.error is None:
                with self._guard():
                    self._writer.add_metadata(rosbag2_meta.RECORD_NAME, self.rosbag2_record())
                    self._writer.finish()
        finally:
            self._raw.close()
            self.closed = True


def stamp_of_cdr(cdr: bytes) -> int:
    """Stamp (ns) of a CDR message whose first field is a builtin_interfaces/Time.

    True of every topic of the graph (``stamp``, ``clock``, ``header.stamp``):
    4 bytes of encapsulation header, then int32 sec and uint32 nanosec.
    """
    little = cdr[1] == 1
    sec = int.from_bytes(cdr[4:8], "little" if little else "big", signed=True)
    nsec = int.from_bytes(cdr[8:12], "little" if little else "big", signed=False)
    return join_ns(sec, nsec)


def load_run(path: str | Path) -> Record:
    """A run from a bag of the graph (.mcap) or a run file (.csv, .parquet): :func:`phfdi.records.read_run`,
    the one reader of runs (kept under this name for the bag tools' users).

    Bag topics map onto the run's signals (``/plant/measurement.ph`` ->
    ``ph_measured``, ...; the table is in docs/ros_graph.md); the time base is
    the stamps of /plant/measurement.
    """
    from .records import read_run

    return read_run(path)


def read_messages(path: str | Path, topic: str) -> list:
    """Every message of one topic, decoded (rosbags objects with the message's field names), in log-time order."""
    from rosbags.highlevel import AnyReader

    path = Path(path)
    if not path.exists():
        raise UserError(f"no such file: {path}")
    try:
        with AnyReader([path]) as reader:
            conns = [c for c in reader.connections if c.topic == topic]
            if not conns:  # rosbags reads every topic when given no connection
                return []
            return [reader.deserialize(raw, conn.msgtype) for conn, _t, raw in reader.messages(connections=conns)]
    except Exception as exc:  # noqa: BLE001 - rosbags, mcap and zstd raise many types on damaged bags
        raise UserError(f"{path}: cannot read the bag ({type(exc).__name__}: {_one_line(exc)}); if its recorder "
                        f"was killed, run: phfdi bag recover {path} FIXED.mcap") from None


def _time(store, ns: int):
    sec, nanosec = split_ns(ns)
    return store.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def write_run(run: Record, path: str | Path, chunk_size: int = DEFAULT_CHUNK_BYTES) -> Path:
    """Write a run as a bag with the graph's per-sample topics (NaN where the run lacks a signal).

    Stamps are time_s (relative to the first sample when it is not 0), so any
    run, simulated or measured, can be replayed into the graph's topics.
    """
    store = typestore()
    ty = store.types
    path = Path(path)
    t = np.asarray(run.time_s, dtype=float)
    t0 = t[0] if len(t) and t[0] < 0 else 0.0
    feeds = _feed_names(run.names)

    def col(name: str) -> np.ndarray:
        return np.asarray(run[name], dtype=float) if name in run else np.full(len(t), np.nan)

    c = {n: col(n) for n in run_signal_names(feeds)}
    sev = c["fault_severity"]
    valve_flow = c.get(f"{run.metadata.get('valve_feed')}_flow_ml_s", np.full(len(t), np.nan))
    bag = BagWriter(path, chunk_size=chunk_size)
    try:
        ch = {tp.name: bag.add_topic(tp.name, tp.type) for tp in T.RECORDED if tp.per_sample}
        meta = dict(run.metadata)
        meta.setdefault("sample_time_s", run.dt_s)
        bag.add_metadata(RUN_METADATA, {"json": json.dumps(meta, default=str)})
        for i in range(len(t)):
            ns = seconds_to_ns(t[i] - t0)
            stamp = _time(store, ns)
            msgs = (
                (T.MEASUREMENT, ty["phfdi_interfaces/msg/Measurement"](
                    stamp=stamp, ph=c["ph_measured"][i], level_cm=c["level_measured_cm"][i])),
                (T.CONTROLLER, ty["phfdi_interfaces/msg/ControllerOutput"](
                    stamp=stamp, ph_setpoint=c["ph_setpoint"][i], ph_output_pct=c["ph_controller_output_pct"][i],
                    ph_manual=False, level_setpoint_cm=c["level_setpoint_cm"][i],
                    level_output_pct=c["level_controller_output_pct"][i], level_manual=False)),
                (T.VALVE_STATE, ty["phfdi_interfaces/msg/ValveState"](
                    stamp=stamp, ph_command_pct=c["valve_command_pct"][i], ph_position_pct=c["valve_position_pct"][i],
                    ph_opening=math.nan, ph_flow_ml_s=valve_flow[i], ph_fault_severity=sev[i],
                    ph_rejected_commands=0, outlet_command_pct=c["level_controller_output_pct"][i],
                    outlet_position_pct=c["outlet_valve_position_pct"][i], outlet_opening=math.nan,
                    outlet_fault_severity=0.0, outlet_rejected_commands=0)),
                (T.PLANT_STATE, ty["phfdi_interfaces/msg/PlantState"](
                    stamp=stamp, ph=c["ph_true"][i], level_cm=c["level_true_cm"][i], feed_names=feeds,
                    feed_flows_ml_s=np.array([c[f"{f}_flow_ml_s"][i] for f in feeds], dtype=np.float64),
                    outlet_flow_ml_s=c["outlet_flow_ml_s"][i], sensor_fault_severity=sev[i])),
            )
            for topic, msg in msgs:
                bag.write(ch[topic.name], ns, bytes(store.serialize_cdr(msg, topic.type)))
    finally:
        bag.close()
    return path


#: the largest record time (s) a bag of a measured record stamps as it is (int64 nanoseconds, with room)
MAX_STAMP_S = 9.0e9


def write_measured(time_s: np.ndarray, x: np.ndarray, channels: list[str], path: str | Path, source: str = "",
                   metadata: dict | None = None, chunk_size: int = DEFAULT_CHUNK_BYTES,
                   file_name: str | None = None) -> Path:
    """A measured record as a bag: one phfdi_interfaces/MeasuredSample per row on /measured/sample,
    stamped with the row's own time to the ns (:func:`phfdi_base.stamps.record_stamps_ns`: the learned node
    then gives the detector the times the offline replay does), schemas embedded (ros2 profile). A record
    whose own time does not fit a stamp (below 0, or beyond ``MAX_STAMP_S``) is stamped from its first row
    (the metadata's ``time_origin_s`` says from which time). ``file_name``: the bag's final name, for its rosbag2
    metadata, when ``path`` is a staging file renamed after."""
    store = typestore()
    msg_type = store.types[T.MEASURED_SAMPLE.type]
    t = np.asarray(time_s, dtype=float)
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape != (len(t), len(channels)):
        raise UserError(f"measured record: {x.shape} values for {len(t)} times and {len(channels)} channels")
    fits = len(t) and 0.0 <= t[0] and np.nanmax(t) < MAX_STAMP_S  # a ROS time and an MCAP log time
    origin = 0.0 if fits or not len(t) else float(t[0])
    stamps = record_stamps_ns(t - origin if origin else t)
    if len(t) > 1 and np.any(np.diff(stamps) <= 0):
        raise UserError("measured record: time stamps must increase")
    names = [str(c) for c in channels]
    bag = BagWriter(Path(path), chunk_size=chunk_size, file_name=file_name)
    try:
        cid = bag.add_topic(T.MEASURED_SAMPLE.name, T.MEASURED_SAMPLE.type)
        bag.add_metadata(RUN_METADATA, {"json": json.dumps({"kind": "measured", "source": source,
                                                            "channels": names, "time_origin_s": origin,
                                                            **(metadata or {})}, default=str)})
        for i in range(len(t)):
            ns = int(stamps[i])
            msg = msg_type(stamp=_time(store, ns), source=source, names=names, values=x[i].copy())
            bag.write(cid, ns, bytes(store.serialize_cdr(msg, T.MEASURED_SAMPLE.type)))
    finally:
        bag.close()
    return Path(path)


# ---- inspecting and recovering ---------------------------------------------------------------
def _scan(path: Path, validate: bool = True):
    """Records of an MCAP file in order, chunks opened, up to the first incomplete or damaged one.

    Returns (records, number of complete chunks, error or None).
    """
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader, breakup_chunk

    out = []
    chunks = 0
    error = None
    with open(path, "rb") as f:
        try:
            for rec in StreamReader(f, emit_chunks=True, validate_crcs=validate).records:
                if isinstance(rec, Chunk):
                    out.extend(breakup_chunk(rec, validate_crc=validate))
                    chunks += 1
                else:
                    out.append(rec)
        except Exception as exc:  # noqa: BLE001 - end of a truncated file, or a damaged record
            error = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return out, chunks, error


def bag_info(path: str | Path) -> dict:
    """Topics (type, message count), time range, chunks and metadata of a bag."""
    from mcap.records import Channel, Header, Message, Schema, Statistics

    from phfdi.records.errors import regular_file

    path = regular_file(path)  # a folder or a FIFO: one line (a FIFO would block the read)
    info: dict = {"path": str(path), "size_bytes": path.stat().st_size}
    summary = None
    try:
        from mcap.reader import make_reader

        with open(path, "rb") as f:
            reader = make_reader(f)
            header = reader.get_header()
            summary = reader.get_summary()
    except Exception:  # noqa: BLE001 - truncated or not MCAP: scanned below
        summary = None
    if summary is not None and summary.statistics is not None:
        st: Statistics = summary.statistics
        info.update(finished=True, profile=header.profile, library=header.library,
                    messages=st.message_count, chunks=st.chunk_count,
                    start_s=st.message_start_time * 1e-9, end_s=st.message_end_time * 1e-9)
        schemas = summary.schemas
        info["topics"] = [{"topic": ch.topic, "type": schemas[ch.schema_id].name if ch.schema_id in schemas else "",
                           "count": st.channel_message_counts.get(cid, 0)}
                          for cid, ch in sorted(summary.channels.items())]
        info["compression"] = sorted({c.compression or "none" for c in summary.chunk_indexes})
    else:
        with open(path, "rb") as f:  # 8 bytes, not the whole file (a sparse 2 GB file was read whole)
            magic = f.read(8)
        if magic != b"\x89MCAP0\r\n":
            raise UserError(f"{path}: not an MCAP file")
        records, n_chunks, error = _scan(path, validate=False)
        schemas = {r.id: r.name for r in records if isinstance(r, Schema)}
        channels = {r.id: r for r in records if isinstance(r, Channel)}
        counts: dict[int, int] = defaultdict(int)
        times = [r.log_time for r in records if isinstance(r, Message)]
        for r in records:
            if isinstance(r, Message):
                counts[r.channel_id] += 1
        header = next((r for r in records if isinstance(r, Header)), None)
        info.update(finished=False, truncated_by=error, profile=header.profile if header else "",
                    library=header.library if header else "", messages=len(times),
                    chunks=n_chunks,
                    start_s=min(times) * 1e-9 if times else math.nan, end_s=max(times) * 1e-9 if times else math.nan)
        info["topics"] = [{"topic": ch.topic, "type": schemas.get(ch.schema_id, ""), "count": counts[cid]}
                          for cid, ch in sorted(channels.items())]
    records = read_metadata(path) if info["finished"] else {}
    info["metadata"] = sorted(records)
    info["rosbag2"] = _rosbag2_summary(records.get(rosbag2_meta.RECORD_NAME))
    return info


def _rosbag2_summary(record: dict[str, str] | None) -> dict | None:
    """Version, distro and message count of a bag's rosbag2 metadata record (None: absent; ``readable`` False:
    not a YAML mapping we read)."""
    if record is None:
        return None
    meta = rosbag2_meta.load_from_bag(record.get(rosbag2_meta.RECORD_KEY, ""))
    if not isinstance(meta, dict):
        return {"readable": False}
    return {"readable": True, "version": meta.get("version"), "ros_distro": meta.get("ros_distro"),
            "message_count": meta.get("message_count")}


def format_info(info: dict) -> str:
    lines = [f"bag       {info['path']} ({info['size_bytes'] / 1e6:.2f} MB, "
             f"{'complete' if info['finished'] else 'NOT FINISHED: recover it with phfdi bag recover'})",
             f"profile   {info['profile']} (written by {info['library']})",
             f"messages  {info['messages']} in {info['chunks']} chunks",
             f"time      {info['start_s']:.3f} .. {info['end_s']:.3f} s (simulated)"]
    if info.get("truncated_by"):
        lines.append(f"stopped   at {info['truncated_by']}")
    r2 = info.get("rosbag2")
    if r2 is None:
        lines.append("rosbag2   no metadata record (written at close; phfdi bag recover adds it)")
    elif not r2["readable"]:
        lines.append("rosbag2   metadata record not readable (not a YAML mapping, too long or with aliases)")
    else:
        lines.append(f"rosbag2   metadata version {r2['version']} ({r2['ros_distro']}), {r2['message_count']} "
                     "messages")
    width = max([len(t["topic"]) for t in info["topics"]] + [5])
    lines.append("topics")
    for t in info["topics"]:
        lines.append(f"  {t['topic']:{width}s}  {t['count']:8d}  {t['type']}")
    return "\n".join(lines)


def _recovered_topics(channels: dict, schemas: dict, counts: dict[int, int]) -> list[rosbag2_meta.TopicStats]:
    """The topics of a recovered bag for its rosbag2 metadata: from the source's channels and schemas (a channel's
    QoS and type hash as the source wrote them; the hash computed for a bag written before it was kept)."""
    out = []
    for cid, ch in channels.items():
        msgtype = schemas[ch.schema_id].name if ch.schema_id in schemas else ""
        digest = ch.metadata.get("topic_type_hash", "")
        if not digest and msgtype:
            with contextlib.suppress(Exception):  # a type of another package: no hash, as rosbag2 allows
                digest = type_hash(msgtype)
        out.append(rosbag2_meta.TopicStats(ch.topic, msgtype,
                                           rosbag2_meta.parse_qos_yaml(ch.metadata.get("offered_qos_profiles", "")),
                                           digest, counts.get(cid, 0), ch.message_encoding))
    return out


def recover(src: str | Path, dst: str | Path, overwrite: bool = True, caller_holds_lock: bool = False) -> dict:
    """Copy everything up to the last complete chunk of a (truncated) bag into a new, finished bag, with the
    rosbag2 metadata record that a killed recorder could not write (counted from what was recovered).

    A bag another process is recording is refused (:class:`BagBusyError`); ``caller_holds_lock``: the caller holds
    ``src``'s writer lock itself (the launcher, recovering a killed recorder's bag in place under :func:`bag_lock`)."""
    from mcap.records import Channel, Message, Metadata, Schema
    from mcap.writer import CompressionType, Writer

    from phfdi.records.errors import regular_file

    src, dst = regular_file(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise UserError("recover writes a new file: give an output path other than the input")
    # a bag being recorded is not truncated, it is growing: a copy of it now would be a partial bag that looks
    # finished; and an output being recorded would be replaced under its recorder
    if not caller_holds_lock:
        check_not_recording(src, "recover it after that recording has ended")
    check_not_recording(dst)
    with open(src, "rb") as f:
        if f.read(8) != b"\x89MCAP0\r\n":
            raise UserError(f"{src}: not an MCAP file")
    records, _chunks, error = _scan(src)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    counts: dict[int, int] = defaultdict(int)
    n = 0
    first_ns = last_ns = None
    with staged(dst, overwrite) as tmp, open(tmp, "wb") as out:
        w = Writer(out, chunk_size=DEFAULT_CHUNK_BYTES, compression=CompressionType.ZSTD)
        header = next((r for r in records if type(r).__name__ == "Header"), None)
        w.start(profile=header.profile if header else "ros2", library=f"phfdi {__version__} (recovered)")
        for r in records:
            if isinstance(r, Schema) and r.id not in schema_ids:
                schema_ids[r.id] = w.register_schema(r.name, r.encoding, r.data)
                schemas[r.id] = r
            elif isinstance(r, Channel) and r.id not in channel_ids:
                channel_ids[r.id] = w.register_channel(r.topic, r.message_encoding, schema_ids.get(r.schema_id, 0),
                                                       dict(r.metadata))
                channels[r.id] = r
            elif isinstance(r, Metadata) and r.name != rosbag2_meta.RECORD_NAME:  # its counts are rewritten below
                w.add_metadata(r.name, dict(r.metadata))
            elif isinstance(r, Message) and r.channel_id in channel_ids:
                w.add_message(channel_ids[r.channel_id], log_time=r.log_time, data=r.data,
                              publish_time=r.publish_time, sequence=r.sequence)
                n += 1
                counts[r.channel_id] += 1
                first_ns = r.log_time if first_ns is None else min(first_ns, r.log_time)
                last_ns = r.log_time if last_ns is None else max(last_ns, r.log_time)
        w.add_metadata("phfdi_recovered", {"source": str(src), "stopped_at": error or "end of file"})
        w.add_metadata(rosbag2_meta.RECORD_NAME, rosbag2_meta.metadata_record(
            dst.name, _recovered_topics(channels, schemas, counts), first_ns, last_ns))
        w.finish()
    return {"path": str(dst), "messages": n, "last_s": None if last_ns is None else last_ns * 1e-9,
            "complete_input": error is None, "stopped_at": error}


# ---- split bags (the recorder's split_after_s) ------------------------------------------

def part_path(path: str | Path, index: int) -> Path:
    """File ``index`` of a split bag: the path itself for 0, then ``<stem>.<index>.mcap``."""
    path = Path(path)
    return path if index == 0 else path.with_name(f"{path.stem}.{index}{path.suffix}")


def bag_parts(path: str | Path) -> list[Path]:
    """The files of a (possibly split) bag, in order: the path, then ``<stem>.1.mcap``, ... while they exist."""
    parts = []
    while part_path(path, len(parts)).exists():
        parts.append(part_path(path, len(parts)))
    return parts


def fault_alarms(path: str | Path) -> list[dict]:
    """Every /fault_alarm message a bag holds, in order (:func:`wavelet_fdi.alarm_messages.to_dict` of each)."""
    return [alarm_message_dict(m) for m in read_messages(path, T.FAULT_ALARM.name)]
