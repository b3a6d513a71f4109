"""ROS 2 node of the learned detector (thin wrapper of wavelet_fdi.learned_detector.LearnedDetector):
/measured/sample in, /fault_alarm out.

Input: /measured/sample (phfdi_interfaces/MeasuredSample: channel names and values of one row of a
measured record, e.g. played from a bag of ``phfdi bag from-csv``). The channels are matched to the
reference's by name (a channel a message lacks is missing for that row). Output: /fault_alarm
(phfdi_interfaces/FaultAlarm) when an alarm is raised or cleared and when a channel goes missing,
with the channels that carry the alarm (``channels``, ``channel_shares``, ``channel_bands``); for a
reference that names faults (the estimator), once more when the alarm is named (``fault_class``,
``severity`` and ``severity_unit``: the hypothesis that explains it best and its size).

The reference is the kind the model file names (a learned ARX reference from ``phfdi calibrate --learn``,
the rig's Kalman estimator from ``phfdi calibrate --estimator``, ...). The core takes each row at its
stamp in seconds (:func:`phfdi_base.stamps.stamp_seconds`; ``phfdi bag from-csv`` stamps a row with the
record's own time to the ns), the times the offline ``phfdi replay RECORD --reference REF`` gives it: the
estimator steps by their differences.

Callbacks only queue rows; a worker thread hands everything queued to the core in one call (the
result is the same for any chunking; :mod:`wavelet_fdi.node_base`). The node prints one JSON line per
published change and, on exit, a ``detector_done`` report with every alarm (the launcher and
``phfdi replay --live`` read it).

    python -m wavelet_fdi.learned_node --ros-args -p reference:=ref.json -p graph_nodes:="[detector]"
"""

from __future__ import annotations

import math
import sys
import traceback

import numpy as np
from phfdi_interfaces.msg import FaultAlarm, MeasuredSample

from phfdi_base.errors import UserError
from phfdi_base.ros.graph_node import NodeStartError, ParamSpec, main, to_time
from phfdi_base.stamps import seconds_to_ns, stamp_seconds, time_ns
from phfdi_base.topics import MEASURED_SAMPLE

from .learned_detector import LearnedDetector, LearnedModel
from .node_base import DetectorNodeBase

PARAMS = (
    ParamSpec("reference", "", "learned reference file (.json) from phfdi calibrate --learn or --estimator"),
    ParamSpec("loop", "measured", "name of the monitored plant or loop in /fault_alarm"),
)
STATE_OF_KIND = {"alarm": FaultAlarm.ALARM, "cleared": FaultAlarm.OK}


class LearnedDetectorNode(DetectorNodeBase):
    PARAMS = PARAMS
    WORKER_NAME = "learned-detector-core"

    def __init__(self) -> None:
        super().__init__()
        path = self.param("reference")
        if not path:
            raise NodeStartError("parameter reference: give the learned reference file (phfdi calibrate --learn)")
        try:
            self.model = LearnedModel.load(path)
        except UserError as exc:
            raise NodeStartError(f"parameter reference = {path!r}: {exc}") from None
        self.core = LearnedDetector(self.model)
        self._index = {c: i for i, c in enumerate(self.model.channels)}
        self._t_last = 0.0
        self.open_alarm_output()
        self.data_subscription(MeasuredSample, MEASURED_SAMPLE.name, self._on_sample)
        self._received = 0
        self.start_worker()
        self.start_barrier()

    # ---- executor thread: queue only ----------------------------------------------------------
    def _on_sample(self, msg: MeasuredSample) -> None:
        row = np.full(len(self._index), np.nan)
        for name, value in zip(msg.names, msg.values):
            i = self._index.get(name)
            if i is not None:
                row[i] = value
        self._received += 1
        self.enqueue([(stamp_seconds(time_ns(msg.stamp)), row)])

    def received(self) -> int:
        return self._received

    # ---- worker thread: the core and the publisher --------------------------------------------
    def process(self, rows: list[tuple[float, np.ndarray]]) -> None:
        t = np.array([r[0] for r in rows])
        x = np.vstack([r[1] for r in rows])
        try:
            events, _ = self.core.process(t, x)
        except Exception:  # noqa: BLE001 - a bug must not take the observer down: report, keep going
            self.core_errors += 1
            self.get_logger().error(f"learned detector failed on {len(rows)} rows:\n" + traceback.format_exc())
            return
        self._t_last = float(t[-1])
        for ev in events:
            self._publish(ev)

    def _publish(self, ev) -> None:
        state = STATE_OF_KIND.get(ev.kind, self._state if self._state == FaultAlarm.ALARM else FaultAlarm.WARN)
        msg = FaultAlarm(loop=self._loop, state=state, message=ev.message, severity=math.nan, wavelet_level=-1)
        msg.stamp = to_time(seconds_to_ns(ev.time_s))
        a = ev.alarm
        if a:
            iso = a.get("isolation") or {}
            msg.fault_class = iso.get("fault_class", "unknown")  # named NAMING_AFTER samples after the detection
            if iso:
                msg.severity, msg.severity_unit = float(iso["size"]), str(iso["unit"])
            msg.detection_time = to_time(seconds_to_ns(a["detection_time"]))
            msg.statistic, msg.threshold = float(a["statistic_value"]), float(a["threshold"])
            cont = a["contributions"] if ev.kind == "alarm" else a.get("episode_contributions") or a["contributions"]
            msg.channels = list(cont)
            msg.channel_shares = [float(v["share"]) for v in cont.values()]
            msg.channel_bands = [max(v["bands"], key=v["bands"].get) for v in cont.values()]
            band = msg.channel_bands[0] if msg.channel_bands else ""
            msg.wavelet_level = int(band[1:]) if band.startswith("D") else 0 if band.startswith("A") else -1
        self.publish_alarm(msg, ev.kind, ev.time_s, a)
        self._state = state

    # ---- the end ---------------------------------------------------------------------------------
    def finish(self) -> None:
        """The stream ended: name the alarms still waiting for their window (as the offline replay does)."""
        for ev in self.core.finish():
            self._publish(ev)

    def done_report(self) -> dict:
        return {"samples": self.core.samples_processed, "alarms": self.core.alarms, "core_errors": self.core_errors,
                "reference": self.param("reference")}


def run() -> int:
    return main(LearnedDetectorNode, "wavelet_fdi.learned_node", __doc__.strip().splitlines()[0], PARAMS)


if __name__ == "__main__":
    sys.exit(run())
