"""ROS 2 node that records the graph's topics to an MCAP bag (ros2 profile).

Subscribes (reliable, keep all) to the topics of :data:`phfdi_base.topics.RECORDED`
as raw CDR and writes each message at its simulated time stamp with
:class:`phfdi.bagio.BagWriter`: 16 KB chunks reach the disk as they fill, and
the chunk in progress is flushed every ``flush_period_s`` of wall time, so a
killed recorder leaves a bag whose complete chunks ``phfdi bag recover``
restores. On SIGINT/SIGTERM it first takes every message its readers already
acknowledged, then finishes the file.

``split_after_s`` > 0 starts a new file every that many seconds of simulated
time (``run.mcap``, ``run.1.mcap``, ``run.2.mcap``, ...; :func:`phfdi.bagio.bag_parts`),
each a complete bag with the run's metadata. Why: the MCAP writer keeps an
index entry per chunk in memory until the file is finished (measured about
0.7 KiB of Python objects per chunk; at ``pace`` 1 the flush makes a chunk a
second, about 60 MiB a day), so a recorder that runs for days needs files of
bounded length. A file starts with the first message stamped in its interval;
messages of the previous interval that arrive after it (the topics are not
ordered with each other) go to the new file.

    python -m phfdi.ros.recorder --ros-args -p path:=bags/run.mcap -p scenario:=paper
"""

from __future__ import annotations

import importlib
import json
import sys
import time
from pathlib import Path

from phfdi import bagio
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
        self._open_part(path)
        self._stamp_of = bagio.stamp_of_cdr
        self.received = 0
        for name in self.param("topics"):
            topic = BY_NAME[name]
            self.data_subscription(_message_class(topic.type), topic.name, self._writer_for(topic.name), raw=True)
        self._last_flush = time.monotonic()
        self._flush_period_s = self.param("flush_period_s")  # read once: after_spin runs per message
        self.start_barrier()

    def _open_part(self, path) -> None:
        try:
            self.bag = bagio.BagWriter(path, chunk_size=self.param("chunk_size_bytes"),
                                       compression=self.param("compression"))
        except OSError as exc:
            raise NodeStartError(f"parameter path: cannot write {path}: {exc.strerror}") from None
        self.bag.add_metadata(bagio.RUN_METADATA, self._meta)
        self._channel = {name: self.bag.add_topic(name, BY_NAME[name].type) for name in self.param("topics")}
        self.parts.append(str(self.bag.path))

    def _next_part(self, stamp_ns: int) -> None:
        """Finish this file and go on in the next: the one of the interval that holds ``stamp_ns``."""

        self._close_part()
        self._part_end_ns = (stamp_ns // self._split_ns + 1) * self._split_ns
        self._open_part(bagio.part_path(self.param("path"), len(self.parts)))

    def _close_part(self) -> None:
        self.bag.close()
        for topic, n in self.bag.counts.items():
            self.counts[topic] = self.counts.get(topic, 0) + n

    def _writer_for(self, topic: str):
        stamp_of = self._stamp_of

        def on_message(cdr: bytes) -> None:
            stamp = stamp_of(cdr)
            if self._split_ns:
                if self._part_end_ns is None:
                    self._part_end_ns = (stamp // self._split_ns + 1) * self._split_ns
                elif stamp >= self._part_end_ns:
                    self._next_part(stamp)
            self.bag.write(self._channel[topic], stamp, cdr)
            self.received += 1

        return on_message

    def after_spin(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self._flush_period_s:
            self.bag.flush()
            self._last_flush = now

    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers already hold (acknowledged to the writers) before closing."""
        self.spin_until_idle(executor, lambda: self.received, idle_s, limit_s)

    def close(self) -> None:
        self._close_part()
        print(json.dumps({"event": "closed", "path": self.parts[0], "parts": self.parts, "counts": self.counts}),
              flush=True)


def run() -> int:
    return main(RecorderNode, "phfdi.ros.recorder", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
