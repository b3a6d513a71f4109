"""The QoS and type hash our bags give each channel are what ``ros2 bag record`` (Jazzy) would store for the graph's
publishers: it stores what DDS discovery reports for each (``get_publishers_info_by_topic``), which is asked here
of a real publisher with the graph's data QoS."""

from __future__ import annotations

import time

import pytest

from phfdi import bagio, rosbag2_meta
from phfdi_base import topics as T

pytestmark = [pytest.mark.ros, pytest.mark.timeout(120)]


def _as_rosbag2(profile) -> dict:
    """An rclpy QoSProfile (as discovery reports it) in rosbag2's version-9 YAML form."""

    def duration(d) -> dict:
        return {"sec": d.nanoseconds // 10**9, "nsec": d.nanoseconds % 10**9}

    return {"history": profile.history.name.lower(), "depth": profile.depth,
            "reliability": profile.reliability.name.lower(), "durability": profile.durability.name.lower(),
            "deadline": duration(profile.deadline), "lifespan": duration(profile.lifespan),
            "liveliness": profile.liveliness.name.lower(),
            "liveliness_lease_duration": duration(profile.liveliness_lease_duration),
            "avoid_ros_namespace_conventions": profile.avoid_ros_namespace_conventions}


def test_channel_qos_and_type_hash_are_what_discovery_reports(rclpy_context):
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from phfdi_interfaces.msg import Measurement

    from phfdi_base.ros.barrier import DATA_QOS

    publisher = rclpy.create_node("qos_probe_publisher", context=rclpy_context)
    observer = rclpy.create_node("qos_probe_observer", context=rclpy_context)
    try:
        publisher.create_publisher(Measurement, T.MEASUREMENT.name, DATA_QOS)
        publisher.create_publisher(DiagnosticArray, T.DIAGNOSTICS.name, DATA_QOS)
        for topic in (T.MEASUREMENT, T.DIAGNOSTICS):
            deadline = time.monotonic() + 30
            while not (infos := observer.get_publishers_info_by_topic(topic.name)) and time.monotonic() < deadline:
                time.sleep(0.05)
            (info,) = infos
            assert [_as_rosbag2(info.qos_profile)] == rosbag2_meta.offered_qos(), topic.name
            assert bagio.qos_metadata() == rosbag2_meta.qos_yaml([_as_rosbag2(info.qos_profile)])
            assert str(info.topic_type_hash) == bagio.type_hash(topic.type), topic.name
    finally:  # the fixture ends the context
        observer.destroy_node()
        publisher.destroy_node()
