"""ROS 2 node that plays a bag into the graph: each message at its simulated time stamp (raw CDR).

``phfdi replay --live`` starts it with a detector node: the player owns
simulated time, as the plant does in a launched graph (it prints the same
JSON lines: connected, progress, done). It publishes the bag's data topics
(reliable, keep all: a slow reader slows the player down, nothing is lost)
in log-time order, regenerates /clock from the stamps of /plant/measurement
for nodes with use_sim_time (as ``ros2 bag play --clock``; from /measured/sample
in a bag of a measured record, phfdi bag from-csv), and leaves out
what a live graph produces itself (/fault_alarm, /diagnostics). After the
last message it waits until every reader acknowledged everything.

    python -m phfdi.ros.player --ros-args -p path:=bags/run.mcap -p graph_nodes:="[player, detector]"
"""

from __future__ import annotations

import json
import sys
import time

from rosgraph_msgs.msg import Clock

from phfdi import bagio
from phfdi.ros.recorder import _message_class
from phfdi_base.ros.graph_node import GraphNode, NodeStartError, ParamSpec, main
from phfdi_base.stamps import split_ns
from phfdi_base.topics import CLOCK, DIAGNOSTICS, FAULT_ALARM, MEASURED_SAMPLE, MEASUREMENT

PLAYER = "player"
#: produced by a live graph's own nodes: not replayed
NOT_PLAYED = (DIAGNOSTICS.name, FAULT_ALARM.name, CLOCK.name)
BATCH_S = 0.02  # publish for at most this long (wall) between executor steps

PARAMS = (
    ParamSpec("path", "", "bag to play (.mcap)"),
    ParamSpec("pace", 0.0, "0: as fast as the readers take it; F > 0: F times real time", range=(0.0, 1e6)),
    ParamSpec("topics", [], "topics to play; [] plays every data topic of the bag but "
                            + ", ".join(NOT_PLAYED)),
    ParamSpec("exit_when_done", True, "end the process after the last message"),
    ParamSpec("progress", True, "print progress as JSON lines on stdout (for the launcher)"),
)


class PlayerNode(GraphNode):
    PARAMS = PARAMS

    def __init__(self) -> None:
        super().__init__(PLAYER)

        path = self.param("path")
        try:
            info = bagio.bag_info(path)
        except Exception as exc:  # noqa: BLE001 - UserError or an unreadable file: one line
            raise NodeStartError(f"parameter path = {path!r}: {exc}") from None
        if not info["finished"]:
            raise NodeStartError(f"parameter path = {path!r}: the bag is not finished; run phfdi bag recover first")
        counts = {t["topic"]: t["count"] for t in info["topics"]}
        types = {t["topic"]: t["type"] for t in info["topics"]}
        wanted = list(self.param("topics")) or [t for t in counts if t not in NOT_PLAYED]
        unknown = [t for t in wanted if t not in counts]
        if unknown:
            raise NodeStartError(f"parameter topics: {unknown[0]} is not in the bag (it has {', '.join(counts)})")
        # one sample per /plant/measurement (a run of the graph), else per /measured/sample (a measured record)
        self.sample_topic = MEASUREMENT.name if MEASUREMENT.name in counts else MEASURED_SAMPLE.name
        self.samples = counts.get(self.sample_topic, 0)
        self.n_messages = sum(counts[t] for t in wanted)
        self.pubs = {t: self.data_publisher(_message_class(types[t]), t) for t in wanted}
        self.pub_clock = self.create_publisher(Clock, CLOCK.name, 10)
        self._clock_msg = Clock()
        self._file = open(path, "rb")
        self._messages = None
        self._pace = self.param("pace")
        self._sent = 0
        self._sample = 0
        self._report_every = max(1, self.samples // 20)
        self._started = False
        self._done = False
        self.start_barrier()

    def _emit(self, event: str, **fields) -> None:
        if self.param("progress"):
            print(json.dumps({"event": event, **fields}), flush=True)

    def on_connected(self) -> None:
        from mcap.reader import make_reader

        self._messages = make_reader(self._file).iter_messages(topics=list(self.pubs), log_time_order=True)
        self._t0 = time.perf_counter()
        self._wall0 = time.monotonic()
        self._first_ns: int | None = None
        self._emit("connected", samples=self.samples, sample_time_s=self.dt_s, scenario=self.spec.name)
        self.get_logger().info(f"graph connected: playing {self.n_messages} messages ({self.samples} samples)")
        self._started = True

    def spin_timeout_s(self) -> float:
        return 0.0 if self._started and not self._done else 0.1

    def after_spin(self) -> None:
        if not self._started or self._done:
            return
        until = time.monotonic() + BATCH_S
        for _schema, channel, message in self._messages:
            if self._pace > 0.0:
                if self._first_ns is None:
                    self._first_ns = message.log_time
                due = self._wall0 + (message.log_time - self._first_ns) * 1e-9 / self._pace
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(min(delay, 0.1))
            self._publish(self.pubs[channel.topic], message.data)
            self._sent += 1
            if channel.topic == self.sample_topic:
                self._tick(message.log_time)
            if time.monotonic() >= until:
                return
        self._finish()

    def _publish(self, pub, cdr: bytes, patience_s: float = 60.0) -> None:
        """Publish, waiting while a reader's backlog fills the writer's history (the publish then fails
        after blocking: seen with a reader stalled for seconds); give up after ``patience_s``."""
        from rclpy._rclpy_pybind11 import RCLError

        deadline = time.monotonic() + patience_s
        while True:
            try:
                pub.publish(cdr)
                return
            except RCLError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.05)

    def _tick(self, stamp_ns: int) -> None:
        if self.pub_clock.get_subscription_count():  # only nodes with use_sim_time listen
            self._clock_msg.clock.sec, self._clock_msg.clock.nanosec = split_ns(stamp_ns)
            self.pub_clock.publish(self._clock_msg)
        self._sample += 1
        if self._sample % self._report_every == 0:
            self._emit("progress", sample=self._sample, of=self.samples)

    def _finish(self) -> None:
        self._done = True
        wall = time.perf_counter() - self._t0
        self.flush_publishers(30.0)
        self._emit("done", samples=self._sample, messages=self._sent, wall_s=wall)
        self.get_logger().info(f"done: {self._sent} messages ({self._sample} samples) in {wall:.2f} s")
        if self.param("exit_when_done"):
            self.finished = True

    def close(self) -> None:
        super().close()
        self._file.close()


def run() -> int:
    return main(PlayerNode, "phfdi.ros.player", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
