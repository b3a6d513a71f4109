"""ROS 2 node that records the graph's topics to an MCAP bag (ros2 profile).

Subscribes (reliable, keep all) to the topics of :data:`phfdi_base.topics.RECORDED`
as raw CDR and writes each message at its simulated time stamp with
:class:`phfdi.bagio.BagWriter`: 16 KB chunks reach the disk as they fill, and
the chunk in progress is flushed every ``flush_period_s`` of wall time, so a
killed recorder leaves a bag whose complete chunks ``phfdi bag recover``
restores. On SIGINT/SIGTERM it first takes every message its readers already
acknowledged, then finishes the file: rosbag2's metadata record (it holds the
final counts, so it is written at close, as rosbag2 does), summary, footer. A
killed recorder's file lacks those; ``phfdi bag recover`` (and the launcher's
in-place recovery) writes them.

``split_after_s`` > 0 starts a new file every that many seconds of simulated
time (``run.mcap``, ``run.1.mcap``, ``run.2.mcap``, ...; :func:`phfdi.bagio.bag_parts`),
each a complete bag with the run's metadata. Why: the MCAP writer keeps an
index entry per chunk in memory until the file is finished (measured about
0.7 KiB of Python objects per chunk; at ``pace`` 1 the flush makes a chunk a
second, about 60 MiB a day), so a recorder that runs for days needs files of
bounded length. A file starts with the first message stamped in its interval;
messages of the previous interval that arrive after it (the topics are not
ordered with each other) go to the new file.

Nothing lost, nothing clobbered (docs/ros_graph.md, "When things go wrong"):

- Each file is locked (exclusive ``flock``, :class:`phfdi.bagio.BagWriter`)
  before it is truncated and until it is closed: a second recorder of the same
  path refuses to start with one line (exit status 2) and leaves the first
  one's file as it was; an existing file is replaced only with ``overwrite``
  (created with O_EXCL otherwise). Once it holds a file and has started it, it
  prints ``{"event": "recording", "path": ...}``: the launcher finishes or
  recovers only the files its recorder took.
- A write that fails (a full disk, a file size limit, an I/O error) ends the
  recording at the last complete chunk: the file is cut back to it (readable by
  ``phfdi bag info``, restorable by ``phfdi bag recover``), the recorder prints
  ``{"event": "write_failed", "path", "error", "errno", "message"}`` and one
  line on stderr, and exits with status 1. It does not try to finish the file:
  the summary would go to the same full disk.

    python -m phfdi.ros.recorder --ros-args -p path:=bags/run.mcap -p scenario:=paper
"""

from __future__ import annotations

import contextlib
import errno
import importlib
import json
import sys
import time
from pathlib import Path

from phfdi import bagio
from phfdi_base.errors import UserError
from phfdi_base.ros.graph_node import GraphNode, NodeStartError, ParamSpec, main
from phfdi_base.stamps import seconds_to_ns
from phfdi_base.topics import BY_NAME, RECORDED, RECORDER

PARAMS = (
    ParamSpec("path", "", "bag file to write (.mcap); its folder is created"),
    ParamSpec("topics", [t.name for t in RECORDED], "topics to record (from the graph's topic table)"),
    ParamSpec("chunk_size_bytes", 16384, "MCAP chunk size: a killed recorder loses at most the chunk in progress",
              range=(1024, 64 * 1024 * 1024)),
    ParamSpec("compression", "zstd", "chunk compression", choices=("zstd", "lz4", "none")),
    ParamSpec("flush_period_s", 1.0, "close the chunk in progress at least this often (s, wall)",
              range=(0.05, 3600.0)),
    ParamSpec("run_metadata", "", "the run's metadata (JSON) written into the bag; phfdi launch passes it, '' "
                                   "computes it from the scenario"),
    ParamSpec("overwrite", False, "replace an existing file (phfdi launch --overwrite); a file another process "
                                  "records is never replaced"),
    ParamSpec("split_after_s", 0.0, "start a new file (<name>.1.mcap, <name>.2.mcap, ...) every this many s of "
                                    "simulated time; 0: one file", range=(0.0, 1e12)),
)


def graph_run_metadata(spec) -> str:
    """The bag metadata of a graph run of ``spec`` (JSON), as the launcher passes it to the recorder."""
    from phfdi.loop import run_metadata  # the whole in-process loop: only for a recorder started by hand

    return json.dumps(run_metadata(spec, "graph"), default=str)


def _message_class(msgtype: str):
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


