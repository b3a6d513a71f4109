"""What rosbag2 (ROS 2 Jazzy) writes into an MCAP bag besides the messages, so that its tools accept ours.

rosbag2's MCAP storage plugin (``rosbag2_storage_mcap/src/mcap_storage.cpp`` in github.com/ros2/rosbag2)
writes two things that a plain ros2-profile MCAP file lacks:

- every channel's metadata holds ``offered_qos_profiles`` (the publishers' QoS, a YAML list:
  ``rosbag2_storage::serialize_rclcpp_qos_vector``, policies as the strings of ``rmw_qos_*_to_str`` since
  metadata version 9) and ``topic_type_hash`` (the type's RIHS01 hash) (``MCAPStorage::create_topic``);
- when the bag is closed, one MCAP metadata record named ``rosbag2`` with the key ``serialized_metadata``: the
  bag's metadata (``YAML::convert<rosbag2_storage::BagMetadata>::encode``, the body of a rosbag2 folder's
  metadata.yaml without its ``rosbag2_bagfile_information`` key) (``MCAPStorage::update_metadata``).
  ``ros2 bag info`` and ``ros2 bag play`` on a bare .mcap read the bag's metadata from it
  (``MCAPStorage::read_metadata``; without it they take the version as 8 and parse the QoS as numbers).

The QoS written is what a Jazzy ``ros2 bag record`` stores for the graph's publishers: what DDS discovery
reports for them (``get_publishers_info_by_topic``), measured here with rclpy 7.1.6 and Fast DDS 2.14.5 for a
publisher of :data:`phfdi_base.ros.barrier.DATA_QOS`: history unknown (discovery does not carry it; the
publishers keep all), depth 0, the policies, and rmw's infinite duration for deadline, lifespan and lease.

No rclpy and no MCAP here: dictionaries and YAML text for :mod:`phfdi.bagio`'s writer.
"""

from __future__ import annotations

from dataclasses import dataclass

import yaml

from phfdi_base import topics as T
from phfdi_base.errors import UserError
from phfdi_base.yamlfile import load_yaml

#: MCAP metadata record (and key) that rosbag2's MCAP storage plugin writes at close
RECORD_NAME = "rosbag2"
RECORD_KEY = "serialized_metadata"
#: rosbag2_storage::BagMetadata version of ROS 2 Jazzy (rosbag2 0.26): QoS policies as strings
METADATA_VERSION = 9
ROS_DISTRO = "jazzy"
STORAGE_ID = "mcap"
#: RMW_DURATION_INFINITE as rosbag2 stores an rmw_time_t (what discovery reports for "no deadline")
INFINITE = {"sec": 9223372036, "nsec": 854775807}


def offered_qos(qos: dict = T.DATA_QOS) -> list[dict]:
    """The offered QoS of a topic's publishers as ``ros2 bag record`` (Jazzy) stores it: discovery's view."""
    return [{"history": "unknown", "depth": 0, "reliability": qos["reliability"], "durability": qos["durability"],
             "deadline": dict(INFINITE), "lifespan": dict(INFINITE), "liveliness": "automatic",
             "liveliness_lease_duration": dict(INFINITE), "avoid_ros_namespace_conventions": False}]


def _dump(data) -> str:
    """Block-style YAML in the given key order, as yaml-cpp's ``YAML::Dump`` writes it."""
    return yaml.safe_dump(data, default_flow_style=False, sort_keys=False).strip()


def qos_yaml(profiles: list[dict]) -> str:
    """A channel's ``offered_qos_profiles`` metadata value."""
    return _dump(profiles)


#: the longest metadata text parsed from a bag (ours are a few kB for the graph's six topics)
MAX_YAML_CHARS = 1 << 20


def load_from_bag(text: str) -> object | None:
    """YAML text of a bag's metadata, parsed; None if it is not readable YAML, is longer than MAX_YAML_CHARS or
    uses aliases (a bag is input from anywhere: nine nested aliases expand a kilobyte into gigabytes)."""
    if not text or len(text) > MAX_YAML_CHARS:
        return None
    try:
        return load_yaml(text, "bag metadata")  # strict: no aliases, no key twice
    except UserError:
        return None


def parse_qos_yaml(text: str) -> list[dict]:
    """A channel's ``offered_qos_profiles`` back as a list ([] when it is empty or not a readable YAML list)."""
    profiles = load_from_bag(text)
    return profiles if isinstance(profiles, list) else []


@dataclass(frozen=True)
class TopicStats:
    """One topic of a bag file, as the metadata lists it."""

    name: str
    msgtype: str
    offered_qos: list[dict]
    type_hash: str
    message_count: int
    serialization_format: str = "cdr"


def bag_metadata(file_name: str, topics: list[TopicStats], start_ns: int | None, end_ns: int | None) -> dict:
    """rosbag2_storage::BagMetadata of one MCAP file, in the key order of rosbag2's YAML encoder.

    ``start_ns``/``end_ns``: the first and last log time (None when the file holds no message)."""
    start = start_ns if start_ns is not None else 0
    duration = {"nanoseconds": (end_ns - start) if end_ns is not None else 0}
    starting = {"nanoseconds_since_epoch": start}
    count = sum(t.message_count for t in topics)
    return {
        "version": METADATA_VERSION,
        "storage_identifier": STORAGE_ID,
        "duration": duration,
        "starting_time": starting,
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t.name, "type": t.msgtype, "serialization_format": t.serialization_format,
                                "offered_qos_profiles": t.offered_qos, "type_description_hash": t.type_hash},
             "message_count": t.message_count}
            for t in topics],
        "compression_format": "",  # chunk compression is the storage's own, not rosbag2's file/message mode
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [{"path": file_name, "starting_time": dict(starting), "duration": dict(duration),
                   "message_count": count}],
        "custom_data": None,  # rosbag2 encodes an empty map as a null node
        "ros_distro": ROS_DISTRO,
    }


def metadata_record(file_name: str, topics: list[TopicStats], start_ns: int | None,
                    end_ns: int | None) -> dict[str, str]:
    """The ``rosbag2`` MCAP metadata record's content: ``{"serialized_metadata": YAML}``."""
    return {RECORD_KEY: _dump(bag_metadata(file_name, topics, start_ns, end_ns))}

