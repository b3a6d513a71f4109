"""ROS 2 node that records the graph's topics to an MCAP bag (ros2 profile).

Subscribes (reliable, keep all) to the topics of :data:`phfdi_base.topics.RECORDED`
as raw CDR and writes each message at its simulated time stamp with
:class:`phfdi.bagio.BagWriter`: 16 KB chunks reach the disk as they fill, and
the chunk in progress is flushed every ``flush_period_s`` of wall time, so a
killed recorder leaves a bag whose complete chunks ``phfdi bag recover``
restores. On SIGINT/SIGTERM it first takes every message its readers already
acknowledged, then finishes the file.

    python -m phfdi.ros.recorder --ros-args -p path:=bags/run.mcap -p scenario:=paper
"""

from __future__ import annotations

import importlib
import json
import sys
import time

from phfdi.ros.node import GraphNode, NodeStartError, ParamSpec, main
from phfdi_base.topics import BY_NAME, RECORDED, RECORDER

PARAMS = (
    ParamSpec("path", "", "bag file to write (.mcap); its folder is created"),
    ParamSpec("topics", [t.name for t in RECORDED], "topics to record (from the graph's topic table)"),
    ParamSpec("chunk_size_bytes", 16384, "MCAP chunk size: a killed recorder loses at most the chunk in progress",
              range=(1024, 64 * 1024 * 1024)),
    ParamSpec("compression", "zstd", "chunk compression", choices=("zstd", "lz4", "none")),
    ParamSpec("flush_period_s", 1.0, "close the chunk in progress at least this often (s, wall)",
              range=(0.05, 3600.0)),
)


def _message_class(msgtype: str):
    package, _, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


class RecorderNode(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(RECORDER)
        from phfdi import bagio
        from phfdi.loop import run_metadata

        path = self.param("path")
        if not path.endswith(".mcap"):
            raise NodeStartError(f"parameter path = {path!r}: give a .mcap file to write")
        unknown = [t for t in self.param("topics") if t not in BY_NAME]
        if unknown:
            raise NodeStartError(f"parameter topics: unknown topic {unknown[0]}; recordable: "
                                 + ", ".join(BY_NAME))
        try:
            self.bag = bagio.BagWriter(path, chunk_size=self.param("chunk_size_bytes"),
                                       compression=self.param("compression"))
        except OSError as exc:
            raise NodeStartError(f"parameter path: cannot write {path}: {exc.strerror}") from None
        meta = run_metadata(self.spec, "graph")
        self.bag.add_metadata(bagio.RUN_METADATA, {"json": json.dumps(meta, default=str)})
        self._stamp_of = bagio.stamp_of_cdr
        self.received = 0
        for name in self.param("topics"):
            topic = BY_NAME[name]
            cid = self.bag.add_topic(topic.name, topic.type)
            self.data_subscription(_message_class(topic.type), topic.name, self._writer_for(cid), raw=True)
        self._last_flush = time.monotonic()
        self._flush_period_s = self.param("flush_period_s")  # read once: after_spin runs per message
        self.start_barrier()

    def _writer_for(self, channel_id: int):
        write, stamp_of = self.bag.write, self._stamp_of

        def on_message(cdr: bytes) -> None:
            write(channel_id, stamp_of(cdr), cdr)
            self.received += 1

        return on_message

    def after_spin(self) -> None:
        now = time.monotonic()
        if now - self._last_flush >= self._flush_period_s:
            self.bag.flush()
            self._last_flush = now

    def drain(self, executor, idle_s: float = 0.3, limit_s: float = 10.0) -> None:
        """Take what the readers already hold (acknowledged to the writers) before closing."""
        t_end = time.monotonic() + limit_s
        last, idle_since = self.received, time.monotonic()
        while time.monotonic() < t_end:
            executor.spin_once(timeout_sec=0.05)
            if self.received != last:
                last, idle_since = self.received, time.monotonic()
            elif time.monotonic() - idle_since >= idle_s:
                break

    def close(self) -> None:
        self.bag.close()
        counts = dict(self.bag.counts)
        print(json.dumps({"event": "closed", "path": str(self.bag.path), "counts": counts}), flush=True)


def run() -> int:
    return main(RecorderNode, "phfdi.ros.recorder", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