class RecorderNode(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(RECORDER)

        path = self.param("path")
        if not path.endswith(".mcap"):
            raise NodeStartError(f"parameter path = {path!r}: give a .mcap file to write")
        unknown = [t for t in self.param("topics") if t not in BY_NAME]
        if unknown:
            raise NodeStartError(f"parameter topics: unknown topic {unknown[0]}; recordable: "
                                 + ", ".join(BY_NAME))
        self._split_ns = seconds_to_ns(self.param("split_after_s"))
        stale = bagio.part_path(path, 1)
        if self._split_ns and stale.exists():  # the parts of an earlier split bag would be read as this run's
            raise NodeStartError(f"parameter path: {stale} exists (a part of an earlier split bag); remove "
                                 f"{Path(path).stem}.*.mcap or pick another name")
        self._meta = {"json": self.param("run_metadata") or graph_run_metadata(self.spec)}
        self._part_end_ns: int | None = None  # stamp that starts the next file (set by the first message)
        self.parts: list[str] = []
        self.counts: dict[str, int] = {}  # all files
        self.failure: dict | None = None  # the write_failed event, once a write failed
        self._open_part(path)
        self._stamp_of = bagio.stamp_of_cdr
        self.received = 0
        self.unrecordable: dict[str, int] = {}  # topic -> messages with no place in a bag (_unrecordable)
        for name in self.param("topics"):
            topic = BY_NAME[name]
            self.data_subscription(_message_class(topic.type), topic.name, self._writer_for(topic.name), raw=True)
        self._last_flush = time.monotonic()
        self._flush_period_s = self.param("flush_period_s")  # read once: after_spin runs per message
        self.start_barrier()

    def _open_part(self, path) -> None:
        """Take the file (locked: refused if another recorder has it, or if it exists and ``overwrite`` is
        false) and start it."""
        try:
            self.bag = bagio.BagWriter(path, chunk_size=self.param("chunk_size_bytes"),
                                       compression=self.param("compression"), overwrite=self.param("overwrite"))
        except UserError as exc:  # another process records it (BagBusyError), it exists (BagExistsError), ...
            raise NodeStartError(str(exc)) from None
        except OSError as exc:
            raise NodeStartError(f"parameter path: cannot write {path}: {exc.strerror or exc}") from None
        try:
            self.bag.add_metadata(bagio.RUN_METADATA, self._meta)
            self._channel = {name: self.bag.add_topic(name, BY_NAME[name].type) for name in self.param("topics")}
        except OSError as exc:
            self.bag.discard()  # a bag without its topics holds nothing: leave no stub
            raise NodeStartError(f"parameter path: cannot write {path}: {exc.strerror or exc}") from None
        # the file is ours (locked) and started: the launcher finishes or recovers only the files so reported
        print(json.dumps({"event": "recording", "path": str(self.bag.path)}), flush=True)
        self.parts.append(str(self.bag.path))

    def _next_part(self, stamp_ns: int) -> None:
        """Finish this file and go on in the next: the one of the interval that holds ``stamp_ns``."""

        self._close_part()
        self._part_end_ns = (stamp_ns // self._split_ns + 1) * self._split_ns
        self._open_part(bagio.part_path(self.param("path"), len(self.parts)))

    def _close_part(self) -> None:
        try:
            self.bag.close()
        finally:
            for topic, n in self.bag.counts.items():
                self.counts[topic] = self.counts.get(topic, 0) + n

    def _fail(self, exc: BaseException) -> None:
        """Stop recording after a failed write: one JSON event and one line naming the file and the cause.

        The file already ends at its last complete chunk (BagWriter cut the failed write off); it is not
        finished, since that would write to the same full disk (the launcher recovers it if there is room)."""
        if self.failure is not None:
            return
        path = self.bag.path
        if isinstance(exc, OSError):
            reason = exc.strerror or str(exc)
            code = errno.errorcode.get(exc.errno or 0, "")
            message = f"cannot write {path}: {reason}"
        else:  # a split part another process holds (BagBusyError), a bad path (NodeStartError)
            reason, code = str(exc), ""
            message = str(exc).removeprefix("parameter path: ")
        self.failure = {"event": "write_failed", "path": str(path), "error": reason, "errno": code,
                        "message": message}
        if not self.bag.closed:
            with contextlib.suppress(OSError):
                self._close_part()  # after a failed write this only releases the file (and adds up its counts)
        print(json.dumps(self.failure), flush=True)
        print(f"recorder: error: {message}; the bag ends at its last complete chunk", file=sys.stderr, flush=True)
        self.finished = True  # the node's main loop ends; exit status 1
        self.exit_code = 1

    def _writer_for(self, topic: str):
        stamp_of = self._stamp_of

        def on_message(cdr: bytes) -> None:
            if self.failure is not None:
                return  # not counted as received: drain() then ends at once
            stamp = stamp_of(cdr) if len(cdr) >= 12 else -1
            if stamp < 0:  # a stray stamped before 0 s: MCAP log times are unsigned (it crashed the recorder)
                self._unrecordable(topic, len(cdr))
                self.received += 1
                return
            try:
                if self._split_ns:
                    if self._part_end_ns is None:
                        self._part_end_ns = (stamp // self._split_ns + 1) * self._split_ns
                    elif stamp >= self._part_end_ns:
                        self._next_part(stamp)
                self.bag.write(self._channel[topic], stamp, cdr)
            except (OSError, NodeStartError) as exc:
                self._fail(exc)
                return
            self.received += 1

        return on_message

    def _unrecordable(self, topic: str, size: int) -> None:
        """Count a message that has no place in the bag (a stamp before 0 s, or too short to hold a stamp); the
        first is logged, the count is in the closing event (``unrecordable``)."""
        self.unrecordable[topic] = self.unrecordable.get(topic, 0) + 1
        if sum(self.unrecordable.values()) == 1:
            self.get_logger().warning(f"left out a message on {topic} that cannot be recorded ({size} bytes, stamp "
                                      "before 0 s or none): a stray publisher on the graph's domain?")

    def after_spin(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self._flush_period_s and self.failure is None:
            try:
                self.bag.flush()
            except OSError as exc:
                self._fail(exc)
            self._last_flush = now

    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers already hold (acknowledged to the writers) before closing."""
        self.spin_until_idle(executor, lambda: self.received, idle_s, limit_s)

    def close(self) -> None:
        if self.failure is None:
            try:
                self._close_part()
            except OSError as exc:  # the summary did not fit: the file still ends at a record boundary
                self._fail(exc)
        print(json.dumps({"event": "closed", "path": self.parts[0], "parts": self.parts, "counts": self.counts,
                          "finished": self.failure is None, "unrecordable": self.unrecordable}), flush=True)


def run() -> int:
    return main(RecorderNode, "phfdi.ros.recorder", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
