"""The graph's topics: one table for the nodes, the recorder, the bag tools and the docs.

Every data message starts with its simulated time stamp (``stamp``, or
``clock`` for /clock, ``header.stamp`` for /diagnostics): the stamp of sample k
is k * sample_time_s. Lock-step order of one sample (as :func:`phfdi.loop.tick`):

    plant        /plant/measurement, /clock (k)
    controllers  /controller/output (k)
    valve        /valve/state (k)
    plant        integrates to k + 1, /plant/measurement, /clock (k + 1), /plant/state (k)

One message per node and sample: in rclpy each message costs tens of
microseconds to build and decode, which bounds the lock-step rate.

No rclpy import here: the bag tools use this table without ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

from .stamps import sample_period_ns  # noqa: F401  (the stamps' time base, named with the topics)

# node names (the ROS node name and the launcher's label)
PLANT = "plant"
CONTROLLERS = "controllers"
VALVE = "valve"
RECORDER = "recorder"
DETECTOR = "detector"
LIVE_VIEW = "foxglove"  # the live view's bridge (phfdi launch --foxglove)

#: nodes a lock-step graph cannot run without
LOOP_NODES = (PLANT, CONTROLLERS, VALVE)


@dataclass(frozen=True)
class Topic:
    name: str
    type: str  # "package/msg/Type"
    publisher: str
    per_sample: bool  # one message per simulated sample
    description: str


MEASUREMENT = Topic("/plant/measurement", "phfdi_interfaces/msg/Measurement", PLANT, True,
                    "pH probe and level transmitter readings: ph (pH), level_cm (cm)")
CLOCK = Topic("/clock", "rosgraph_msgs/msg/Clock", PLANT, True,
              "simulated time, one message per sample (for nodes with use_sim_time)")
CONTROLLER = Topic("/controller/output", "phfdi_interfaces/msg/ControllerOutput", CONTROLLERS, True,
                   "both PI loops: setpoints (pH, cm) and outputs = valve commands (%)")
VALVE_STATE = Topic("/valve/state", "phfdi_interfaces/msg/ValveState", VALVE, True,
                    "pH valve and outlet valve: command, stem position (%), opening, flow (mL/s), fault severity")
PLANT_STATE = Topic("/plant/state", "phfdi_interfaces/msg/PlantState", PLANT, True,
                    "simulation ground truth: true pH and level, feed and outlet flows (mL/s), sensor fault")
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", VALVE, False,
                    "valve health: commands held (not finite / out of range), active faults; the detector's "
                    "input counters, state and processing lag")
MEASURED_SAMPLE = Topic("/measured/sample", "phfdi_interfaces/msg/MeasuredSample", "player", True,
                        "one row of a measured record (phfdi bag from-csv): channel names and values")
FAULT_ALARM = Topic("/fault_alarm", "phfdi_interfaces/msg/FaultAlarm", DETECTOR, False,
                    "the fault detector's state: on every change and as a heartbeat")
DETECTOR_MONITOR = Topic("/detector/monitor", "phfdi_interfaces/msg/MeasuredSample", DETECTOR, False,
                         "the detector's residuals and CUSUM statistics over their thresholds, for the live view "
                         "(detector parameter monitor_topic; names ph_residual, level_residual_cm, "
                         "ratio:<statistic>); not recorded")

#: every topic the recorder can write, in lock-step order
RECORDABLE: tuple[Topic, ...] = (MEASUREMENT, CLOCK, CONTROLLER, VALVE_STATE, PLANT_STATE, DIAGNOSTICS, FAULT_ALARM)
#: what it writes by default: all but /clock, which repeats the stamps every message
#: carries and the bag's log times (players regenerate it, as ``ros2 bag play --clock``)
RECORDED: tuple[Topic, ...] = tuple(t for t in RECORDABLE if t is not CLOCK)
BY_NAME = {t.name: t for t in RECORDABLE}

#: where nodes announce that their endpoints are up and matched (not recorded)
GRAPH_READY = "/graph/ready"

#: QoS every publisher of a data topic offers. Reliable and keep-all: nothing is lost, a slow
#: reliable reader slows the writer down. Bags store it as discovery reports it, which is what
#: ``ros2 bag record`` stores (no history, infinite durations: :func:`phfdi.rosbag2_meta.offered_qos`).
DATA_QOS = {"history": "keep_all", "depth": 0, "reliability": "reliable", "durability": "volatile"}


def stamp_ns(k: int, dt_ns: int) -> int:
    """Stamp (ns) of sample k."""
    return k * dt_ns


